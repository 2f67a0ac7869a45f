"""What the line's own equipment sees, once a second: where every train is, the signals'
aspects (the cab signal each train sees), and every TSR, red signal and static speed
limit against what the trains do (docs/line-run.md "KPIs").

:class:`Trackside` is the truth the KPIs come from, not what the trains or the ground
believe. It has no transport and no clock of its own: a run hands it what it saw
(:meth:`Trackside.look`), the co-simulation from its train drivers at the same instant,
the live run (cosim/live.py) from the trains' last reports over the trackside wire.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from railpilot.ground.occupancy import (
    Occupancy,
    TrainReport,
    compute_occupancy,
    direction_sign,
)
from railpilot.ground.operations import CancelTsr, SetTsr
from railpilot.ground.targets import find_target
from railpilot.line.model import RailLine
from railpilot.link import TravelDirection
from railpilot.onboard.mrsp import SpeedProfile, train_span_m

#: how many block sections ahead a cab signal shows (3-aspect signalling: the next
#: signal's aspect tells whether the one after it is red)
CAB_SIGNAL_BLOCKS = 2
#: over a limit by more than this is a violation [m/s] (the speed sensor's resolution)
OVERSPEED_TOLERANCE_MPS = 0.01


class TrainShape(NamedTuple):
    """What the trackside knows of a train before it runs: which way it goes, how long it
    is [m], and its category (whose static speed limits it obeys, line/model.py)."""

    direction: TravelDirection
    length_m: float
    category: str


@dataclass
class TsrWatch:
    """A TSR as the dispatcher set it: the truth the trains are checked against."""

    start_m: float
    end_m: float
    limit_mps: float
    valid_from_s: float  # epoch
    valid_until_s: float
    session: int


@dataclass(frozen=True)
class TrainSeen:
    """One train as the trackside sees it: its head [m], its speed [m/s], and the km post
    of the station it stops at next [m] (how far its target point may lie)."""

    head_m: float
    speed_mps: float
    next_stop_m: float


@dataclass(frozen=True)
class CabView:
    """What a train's cab signal shows: the red signal within sight [m] (None: none), and
    the km post of the last signal in sight [m]."""

    red_signal_m: float | None
    sight_m: float


class Trackside:
    """The line's equipment (module docstring).

    ``trains``: every train that may run, by id.
    """

    def __init__(self, line: RailLine, trains: Mapping[int, TrainShape]):
        self.line = line
        self.trains = dict(trains)
        #: train id -> rows (t [s], head km post [m], speed [m/s]), one per look
        self.trace: dict[int, list[tuple[float, float, float]]] = {i: [] for i in trains}
        self.tsrs: list[TsrWatch] = []
        self.tsr_violations: list[dict[str, Any]] = []
        self._violated: set[tuple[int, int]] = set()
        self.passed_at_red: list[dict[str, Any]] = []
        self._occupancy: Occupancy | None = None

    def traces(self) -> dict[int, np.ndarray]:
        """Each train's rows (t [s], head km post [m], speed [m/s]) as an array."""
        return {i: np.asarray(rows, dtype=float).reshape(-1, 3) for i, rows in self.trace.items()}

    def dispatched(
        self, operation: object, result: Mapping[str, Any], now_s: float, epoch_s: float
    ) -> dict[str, Any] | None:
        """A dispatcher's operation the ground carried out at ``now_s`` [epoch s], as the
        track takes it: a TSR set is laid from then on, for the validity the ground pinned
        (its ``result``); a TSR cancelled is lifted. Returns the TSR set as a run's event
        log shows it (times in s since ``epoch_s``), None for any other operation."""
        if isinstance(operation, CancelTsr):
            for tsr in self.tsrs:
                if tsr.session == operation.session:
                    tsr.valid_until_s = min(tsr.valid_until_s, now_s)
            return None
        if not isinstance(operation, SetTsr):
            return None
        session = int(result["session"])
        valid_from, valid_until = float(result["valid_from_s"]), float(result["valid_until_s"])
        self.tsrs.append(
            TsrWatch(
                operation.start_m,
                operation.end_m,
                operation.limit_mps,
                valid_from,
                valid_until,
                session,
            )
        )
        return {
            "session": session,
            "start_km": operation.start_m / 1000.0,
            "end_km": operation.end_m / 1000.0,
            "limit_kmh": round(operation.limit_mps * 3.6, 1),
            "from_s": valid_from - epoch_s,
            "until_s": valid_until - epoch_s,
        }

    def look(self, t: float, now_s: float, seen: Mapping[int, TrainSeen]) -> dict[int, CabView]:
        """The trains on the line at ``t`` [s since the start; ``now_s`` epoch s]: record
        them, check every TSR and every signal passed since the last look, and say what
        each one's cab signal shows."""
        reports = []
        for train_id, train in seen.items():
            direction, length, _ = self.trains[train_id]
            self.trace[train_id].append((t, train.head_m, train.speed_mps))
            reports.append(TrainReport(train_id, train.head_m, direction, length, now_s))
            self._check_tsrs(train_id, train, now_s, t)
        occupancy = compute_occupancy(self.line, reports, now_s)
        previous = self._occupancy
        placed = set(previous.train_ids) if previous is not None else set()
        views = {}
        for train_id, train in seen.items():
            if previous is not None and train_id in placed:
                self._check_signals(train_id, previous, occupancy, t)
            views[train_id] = self._cab_view(occupancy, train_id, train)
        self._occupancy = occupancy
        return views

    def _cab_view(self, occupancy: Occupancy, train_id: int, train: TrainSeen) -> CabView:
        line = self.line
        direction = self.trains[train_id][0]
        sections = line.block_sections_for(direction)
        me = occupancy.train(train_id)
        here = line.block_index(me.head_block_id, direction)
        assert here is not None  # the occupancy came from this direction's sections
        sight = sections[min(here + CAB_SIGNAL_BLOCKS, len(sections) - 1)].entry_m
        target = find_target(line, occupancy, train_id, horizon_m=train.next_stop_m)
        if target is None:
            return CabView(None, sight)
        there = line.block_index(target.block_id, direction)
        if there is None or there - here > CAB_SIGNAL_BLOCKS:
            return CabView(None, sight)
        return CabView(target.position_m, sight)

    def _check_tsrs(self, train_id: int, train: TrainSeen, now_s: float, t: float) -> None:
        speed = train.speed_mps
        if not self.tsrs or speed <= 0.0:
            return
        direction, length, _ = self.trains[train_id]
        head = train.head_m
        tail = head - direction_sign(direction) * length
        for tsr in self.tsrs:
            if (
                not tsr.valid_from_s <= now_s < tsr.valid_until_s
                or speed <= tsr.limit_mps + OVERSPEED_TOLERANCE_MPS
            ):
                continue
            low, high = sorted((tsr.start_m, tsr.end_m))
            where = [end for end, x in (("head", head), ("tail", tail)) if low <= x <= high]
            if where and (train_id, tsr.session) not in self._violated:
                self._violated.add((train_id, tsr.session))
                self.tsr_violations.append(
                    {
                        "train": train_id,
                        "session": tsr.session,
                        "t_s": t,
                        "at": where,
                        "speed_kmh": round(speed * 3.6, 2),
                        "limit_kmh": round(tsr.limit_mps * 3.6, 2),
                    }
                )

    def _check_signals(self, train_id: int, before: Occupancy, now: Occupancy, t: float) -> None:
        """Every signal the head passed since the last look (the entries of the blocks it
        went into), against the blocks' occupancy at the last look."""
        line = self.line
        direction = self.trains[train_id][0]
        first = line.block_index(before.train(train_id).head_block_id, direction)
        last = line.block_index(now.train(train_id).head_block_id, direction)
        assert first is not None and last is not None  # both from this direction's blocks
        for section in line.block_sections_for(direction)[first + 1 : last + 1]:
            others = [i for i in before.occupants(section.id) if i != train_id]
            if others:
                self.passed_at_red.append(
                    {
                        "train": train_id,
                        "t_s": t,
                        "signal_km": section.entry_m / 1000.0,
                        "block": section.id,
                        "held_by": others,
                    }
                )


