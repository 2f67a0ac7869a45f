"""The ground's view of its trains: registration, live state, link health, timetable.

No I/O, time passed in. The transport (net/server.py) feeds it the link's events and the
accepted messages; the dashboard, the TSR manager and the re-timing read it.

- **Live state**: registered or not, train number, length, the last running info with its
  age, and whether it is still valid (younger than ``validity_s``: the link's running-info
  timeout).
- **Link health**: connected, timeouts, link failures, and frames rejected by check.
- **Timetable**: each train's stops with planned arrival and departure [s, ground clock]
  and its section running times; the planned-curve reports (``PlannedCurve``: time already
  run and remaining on the current station pair) give the expected arrival and the
  deviation from plan, which is what triggers a re-timing (``off_plan``). Where another
  part of the ground holds the plan in force (a line run's retimer), ``planned_arrival``
  gives it for a train the registry holds no timetable of.
"""

from __future__ import annotations

import contextlib
import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace

from railpilot.errors import ConfigError, is_finite_number
from railpilot.link.checks import Check
from railpilot.link.messages import U32_MAX, PlannedCurve, RegisterRequest, RunningInfo

#: Running info older than this is no longer valid [s] (the link's default timeout).
DEFAULT_VALIDITY_S = 4.0
#: A train this far [s] from its planned arrival at the end of its section is off plan.
DEFAULT_OFF_PLAN_S = 60.0


@dataclass(frozen=True)
class TimetableStop:
    """A stop: station id, planned arrival and departure [s, ground clock]."""

    station_id: int
    arrival_s: float
    departure_s: float

    def __post_init__(self) -> None:
        if type(self.station_id) is not int or not 0 <= self.station_id <= U32_MAX:
            raise ConfigError("stop.station_id", self.station_id, "a station id")
        if not (is_finite_number(self.arrival_s) and is_finite_number(self.departure_s)):
            raise ConfigError("stop.arrival_s", self.arrival_s, "finite times [s]")
        if self.departure_s < self.arrival_s:
            raise ConfigError(
                "stop.departure_s", self.departure_s, f"a time >= arrival_s = {self.arrival_s}"
            )


@dataclass(frozen=True)
class TrainTimetable:
    """One train's stops in order (the first: its origin, the last: its destination)."""

    train_id: int
    stops: tuple[TimetableStop, ...]

    def __post_init__(self) -> None:
        if len(self.stops) < 2:
            raise ConfigError("timetable.stops", len(self.stops), "two or more stops")
        for i in range(1, len(self.stops)):
            if self.stops[i].arrival_s < self.stops[i - 1].departure_s:
                raise ConfigError(
                    f"timetable.stops[{i}].arrival_s",
                    self.stops[i].arrival_s,
                    f"a time >= the departure before it ({self.stops[i - 1].departure_s})",
                )

    @classmethod
    def from_running_times(
        cls,
        train_id: int,
        station_ids: Iterable[int],
        running_times_s: Iterable[float],
        departure_s: float,
        dwell_s: float = 0.0,
    ) -> TrainTimetable:
        """Stops from the origin's departure, section running times and a dwell [s]."""
        ids = list(station_ids)
        times = list(running_times_s)
        if len(times) != len(ids) - 1:
            raise ConfigError("running_times_s", len(times), f"one per section ({len(ids) - 1})")
        stops = [TimetableStop(ids[0], departure_s, departure_s)]
        t = departure_s
        for station, run in zip(ids[1:], times, strict=True):
            t += run
            last = station == ids[-1]
            stops.append(TimetableStop(station, t, t if last else t + dwell_s))
            t = stops[-1].departure_s
        return cls(train_id, tuple(stops))

    def section_running_times_s(self) -> tuple[float, ...]:
        return tuple(
            b.arrival_s - a.departure_s for a, b in zip(self.stops, self.stops[1:], strict=False)
        )

    def planned_arrival_s(self, station_id: int) -> float:
        for stop in self.stops:
            if stop.station_id == station_id:
                return stop.arrival_s
        ids = ", ".join(str(s.station_id) for s in self.stops)
        raise ConfigError("station_id", station_id, f"a stop of train {self.train_id}: {ids}")


