"""The braking scenario file's format (``kind = "ep-braking"``, the default): its tables,
keys and types; examples/paper000_smarc_ep.toml is a complete one.

The values' bounds are the config dataclasses' (railpilot.scenario.model, the brakes, the
sim): a key the file leaves out is not passed to them, so their defaults apply, and they
check what the file gives. Where the reader itself bounds a key (a km post, a mass > 0),
the bound is declared here.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, create_model

from railpilot.brakes.registry import BRAKES
from railpilot.control.registry import CONTROLLERS
from railpilot.schema.config import ConfigTable, config_table
from railpilot.schema.fields import NOT_GIVEN, FloatHeld, Says, Unit, WhenMissing, tagged
from railpilot.schema.line_table import KmPost, LineTable
from railpilot.units import MAX_KM_POST

Positive = Annotated[float, Field(gt=0.0)]
AtLeastZero = Annotated[float, Field(ge=0.0)]
Whole = Annotated[int, FloatHeld()]
#: the resistance a0, a1, a2 [N/kN, v in km/h]; a nan or inf is the dataclass's to refuse
Davis = Annotated[
    list[Annotated[float, Field(allow_inf_nan=True)]],
    Field(min_length=3, max_length=3),
    Says("a list of 3 numbers", whole=True),
]
SCENARIO_NAME = (
    "a scenario name: the one key every scenario file must give (every other key has a "
    "default: the config dataclasses of railpilot.scenario.model; the keys are listed at "
    "the top of railpilot/scenario/loader.py)"
)


class ElectricBrakeTable(ConfigTable):
    """``[train.electric_brake]``: the electric brake's force and power limits."""

    max_force_kn: Annotated[float, Unit("kN")] = NOT_GIVEN
    max_power_kw: Annotated[float, Unit("kW")] = NOT_GIVEN


class TrainTable(ConfigTable):
    """``[train]``: the point-mass train (defaults: railpilot.vehicle.train.Train)."""

    mass_t: Annotated[Positive, Unit("t")] = NOT_GIVEN
    rotating_mass_factor: float = NOT_GIVEN
    length_m: Annotated[Positive, Unit("m")] = NOT_GIVEN
    max_service_decel_mps2: Annotated[Positive, Unit("m/s^2")] = NOT_GIVEN
    motor_cars: Whole = NOT_GIVEN
    davis: Davis = NOT_GIVEN
    electric_brake: ElectricBrakeTable = NOT_GIVEN


def _brake_table(name: str, cls: type) -> type[ConfigTable]:
    """A brake model's table: its config dataclass's keys and ``model = name``."""
    base = config_table(cls)
    tag = Literal[name]  # type: ignore[valid-type]
    model: type[ConfigTable] = create_model(
        f"{cls.__name__}Table",
        __base__=base,
        __doc__=f'``[brake]`` with ``model = "{name}"``: {base.__doc__}',
        model=(tag, name),
    )
    return model


#: the default brake model (a table without ``model``)
DEFAULT_BRAKE = "ep-blended"
BRAKE_TABLES = {name: _brake_table(name, entry.cls) for name, entry in BRAKES.items()}
BrakeTable = tagged("model", DEFAULT_BRAKE, BRAKE_TABLES)


class _ReferenceTable(ConfigTable):
    start_km: KmPost = NOT_GIVEN
    v0_kmh: Annotated[float, Unit("km/h")] = NOT_GIVEN
    decel_mps2: Annotated[float, Unit("m/s^2")] = NOT_GIVEN


class SmoothReferenceTable(_ReferenceTable):
    """``[reference]`` with ``shape = "smooth"`` (the default): a braking curve with
    jerk-limited transitions (railpilot.scenario.model.SmoothStopSpec)."""

    shape: Literal["smooth"] = "smooth"
    coast_s: Annotated[float, Unit("s")] = NOT_GIVEN
    jerk_mps3: Annotated[float, Unit("m/s^3")] = NOT_GIVEN
    final_decel_mps2: Annotated[float, Unit("m/s^2")] = NOT_GIVEN
    final_phase_speed_kmh: Annotated[float, Unit("km/h")] = NOT_GIVEN
    ease_out: bool = NOT_GIVEN


class ConstantReferenceTable(_ReferenceTable):
    """``[reference]`` with ``shape = "constant"``: a constant deceleration."""

    shape: Literal["constant"]
    coast_s: Annotated[float, Unit("s")] = NOT_GIVEN
    decel_mps2: Annotated[float, Unit("m/s^2")]


class DriveReferenceTable(_ReferenceTable):
    """``[reference]`` with ``shape = "drive"``: a whole run from ``start_km`` to
    ``stop_km`` under the line's speed limits."""

    shape: Literal["drive"]
    stop_km: KmPost
    cruise_kmh: Annotated[float, Unit("km/h")] = NOT_GIVEN
    accel_mps2: Annotated[float, Unit("m/s^2")] = NOT_GIVEN


ReferenceTable = tagged(
    "shape",
    "smooth",
    {
        "smooth": SmoothReferenceTable,
        "constant": ConstantReferenceTable,
        "drive": DriveReferenceTable,
    },
)


class RegionTable(ConfigTable):
    """A region of extra force: ``force_kn`` or ``accel_mps2`` (exactly one; the
    reader's rule) from ``start_km`` to ``end_km``."""

    start_km: KmPost
    end_km: KmPost
    force_kn: Annotated[float, Unit("kN")] = NOT_GIVEN
    accel_mps2: Annotated[float, Unit("m/s^2")] = NOT_GIVEN


