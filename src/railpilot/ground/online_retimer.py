"""Re-timing in the loop: when a train runs off plan, the ground re-times it and the trains
behind it and sends them new running times (paper 001 section 2.3).

:mod:`railpilot.ground.running_time_lp` solves one re-timing problem. :class:`OnlineRetimer` decides
when to pose one and what it holds, from what the ground knows on the line: each train's
timetable (given by the operator), its planned-curve reports (link ``PlannedCurve``: the
station pair it runs, the time run and the time its plan still needs), its running info
(link ``RunningInfo``: whether a train standing at a station has left it) and the sections'
energy-time curves (ground/energy.py, through ``curves``). No I/O, time passed in.

When
    At most every ``every_s``, if a train's report puts its arrival at the station it runs
    to more than ``off_plan_s`` from the plan in force (the timetable, or the last
    re-timing's times), either way; or if a train that has arrived at a station is still
    there ``off_plan_s`` after the plan in force has it leave (held by a failure or a red
    signal: on time in, late out). A retimer that has just started (a ground started, or
    restarted) first waits for a report from every train its timetable has on the line
    (departed from its origin, not yet due at its destination plus ``off_plan_s``; they
    report at least once a minute), or ``every_s`` at most: re-timing some of the trains
    of a direction without knowing where the others are would bind them to a plan that
    ignores them.
Who
    The front-most such train of a direction and every train behind it in that direction
    (the order of the timetable's departures: on a fixed-block line trains do not
    overtake), those still to leave their origin included. A train at or running to its
    destination has nothing left to re-time and is left out (its last section does not
    bound the trains behind it in the problem: the signals still do).
What each train still has
    No section slower than the timetable's: re-timing recovers delay, it does not spend
    the timetable's recovery margin on saving energy, which a train's run would then
    lack when it meets what the curves do not know (a TSR, a red signal, a failure). The
    LP's energy term decides how much of its margin a late train uses. From its last
    report: the section it runs is committed (departed at ``report time - elapsed``,
    arriving at ``report time + remaining``); a report with nothing remaining says it
    has arrived, at its departure as known plus the time run, or the report's time if
    that is earlier (the report can come a minute after the arrival; a train standing at
    a station repeats it once a minute, and only the first one heard counts). A train
    that has arrived and is then seen at rest and then moving in its running info has
    left, at that time, and runs the next section in the plan's time until its report
    of it comes.
    Its remaining sections start at that station, no earlier than the arrival plus its
    minimum dwell, and, if it has arrived, no earlier than now (it is still there).
    After a re-timing, the plan in force is its times, and for the section a train runs,
    the arrival the re-timing expected: it is off plan again only if that expectation
    moves. A train that has not reported has all its sections left, from its planned
    departure, until ``every_s`` after that; later, where it is is not known and it is
    left out. A train that has deregistered (at its destination) is done: its last
    report may not have come.
What goes out
    :func:`~railpilot.ground.running_time_lp.retime` (the LP; its proportional-slack fallback if
    HiGHS fails): each train of the problem whose running times changed by more than
    ``SENT_TOLERANCE_S`` gets ``RunningTimes`` for its remaining sections. The times are
    unacknowledged (the link's ``send``); a train that registers later gets the last ones
    sent to it (:meth:`times_for`), and a lost message is made good by the next
    re-timing, which a train still off the plan in force triggers.

Each re-timing is kept in :attr:`OnlineRetimer.log`: when, the train that triggered it, the
trains, the status (and fallback reason), the total lateness at the destinations under the
fixed plan and under the new times, the energy of both, and the solve time.

The state is derived (the timetables, the reports, the times sent): a restarted ground
starts a new retimer, which re-times again the trains still off their timetable.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from railpilot.errors import ConfigError, is_finite_number
from railpilot.link.messages import PlannedCurve, RunningTimes

from .running_time_lp import (
    CommittedSection,
    EnergyCurve,
    RetimeProblem,
    Section,
    TrainPlan,
    fixed_plan,
    retime,
)

#: running times that differ by no more than this from those sent last are not sent [s]
SENT_TOLERANCE_S = 1.0


@dataclass(frozen=True)
class RetimerSettings:
    """How the ground re-times (the ``[retiming]`` table of a line-run file).

    Attributes
    ----------
    headway_s
        The fixed-block headway between consecutive trains on a section [s]
        (ground/running_time_lp.py).
    energy_weight_s_per_kwh
        What one kWh is worth in seconds of lateness.
    off_plan_s
        A train is off plan when its expected arrival is this far from the plan [s].
    every_s
        At most one re-timing this often [s].
    """

    headway_s: float = 480.0
    energy_weight_s_per_kwh: float = 0.25
    off_plan_s: float = 120.0
    every_s: float = 300.0

    def __post_init__(self) -> None:
        for name, low in (
            ("headway_s", 0.0),
            ("energy_weight_s_per_kwh", 0.0),
            ("off_plan_s", 1e-9),
            ("every_s", 1e-9),
        ):
            value = getattr(self, name)
            if not is_finite_number(value) or value < low:
                allowed = f"a number >= {low:g}" if low == 0.0 else "a number > 0"
                raise ConfigError(f"retiming.{name}", value, allowed)


@dataclass(frozen=True)
class SectionCurve:
    """What the ground knows of one section for one train: its fastest run [s] and its
    energy-time curve (ground/energy.py)."""

    fastest_s: float
    energy: EnergyCurve


@dataclass(frozen=True)
class TimetabledTrain:
    """One train's timetable as the ground holds it [s, ground clock].

    ``stations`` in running order, stopping at ``stops_m`` (km posts [m]);
    ``departures_s[j]`` the planned departure from ``stations[j]``, ``arrivals_s[j]`` the
    planned arrival at ``stations[j + 1]``.
    """

    train_id: int
    stations: tuple[int, ...]
    stops_m: tuple[float, ...]
    departures_s: tuple[float, ...]
    arrivals_s: tuple[float, ...]
    min_dwell_s: float

    def __post_init__(self) -> None:
        where = f"timetable of train {self.train_id}"
        n = len(self.stations)
        sizes = (n, len(self.stops_m), len(self.departures_s), len(self.arrivals_s))
        if n < 2 or sizes != (n, n, n - 1, n - 1):
            raise ConfigError(
                where,
                sizes,
                "two or more stations and their stops, one departure and one arrival per section",
            )
        for j in range(n - 1):
            if not self.departures_s[j] <= self.arrivals_s[j]:
                raise ConfigError(
                    f"{where}.arrivals_s[{j}]", self.arrivals_s[j], "a time after its departure"
                )

    @property
    def up(self) -> bool:
        return self.stations[-1] > self.stations[0]

    @cached_property
    def section_of(self) -> dict[tuple[int, int], int]:
        """Station pair -> its section's index (built once: every report looks it up)."""
        return {pair: j for j, pair in enumerate(itertools.pairwise(self.stations))}