@dataclass(frozen=True)
class LinkHealth:
    """What the link did for one train."""

    connected: bool = False
    timeouts: int = 0
    failures: int = 0
    rejections: tuple[tuple[str, int], ...] = ()  # (check, count), by check


@dataclass(frozen=True)
class TrainState:
    """One train as the ground sees it at ``now_s``."""

    train_id: int
    registered: bool
    train_number: str | None
    length_m: float | None
    running_info: RunningInfo | None
    info_age_s: float | None
    info_valid: bool
    health: LinkHealth
    #: the last planned-curve report and the arrival it implies [s, ground clock]
    planned_curve: PlannedCurve | None
    expected_arrival_s: float | None
    #: expected minus planned arrival at the end of the current section [s] (+ late)
    deviation_s: float | None


@dataclass
class _Train:
    train_id: int
    registered: bool = False
    request: RegisterRequest | None = None
    info: RunningInfo | None = None
    info_at_s: float = -math.inf
    connected: bool = False
    timeouts: int = 0
    failures: int = 0
    rejections: Counter[str] = field(default_factory=Counter)
    curve: PlannedCurve | None = None
    curve_at_s: float = -math.inf
    timetable: TrainTimetable | None = None


#: The plan in force held elsewhere: ``(train id, station id)`` -> the planned arrival [s,
#: ground clock], or None where it has none.
PlannedArrival = Callable[[int, int], float | None]


