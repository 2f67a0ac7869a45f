"""Online running-time re-optimisation on the ground (paper 001 section 2.3).

When a train's planned-curve report shows it off plan, the ground re-times the remaining
sections of that train and of the trains behind it, and sends the new running times
(link ``RunningTimes``). No I/O and no clock: the caller passes ``now_s`` in and sends
what comes out; the time the solve took is measured, nothing waits on it.

The linear programme (solved by HiGHS through ``scipy.optimize.linprog``). For every
train ``k`` (in the fixed order, the front train first) and each of its remaining sections
``j`` (station ``j`` to station ``j + 1`` of its route):

variables
    ``d[k,j]`` departure [s], ``r[k,j]`` running time [s], ``e[k,j]`` net energy [kWh]
    (an epigraph variable), ``L[k]`` lateness at the destination [s]; the arrival is
    ``a[k,j] = d[k,j] + r[k,j]``.
objective
    ``sum_k w_k L[k] + energy_weight * sum e[k,j]`` [s] (the energy weight converts kWh to
    seconds of lateness), plus ``1e-6 x sum a[k,j]`` so that among equally good plans the
    trains run as early as they can (a tie-break, never a trade-off that matters).
running time
    ``r_min <= r <= r_max``: the fastest run the onboard can plan and the slowest time its
    energy curve was sampled at (running slower saves nothing the curve knows about).
energy
    ``e >= slope_p r + intercept_p`` for every piece ``p`` of the section's convex,
    non-increasing, piecewise-linear energy-time curve (:class:`EnergyCurve`), so that at
    the optimum ``e`` is the curve at ``r``.
dwell
    ``d[k,j+1] >= a[k,j] + min_dwell[k,j]``.
never early
    ``d[k,j] >= planned departure``: a train never leaves a station before its timetable
    (freight is loaded and crews are booked to it; and leaving early only moves the train
    into the block of the one ahead).
now
    ``d[k,0] >= max(earliest_departure_k, now_s)``: the first remaining section starts no
    earlier than the train can (its delay, or its planned-curve report's expected arrival
    plus the minimum dwell when it is running on a section the ground does not re-time).
headway (fixed block, fixed order)
    For a train ``f`` and the nearest train ``l`` ahead of it in the order that runs the
    same section (same station pair):
    ``d[f] >= d[l] + h`` (the follower enters the section's first block only ``h`` after the
    leader entered it: by then the leader has cleared the blocks a green aspect needs) and
    ``a[f] >= a[l] + h`` (it arrives only ``h`` after the leader arrived: it may not catch
    up inside the section, where the same blocks separate them). No overtaking: the order
    is fixed. A leader's section that is run already or being run (``TrainPlan.committed``)
    bounds the follower the same way with its known times.
lateness
    ``L[k] >= a[k,last] - planned arrival``, ``L[k] >= 0``.
latest arrival (optional, hard)
    ``a[k,last] <= latest_arrival_s``: a path booked beyond the route or a crew's hours.
    This is what can make the problem infeasible: nothing else bounds a time from above.

If HiGHS reports the problem infeasible (or fails), :func:`retime` falls back to
**proportional slack redistribution**: train by train in the order, the train's lateness
(or its overrun of its latest arrival, whichever is larger) is recovered by shortening
every remaining section by the same share of its slack ``planned - minimum`` (up to all of
it); departures then follow as early as the headway, order and dwells allow. The result
says so (``status`` "fallback: proportional slack" and a ``reason`` naming the trains),
and so does the log (a warning): the dashboard shows both.

:func:`fixed_plan` is the baseline: every train keeps its planned running times and only
the dwells, the headway and the order push it later (the earliest times that satisfy all
constraints, computed directly as a longest path, no LP).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.optimize import linprog

from railpilot.errors import ConfigError
from railpilot.link.messages import RunningTime, RunningTimes

logger = logging.getLogger(__name__)

STATUS_OPTIMAL = "optimal"
STATUS_FIXED = "fixed plan"
STATUS_FALLBACK = "fallback: proportional slack"

#: the tie-break's weight [s per s of arrival time]: small against any lateness weight or
#: energy slope that matters, large enough for HiGHS to see
TIE_BREAK = 1e-6
#: relative tolerance of the curve's monotonicity and convexity checks (float rounding)
SLOPE_RTOL = 1e-9
#: tolerance [s] of the plan's own consistency checks (a timetable printed to 1e-6 s)
TIME_ATOL_S = 1e-6
#: station-pair keys: ``from * KEY_BASE + to``
_KEY_BASE = 1 << 32


# ------------------------------------------------------------------------- validation


def _number(field: str, value: Any, allowed: str, *, lo: float = -math.inf) -> float:
    """``value`` as a finite float >= ``lo``, or a ConfigError naming ``field``."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ConfigError(field, value, allowed)
    out = float(value)
    if not (math.isfinite(out) and out >= lo):
        raise ConfigError(field, value, allowed)
    return out


