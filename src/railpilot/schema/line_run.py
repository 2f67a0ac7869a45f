"""The line-run file's format (docs/line-run.md): the line, the trains' services, the radio,
the ground's re-timing and what happens when.

The rules that need the line or the other keys (a station id of the line, an event within
the run, train ids used once) are the reader's, railpilot.cosim.scenario; the ``[channel]``
table is railpilot.schema.channel's, and a dispatcher's operation in ``[[events]]`` is
railpilot.schema.operations' (the ground reads it, against the line).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, Tag, TypeAdapter, create_model

from railpilot.schema.channel import ChannelFileTable
from railpilot.schema.fields import NOT_GIVEN, FileTable, PlainWords, Says, Unit, number_words
from railpilot.schema.operations import MAX_TRAINS, OPERATIONS

#: the train kinds a service may name
SERVICE_KINDS = ("loaded", "empty")
#: the trains' model in a line run: the point mass (fast), or every vehicle of its consist
TRAIN_MODELS = ("point-mass", "consist")
#: the largest seed (a run's randomness: the radio's and the reconnects')
MAX_SEED = 2**63 - 1
#: the longest run [h], and the latest departure and event [min]
MAX_DURATION_H = 7 * 24.0
MAX_DEPARTURE_MIN = 7 * 24 * 60.0
#: the largest train id (link ids are 16-bit; the ground's own ids lie above)
MAX_TRAIN_ID = 65_000
#: the most trains a line run holds, its services' counts summed: a dispatcher's request
#: (a TSR's ``trains``, a dispatch command) names at most MAX_TRAINS trains, and every train
#: of a run must fit one request; a run that large also costs hours of wall clock (the
#: co-simulation's speed, docs/line-run.md)
MAX_LINE_RUN_TRAINS = MAX_TRAINS
MAX_LINE_RUN_TRAINS_WHY = "the most trains one dispatcher's request may name"
#: a day [min]
DAY_MIN = 24 * 60.0
#: the events that are not a dispatcher's operation
TRAIN_FAILURE = "train_failure"
GROUND_RESTART = "ground_restart"
#: what the ``train`` of a train failure must be
TRAIN_ID = "the id of a train of the scenario"


class LineRunWords(PlainWords):
    """The line-run file's way: every number with its interval."""

    unknown_key = "one of the keys {keys}"

    @staticmethod
    def number(fault: str, gt: float | None, ge: float | None, le: float | None, unit: str) -> str:
        if ge is None or le is None:
            return number_words(gt, ge, le, unit)
        return f"a number in [{ge:g}, {le:g}]"

    @staticmethod
    def whole(ge: float | None, le: float | None) -> str:
        return f"an integer in [{ge}, {le}]"

    @staticmethod
    def required(allowed: str) -> str:
        return f"{allowed} (required)"


class LineRunTable(FileTable):
    WORDS = LineRunWords


class RetimingTable(LineRunTable):
    """``[retiming]``: the ground re-times trains off plan (defaults:
    railpilot.ground.online_retimer.RetimerSettings); ``enabled = false``: the fixed plan."""

    enabled: bool = True
    headway_min: Annotated[float, Field(ge=0.0, le=120.0), Unit("min")] = NOT_GIVEN
    energy_weight_s_per_kwh: Annotated[float, Field(ge=0.0, le=1e4), Unit("s/kWh")] = NOT_GIVEN
    off_plan_min: Annotated[float, Field(ge=0.1, le=120.0), Unit("min")] = NOT_GIVEN
    every_min: Annotated[float, Field(ge=0.1, le=DAY_MIN), Unit("min")] = NOT_GIVEN


class TrainsTable(LineRunTable):
    """``[trains]``: what follows each train's plan."""

    model: Literal["point-mass", "consist"] = "point-mass"


StationId = Annotated[float, Says("a station id of the line")]


class ServiceTable(LineRunTable):
    """``[[services]]``: one train, or ``count`` of them ``every_min`` apart."""

    kind: Literal["loaded", "empty"]
    from_: Annotated[StationId, Field(alias="from")]
    to: StationId
    first_departure_min: Annotated[float, Field(ge=0.0, le=MAX_DEPARTURE_MIN), Unit("min")]
    every_min: Annotated[float, Field(ge=1.0, le=DAY_MIN), Unit("min")] = 60.0
    count: Annotated[int, Field(ge=1, le=1000)] = 1
    #: link ids first_id, first_id + 1, ...; the last at most MAX_TRAIN_ID (the reader's)
    first_id: Annotated[int, Field(ge=2, le=MAX_TRAIN_ID - 1)]
    dwell_min: Annotated[float, Field(ge=0.0, le=600.0), Unit("min")] = 5.0
    supplement: Annotated[float, Field(ge=0.0, le=1.0)] = 0.10
    #: the trains' numbers' prefix (default: K for loaded, E for empty trains)
    number_prefix: Annotated[
        str, Field(min_length=1, max_length=2), Says("1 or 2 letters or digits")
    ] = NOT_GIVEN


