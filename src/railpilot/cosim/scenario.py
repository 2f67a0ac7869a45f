"""A line-run scenario: the line, the trains' timetable, the radio, what happens when
(the format is in docs/line-run.md; its JSON Schema: ``railpilot schema line-run``).

TOML::

    name = "A day on the heavy-haul line"
    line = "heavy-haul"             # a shipped line or a line file
    seed = 1                        # the radio's and the reconnects' randomness
    duration_h = 9.0                # simulated time [h]

    [channel]                       # cosim/channel.py: latency, loss, dead zones, outages
    loss = 0.3
    dead_zones = [{ start_km = 150.0, end_km = 156.0 }]

    [retiming]                      # the ground re-times trains off plan (ground/online_retimer.py)
    enabled = true                  # the default; false: the fixed plan
    headway_min = 8.0               # fixed-block headway between trains on a section
    energy_weight_s_per_kwh = 0.25  # one kWh is worth this many seconds of lateness
    off_plan_min = 2.0              # a train this far off its plan is re-timed ...
    every_min = 5.0                 # ... at most this often

    [[services]]                    # one train, or a series of them at a fixed interval
    kind = "loaded"                 # loaded | empty (the heavy-haul presets)
    from = 1                        # station ids; the direction follows
    to = 20
    first_departure_min = 10.0
    every_min = 30.0                # optional, with count
    count = 10
    first_id = 101                  # link ids: first_id, first_id + 1, ...
    dwell_min = 5.0                 # planned dwell at each intermediate station
    supplement = 0.10               # running time over the fastest run

    [[events]]                      # at_min, then a dispatcher's operation (ground/operations.py)
    at_min = 60.0
    op = "tsr_set"
    start_km = 120.0
    end_km = 124.0
    limit_kmh = 45
    valid_until_min = 180
    reason = "track work"

    [[events]]
    at_min = 200.0
    op = "train_failure"            # the train brakes to a stand and stands stand_min
    train = 104
    stand_min = 10.0

    [[events]]
    at_min = 240.0
    op = "ground_restart"           # the ground is killed (kill -9) and restarts from its
    down_min = 2.0                  # store down_min later

Every field is checked when the file is read, a dispatcher's operation by the same schema
the admin port, the web page and the command line use, so a scenario that loads runs to
its end. An error names the field (``services[2].every_min``), its value and what is allowed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from railpilot.errors import ConfigError, ScenarioError
from railpilot.ground.online_retimer import RetimerSettings
from railpilot.ground.operations import OPS, Operation, OperationError, parse_operation
from railpilot.line.loader import load_line
from railpilot.line.model import RailLine
from railpilot.schema.line_run import (
    GROUND_RESTART,
    MAX_SEED,
    MAX_TRAIN_ID,
    TRAIN_FAILURE,
    TRAIN_ID,
    TRAIN_MODELS,
    EventTable,
    GroundRestartTable,
    LineRunFileTable,
    RetimingTable,
    ServiceTable,
    TrainFailureTable,
)
from railpilot.schema.reading import read_document
from railpilot.schema.validate import check

from .channel import ChannelModel
from .driver import Service, Stop, planned_running_time_s

__all__ = [
    "MAX_SEED",
    "TRAIN_MODELS",
    "GroundRestart",
    "LineScenario",
    "ScenarioEvent",
    "TrainFailure",
    "line_scenario_from_mapping",
    "load_line_scenario",
]

#: the train kinds a service may name, and their presets (onboard/drive.py)
KINDS = {"loaded": "heavy-haul-loaded", "empty": "heavy-haul-empty"}
#: the link epoch the run starts at when the file gives none [s] (2027-01-15 08:00 UTC)
DEFAULT_EPOCH_S = 1_800_000_000.0


@dataclass(frozen=True)
class TrainFailure:
    train_id: int
    stand_s: float


@dataclass(frozen=True)
class GroundRestart:
    """The ground process is killed and starts again ``down_s`` later from its store."""

    down_s: float


@dataclass(frozen=True)
class ScenarioEvent:
    """Something that happens ``at_s`` seconds into the run."""

    at_s: float
    action: Operation | TrainFailure | GroundRestart
    label: str
    #: the operation's fields as the file gives them (minutes from now, km, km/h): what
    #: the live run sends the ground's admin port at ``at_s``
    fields: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LineScenario:
    name: str
    line: RailLine
    services: tuple[Service, ...]
    channel: ChannelModel
    seed: int = 0
    duration_s: float = 9 * 3600.0
    epoch_s: float = DEFAULT_EPOCH_S
    margin_kmh: float = 5.0
    events: tuple[ScenarioEvent, ...] = field(default_factory=tuple)
    #: how the ground re-times trains off plan (None: it does not; the fixed plan)
    retiming: RetimerSettings | None = field(default_factory=RetimerSettings)
    #: what follows each train's plan: ``point-mass`` or ``consist`` (docs/consist-run.md)
    train_model: str = "point-mass"

    def with_(self, **changes: Any) -> LineScenario:
        """A copy with some fields changed (a sweep's seed, a test's channel)."""
        values = {f: getattr(self, f) for f in self.__dataclass_fields__}
        values.update(changes)
        return LineScenario(**values)


def _services(
    tables: list[ServiceTable], written: list[Mapping[str, Any]], line: RailLine, margin: float
) -> tuple[Service, ...]:
    """The trains of the services ``tables`` (``written``: the same as the file gives them,
    for the errors' values)."""
    services: list[Service] = []
    station_ids = {s.id for s in line.stations}
    for i, (table, raw) in enumerate(zip(tables, written, strict=True)):
        where = f"services[{i}]."
        ends = []
        for key, value in (("from", table.from_), ("to", table.to)):
            if value not in station_ids:
                raise ScenarioError(
                    f"{where}{key}", raw[key], f"a station id of line '{line.name}'"
                )
            ends.append(int(value))
        if ends[0] == ends[1]:
            raise ScenarioError(f"{where}to", ends[1], "a station other than 'from'")
        first, count, every = table.first_departure_min, table.count, table.every_min
        if table.first_id > MAX_TRAIN_ID - count:
            raise ScenarioError(
                f"{where}first_id", table.first_id, f"an integer in [2, {MAX_TRAIN_ID - count}]"
            )
        dwell, supplement = table.dwell_min, table.supplement
        prefix = (
            table.number_prefix
            if table.given("number_prefix")
            else ("K" if table.kind == "loaded" else "E")
        )
        if not prefix.isalnum():
            raise ScenarioError(f"{where}number_prefix", prefix, "1 or 2 letters or digits")
        step = 1 if ends[1] > ends[0] else -1
        stations = list(range(ends[0], ends[1] + step, step))
        preset = KINDS[table.kind]
        for n in range(count):
            t = (first + n * every) * 60.0
            stops = []
            for j, station in enumerate(stations):
                arrival = math.nan
                if j > 0:
                    arrival = t + planned_running_time_s(
                        line, preset, stations[j - 1], station, margin, supplement
                    )
                    t = arrival + dwell * 60.0
                departure = math.nan if j == len(stations) - 1 else t
                stops.append(Stop(station, arrival, departure))
            train_id = table.first_id + n
            services.append(Service(train_id, f"{prefix}{train_id}", preset, tuple(stops)))
    ids = [s.train_id for s in services]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise ScenarioError("services", twice, "train ids used once (first_id and count overlap)")
    return tuple(services)


def _events(
    tables: list[EventTable],
    line: RailLine,
    epoch_s: float,
    duration_s: float,
    train_ids: set[int],
) -> tuple[ScenarioEvent, ...]:
    events = []
    for i, table in enumerate(tables):
        where = f"events[{i}]."
        if not table.at_min <= duration_s / 60.0:
            raise ScenarioError(
                f"{where}at_min", table.at_min, f"a number in [0, {duration_s / 60.0:g}]"
            )
        at_s = table.at_min * 60.0
        op = table.op
        fields = dict(table.model_extra or {})
        action: Operation | TrainFailure | GroundRestart
        if op == GROUND_RESTART:
            restart = check(GroundRestartTable, fields, ScenarioError, at=("events", i))
            action = GroundRestart(float(restart.down_min) * 60.0)
        elif op == TRAIN_FAILURE:
            failure = check(TrainFailureTable, fields, ScenarioError, at=("events", i))
            if failure.train not in train_ids:
                raise ScenarioError(f"{where}train", fields["train"], TRAIN_ID)
            action = TrainFailure(int(failure.train), float(failure.stand_min) * 60.0)
        elif op not in OPS:
            raise ScenarioError(
                f"{where}op",
                op,
                f"one of {', '.join((*OPS, TRAIN_FAILURE, GROUND_RESTART))}"
                + (" (the key is required)" if op is None else ""),
            )
        else:
            try:
                action = parse_operation(op, fields, line=line, now_s=epoch_s + at_s)
            except OperationError as error:
                name, why = next(iter(error.errors.items()))
                refused = ScenarioError(f"{where}{name}", fields.get(name), why)
                # the ground's own message says the value and what is allowed: not again
                refused.args = (f"{where}{name}: {why}",)
                raise refused from None
        events.append(ScenarioEvent(at_s, action, str(op), fields))
    return tuple(sorted(events, key=lambda e: e.at_s))


def _retiming(table: RetimingTable) -> RetimerSettings | None:
    if not table.enabled:
        return None
    default = RetimerSettings()

    def given(key: str, default_value: float) -> float:
        return float(getattr(table, key)) if table.given(key) else default_value

    return RetimerSettings(
        headway_s=given("headway_min", default.headway_s / 60) * 60.0,
        energy_weight_s_per_kwh=given("energy_weight_s_per_kwh", default.energy_weight_s_per_kwh),
        off_plan_s=given("off_plan_min", default.off_plan_s / 60) * 60.0,
        every_s=given("every_min", default.every_s / 60) * 60.0,
    )


def line_scenario_from_mapping(data: Mapping[str, Any]) -> LineScenario:
    """A :class:`LineScenario` from a parsed file, every field checked (module docstring)."""
    top = check(LineRunFileTable, data, ScenarioError, top="scenario")
    line = load_line(top.line)
    margin = float(top.margin_kmh)
    duration_s = float(top.duration_h) * 3600.0
    epoch_s = float(top.start_epoch_s) if top.given("start_epoch_s") else DEFAULT_EPOCH_S
    channel = ChannelModel.from_mapping(top.channel)
    retiming = _retiming(top.retiming)
    services = _services(top.services, data["services"], line, margin)
    events = _events(top.events, line, epoch_s, duration_s, {s.train_id for s in services})
    return LineScenario(
        top.name,
        line,
        services,
        channel,
        top.seed,
        duration_s,
        epoch_s,
        margin,
        events,
        retiming,
        top.trains.model,
    )


def load_line_scenario(path: str | os.PathLike[str]) -> LineScenario:
    """Read and check a line-run file (TOML, or JSON if its name ends in ``.json``);
    errors name the file."""
    name = os.path.basename(path)
    data = read_document(path, "SCENARIO", "line-run file", ScenarioError)
    try:
        return line_scenario_from_mapping(data)
    except ConfigError as error:
        raise ScenarioError(f"{name}: {error.field}", error.value, error.allowed) from None