def static_limit_under(line: RailLine, train: TrainShape, head_m: np.ndarray) -> np.ndarray:
    """The lowest static limit [m/s] of ``train``'s category and direction anywhere
    between its tail and its head, for each head km post in ``head_m`` [m].

    Boundaries included (the MRSP's convention, onboard/mrsp.py): a limit rises only when
    the tail has left the lower one, and a short slow stretch under the middle of a long
    train counts. The part of a train beyond either end of the line (a long train starting
    at a terminus) is held to the limit at that end.
    """
    static = SpeedProfile(*line.static_limit(train.category, train.direction))
    return static.lowest_along(*train_span_m(head_m, train.direction, train.length_m))


def static_overspeeds(
    line: RailLine, traces: Mapping[int, np.ndarray], trains: Mapping[int, TrainShape]
) -> list[dict[str, Any]]:
    """The spells in which a train, moving, was faster than :func:`static_limit_under`
    (the lowest static limit along it) by more than :data:`OVERSPEED_TOLERANCE_MPS`.

    ``traces``: each train's rows (t [s], head km post [m], speed [m/s]), one per look.
    Returns one entry per spell (consecutive looks over), in train then time order: the
    train, the spell's first and last look [s], and its worst look: ``t_s``, the head's
    km post, the speed and the limit [km/h] and the excess [km/h].
    """
    out: list[dict[str, Any]] = []
    for train_id, rows in sorted(traces.items()):
        if not len(rows):
            continue
        t, head, speed = rows[:, 0], rows[:, 1], rows[:, 2]
        limit = static_limit_under(line, trains[train_id], head)
        excess = speed - limit
        over = (speed > 0.0) & (excess > OVERSPEED_TOLERANCE_MPS)
        if not over.any():
            continue
        # spells: runs of consecutive looks over the limit
        change = np.flatnonzero(np.diff(over.astype(np.int8), prepend=0, append=0))
        for start, stop in zip(change[0::2], change[1::2], strict=True):
            worst = start + int(np.argmax(excess[start:stop]))
            out.append(
                {
                    "train": train_id,
                    "from_s": float(t[start]),
                    "to_s": float(t[stop - 1]),
                    "t_s": float(t[worst]),
                    "head_km": round(float(head[worst]) / 1000.0, 3),
                    "speed_kmh": round(float(speed[worst]) * 3.6, 2),
                    "limit_kmh": round(float(limit[worst]) * 3.6, 2),
                    "excess_kmh": round(float(excess[worst]) * 3.6, 2),
                }
            )
    return out