@dataclass(frozen=True)
class _Progress:
    """Where a train's last report puts it: on section ``j`` (``stations[j]`` to
    ``stations[j + 1]``), departed and arriving (or arrived) when, and how far along the
    section by its times (0 to 1)."""

    j: int
    departed_s: float
    arrival_s: float
    arrived: bool
    share: float


@dataclass
class OnlineRetimer:
    """Re-timing in the loop (module docstring).

    ``curves(train_id, from_station, to_station)`` gives a section's
    :class:`SectionCurve` for that train (the caller caches: the same section and kind
    come back for every train).
    """

    trains: Mapping[int, TimetabledTrain]
    curves: Callable[[int, int, int], SectionCurve]
    settings: RetimerSettings = field(default_factory=RetimerSettings)
    log: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._progress: dict[int, _Progress] = {}
        self._done: set[int] = set()
        #: trains at a station by their last report, seen at rest there since
        self._standing: set[int] = set()
        #: the plan in force: per train, the arrival at each station after the first
        self._plan = {i: np.array(t.arrivals_s, dtype=float) for i, t in self.trains.items()}
        #: and the departure from each station but the last
        self._leave = {i: np.array(t.departures_s, dtype=float) for i, t in self.trains.items()}
        self._sent: dict[int, RunningTimes] = {}
        self._last_s = -math.inf
        self._started_s: float | None = None

    # ------------------------------------------------------------------ what it hears

    def report(self, train_id: int, report: PlannedCurve, now_s: float) -> None:
        """A train's planned-curve report, received at ``now_s``."""
        timetable = self.trains.get(train_id)
        if timetable is None:
            return
        j = timetable.section_of.get((report.from_station_id, report.to_station_id))
        if j is None:
            return  # not a section of its timetable: nothing the ground can re-time
        arrived = report.remaining_s <= 0.0
        known = self._progress.get(train_id)
        if known is not None and j < known.j:
            return  # stale: the train has been heard of further along (its running info)
        if arrived and known is not None and known.arrived and known.j == j:
            # the same arrival again: a train standing at a station says so once a minute,
            # and the report's time is not its arrival's (the first such report's is)
            return
        at_s = now_s
        if arrived and known is not None and known.j == j:
            # the report of an arrival can come up to a minute after it (the onboard
            # reports again when its prediction moves by a second or a minute has passed)
            # or later (lost): the departure it knows and the section's time run date
            # the arrival (both no earlier than the truth, as the report's time)
            at_s = min(now_s, known.departed_s + report.elapsed_s)
        total = report.elapsed_s + report.remaining_s
        self._progress[train_id] = _Progress(
            j,
            at_s - report.elapsed_s,
            at_s + report.remaining_s,
            arrived,
            1.0 if arrived or total <= 0.0 else report.elapsed_s / total,
        )
        self._standing.discard(train_id)
        if arrived and j == len(timetable.stations) - 2:
            self._done.add(train_id)

    def running(self, train_id: int, speed_mps: float, now_s: float) -> None:
        """A train's running info, received at ``now_s``: a train the last report has
        at a station, seen at rest there and now moving, has left it.

        The planned-curve report of the new section says so too, but it is sent once and
        then only when the prediction moves or a minute has passed; with it lost, the
        train would look held at the station and be re-timed as late (seed 77 of the
        heavy-haul sweep, docs/results.md). Until its report comes, the train is taken to
        have left now and to run the section in the plan's time. At rest first: the
        report of an arrival goes when the plan has no time left, while the train may
        still roll the last centimetres to its stop.
        """
        p = self._progress.get(train_id)
        if p is None or not p.arrived or train_id in self._done:
            return  # (a train arrived at its destination is done)
        if speed_mps <= 0.0:
            self._standing.add(train_id)
            return
        if train_id not in self._standing:
            return  # still rolling to the stop its report has reached
        self._standing.discard(train_id)
        j = p.j + 1
        planned_s = self._plan[train_id][j] - self._leave[train_id][j]
        self._progress[train_id] = _Progress(j, now_s, now_s + planned_s, False, 0.0)

    def left(self, train_id: int) -> None:
        """``train_id`` deregistered (at its destination, or off the main line): it is not
        re-timed again, and no longer holds anyone."""
        self._done.add(train_id)

    def planned_arrivals(self, train_id: int) -> np.ndarray:
        """The plan in force for ``train_id``: its arrival at each station after its first
        [s] (the timetable's, or the last re-timing's from where that began)."""
        return self._plan[train_id].copy()

    def planned_arrival_s(self, train_id: int, station_id: int) -> float | None:
        """The plan in force's arrival [s] of ``train_id`` at ``station_id`` (a station
        after its first), or None where the timetable has no such train or stop."""
        train = self.trains.get(train_id)
        if train is None or station_id not in train.stations[1:]:
            return None
        return float(self._plan[train_id][train.stations.index(station_id, 1) - 1])

    def planned_departures(self, train_id: int) -> np.ndarray:
        """The plan in force for ``train_id``: its departure from each station but its
        last [s] (the timetable's, or the last re-timing's)."""
        return self._leave[train_id].copy()

    def times_for(self, train_id: int) -> RunningTimes | None:
        """The running times last sent to ``train_id`` (for a train that registers)."""
        return self._sent.get(train_id)

    # ------------------------------------------------------------------ what it decides

    def off_plan(self, now_s: float) -> list[int]:
        """The trains whose expected arrival is off the plan in force, front first."""
        late = []
        for train_id, p in self._progress.items():
            if train_id in self._done or p.j + 1 >= len(self.trains[train_id].stations) - 1:
                continue  # nothing left to re-time once on its last section
            expected = p.arrival_s if p.arrived else max(p.arrival_s, now_s)
            if abs(expected - self._plan[train_id][p.j]) > self.settings.off_plan_s:
                late.append(train_id)
            elif (
                p.arrived
                and self._leaves_s(train_id, p, now_s) - self._leave[train_id][p.j + 1]
                > self.settings.off_plan_s
            ):
                late.append(train_id)  # on time in, held at the station (a failure, a red)
        return sorted(late, key=self._order_key)

    def update(self, now_s: float) -> list[tuple[int, RunningTimes]]:
        """Re-time if due (module docstring): the messages to send, ``(train, times)``."""
        if self._started_s is None:
            self._started_s = now_s
        every = self.settings.every_s
        if now_s - self._last_s < every:
            return []
        if now_s - self._started_s < every and not self._heard_from_all(now_s):
            return []
        off = self.off_plan(now_s)
        if not off:
            return []
        self._last_s = now_s
        out: list[tuple[int, RunningTimes]] = []
        for up in (True, False):
            front = next((i for i in off if self.trains[i].up == up), None)
            if front is not None:
                out += self._retime(front, now_s)
        return out

    def _heard_from_all(self, now_s: float) -> bool:
        """Every train the timetable has on the line at ``now_s`` has reported to this
        retimer (or is done)."""
        late = self.settings.off_plan_s
        for train_id, t in self.trains.items():
            if train_id in self._progress or train_id in self._done:
                continue
            if t.departures_s[0] <= now_s < t.arrivals_s[-1] + late:
                return False
        return True

    def _order_key(self, train_id: int) -> tuple[bool, float, float]:
        """Front first: by direction, then how far along the line the train is (its
        report, or its origin), then its planned departure from the origin."""
        t = self.trains[train_id]
        p = self._progress.get(train_id)
        if p is None:
            at = t.stops_m[0]
        else:
            at = t.stops_m[p.j] + p.share * (t.stops_m[p.j + 1] - t.stops_m[p.j])
        return (not t.up, -at if t.up else at, t.departures_s[0])

    def _retime(self, front: int, now_s: float) -> list[tuple[int, RunningTimes]]:
        up = self.trains[front].up
        same_way = sorted(
            (i for i, t in self.trains.items() if t.up == up and i not in self._done),
            key=self._order_key,
        )
        behind = same_way[same_way.index(front) :]
        plans = []
        ahead = []  # the current sections of the trains not re-timed, front first
        for train_id in same_way:
            plan = self._train_plan(train_id, now_s) if train_id in behind else None
            if plan is not None:
                plans.append(plan)
            elif train_id in self._progress:
                ahead.append(self._committed(train_id, now_s))
        entry: dict[str, Any] = {"t_s": now_s, "trigger": front, "trains": []}
        self.log.append(entry)
        if not plans:
            entry["status"] = "nothing to re-time"
            return []
        try:
            problem = RetimeProblem(
                tuple(plans),
                self.settings.headway_s,
                now_s,
                self.settings.energy_weight_s_per_kwh,
                tuple(ahead),
            )
        except ConfigError as error:
            # the reports and the order disagree (a train passed another at a station):
            # no re-timing this time, said in the log
            entry["status"] = f"not re-timed: {error}"
            return []
        result = retime(problem)
        fixed = fixed_plan(problem)
        entry.update(
            status=result.status,
            reason=result.reason,
            trains=[int(t.train_id) for t in result.trains],
            lateness_fixed_s=float(np.sum(fixed.lateness_s)),
            lateness_s=float(np.sum(result.lateness_s)),
            energy_fixed_kwh=fixed.total_energy_kwh,
            energy_kwh=result.total_energy_kwh,
            solve_ms=result.solve_ms,
        )
        out = []
        for times in result.trains:
            train_id = int(times.train_id)
            stations = self.trains[train_id].stations
            k = stations.index(times.stations[0][0])
            self._plan[train_id][k:] = times.arrival_s
            self._leave[train_id][k:] = times.departure_s
            p = self._progress.get(train_id)
            if p is not None:
                # the section it runs: the expectation the re-timing took is the plan now
                self._plan[train_id][p.j] = self._committed(train_id, now_s).arrival_s
            message = times.message()
            if not _same(self._sent.get(train_id), message):
                self._sent[train_id] = message
                out.append((train_id, message))
        entry["sent_to"] = [i for i, _ in out]
        entry["times_s"] = {
            i: {f"{t.from_station_id}-{t.to_station_id}": t.running_time_s for t in m.times}
            for i, m in out
        }
        return out

    def _train_plan(self, train_id: int, now_s: float) -> TrainPlan | None:
        """What ``train_id`` still has to run, from its last report (module docstring)."""
        t = self.trains[train_id]
        p = self._progress.get(train_id)
        dwell = t.min_dwell_s
        committed: tuple[CommittedSection, ...] = ()
        if p is None:
            if now_s > t.departures_s[0] + self.settings.every_s:
                return None  # due to have left long ago, and not heard of: not known
            first, earliest = 0, t.departures_s[0]
        else:
            first = p.j + 1
            current = self._committed(train_id, now_s)
            if p.arrived:
                earliest = self._leaves_s(train_id, p, now_s)
            else:
                earliest = current.arrival_s + dwell
            committed = (current,)
        n = len(t.stations) - 1
        if first >= n:
            return None
        sections = []
        dwells = []
        for j in range(first, n):
            curve = self.curves(train_id, t.stations[j], t.stations[j + 1])
            planned = t.arrivals_s[j] - t.departures_s[j]
            fastest = min(curve.fastest_s, planned)
            if fastest < curve.energy.min_time_s:
                curve = SectionCurve(fastest, _extended(curve.energy, fastest))
            sections.append(
                Section(
                    t.stations[j],
                    t.stations[j + 1],
                    fastest,
                    planned,
                    curve.energy,
                    max_running_s=planned,
                )
            )
            if j > first:
                # the timetable's dwell, if it planned less than the minimum
                dwells.append(min(dwell, max(t.departures_s[j] - t.arrivals_s[j - 1], 0.0)))
        return TrainPlan(
            str(train_id),
            tuple(sections),
            tuple(t.departures_s[first:]),
            tuple(dwells),
            earliest,
            committed=committed,
        )

    def _leaves_s(self, train_id: int, p: _Progress, now_s: float) -> float:
        """The earliest ``train_id``, at a station by its last report ``p``, can leave [s]:
        its minimum dwell after the arrival, and not before now (it is still there)."""
        return max(p.arrival_s + self.trains[train_id].min_dwell_s, now_s)

    def _committed(self, train_id: int, now_s: float) -> CommittedSection:
        """The section ``train_id`` runs or has just run, by its last report: departed,
        and arrived or expected (no earlier than now if it is still running)."""
        t = self.trains[train_id]
        p = self._progress[train_id]
        arrival = p.arrival_s if p.arrived else max(p.arrival_s, now_s)
        return CommittedSection(
            t.stations[p.j], t.stations[p.j + 1], min(p.departed_s, arrival), arrival
        )


