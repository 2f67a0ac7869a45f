"""A line-run scenario: the line, the trains' timetable, the radio, what happens when
(the format is in docs/line-run.md; its JSON Schema: ``railpilot schema line-run``).

TOML::

    name = "A day on the heavy-haul line"
    line = "heavy-haul"             # a shipped line or a line file (relative to this file)
    seed = 1                        # the radio's and the reconnects' randomness
    duration_h = 9.0                # simulated time [h]
    conflicts = "refuse"            # trains sharing a block section: refused, or "shift"
                                    # (each later train moved later until none does)

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
its end; and against each other (railpilot.schema.cross_checks): every km post on the
line, every station one of its, at most MAX_LINE_RUN_TRAINS trains. An error names the
field (``services[2].every_min``), its value and what is allowed.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from railpilot.errors import MISSING, ConfigError, ScenarioError
from railpilot.ground.online_retimer import RetimerSettings
from railpilot.ground.operations import OPS, Operation, OperationError, parse_operation
from railpilot.line.loader import SHIPPED_LINES, load_line
from railpilot.line.model import RailLine
from railpilot.schema.cross_checks import (
    on_line,
    running_times_possible,
    station_of,
    timetable_stations,
    trains_within,
)
from railpilot.schema.line_run import (
    GROUND_RESTART,
    MAX_LINE_RUN_TRAINS,
    MAX_LINE_RUN_TRAINS_WHY,
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
from .driver import Service, Stop, fastest_run, planned_running_time_s
from .headway import ConflictsRemain, headway_conflicts, shift_until_clear

__all__ = [
    "MAX_SEED",
    "TRAIN_MODELS",
    "GroundRestart",
    "LineScenario",
    "ScenarioEvent",
    "TrainFailure",
    "check_timetable",
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
    #: with ``conflicts = "shift"``: how far [s] each train was moved later to clear a
    #: timetable conflict, by id (cosim/headway.py)
    shifted_s: Mapping[int, float] = field(default_factory=dict)

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
    # before any train is planned: a file asking for too many is refused at once
    trains_within(
        "services",
        sum(t.count for t in tables),
        MAX_LINE_RUN_TRAINS,
        f"{MAX_LINE_RUN_TRAINS_WHY}; the services' counts summed",
        ScenarioError,
    )
    for i, (table, raw) in enumerate(zip(tables, written, strict=True)):
        where = f"services[{i}]."
        ends = [
            station_of(f"{where}{key}", raw[key], line, ScenarioError) for key in ("from", "to")
        ]
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
    uses = Counter(s.train_id for s in services)
    twice = sorted(i for i, n in uses.items() if n > 1)
    if twice:
        # the entries that give the first id used twice: the later one is the one to change
        entries = [i for i, t in enumerate(tables) if t.first_id <= twice[0] < t.first_id + t.count]
        given = " and ".join(f"services[{i}]" for i in entries)
        raise ScenarioError(
            f"services[{entries[-1]}].first_id",
            tables[entries[-1]].first_id,
            f"train ids used once: {given} both give train {twice[0]} (first_id and count "
            f"overlap; {len(twice)} id(s) in all)",
        )
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
                MISSING if op is None else op,
                f"one of {', '.join((*OPS, TRAIN_FAILURE, GROUND_RESTART))}",
            )
        else:
            try:
                action = parse_operation(op, fields, line=line, now_s=epoch_s + at_s)
            except OperationError as error:
                name, why = next(iter(error.errors.items()))
                refused = ScenarioError(f"{where}{name}", fields.get(name), why)
                # the ground's own message says the value and what is allowed (or that it
                # is required): said once, in the words of every other file error
                required = "required: "
                if why.startswith(required):
                    sentence = f"{where}{name} is missing: expected {why[len(required) :]}"
                else:
                    sentence = f"{where}{name} = {why}"
                refused.args = (sentence,)
                raise refused from None
        events.append(ScenarioEvent(at_s, action, str(op), fields))
    return tuple(sorted(events, key=lambda e: e.at_s))


def _no_headway_conflicts(
    tables: list[ServiceTable], services: tuple[Service, ...], line: RailLine, margin: float
) -> None:
    """No two trains in one block section at once as the timetable runs them
    (cosim/headway.py): the later one would only stand at a red signal. The error names
    the entry that makes the later train of the earliest conflict: its ``every_min`` when
    both trains are of that entry, else its ``first_departure_min``."""
    conflicts = headway_conflicts(services, line, margin)
    if not conflicts:
        return
    entry = {t.first_id + n: i for i, t in enumerate(tables) for n in range(t.count)}
    earliest = conflicts[0]
    i = entry[earliest.second.train_id]
    key = "every_min" if entry[earliest.first.train_id] == i else "first_departure_min"
    more = f" ({len(conflicts)} conflicts in all)" if len(conflicts) > 1 else ""
    raise ScenarioError(
        f"services[{i}].{key}",
        getattr(tables[i], key),
        "trains of one track never in one block section at once (docs/line-run.md, "
        f"'Timetable conflicts'), but {earliest.describe()}{more}",
    )


def _dead_zones_on_line(channel: ChannelModel, line: RailLine) -> None:
    """Every dead zone of the radio lies on the line (its ends within the line's km posts):
    one beyond them would never be met, and the run would seem to prove the radio robust."""
    for i, zone in enumerate(channel.dead_zones):
        for key, km in (("start_km", zone.start_km), ("end_km", zone.end_km)):
            on_line(f"channel.dead_zones[{i}].{key}", km, line, ScenarioError)


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


def line_of(name: str, folder: str | os.PathLike[str] | None) -> RailLine:
    """The line a file names: a shipped line, or a line file, whose path is taken from
    ``folder`` (the naming file's, so the file runs from any working directory) unless it
    is absolute; ``folder`` None: from the working directory."""
    if name in SHIPPED_LINES:
        return load_line(name)
    path = Path(name) if folder is None else Path(folder) / name
    if not path.is_file():
        shipped = ", ".join(SHIPPED_LINES)
        raise ScenarioError(
            "line",
            name,
            f"a shipped line ({shipped}) or a line file, its path relative to this file's "
            f"folder (there is no file {path})",
        )
    return load_line(path)


def line_scenario_from_mapping(
    data: Mapping[str, Any], folder: str | os.PathLike[str] | None = None
) -> LineScenario:
    """A :class:`LineScenario` from a parsed file, every field checked (module docstring);
    ``folder``: the file's, where a line file it names is found (:func:`line_of`)."""
    top = check(LineRunFileTable, data, ScenarioError, top="scenario")
    line = line_of(top.line, folder)
    margin = float(top.margin_kmh)
    duration_s = float(top.duration_h) * 3600.0
    epoch_s = float(top.start_epoch_s) if top.given("start_epoch_s") else DEFAULT_EPOCH_S
    channel = ChannelModel.from_mapping(top.channel)
    _dead_zones_on_line(channel, line)
    retiming = _retiming(top.retiming)
    services = _services(top.services, data["services"], line, margin)
    shifts: dict[int, float] = {}
    if top.conflicts == "shift":
        try:
            services, shifts = shift_until_clear(services, line, margin, duration_s)
        except ConflictsRemain as left:
            raise ScenarioError(
                "conflicts",
                "shift",
                "'refuse', or 'shift' with room in the run for every train: moved later "
                f"to clear it, a train would leave after the run's end ({left})",
            ) from None
    else:  # a shift ends only once no conflict is left
        _no_headway_conflicts(top.services, services, line, margin)
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
        shifts,
    )


def load_line_scenario(path: str | os.PathLike[str]) -> LineScenario:
    """Read and check a line-run file (TOML, or JSON if its name ends in ``.json``);
    errors name the file."""
    name = os.path.basename(path)
    data = read_document(path, "SCENARIO", "line-run file", ScenarioError)
    try:
        return line_scenario_from_mapping(data, Path(path).parent)
    except ConfigError as error:
        raise error.in_file(name, ScenarioError) from None


def check_timetable(
    sections: Sequence[Any],
    line: RailLine,
    preset_name: str,
    margin_kmh: float,
    driven: tuple[int, int] | None = None,
) -> None:
    """A timetable (its ``sections``, railpilot.onboard.timetable) against the line and the
    train that runs it, before anything runs: every station one of the line's, and no
    running time below the train's fastest run of its section (with the drive's
    ``margin_kmh``). ``driven``: the sections from station ``driven[0]`` on to
    ``driven[1]`` (the ones a drive runs), whose running times alone are checked (None:
    every section's)."""
    timetable_stations(sections, line, ConfigError)
    indexed = list(enumerate(sections))
    if driven is not None:
        start = next((i for i, s in indexed if s.from_id == driven[0]), len(indexed))
        end = next((i for i, s in indexed[start:] if s.to_id == driven[1]), len(indexed) - 1)
        indexed = indexed[start : end + 1]

    def fastest_s(from_id: int, to_id: int) -> float:
        return fastest_run(line, preset_name, from_id, to_id, margin_kmh).running_time_s

    how = f"up to the speed limits less {margin_kmh:g} km/h, --margin"
    running_times_possible(indexed, fastest_s, preset_name, ConfigError, how)
