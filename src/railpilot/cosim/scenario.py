"""A line-run scenario: the line, the trains' timetable, the radio, what happens when
(issue 12 item 3; the format is in docs/line-run.md).

TOML::

    name = "A day on the heavy-haul line"
    line = "heavy-haul"             # a shipped line or a line file
    seed = 1                        # the radio's and the reconnects' randomness
    duration_h = 9.0                # simulated time [h]

    [channel]                       # cosim/channel.py: latency, loss, dead zones, outages
    loss = 0.3
    dead_zones = [{ start_km = 150.0, end_km = 156.0 }]

    [retiming]                      # the ground re-times trains off plan (ground/retimer.py)
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
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError, ScenarioError, is_finite_number
from railpilot.ground.operations import OPS, Operation, OperationError, parse_operation
from railpilot.ground.retimer import RetimerSettings
from railpilot.line.loader import load_line
from railpilot.line.model import RailLine
from railpilot.textfile import read_toml

from .channel import ChannelModel
from .driver import Service, Stop, planned_running_time_s

#: the train kinds a service may name, and their presets (onboard/drive.py)
KINDS = {"loaded": "heavy-haul-loaded", "empty": "heavy-haul-empty"}
TOP_KEYS = (
    "name",
    "line",
    "seed",
    "duration_h",
    "start_epoch_s",
    "margin_kmh",
    "channel",
    "retiming",
    "services",
    "events",
    "trains",
)
#: the trains' model in a line run: the point mass (fast), or every vehicle of its consist
TRAIN_MODELS = ("point-mass", "consist")
RETIMING_KEYS = (
    "enabled",
    "headway_min",
    "energy_weight_s_per_kwh",
    "off_plan_min",
    "every_min",
)
SERVICE_KEYS = (
    "kind",
    "from",
    "to",
    "first_departure_min",
    "every_min",
    "count",
    "first_id",
    "dwell_min",
    "supplement",
    "number_prefix",
)
#: the events that are not a dispatcher's operation
TRAIN_FAILURE = "train_failure"
GROUND_RESTART = "ground_restart"
#: the largest seed (a run's randomness: the radio's and the reconnects')
MAX_SEED = 2**63 - 1
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


def _number(
    table: Mapping[str, Any],
    key: str,
    where: str,
    low: float,
    high: float,
    default: float | None = None,
) -> float:
    value = table.get(key, default)
    if value is None:
        raise ScenarioError(f"{where}{key}", None, f"a number in [{low:g}, {high:g}] (required)")
    if not is_finite_number(value) or not low <= value <= high:
        raise ScenarioError(f"{where}{key}", value, f"a number in [{low:g}, {high:g}]")
    return float(value)


def _integer(
    table: Mapping[str, Any], key: str, where: str, low: int, high: int, default: int | None = None
) -> int:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ScenarioError(f"{where}{key}", value, f"an integer in [{low}, {high}]")
    return value


def _check_keys(table: Any, where: str, allowed: tuple[str, ...]) -> Mapping[str, Any]:
    if not isinstance(table, Mapping):
        raise ScenarioError(where or "scenario", table, "a table")
    for key in table:
        if key not in allowed:
            raise ScenarioError(
                f"{where}{key}", table[key], f"one of the keys {', '.join(allowed)}"
            )
    return table


def _services(raw: Any, line: RailLine, margin: float) -> tuple[Service, ...]:
    if not isinstance(raw, list) or not raw:
        raise ScenarioError("services", raw, "a list of at least one [[services]] table")
    services: list[Service] = []
    station_ids = {s.id for s in line.stations}
    for i, table in enumerate(raw):
        where = f"services[{i}]."
        _check_keys(table, where, SERVICE_KEYS)
        kind = table.get("kind")
        if not isinstance(kind, str) or kind not in KINDS:
            raise ScenarioError(f"{where}kind", kind, f"one of {', '.join(KINDS)}")
        ends = []
        for key in ("from", "to"):
            value = table.get(key)
            # a number first: a file's list or table is no id, and is unhashable
            if not is_finite_number(value) or value not in station_ids:
                raise ScenarioError(f"{where}{key}", value, f"a station id of line '{line.name}'")
            ends.append(int(value))
        if ends[0] == ends[1]:
            raise ScenarioError(f"{where}to", ends[1], "a station other than 'from'")
        first = _number(table, "first_departure_min", where, 0.0, 7 * 24 * 60.0)
        count = _integer(table, "count", where, 1, 1000, 1)
        every = _number(table, "every_min", where, 1.0, 24 * 60.0, 60.0)
        first_id = _integer(table, "first_id", where, 2, 65_000 - count)
        dwell = _number(table, "dwell_min", where, 0.0, 600.0, 5.0)
        supplement = _number(table, "supplement", where, 0.0, 1.0, 0.10)
        prefix = table.get("number_prefix", "K" if kind == "loaded" else "E")
        if not isinstance(prefix, str) or not 1 <= len(prefix) <= 2 or not prefix.isalnum():
            raise ScenarioError(f"{where}number_prefix", prefix, "1 or 2 letters or digits")
        step = 1 if ends[1] > ends[0] else -1
        stations = list(range(ends[0], ends[1] + step, step))
        preset = KINDS[kind]
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
            train_id = first_id + n
            services.append(Service(train_id, f"{prefix}{train_id}", preset, tuple(stops)))
    ids = [s.train_id for s in services]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise ScenarioError("services", twice, "train ids used once (first_id and count overlap)")
    return tuple(services)


def _events(
    raw: Any, line: RailLine, epoch_s: float, duration_s: float, train_ids: set[int]
) -> tuple[ScenarioEvent, ...]:
    if not isinstance(raw, list):
        raise ScenarioError("events", raw, "a list of [[events]] tables")
    events = []
    for i, table in enumerate(raw):
        where = f"events[{i}]."
        if not isinstance(table, Mapping):
            raise ScenarioError(f"events[{i}]", table, "a table")
        at_s = _number(table, "at_min", where, 0.0, duration_s / 60.0) * 60.0
        op = table.get("op")
        fields = {k: v for k, v in table.items() if k not in ("at_min", "op")}
        action: Operation | TrainFailure | GroundRestart
        if op == GROUND_RESTART:
            _check_keys(fields, where, ("down_min",))
            action = GroundRestart(_number(fields, "down_min", where, 0.0, 24 * 60.0, 2.0) * 60.0)
        elif op == TRAIN_FAILURE:
            _check_keys(fields, where, ("train", "stand_min"))
            train = fields.get("train")
            if not is_finite_number(train) or train not in train_ids:
                raise ScenarioError(f"{where}train", train, "the id of a train of the scenario")
            stand = _number(fields, "stand_min", where, 0.0, 24 * 60.0, 10.0)
            action = TrainFailure(int(train), stand * 60.0)
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
                refused = ScenarioError(f"{where}{name}", table.get(name), why)
                # the ground's own message says the value and what is allowed: not again
                refused.args = (f"{where}{name}: {why}",)
                raise refused from None
        events.append(ScenarioEvent(at_s, action, str(op), fields))
    return tuple(sorted(events, key=lambda e: e.at_s))


def _retiming(raw: Any) -> RetimerSettings | None:
    if not isinstance(raw, Mapping):
        raise ScenarioError("retiming", raw, "a [retiming] table")
    table = _check_keys(raw, "retiming.", RETIMING_KEYS)
    enabled = table.get("enabled", True)
    if not isinstance(enabled, bool):
        raise ScenarioError("retiming.enabled", enabled, "true or false")
    default = RetimerSettings()
    settings = RetimerSettings(
        headway_s=_number(table, "headway_min", "retiming.", 0.0, 120.0, default.headway_s / 60)
        * 60.0,
        energy_weight_s_per_kwh=_number(
            table,
            "energy_weight_s_per_kwh",
            "retiming.",
            0.0,
            1e4,
            default.energy_weight_s_per_kwh,
        ),
        off_plan_s=_number(table, "off_plan_min", "retiming.", 0.1, 120.0, default.off_plan_s / 60)
        * 60.0,
        every_s=_number(table, "every_min", "retiming.", 0.1, 24 * 60.0, default.every_s / 60)
        * 60.0,
    )
    return settings if enabled else None


def scenario_from_mapping(data: Mapping[str, Any]) -> LineScenario:
    """A :class:`LineScenario` from a parsed file, every field checked (module docstring)."""
    _check_keys(data, "", TOP_KEYS)
    name = data.get("name", "line run")
    if not isinstance(name, str):
        raise ScenarioError("name", name, "a string")
    line_name = data.get("line", "heavy-haul")
    if not isinstance(line_name, str):
        raise ScenarioError("line", line_name, "a shipped line name or a line file path")
    line = load_line(line_name)
    margin = _number(data, "margin_kmh", "", 0.0, 50.0, 5.0)
    seed = _integer(data, "seed", "", 0, MAX_SEED, 0)
    duration_s = _number(data, "duration_h", "", 0.01, 7 * 24.0, 9.0) * 3600.0
    epoch_s = _number(data, "start_epoch_s", "", 1.0, 4.0e9, DEFAULT_EPOCH_S)
    channel_table = data.get("channel", {})
    if not isinstance(channel_table, Mapping):
        raise ScenarioError("channel", channel_table, "a [channel] table")
    channel = ChannelModel.from_mapping(channel_table)
    retiming = _retiming(data.get("retiming", {}))
    trains = data.get("trains", {})
    if not isinstance(trains, Mapping):
        raise ScenarioError("trains", trains, "a [trains] table")
    _check_keys(trains, "trains", ("model",))
    model = trains.get("model", "point-mass")
    if model not in TRAIN_MODELS:
        raise ScenarioError("trains.model", model, f"one of {', '.join(TRAIN_MODELS)}")
    services = _services(data.get("services"), line, margin)
    events = _events(
        data.get("events", []), line, epoch_s, duration_s, {s.train_id for s in services}
    )
    return LineScenario(
        name, line, services, channel, seed, duration_s, epoch_s, margin, events, retiming, model
    )


def load_scenario(path: str | os.PathLike[str]) -> LineScenario:
    """Read and check a line-run file; errors name the file."""
    p = Path(path)
    data = read_toml(path, "SCENARIO", "line-run file", ScenarioError)
    try:
        return scenario_from_mapping(data)
    except ConfigError as error:
        raise ScenarioError(f"{p.name}: {error.field}", error.value, error.allowed) from None