def _extended(curve: EnergyCurve, time_s: float) -> EnergyCurve:
    """``curve`` with a knot at ``time_s`` before its first (a timetable tighter than the
    planner's fastest run): its first piece extended, so it stays convex."""
    slope = float(curve.pieces[0][0])
    start = curve.energy_kwh[0] + slope * (time_s - curve.times_s[0])
    return EnergyCurve((time_s, *curve.times_s), (start, *curve.energy_kwh))


def _same(a: RunningTimes | None, b: RunningTimes) -> bool:
    if a is None or len(a.times) != len(b.times):
        return False
    return all(
        (x.from_station_id, x.to_station_id) == (y.from_station_id, y.to_station_id)
        and abs(x.running_time_s - y.running_time_s) <= SENT_TOLERANCE_S
        for x, y in zip(a.times, b.times, strict=True)
    )


def timetabled(
    train_id: int,
    stations: Iterable[int],
    stops_m: Iterable[float],
    departures_s: Iterable[float],
    arrivals_s: Iterable[float],
    min_dwell_s: float,
) -> TimetabledTrain:
    """A :class:`TimetabledTrain` from iterables (floats, tuples)."""
    return TimetabledTrain(
        train_id,
        tuple(int(s) for s in stations),
        tuple(float(m) for m in stops_m),
        tuple(float(d) for d in departures_s),
        tuple(float(a) for a in arrivals_s),
        float(min_dwell_s),
    )