class DisturbanceTable(ConfigTable):
    """``[disturbance]``: forces on the train (railpilot.sim.disturbance)."""

    regions: list[RegionTable] = Field(default_factory=list)
    constant_kn: Annotated[float, Unit("kN")] = NOT_GIVEN
    random_std_kn: Annotated[float, Unit("kN")] = NOT_GIVEN
    random_hold_s: Annotated[float, Unit("s")] = NOT_GIVEN
    target_fraction: float = NOT_GIVEN
    seed: Whole = NOT_GIVEN


class AtoTable(ConfigTable):
    """``[ato]``: what the controllers believe about the train
    (railpilot.scenario.model.ATOModel)."""

    mass_t: Annotated[float, Unit("t")] = NOT_GIVEN
    brake_delay_s: Annotated[float, Unit("s")] = NOT_GIVEN
    brake_lag_s: Annotated[float, Unit("s")] = NOT_GIVEN
    reference: str = NOT_GIVEN
    gradient_feedforward: bool = NOT_GIVEN
    preview_s: Annotated[float, Unit("s")] = NOT_GIVEN
    davis: Davis = NOT_GIVEN


#: ``[controller]``: ``name`` (a built-in or ``module:Name``) and a table of parameters
#: for each built-in controller (its constructor's keywords)
_CONTROLLER_PARAMS: dict[str, Any] = {
    controller: (Annotated[dict[str, Any], Says("a table of controller parameters")], NOT_GIVEN)
    for controller in CONTROLLERS
}
ControllerTable: type[ConfigTable] = create_model(
    "ControllerTable",
    __base__=ConfigTable,
    __doc__="``[controller]``: which controller runs, and each built-in's parameters.",
    name=(str, NOT_GIVEN),
    **_CONTROLLER_PARAMS,
)


class SimTable(ConfigTable):
    """``[sim]``: the run's step, length and control period
    (railpilot.scenario.model.SimSettings)."""

    dt_s: Annotated[float, Unit("s")] = NOT_GIVEN
    duration_s: Annotated[float, Unit("s")] = NOT_GIVEN
    control_period_s: Annotated[float, Unit("s")] = NOT_GIVEN
    record_every: Whole = NOT_GIVEN


BaliseKm = Annotated[float, Field(ge=-MAX_KM_POST, le=MAX_KM_POST, allow_inf_nan=True), Unit("km")]


class RealismTable(ConfigTable):
    """``[realism]``: the measurement and adhesion effects (railpilot.sim.realism)."""

    balises_km: Annotated[
        list[Annotated[BaliseKm, Says(f"a km post in [{-MAX_KM_POST:g}, {MAX_KM_POST:g}]")]],
        Says("a list of km posts", whole=True),
    ] = NOT_GIVEN
    speed_noise_std_mps: Annotated[AtLeastZero, Unit("m/s")] = NOT_GIVEN
    speed_resolution_mps: Annotated[AtLeastZero, Unit("m/s")] = NOT_GIVEN
    wheel_scale_error: float = NOT_GIVEN
    slide_slip: float = NOT_GIVEN
    adhesion: AtLeastZero = NOT_GIVEN
    slide_ratio: float = NOT_GIVEN
    notches: Whole = NOT_GIVEN
    seed: Whole = NOT_GIVEN


class UniformTable(ConfigTable):
    """A parameter drawn uniformly from ``[min, max]``."""

    dist: Literal["uniform"] = "uniform"
    min: float
    max: float


class NormalTable(ConfigTable):
    """A parameter drawn from a normal distribution, cut to ``[min, max]``."""

    dist: Literal["normal"]
    min: float = NOT_GIVEN
    max: float = NOT_GIVEN
    mean: float
    std: float


VaryTable = tagged("dist", "uniform", {"uniform": UniformTable, "normal": NormalTable})


class MonteCarloTable(ConfigTable):
    """``[montecarlo]``: a sweep over parameters drawn at random (docs/montecarlo.md)."""

    vary: dict[str, VaryTable] = Field(default_factory=dict)  # type: ignore[valid-type]
    runs: Whole = NOT_GIVEN
    seed: Whole = NOT_GIVEN
    chunk: Whole = NOT_GIVEN


class ScenarioFileTable(ConfigTable):
    """A braking scenario file: a train, its brake, the line, the reference it follows,
    the controller, and the run's settings."""

    kind: Literal["ep-braking"] = "ep-braking"
    name: Annotated[str, WhenMissing(SCENARIO_NAME)]
    train: TrainTable = Field(default_factory=TrainTable)
    line: LineTable = Field(default_factory=LineTable)
    brake: BrakeTable = Field(default_factory=dict, validate_default=True)  # type: ignore[valid-type]
    reference: ReferenceTable = Field(default_factory=dict, validate_default=True)  # type: ignore[valid-type]
    disturbance: DisturbanceTable = Field(default_factory=DisturbanceTable)
    ato: AtoTable = Field(default_factory=AtoTable)
    controller: ControllerTable = Field(default_factory=dict, validate_default=True)  # type: ignore[valid-type]
    sim: SimTable = Field(default_factory=SimTable)
    realism: RealismTable = Field(default_factory=RealismTable)
    montecarlo: MonteCarloTable = NOT_GIVEN
