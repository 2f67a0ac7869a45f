"""The eddy-current brake scenario's format (``kind = "eddy-brake"``,
docs/paper-003-eddy-brake.md): the demand, the run, the controllers' settings, the brake,
coil and train, the torque table and the metrics' windows.

These models check each key alone (its type, and the run's bounds); the rules that need
more than one key (a step that fits the run, a table of a CSV or of the model's grid, the
metrics' windows within the run's range, each controller's own bounds) are the reader's,
railpilot.eddy.scenario. The ``[brake]``, ``[coil]`` and ``[train]`` tables are derived from
the eddy package's config dataclasses (railpilot.schema.config), which check their values;
the reader adds them to :class:`EddyScenarioKeys` (the eddy package imports this one, so
this one cannot import the eddy package).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field, create_model

from railpilot.errors import is_finite_number
from railpilot.schema.fields import (
    NOT_GIVEN,
    FileTable,
    OutOfBounds,
    PlainWords,
    Says,
    Unit,
    WhenMissing,
    says,
)

KIND = "eddy-brake"
CONTROLLERS: tuple[str, ...] = ("open_loop", "pid", "fuzzy", "fuzzy_pi")

#: Paper 003 section 3.1 gains; the derivative filter is Simulink's default N = 100.
PID_DEFAULTS: dict[str, float] = {"kp": 1.5, "ki": 0.00125, "kd": 0.25, "derivative_filter_s": 0.01}
#: Our tuning (grid search, docs/paper-003-eddy-brake.md).
FUZZY_DEFAULTS: dict[str, float] = {
    "e_scale": 2000.0,
    "ce_scale": 100_000.0,
    "u_scale": 10_000.0,
    "ce_filter_s": 0.01,
    "n_grid": 51,
}
FUZZY_PI_DEFAULTS: dict[str, float] = {
    "kp1": 5.0,
    "ki1": 0.0,
    "kp_span": 1.0,
    "ki_span": 0.0,
    "e_scale": 3500.0,
    "ce_scale": 30_000.0,
    "ce_filter_s": 0.01,
    "n_grid": 51,
}
TABLE_GRID_DEFAULTS: dict[str, float] = {
    "max_current_a": 500.0,
    "current_step_a": 2.0,
    "max_speed_kmh": 300.0,
    "speed_step_kmh": 0.5,
}
METRICS_DEFAULTS: dict[str, float] = {
    "settling_band": 0.02,
    "hold_band": 0.01,
    "steady_start_s": 5.0,
    "steady_end_speed_kmh": 30.0,
}
#: Fastest initial speed [km/h] (and so the fastest speed the metrics can name)
MAX_INITIAL_SPEED_KMH = 400.0
#: Longest run [s]: the paper's runs take 100 s and an eddy brake stops a train from the
#: fastest initial speed in minutes; every step is kept for the metrics
MAX_DURATION_S = 3600.0
#: Largest torque demand [N m]: far above what a wheel's adhesion can take (the paper
#: demands 3500-4500 N m)
MAX_TORQUE_DEMAND_NM = 100_000.0
#: the longest step [s] (at most the run's duration too: the reader's rule)
MAX_DT_S = 1e-2
#: the settings that are whole numbers (a float that is one is taken)
WHOLE_SETTINGS = frozenset({"n_grid"})


class EddyWords(PlainWords):
    """The eddy scenario's way: a value that is no number is "a number", nan "a finite
    number"; a number out of bounds is told the range in its unit; an unknown key is told
    the table's keys, sorted, and a value of the wrong kind for a table "a table of keys"."""

    unknown_key = "one of {keys}"
    sorted_keys = True
    not_a_number = "a number"
    float_values = True

    @staticmethod
    def number(fault: str, gt: float | None, ge: float | None, le: float | None, unit: str) -> str:
        return "a finite number"

    @staticmethod
    def table(keys: Sequence[str]) -> str:
        return "a table of keys"


class ParamsWords(EddyWords):
    """A brake's, coil's or train's table: its keys listed in the dataclass's order."""

    sorted_keys = False


class EddyTable(FileTable):
    WORDS = EddyWords