class EventTable(LineRunTable):
    """``[[events]]``: at ``at_min``, ``op`` with its own keys: ``train_failure``
    (``train``, ``stand_min``), ``ground_restart`` (``down_min``), or a dispatcher's
    operation (``tsr_set``, ...: its keys in railpilot.schema.operations). The file's
    check reads ``at_min`` and ``op`` here, then the event's keys by its kind (the
    reader's); the JSON Schema lists each kind's keys (:class:`EventsSchema`)."""

    model_config = ConfigDict(extra="allow")

    #: at most the run's duration (the reader's rule)
    at_min: Annotated[float, Field(ge=0.0, le=MAX_DEPARTURE_MIN), Unit("min")]
    #: train_failure, ground_restart or one of the dispatcher's operations (the reader
    #: checks which, and the ground reads an operation against the line)
    op: Any = Field(NOT_GIVEN, json_schema_extra={"type": "string"})


class TrainFailureTable(LineRunTable):
    """A ``train_failure`` event's keys besides ``at_min`` and ``op``: the train brakes to
    a stand and stands ``stand_min``."""

    train: Annotated[float, Says(TRAIN_ID)]
    stand_min: Annotated[float, Field(ge=0.0, le=DAY_MIN), Unit("min")] = 10.0


class GroundRestartTable(LineRunTable):
    """A ``ground_restart`` event's keys besides ``at_min`` and ``op``: the ground is killed
    and restarts from its store ``down_min`` later."""

    down_min: Annotated[float, Field(ge=0.0, le=DAY_MIN), Unit("min")] = 2.0


AtMin = Annotated[float, Field(ge=0.0, le=MAX_DEPARTURE_MIN), Unit("min")]


def _event(name: str, base: type[BaseModel], doc: str) -> Any:
    """The event ``op = name``: ``at_min`` and ``op``, and the keys of ``base``."""
    model = create_model(
        "".join(part.title() for part in name.split("_")) + "Event",
        __base__=base,
        __doc__=doc,
        at_min=(AtMin, ...),
        op=(Literal[name], ...),  # type: ignore[arg-type]
    )
    return Annotated[model, Tag(name)]


class EventsSchema:
    """The JSON Schema of ``[[events]]``: a list of tables, each one kind of event picked
    by its ``op`` (a train's failure, a ground restart, or one of the dispatcher's
    operations, railpilot.schema.operations), so an editor knows each one's keys. The
    reader checks an event's ``at_min`` and ``op`` first, then its keys by its kind."""

    def __get_pydantic_json_schema__(self, schema: Any, handler: Any) -> Any:
        variants = [
            _event(TRAIN_FAILURE, TrainFailureTable, "The train brakes to a stand."),
            _event(GROUND_RESTART, GroundRestartTable, "The ground is killed and restarts."),
            *(_event(op, model, model.__doc__ or op) for op, model in OPERATIONS.items()),
        ]
        union: Any = Annotated[Union[tuple(variants)], Field(discriminator="op")]  # noqa: UP007
        return handler(TypeAdapter(list[union]).core_schema)


class LineRunFileTable(LineRunTable):
    """A line-run file: the line, the trains' timetable, the radio, what happens when."""

    name: str = "line run"
    line: Annotated[str, Says("a shipped line name or a line file path")] = "heavy-haul"
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = 0
    duration_h: Annotated[float, Field(ge=0.01, le=MAX_DURATION_H), Unit("h")] = 9.0
    start_epoch_s: Annotated[float, Field(ge=1.0, le=4.0e9), Unit("s")] = NOT_GIVEN
    margin_kmh: Annotated[float, Field(ge=0.0, le=50.0), Unit("km/h")] = 5.0
    channel: Annotated[ChannelFileTable, Says("a [channel] table")] = Field(
        default_factory=ChannelFileTable
    )
    retiming: Annotated[RetimingTable, Says("a [retiming] table")] = Field(
        default_factory=RetimingTable
    )
    services: Annotated[
        list[ServiceTable],
        Field(min_length=1),
        Says("a list of at least one [[services]] table"),
    ]
    events: Annotated[list[EventTable], Says("a list of [[events]] tables"), EventsSchema()] = (
        Field(default_factory=list)
    )
    trains: Annotated[TrainsTable, Says("a [trains] table")] = Field(default_factory=TrainsTable)
    #: a timetable whose trains would share a block section: refused, or each later train
    #: moved later until none does (docs/line-run.md, "Timetable conflicts")
    conflicts: Literal["refuse", "shift"] = "refuse"