def _station(field: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise ConfigError(field, value, "a station id (an integer >= 0)")
    return int(value)


def _float_tuple(field: str, values: Any, allowed: str) -> tuple[float, ...]:
    """A 1-D sequence of finite numbers as a tuple of floats."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(field, values, allowed) from None
    if arr.ndim != 1 or not np.all(np.isfinite(arr)):
        raise ConfigError(field, values, allowed)
    return tuple(float(v) for v in arr)


# ---------------------------------------------------------------------- energy curve


@dataclass(frozen=True)
class EnergyCurve:
    """Net energy [kWh] of a section against its running time [s], from the onboard planner.

    Convex, non-increasing and piecewise linear between its knots ``(times_s[i],
    energy_kwh[i])``; flat beyond the last knot (running slower than the slowest sample is
    assumed to save nothing more). Below the first knot the first piece is extended, but a
    :class:`Section` never asks there (its minimum running time is at or after the first
    knot). Raw planner samples, which need be neither convex nor monotone, go through
    :meth:`from_samples`.
    """

    times_s: tuple[float, ...]
    energy_kwh: tuple[float, ...]

    def __post_init__(self) -> None:
        t = _float_tuple("times_s", self.times_s, "finite running times [s], one per knot")
        e = _float_tuple("energy_kwh", self.energy_kwh, "finite energies [kWh], one per knot")
        if not t:
            raise ConfigError("times_s", t, "at least one knot")
        if len(e) != len(t):
            raise ConfigError(
                "energy_kwh", self.energy_kwh, f"{len(t)} values, one per knot of times_s"
            )
        if t[0] <= 0:
            raise ConfigError("times_s", t, "running times > 0 [s]")
        dt = np.diff(t)
        if np.any(dt <= 0):
            raise ConfigError("times_s", t, "strictly increasing running times [s] (sorted knots)")
        slopes = np.diff(e) / dt
        tol = SLOPE_RTOL * max(1.0, float(np.max(np.abs(slopes), initial=0.0)))
        if np.any(slopes > tol):
            raise ConfigError(
                "energy_kwh",
                e,
                "energies non-increasing in the running time "
                "(EnergyCurve.from_samples takes raw samples)",
            )
        if np.any(np.diff(slopes) < -tol):
            raise ConfigError(
                "energy_kwh",
                e,
                "a convex curve: slopes [kWh/s] non-decreasing from knot to knot "
                "(EnergyCurve.from_samples takes raw samples)",
            )
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "energy_kwh", e)

    @classmethod
    def from_samples(cls, times_s: npt.ArrayLike, energy_kwh: npt.ArrayLike) -> EnergyCurve:
        """The lower convex hull of samples ``(time [s], energy [kWh])``, up to its minimum.

        The planner's energy is not always convex, nor even monotone, in the running time
        (on steep descents it moves between strategies; docs/onboard.md). The hull is the
        best the onboard can do by mixing two of its plans' running times, and it lies on
        or below every sample. Knots after the hull's lowest one are dropped: running
        slower than the cheapest sample is never worth it. Samples at one time keep the
        lowest energy.
        """
        t = np.asarray(_float_tuple("times_s", times_s, "finite running times [s], one per sample"))
        e = np.asarray(
            _float_tuple("energy_kwh", energy_kwh, "finite energies [kWh], one per sample")
        )
        if t.size == 0:
            raise ConfigError("times_s", tuple(t), "at least one sample")
        if e.size != t.size:
            raise ConfigError("energy_kwh", tuple(e), f"{t.size} values, one per sample")
        order = np.lexsort((e, t))
        t, e = t[order], e[order]
        first = np.concatenate([[True], np.diff(t) > 0])  # the lowest energy at each time
        t, e = t[first], e[first]
        # Andrew's monotone chain, lower half (scipy's Qhull rejects the collinear and
        # two-point sets a section's samples often are)
        hull: list[int] = []
        for i in range(t.size):
            while len(hull) >= 2:
                o, a = hull[-2], hull[-1]
                cross = (t[a] - t[o]) * (e[i] - e[o]) - (e[a] - e[o]) * (t[i] - t[o])
                if cross > 0:
                    break  # a left turn: a stays on the lower hull
                hull.pop()
            hull.append(i)
        idx = np.asarray(hull)
        lowest = int(np.argmin(e[idx]))
        idx = idx[: lowest + 1]
        return cls(tuple(t[idx]), tuple(e[idx]))

    @property
    def min_time_s(self) -> float:
        return self.times_s[0]

    @property
    def max_time_s(self) -> float:
        return self.times_s[-1]

    @cached_property
    def pieces(self) -> tuple[np.ndarray, np.ndarray]:
        """``(slopes [kWh/s], intercepts [kWh])``: the curve is ``max(slope t + intercept)``;
        the last piece is the flat one beyond the last knot."""
        t = np.asarray(self.times_s)
        e = np.asarray(self.energy_kwh)
        slopes = np.append(np.diff(e) / np.diff(t), 0.0)
        intercepts = e - slopes * t
        return slopes, intercepts

    def energy_at(self, time_s: float | np.ndarray) -> np.ndarray:
        """Net energy [kWh] at running times ``time_s`` [s] (vectorised)."""
        slopes, intercepts = self.pieces
        t = np.asarray(time_s, dtype=float)
        return np.max(np.multiply.outer(t, slopes) + intercepts, axis=-1)


# ------------------------------------------------------------------------ the problem


@dataclass(frozen=True)
class Section:
    """One inter-station section a train still has to run.

    Attributes
    ----------
    from_station, to_station
        Station ids (the line's).
    min_running_s
        The fastest the train can run it [s] (the onboard planner's fastest run).
    planned_running_s
        The timetable's running time [s].
    energy
        Net energy against running time (:class:`EnergyCurve`); it must cover
        ``min_running_s``.
    max_running_s
        The slowest running time the ground may send [s]; None: the curve's last knot (or
        the planned time if that is slower).
    """

    from_station: int
    to_station: int
    min_running_s: float
    planned_running_s: float
    energy: EnergyCurve
    max_running_s: float | None = None

    def __post_init__(self) -> None:
        a = _station("section.from_station", self.from_station)
        b = _station("section.to_station", self.to_station)
        where = f"section {a}->{b}"
        if a == b:
            raise ConfigError(f"{where}.to_station", b, "a station other than from_station")
        if not isinstance(self.energy, EnergyCurve):
            raise ConfigError(f"{where}.energy", self.energy, "an EnergyCurve")
        r_min = _number(f"{where}.min_running_s", self.min_running_s, "a time > 0 [s]", lo=0.0)
        if r_min <= 0:
            raise ConfigError(f"{where}.min_running_s", r_min, "a time > 0 [s]")
        if r_min < self.energy.min_time_s - TIME_ATOL_S:
            raise ConfigError(
                f"{where}.min_running_s",
                r_min,
                f"a time >= {self.energy.min_time_s:g} s, the energy curve's first knot "
                "(the curve must cover every running time the ground may send)",
            )
        planned = _number(
            f"{where}.planned_running_s",
            self.planned_running_s,
            f"a time >= min_running_s = {r_min:g} s",
            lo=r_min,
        )
        top = self.max_running_s
        if top is not None:
            _number(f"{where}.max_running_s", top, f"a time >= planned_running_s = {planned:g} s")
            if top < planned:
                raise ConfigError(
                    f"{where}.max_running_s", top, f"a time >= planned_running_s = {planned:g} s"
                )
        object.__setattr__(self, "from_station", a)
        object.__setattr__(self, "to_station", b)

    @property
    def key(self) -> int:
        return self.from_station * _KEY_BASE + self.to_station

    @property
    def upper_running_s(self) -> float:
        """The slowest running time the ground may send [s]."""
        if self.max_running_s is not None:
            return float(self.max_running_s)
        return max(self.energy.max_time_s, float(self.planned_running_s))

    @property
    def slack_s(self) -> float:
        """Planned minus minimum running time [s]."""
        return float(self.planned_running_s) - float(self.min_running_s)


@dataclass(frozen=True)
class CommittedSection:
    """A section a train has run or is running: its departure and (expected) arrival [s].

    The ground does not re-time it (for the one being run, the arrival is the planned-curve
    report's elapsed plus remaining time); it only bounds the train behind by the headway.
    """

    from_station: int
    to_station: int
    departure_s: float
    arrival_s: float

    def __post_init__(self) -> None:
        a = _station("committed.from_station", self.from_station)
        b = _station("committed.to_station", self.to_station)
        where = f"committed {a}->{b}"
        dep = _number(f"{where}.departure_s", self.departure_s, "a finite time [s]")
        _number(f"{where}.arrival_s", self.arrival_s, f"a time >= departure_s = {dep:g} s", lo=dep)

    @property
    def key(self) -> int:
        return int(self.from_station) * _KEY_BASE + int(self.to_station)


@dataclass(frozen=True)
class TrainPlan:
    """One train's remaining run as the timetable has it and as far as it can be changed.

    Attributes
    ----------
    train_id
        The train number.
    sections
        Its remaining sections in running order, chained (each starts where the last
        ended).
    planned_departures_s
        The timetable's departure from the start of each section [s] (dwells included).
    min_dwell_s
        The shortest stop at each station between two remaining sections [s] (one fewer
        than ``sections``).
    earliest_departure_s
        The earliest its first remaining section can start [s] (its delay lands here).
    weight
        Weight of its lateness at the destination (per second).
    latest_arrival_s
        A hard latest arrival at the destination [s] (``inf``: none).
    committed
        Sections it has run or is running (their times bound the trains behind it).
    """

    train_id: str
    sections: tuple[Section, ...]
    planned_departures_s: tuple[float, ...]
    min_dwell_s: tuple[float, ...]
    earliest_departure_s: float
    weight: float = 1.0
    latest_arrival_s: float = math.inf
    committed: tuple[CommittedSection, ...] = ()

    def __post_init__(self) -> None:
        tid = self.train_id
        if not isinstance(tid, str) or not tid.strip():
            raise ConfigError("train_id", tid, "a non-empty string (the train number)")
        where = f"train {tid}"
        sections = tuple(self.sections) if isinstance(self.sections, Sequence) else None
        if not sections or not all(isinstance(s, Section) for s in sections):
            raise ConfigError(f"{where}.sections", self.sections, "a non-empty tuple of Section")
        for j in range(1, len(sections)):
            if sections[j].from_station != sections[j - 1].to_station:
                raise ConfigError(
                    f"{where}.sections[{j}].from_station",
                    sections[j].from_station,
                    f"{sections[j - 1].to_station}, where sections[{j - 1}] ends "
                    "(sections must chain)",
                )
        n = len(sections)
        planned = _float_tuple(
            f"{where}.planned_departures_s",
            self.planned_departures_s,
            "finite departure times [s], one per section",
        )
        if len(planned) != n:
            raise ConfigError(
                f"{where}.planned_departures_s",
                self.planned_departures_s,
                f"{n} departure times, one per section",
            )
        dwell = _float_tuple(f"{where}.min_dwell_s", self.min_dwell_s, "finite dwells >= 0 [s]")
        if len(dwell) != n - 1:
            raise ConfigError(
                f"{where}.min_dwell_s",
                self.min_dwell_s,
                f"{n - 1} dwells, one per station between two sections",
            )
        if any(d < 0 for d in dwell):
            raise ConfigError(f"{where}.min_dwell_s", dwell, "dwells >= 0 [s]")
        for j in range(1, n):
            arrival = planned[j - 1] + sections[j - 1].planned_running_s
            if planned[j] < arrival + dwell[j - 1] - TIME_ATOL_S:
                raise ConfigError(
                    f"{where}.planned_departures_s[{j}]",
                    planned[j],
                    f"a departure >= {arrival + dwell[j - 1]:g} s, the planned arrival plus "
                    "the minimum dwell",
                )
        _number(f"{where}.earliest_departure_s", self.earliest_departure_s, "a finite time [s]")
        _number(f"{where}.weight", self.weight, "a weight >= 0 [per s]", lo=0.0)
        latest = self.latest_arrival_s
        if isinstance(latest, bool) or not isinstance(latest, int | float) or math.isnan(latest):
            raise ConfigError(f"{where}.latest_arrival_s", latest, "a time [s] or inf")
        committed = tuple(self.committed) if isinstance(self.committed, Sequence) else None
        if committed is None or not all(isinstance(c, CommittedSection) for c in committed):
            raise ConfigError(f"{where}.committed", self.committed, "a tuple of CommittedSection")
        object.__setattr__(self, "sections", sections)
        object.__setattr__(self, "planned_departures_s", planned)
        object.__setattr__(self, "min_dwell_s", dwell)
        object.__setattr__(self, "committed", committed)

    @property
    def planned_arrival_s(self) -> float:
        """The timetable's arrival at the destination [s]."""
        return self.planned_departures_s[-1] + float(self.sections[-1].planned_running_s)

    @property
    def destination(self) -> int:
        return self.sections[-1].to_station


@dataclass(frozen=True)
class RetimeProblem:
    """The trains to re-time, in their fixed order on the line (the front train first).

    Attributes
    ----------
    trains
        The trains, front first.
    headway_s
        The fixed-block headway ``h`` [s] (module docstring: between departures and
        between arrivals of consecutive trains on a section).
    now_s
        The time of the re-timing [s]; no remaining section starts before it.
    energy_weight_s_per_kwh
        What one kWh is worth in seconds of (weighted) lateness.
    ahead
        Sections run or being run by trains ahead of all of ``trains`` that are not
        re-timed (a train on its last section), front first: like a train's
        ``committed`` sections, they bound the trains behind by the headway.
    """

    trains: tuple[TrainPlan, ...]
    headway_s: float
    now_s: float
    energy_weight_s_per_kwh: float
    ahead: tuple[CommittedSection, ...] = ()

    def __post_init__(self) -> None:
        trains = tuple(self.trains) if isinstance(self.trains, Sequence) else None
        if not trains or not all(isinstance(t, TrainPlan) for t in trains):
            raise ConfigError("trains", self.trains, "a non-empty tuple of TrainPlan")
        ids = [t.train_id for t in trains]
        if len(set(ids)) != len(ids):
            twice = sorted({i for i in ids if ids.count(i) > 1})
            raise ConfigError("trains", twice, "each train once (unique train ids)")
        _number("headway_s", self.headway_s, "a headway >= 0 [s]", lo=0.0)
        _number("now_s", self.now_s, "a finite time [s]")
        _number(
            "energy_weight_s_per_kwh",
            self.energy_weight_s_per_kwh,
            "a weight >= 0 [s per kWh]",
            lo=0.0,
        )
        ahead = tuple(self.ahead) if isinstance(self.ahead, Sequence) else None
        if ahead is None or not all(isinstance(c, CommittedSection) for c in ahead):
            raise ConfigError("ahead", self.ahead, "a tuple of CommittedSection")
        object.__setattr__(self, "trains", trains)
        object.__setattr__(self, "ahead", ahead)
        _ = self._layout  # the order and the section pairs are checked here, once

    @cached_property
    def _layout(self) -> _Layout:
        return _Layout.of(self)


# ------------------------------------------------------------------------- the layout


@dataclass(frozen=True, eq=False)
class _Layout:
    """The problem flattened: one entry per remaining section, times relative to ``now``.

    ``g`` indexes remaining sections train by train in the order; ``start[k]:start[k+1]``
    are train ``k``'s. ``leader[g]``: the remaining section of the nearest train ahead
    that runs the same station pair (-1: none); ``fixed_dep``/``fixed_arr``: the known
    departure/arrival [s, from now] of a committed leader section (-inf: none).
    """

    start: np.ndarray
    train_of: np.ndarray
    dep_lb: np.ndarray
    planned_dep: np.ndarray
    r_min: np.ndarray
    r_max: np.ndarray
    r_plan: np.ndarray
    dwell_after: np.ndarray
    leader: np.ndarray
    fixed_dep: np.ndarray
    fixed_arr: np.ndarray
    planned_arr: np.ndarray
    latest_arr: np.ndarray
    weight: np.ndarray
    piece_of: np.ndarray
    piece_slope: np.ndarray
    piece_intercept: np.ndarray
    piece_start: np.ndarray

    @property
    def n(self) -> int:
        return int(self.start[-1])

    @property
    def k(self) -> int:
        return int(self.start.size - 1)

    @property
    def last(self) -> np.ndarray:
        return self.start[1:] - 1

    @classmethod
    def of(cls, problem: RetimeProblem) -> _Layout:
        now = float(problem.now_s)
        trains = problem.trains
        counts = np.array([len(t.sections) for t in trains])
        start = np.concatenate([[0], np.cumsum(counts)])
        train_of = np.repeat(np.arange(len(trains)), counts)
        sections = [s for t in trains for s in t.sections]
        planned_dep = np.concatenate([t.planned_departures_s for t in trains]) - now
        r_min = np.array([s.min_running_s for s in sections], dtype=float)
        r_max = np.array([s.upper_running_s for s in sections], dtype=float)
        r_plan = np.array([s.planned_running_s for s in sections], dtype=float)
        dwell_after = np.zeros(start[-1])
        for k, t in enumerate(trains):
            dwell_after[start[k] : start[k + 1] - 1] = t.min_dwell_s
        dep_lb = planned_dep.copy()
        first = start[:-1]
        earliest = np.array([t.earliest_departure_s for t in trains]) - now
        dep_lb[first] = np.maximum(np.maximum(dep_lb[first], earliest), 0.0)

        leader, fixed_dep, fixed_arr = _pairs(problem, start, sections, now)

        pieces = [s.energy.pieces for s in sections]
        n_pieces = np.array([p[0].size for p in pieces])
        piece_start = np.concatenate([[0], np.cumsum(n_pieces)])[:-1]
        return cls(
            start=start,
            train_of=train_of,
            dep_lb=dep_lb,
            planned_dep=planned_dep,
            r_min=r_min,
            r_max=r_max,
            r_plan=r_plan,
            dwell_after=dwell_after,
            leader=leader,
            fixed_dep=fixed_dep,
            fixed_arr=fixed_arr,
            planned_arr=np.array([t.planned_arrival_s for t in trains]) - now,
            latest_arr=np.array([float(t.latest_arrival_s) for t in trains]) - now,
            weight=np.array([float(t.weight) for t in trains]),
            piece_of=np.repeat(np.arange(len(sections)), n_pieces),
            piece_slope=np.concatenate([p[0] for p in pieces]),
            piece_intercept=np.concatenate([p[1] for p in pieces]),
            piece_start=piece_start,
        )

    def energy(self, r: np.ndarray) -> np.ndarray:
        """Net energy [kWh] of every remaining section at running times ``r`` [s]."""
        values = self.piece_slope * r[self.piece_of] + self.piece_intercept
        return np.maximum.reduceat(values, self.piece_start)


def _pairs(
    problem: RetimeProblem, start: np.ndarray, sections: list[Section], now: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each remaining section's leader: the nearest train ahead on the same station pair.

    Sorting every (remaining or committed) section by (station pair, train order) puts each
    leader just before its follower.
    """
    trains = problem.trains
    n = int(start[-1])
    # the sections of trains ahead come first in the order (negative, front first)
    ahead = problem.ahead
    committed = [(i - len(ahead), c) for i, c in enumerate(ahead)]
    committed += [(k, c) for k, t in enumerate(trains) for c in t.committed]
    key = np.array([s.key for s in sections] + [c.key for _, c in committed], dtype=np.int64)
    order = np.concatenate(
        [np.repeat(np.arange(len(trains)), np.diff(start)), [k for k, _ in committed]]
    ).astype(np.int64)
    c_dep = np.array([c.departure_s for _, c in committed], dtype=float) - now
    c_arr = np.array([c.arrival_s for _, c in committed], dtype=float) - now
    perm = np.lexsort((order, key))
    same = key[perm][1:] == key[perm][:-1]
    lead, foll = perm[:-1][same], perm[1:][same]
    twice = order[lead] == order[foll]
    if np.any(twice):
        k = int(order[lead][twice][0])
        pair = int(key[lead][twice][0])
        raise ConfigError(
            f"trains[{k}] ({trains[k].train_id})",
            f"{pair // _KEY_BASE}->{pair % _KEY_BASE}",
            "each station pair once per train (remaining and committed sections together)",
        )
    behind = (lead < n) & (foll >= n)
    if np.any(behind):
        i = int(np.flatnonzero(behind)[0])
        k = int(order[foll[i]])
        pair = int(key[foll[i]])
        raise ConfigError(
            f"trains[{k}] ({trains[k].train_id}).committed",
            f"{pair // _KEY_BASE}->{pair % _KEY_BASE}",
            f"sections the train ahead ({trains[int(order[lead[i]])].train_id}) has run "
            "too: the order is fixed, no train passes another",
        )
    leader = np.full(n, -1, dtype=np.int64)
    fixed_dep = np.full(n, -np.inf)
    fixed_arr = np.full(n, -np.inf)
    both = (lead < n) & (foll < n)
    leader[foll[both]] = lead[both]
    known = (lead >= n) & (foll < n)
    fixed_dep[foll[known]] = c_dep[lead[known] - n]
    fixed_arr[foll[known]] = c_arr[lead[known] - n]
    return leader, fixed_dep, fixed_arr


# ---------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class TrainTimes:
    """A train's new times: per remaining section, departure [s], running time [s] and the
    net energy [kWh] its curve gives for it."""

    train_id: str
    stations: tuple[tuple[int, int], ...]
    departure_s: np.ndarray
    running_s: np.ndarray
    energy_kwh: np.ndarray
    planned_arrival_s: float
    weight: float
    latest_arrival_s: float

    @property
    def arrival_s(self) -> np.ndarray:
        """Arrival at the end of each section [s]."""
        return self.departure_s + self.running_s

    @property
    def lateness_s(self) -> float:
        """Lateness at the destination [s] (0 if on time or early)."""
        return max(0.0, float(self.arrival_s[-1]) - self.planned_arrival_s)

    def message(self) -> RunningTimes:
        """The link message that sends these running times to the train."""
        return RunningTimes(
            tuple(
                RunningTime(a, b, float(r))
                for (a, b), r in zip(self.stations, self.running_s, strict=True)
            )
        )


@dataclass(frozen=True, eq=False)
class RetimeResult:
    """New times for every train of a :class:`RetimeProblem`.

    ``status``: "optimal" (the LP), "fixed plan" (the baseline) or "fallback: proportional
    slack" (the LP failed; ``reason`` says why). ``solve_ms``: wall time of the call
    (building the matrices, HiGHS, reading the answer) [ms]; ``lp_ms``: HiGHS alone.
    """

    status: str
    reason: str
    trains: tuple[TrainTimes, ...]
    energy_weight_s_per_kwh: float
    solve_ms: float
    lp_ms: float = 0.0

    @property
    def fallback(self) -> bool:
        return self.status == STATUS_FALLBACK

    def train(self, train_id: str) -> TrainTimes:
        for t in self.trains:
            if t.train_id == train_id:
                return t
        raise ConfigError("train_id", train_id, f"one of {[t.train_id for t in self.trains]}")

    @property
    def lateness_s(self) -> np.ndarray:
        """Lateness at the destination per train [s], in the order."""
        return np.array([t.lateness_s for t in self.trains])

    @property
    def total_weighted_lateness_s(self) -> float:
        return float(sum(t.weight * t.lateness_s for t in self.trains))

    @property
    def total_energy_kwh(self) -> float:
        """Net energy of all remaining sections [kWh]."""
        return float(sum(float(np.sum(t.energy_kwh)) for t in self.trains))

    @property
    def objective_s(self) -> float:
        """Weighted lateness plus weighted energy [s] (the LP's objective, no tie-break)."""
        return self.total_weighted_lateness_s + (
            self.energy_weight_s_per_kwh * self.total_energy_kwh
        )

    def latest_arrival_missed(self) -> tuple[str, ...]:
        """The trains arriving after their hard latest arrival."""
        return tuple(
            t.train_id
            for t in self.trains
            if float(t.arrival_s[-1]) > t.latest_arrival_s + TIME_ATOL_S
        )


def _result(
    problem: RetimeProblem,
    layout: _Layout,
    d: np.ndarray,
    r: np.ndarray,
    status: str,
    reason: str,
    started: float,
    lp_ms: float = 0.0,
) -> RetimeResult:
    now = float(problem.now_s)
    energy = layout.energy(r)
    trains = []
    for k, plan in enumerate(problem.trains):
        sl = slice(int(layout.start[k]), int(layout.start[k + 1]))
        trains.append(
            TrainTimes(
                plan.train_id,
                tuple((s.from_station, s.to_station) for s in plan.sections),
                d[sl] + now,
                r[sl].copy(),
                energy[sl],
                plan.planned_arrival_s,
                float(plan.weight),
                float(plan.latest_arrival_s),
            )
        )
    return RetimeResult(
        status,
        reason,
        tuple(trains),
        float(problem.energy_weight_s_per_kwh),
        (time.perf_counter() - started) * 1e3,
        lp_ms,
    )


# ----------------------------------------------------------- direct schedules (no LP)


def _train_departures(
    layout: _Layout, h: float, k: int, r: np.ndarray, d: np.ndarray
) -> np.ndarray:
    """Train ``k``'s earliest departures [s, from now] for running times ``r``, its
    leaders' times in ``d`` already set: a longest path, as a max-plus scan.

    ``d_j = max(c_j, d_{j-1} + r_{j-1} + dwell_{j-1})`` with ``c_j`` the bounds of the
    section alone (never early, the leader's departure and arrival plus the headway), so
    ``d_j = D_j + max_{i <= j}(c_i - D_i)``, ``D`` the prefix sums of ``r + dwell``.
    """
    sl = slice(int(layout.start[k]), int(layout.start[k + 1]))
    rk = r[sl]
    c = np.maximum(layout.dep_lb[sl], layout.fixed_dep[sl] + h)
    c = np.maximum(c, layout.fixed_arr[sl] + h - rk)
    lead = layout.leader[sl]
    has = lead >= 0
    if np.any(has):
        lg = lead[has]
        c[has] = np.maximum(c[has], np.maximum(d[lg] + h, d[lg] + r[lg] + h - rk[has]))
    step = rk + layout.dwell_after[sl]
    prefix = np.concatenate([[0.0], np.cumsum(step[:-1])])
    return prefix + np.maximum.accumulate(c - prefix)


def _schedule(layout: _Layout, h: float, r: np.ndarray) -> np.ndarray:
    """Everyone's earliest departures [s, from now] for running times ``r``."""
    d = np.empty(layout.n)
    for k in range(layout.k):
        d[layout.start[k] : layout.start[k + 1]] = _train_departures(layout, h, k, r, d)
    return d


def fixed_plan(problem: RetimeProblem) -> RetimeResult:
    """The baseline: planned running times; the dwells, headway and order push trains later.

    The earliest departures that satisfy every constraint with the running times fixed
    (module docstring); a hard latest arrival is not enforced (it may be missed:
    :meth:`RetimeResult.latest_arrival_missed`).
    """
    started = time.perf_counter()
    layout = problem._layout
    r = layout.r_plan.copy()
    d = _schedule(layout, float(problem.headway_s), r)
    return _result(problem, layout, d, r, STATUS_FIXED, "", started)


def proportional_slack(problem: RetimeProblem, reason: str = "") -> RetimeResult:
    """The fallback: each train recovers what it is late by shortening every remaining
    section by the same share of its slack (module docstring)."""
    started = time.perf_counter()
    layout = problem._layout
    h = float(problem.headway_s)
    r = layout.r_plan.copy()
    d = np.empty(layout.n)
    for k in range(layout.k):
        sl = slice(int(layout.start[k]), int(layout.start[k + 1]))
        d[sl] = _train_departures(layout, h, k, r, d)
        arrival = d[sl][-1] + r[sl][-1]
        late = max(arrival - layout.planned_arr[k], arrival - layout.latest_arr[k], 0.0)
        slack = layout.r_plan[sl] - layout.r_min[sl]
        total = float(np.sum(slack))
        if late > 0 and total > 0:
            share = min(1.0, late / total)
            r[sl] = layout.r_plan[sl] - share * slack
            d[sl] = _train_departures(layout, h, k, r, d)
    result = _result(problem, layout, d, r, STATUS_FALLBACK, reason, started)
    missed = result.latest_arrival_missed()
    if missed:
        reason = f"{reason}; latest arrival still missed by {', '.join(missed)}"
    return RetimeResult(
        result.status,
        reason,
        result.trains,
        result.energy_weight_s_per_kwh,
        (time.perf_counter() - started) * 1e3,
    )


def _infeasible_reason(problem: RetimeProblem, layout: _Layout, message: str) -> str:
    """Why the LP has no solution, in words: the trains that cannot make their latest
    arrival even alone at their minimum running times, else the headway and order."""
    alone = []
    for k, plan in enumerate(problem.trains):
        sl = slice(int(layout.start[k]), int(layout.start[k + 1]))
        c = np.maximum(layout.dep_lb[sl], layout.fixed_dep[sl] + problem.headway_s)
        c = np.maximum(c, layout.fixed_arr[sl] + problem.headway_s - layout.r_min[sl])
        step = layout.r_min[sl] + layout.dwell_after[sl]
        prefix = np.concatenate([[0.0], np.cumsum(step[:-1])])
        d = prefix + np.maximum.accumulate(c - prefix)
        earliest = d[-1] + layout.r_min[sl][-1]
        if earliest > layout.latest_arr[k] + TIME_ATOL_S:
            now = float(problem.now_s)
            alone.append(
                f"{plan.train_id} (latest arrival {layout.latest_arr[k] + now:.0f} s, "
                f"earliest possible {earliest + now:.0f} s)"
            )
    if alone:
        return f"LP infeasible ({message}): cannot arrive in time even alone: " + "; ".join(alone)
    return (
        f"LP infeasible ({message}): the latest arrivals cannot all be met with a "
        f"{problem.headway_s:g} s headway in the fixed order"
    )


# ----------------------------------------------------------------------------- the LP


def _block(
    row0: int, n_rows: int, terms: Sequence[tuple[np.ndarray, float | np.ndarray]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COO triplets of ``n_rows`` rows from ``row0``, each row ``sum coeff x[cols[i]]``."""
    rows = np.arange(row0, row0 + n_rows)
    return (
        np.concatenate([rows] * len(terms)),
        np.concatenate([np.asarray(cols) for cols, _ in terms]),
        np.concatenate([np.broadcast_to(np.asarray(v, dtype=float), n_rows) for _, v in terms]),
    )


def _lp(problem: RetimeProblem, layout: _Layout) -> tuple[Any, ...]:
    """``c, A_ub, b_ub, bounds`` of the LP (module docstring); columns ``d | r | e | L``."""
    n, k = layout.n, layout.k
    h = float(problem.headway_s)
    D, R, E, L = 0, n, 2 * n, 3 * n
    g = np.arange(n)
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    rhs: list[np.ndarray] = []
    row = 0

    def add(terms: Sequence[tuple[np.ndarray, float | np.ndarray]], b: np.ndarray) -> None:
        nonlocal row
        if b.size:
            blocks.append(_block(row, b.size, terms))
            rhs.append(b)
            row += b.size

    # dwell: d[g] + r[g] - d[g+1] <= -dwell  (g not a train's last section)
    inner = np.setdiff1d(g, layout.last, assume_unique=True)
    add([(D + inner, 1.0), (R + inner, 1.0), (D + inner + 1, -1.0)], -layout.dwell_after[inner])
    # headway between remaining sections: departures, then arrivals
    foll = np.flatnonzero(layout.leader >= 0)
    lead = layout.leader[foll]
    add([(D + lead, 1.0), (D + foll, -1.0)], np.full(foll.size, -h))
    add(
        [(D + lead, 1.0), (R + lead, 1.0), (D + foll, -1.0), (R + foll, -1.0)],
        np.full(foll.size, -h),
    )
    # a committed leader's known arrival: -d - r <= -(arrival + h)
    known = np.flatnonzero(np.isfinite(layout.fixed_arr))
    add([(D + known, -1.0), (R + known, -1.0)], -(layout.fixed_arr[known] + h))
    # energy epigraph: slope r - e <= -intercept, every piece
    p = layout.piece_of
    add([(R + p, layout.piece_slope), (E + p, -1.0)], -layout.piece_intercept)
    # lateness: d + r - L <= planned arrival (last sections)
    last = layout.last
    add([(D + last, 1.0), (R + last, 1.0), (L + np.arange(k), -1.0)], layout.planned_arr)
    # hard latest arrival where given
    bounded = np.flatnonzero(np.isfinite(layout.latest_arr))
    add([(D + last[bounded], 1.0), (R + last[bounded], 1.0)], layout.latest_arr[bounded])

    rows_i = np.concatenate([b[0] for b in blocks])
    cols_i = np.concatenate([b[1] for b in blocks])
    vals = np.concatenate([b[2] for b in blocks])
    a_ub = sp.csr_array((vals, (rows_i, cols_i)), shape=(row, 3 * n + k))
    b_ub = np.concatenate(rhs)

    c = np.concatenate(
        [
            np.full(n, TIE_BREAK),
            np.full(n, TIE_BREAK),
            np.full(n, float(problem.energy_weight_s_per_kwh)),
            layout.weight,
        ]
    )
    dep_lb = np.maximum(layout.dep_lb, layout.fixed_dep + h)
    lower = np.concatenate([dep_lb, layout.r_min, np.full(n, -np.inf), np.zeros(k)])
    upper = np.concatenate([np.full(n, np.inf), layout.r_max, np.full(n + k, np.inf)])
    return c, a_ub, b_ub, np.column_stack([lower, upper])


def retime(problem: RetimeProblem) -> RetimeResult:
    """New running times for every train of ``problem``: the LP, or the fallback.

    Returns status "optimal" when HiGHS solves the LP; otherwise the proportional slack
    redistribution with status "fallback: proportional slack" and the reason, logged as a
    warning (module docstring).
    """
    started = time.perf_counter()
    layout = problem._layout
    c, a_ub, b_ub, bounds = _lp(problem, layout)
    lp_started = time.perf_counter()
    res = linprog(c, A_ub=a_ub, b_ub=b_ub, bounds=bounds, method="highs")
    lp_ms = (time.perf_counter() - lp_started) * 1e3
    if res.status != 0:
        if res.status == 2:
            reason = _infeasible_reason(problem, layout, res.message)
        else:
            reason = f"LP not solved (HiGHS status {res.status}: {res.message})"
        logger.warning("re-timing falls back to proportional slack redistribution: %s", reason)
        out = proportional_slack(problem, reason)
        return RetimeResult(
            out.status,
            out.reason,
            out.trains,
            out.energy_weight_s_per_kwh,
            (time.perf_counter() - started) * 1e3,
            lp_ms,
        )
    n = layout.n
    x = res.x
    # HiGHS meets bounds to its feasibility tolerance (1e-7): clip what it sends
    r = np.clip(x[n : 2 * n], layout.r_min, layout.r_max)
    d = x[:n]
    return _result(problem, layout, d, r, STATUS_OPTIMAL, "", started, lp_ms)