class TrainRegistry:
    """Every train the ground has heard of (module docstring).

    ``planned_arrival`` is the plan in force where another part of the ground holds it
    (:data:`PlannedArrival`); a train's own timetable (:meth:`set_timetable`) comes first.
    """

    def __init__(
        self,
        validity_s: float = DEFAULT_VALIDITY_S,
        off_plan_s: float = DEFAULT_OFF_PLAN_S,
        planned_arrival: PlannedArrival | None = None,
    ) -> None:
        if not (is_finite_number(validity_s) and validity_s > 0):
            raise ConfigError("validity_s", validity_s, "a time > 0 [s]")
        if not (is_finite_number(off_plan_s) and off_plan_s > 0):
            raise ConfigError("off_plan_s", off_plan_s, "a time > 0 [s]")
        self.validity_s = float(validity_s)
        self.off_plan_s = float(off_plan_s)
        self._planned_arrival = planned_arrival
        self._trains: dict[int, _Train] = {}

    # --- what the link reports

    def connected(self, train_id: int) -> None:
        self._train(train_id).connected = True

    def disconnected(self, train_id: int) -> None:
        self._train(train_id).connected = False

    def registered(self, train_id: int, request: RegisterRequest) -> None:
        train = self._train(train_id)
        train.registered = True
        train.request = request

    def deregistered(self, train_id: int) -> None:
        self._train(train_id).registered = False

    def running_info(self, train_id: int, info: RunningInfo, now_s: float) -> None:
        train = self._train(train_id)
        train.info = info
        train.info_at_s = _time(now_s)

    def planned_curve(self, train_id: int, report: PlannedCurve, now_s: float) -> None:
        train = self._train(train_id)
        train.curve = report
        train.curve_at_s = _time(now_s)

    def timed_out(self, train_id: int) -> None:
        self._train(train_id).timeouts += 1

    def link_failed(self, train_id: int) -> None:
        train = self._train(train_id)
        train.failures += 1
        train.connected = False

    def rejected(self, train_id: int, check: Check) -> None:
        self._train(train_id).rejections[Check(check).value] += 1

    # --- what the dispatcher plans

    def set_timetable(self, timetable: TrainTimetable) -> None:
        self._train(timetable.train_id).timetable = timetable

    def timetable(self, train_id: int) -> TrainTimetable | None:
        train = self._trains.get(train_id)
        return None if train is None else train.timetable

    # --- views

    def train_ids(self) -> tuple[int, ...]:
        return tuple(sorted(self._trains))

    def report(self, train_id: int) -> tuple[int, RunningInfo, float, float] | None:
        """``(train id, last running info, train length [m], when it came [s])`` of a
        registered train that has reported, else None: what the occupancy and the TSR
        routes need, per running info, without building a :class:`TrainState`."""
        t = self._trains.get(train_id)
        if t is None or not t.registered or t.info is None or t.request is None:
            return None
        return t.train_id, t.info, t.request.train_length_m, t.info_at_s

    def reports(self) -> list[tuple[int, RunningInfo, float, float]]:
        """:meth:`report` of every registered train that has reported."""
        return [r for t in self._trains if (r := self.report(t)) is not None]

    def knows(self, train_id: int) -> bool:
        """Whether the registry has heard of ``train_id``."""
        return train_id in self._trains

    def state(self, train_id: int, now_s: float) -> TrainState:
        """Train ``train_id`` at ``now_s`` [s]; an unknown train is an error naming it."""
        now = _time(now_s)
        train = self._trains.get(train_id)
        if train is None:
            known = ", ".join(str(t) for t in sorted(self._trains)) or "none"
            raise ConfigError("train_id", train_id, f"a train the ground knows ({known})")
        age = None if train.info is None else now - train.info_at_s
        expected, deviation = self._deviation(train, now)
        return TrainState(
            train.train_id,
            train.registered,
            None if train.request is None else train.request.train_number,
            None if train.request is None else train.request.train_length_m,
            train.info,
            age,
            age is not None and age <= self.validity_s,
            LinkHealth(
                train.connected,
                train.timeouts,
                train.failures,
                tuple(sorted(train.rejections.items())),
            ),
            train.curve,
            expected,
            deviation,
        )

    def states(self, now_s: float) -> tuple[TrainState, ...]:
        return tuple(self.state(t, now_s) for t in sorted(self._trains))

    def off_plan(self, now_s: float) -> tuple[TrainState, ...]:
        """Trains whose expected arrival is ``off_plan_s`` or more from the plan."""
        return tuple(
            s
            for s in self.states(now_s)
            if s.deviation_s is not None and abs(s.deviation_s) >= self.off_plan_s
        )

    # --- internals

    def _train(self, train_id: int) -> _Train:
        if type(train_id) is not int or not 0 <= train_id <= U32_MAX:
            raise ConfigError("train_id", train_id, f"an integer in [0, {U32_MAX}]")
        train = self._trains.get(train_id)
        if train is None:
            train = self._trains[train_id] = _Train(train_id)
        return train

    def _deviation(self, train: _Train, now_s: float) -> tuple[float | None, float | None]:
        """Expected arrival at the report's next station and its deviation from plan (the
        train's timetable, else the plan in force held elsewhere).

        The report says how long the train has still to run, as of when it was received;
        what has passed since is taken off (the train ran on meanwhile).
        """
        if train.curve is None:
            return None, None
        remaining = max(train.curve.remaining_s - (now_s - train.curve_at_s), 0.0)
        expected = now_s + remaining
        station = train.curve.to_station_id
        planned: float | None = None
        if train.timetable is not None:
            with contextlib.suppress(ConfigError):  # not one of its stops
                planned = train.timetable.planned_arrival_s(station)
        elif self._planned_arrival is not None:
            planned = self._planned_arrival(train.train_id, station)
        return expected, None if planned is None else expected - planned


def with_departure(timetable: TrainTimetable, departure_s: float) -> TrainTimetable:
    """The same timetable shifted so the origin's departure is ``departure_s`` [s]."""
    shift = _time(departure_s) - timetable.stops[0].departure_s
    return replace(
        timetable,
        stops=tuple(
            TimetableStop(s.station_id, s.arrival_s + shift, s.departure_s + shift)
            for s in timetable.stops
        ),
    )


def _time(now_s: float) -> float:
    if not is_finite_number(now_s):
        raise ConfigError("now_s", now_s, "a finite time [s]")
    return float(now_s)