def _whole(value: Any) -> Any:
    """A whole number, as an int (``n_grid = 51.0`` is 51): a flag, a string or a
    fraction is "an integer", a number no float holds "a finite number"."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise says("an integer")
    if isinstance(value, float) and not value.is_integer():
        raise says("an integer")
    if not is_finite_number(value):
        raise says("a finite number")
    return int(value)


#: a whole number, written as an int or a float
Whole = Annotated[int, BeforeValidator(_whole)]


def _settings(name: str, defaults: Mapping[str, float], doc: str) -> type[EddyTable]:
    """The model of a table of numbers with these ``defaults`` (every key optional)."""
    fields: dict[str, Any] = {}
    for key, default in defaults.items():
        kind: Any = float
        if key in WHOLE_SETTINGS:
            kind = Whole
        fields[key] = (kind, Field(NOT_GIVEN, json_schema_extra={"default": default}))
    model: type[EddyTable] = create_model(name, __base__=EddyTable, __doc__=doc, **fields)
    return model


PidTable = _settings("PidTable", PID_DEFAULTS, "``[pid]``: the PID controller's gains.")
FuzzyTable = _settings("FuzzyTable", FUZZY_DEFAULTS, "``[fuzzy]``: the fuzzy controller's scales.")
FuzzyPiTable = _settings(
    "FuzzyPiTable", FUZZY_PI_DEFAULTS, "``[fuzzy_pi]``: the fuzzy PI controller's gains and scales."
)
MetricsTable = _settings(
    "MetricsTable",
    METRICS_DEFAULTS,
    "``[metrics]``: the step metrics' bands (fractions of the demand) and steady window.",
)
TableGridTable = _settings(
    "TableGridTable",
    TABLE_GRID_DEFAULTS,
    "The grid the analytic torque model is sampled on [A, km/h].",
)


class TorqueTableTable(TableGridTable):  # type: ignore[valid-type, misc]
    """``[table]``: the brake body's torque table: a CSV file (``csv``, relative to the
    scenario file), or the grid the analytic model is sampled on (not both)."""

    csv: Annotated[str, Field(min_length=1), Says("a path string")] = NOT_GIVEN


TorqueDemand = Annotated[
    float,
    Field(gt=0.0, le=MAX_TORQUE_DEMAND_NM),
    Unit("N m"),
    OutOfBounds(f"a torque in (0, {MAX_TORQUE_DEMAND_NM:g}] N m"),
]
InitialSpeed = Annotated[
    float,
    Field(gt=0.0, le=MAX_INITIAL_SPEED_KMH),
    Unit("km/h"),
    OutOfBounds(f"a speed in (0, {MAX_INITIAL_SPEED_KMH:g}] km/h"),
]
Duration = Annotated[
    float,
    Field(gt=0.0, le=MAX_DURATION_S),
    Unit("s"),
    OutOfBounds(f"a time in (0, {MAX_DURATION_S:g}] s"),
]

REQUIRED_NUMBER = WhenMissing("a number (this key is required)")


class EddyScenarioKeys(EddyTable):
    """An eddy-current brake scenario: a brake holding a torque demand as the train
    slows, under one of four controllers."""

    kind: Annotated[Literal["eddy-brake"], Says(f"'{KIND}'")] = "eddy-brake"
    torque_demand_nm: Annotated[TorqueDemand, REQUIRED_NUMBER]
    initial_speed_kmh: Annotated[InitialSpeed, REQUIRED_NUMBER]
    name: str = "eddy-brake"
    controller: Literal["open_loop", "pid", "fuzzy", "fuzzy_pi"] = "fuzzy_pi"
    duration_s: Duration = 100.0
    #: at most duration_s too, and at most MAX_STEPS steps of it (the reader's rules)
    dt_s: Annotated[
        float, Unit("s"), Field(json_schema_extra={"exclusiveMinimum": 0.0, "maximum": MAX_DT_S})
    ] = 1e-4
    #: keep every record_every-th step in the stored series (the metrics use every step)
    record_every: Annotated[
        int, Field(ge=1), BeforeValidator(_whole), OutOfBounds("an integer >= 1")
    ] = 10
    table: TorqueTableTable = Field(default_factory=TorqueTableTable)
    metrics: MetricsTable = Field(default_factory=MetricsTable)  # type: ignore[valid-type]
    pid: PidTable = Field(default_factory=PidTable)  # type: ignore[valid-type]
    fuzzy: FuzzyTable = Field(default_factory=FuzzyTable)  # type: ignore[valid-type]
    fuzzy_pi: FuzzyPiTable = Field(default_factory=FuzzyPiTable)  # type: ignore[valid-type]
