"""Headway conflicts of a line run's timetable, found before the run.

Two trains on one track conflict when the timetable has both in one block section at the
same time: the later one could only be held at a red signal, and a line run would show it
standing there for the rest of the day. :func:`headway_conflicts` finds every such pair
from the timetable alone (no simulation), so that a run can be refused before it starts
(cosim/scenario.py).

Block occupation, the occupation part of a blocking time (Pachl, *Railway Operation and
Control*, ch. 4; UIC leaflet 406): a train occupies a block section of its direction from
when its head enters the section until its tail has left it, the rule the ground's
occupancy uses (ground/occupancy.py: a tail on the boundary still holds the section). It
occupies the sections under it while it stands at a station between its arrival and its
departure, at its origin from when it is placed there (powered on), and at its
destination until it arrives (it then leaves the line, as a line run retires it). A train
departs on a proceed aspect only, so the section beyond the signal ahead of its stop is
its own from its departure, however few metres ahead that signal stands (the line run's
driver does not leave against a red exit signal either).

Between its stops a train runs as the plan its driving system departs on for the
timetable's running time (the onboard's planner, no TSR: full traction away from the
stop, then the energy-saving cruise and coast), so a train is where the run will have it;
a stretch of its fastest run to the running time instead puts it behind its plan in the
first minutes and finds conflicts the run does not have. Approach and release times, and
the signal aspects a following train sees before a section it needs is free, are not
counted: a timetable this check passes can still slow a train at a yellow signal, which
the run shows; one it refuses holds a train at a red one.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from railpilot.line.model import BlockSection, RailLine
from railpilot.link.messages import TravelDirection
from railpilot.onboard.mrsp import direction_sign
from railpilot.units import hms

from .driver import Service, planned_run, shared_route


@dataclass(frozen=True)
class Occupation:
    """A train in a block section from ``start_s`` to ``end_s`` [s since the run's start]."""

    train_id: int
    block: BlockSection
    start_s: float
    end_s: float


@dataclass(frozen=True)
class HeadwayConflict:
    """Two trains in one block section at once: ``first`` holds it when ``second``
    enters (or is placed in) it."""

    first: Occupation
    second: Occupation

    @property
    def overlap_s(self) -> float:
        return min(self.first.end_s, self.second.end_s) - self.second.start_s

    def describe(self) -> str:
        block = self.first.block
        return (
            f"trains {self.first.train_id} and {self.second.train_id} would both be in block "
            f"section {block.id} (km {block.start_m / 1000:.3f}-{block.end_m / 1000:.3f}): "
            f"{self.first.train_id} holds it {hms(self.first.start_s)}-"
            f"{hms(self.first.end_s)}, {self.second.train_id} enters it at "
            f"{hms(self.second.start_s)}"
        )


def head_path(service: Service, line: RailLine, margin_kmh: float) -> tuple[np.ndarray, np.ndarray]:
    """The head's way along the track as the timetable has it (its plans keeping
    ``margin_kmh`` below the limits): times [s since the run's start] and the head's
    distance in the direction of travel [m] (``direction_sign`` times the km post),
    non-decreasing; from its placing at the origin to its arrival at the destination."""
    direction = service.direction
    sign = direction_sign(direction)
    origin = service.stops[0]
    at = sign * line.station(origin.station).stop_m(direction)
    times = [service.power_on_s, origin.departure_s]
    places = [at, at]
    for before, after in zip(service.stops[:-1], service.stops[1:], strict=True):
        running_time = after.arrival_s - before.departure_s
        run = planned_run(
            line, service.kind, before.station, after.station, margin_kmh, running_time
        )
        # the plan meets its running time to the planner's tolerance: the timetable's exactly
        stretch = running_time / run.running_time_s
        times.extend(before.departure_s + stretch * run.elapsed_s[1:])
        places.extend(at + run.s_m[1:])
        at = sign * line.station(after.station).stop_m(direction)
        # the grid ends at the stop point: the station's own km post from here on
        places[-1] = at
        if math.isfinite(after.departure_s):
            times.append(after.departure_s)
            places.append(at)
    return np.asarray(times), np.asarray(places)


def _first_time_at(times: np.ndarray, places: np.ndarray, place: float) -> float:
    """When the head first reaches ``place`` [s]: ``times[0]`` if it starts there or
    beyond, ``inf`` if it never does."""
    if places[0] >= place:
        return float(times[0])
    if places[-1] < place:
        return math.inf
    i = int(np.searchsorted(places, place, side="left"))
    share = (place - places[i - 1]) / (places[i] - places[i - 1])
    return float(times[i - 1] + share * (times[i] - times[i - 1]))


def _first_time_beyond(times: np.ndarray, places: np.ndarray, place: float) -> float:
    """When the head is first strictly beyond ``place`` [s] (``inf``: never)."""
    if places[0] > place:
        return float(times[0])
    if places[-1] <= place:
        return math.inf
    i = int(np.searchsorted(places, place, side="right"))
    share = (place - places[i - 1]) / (places[i] - places[i - 1])
    return float(times[i - 1] + share * (times[i] - times[i - 1]))


def occupations(service: Service, line: RailLine, margin_kmh: float) -> list[Occupation]:
    """Every block section of its direction ``service``'s train occupies, and when."""
    times, places = head_path(service, line, margin_kmh)
    first, second = service.stops[0].station, service.stops[1].station
    length_m = shared_route(line, service.kind, first, second, margin_kmh).preset.train.length_m
    direction = service.direction
    sign = direction_sign(direction)
    start, end = float(times[0]), float(times[-1])
    # the sections of its direction in the order it meets them: (near end, far end) in its
    # direction of travel [m]
    spans = sorted(
        (min(sign * b.start_m, sign * b.end_m), max(sign * b.start_m, sign * b.end_m), b)
        for b in line.block_sections
        if b.direction is direction
    )
    nears = np.array([near for near, _, _ in spans])
    # A train departs on a proceed aspect only: the section beyond the signal ahead of its
    # stop is its own from its departure, however short the way to that signal.
    claimed_from: dict[int, float] = {}
    for stop in service.stops[:-1]:
        at = sign * line.station(stop.station).stop_m(direction)
        ahead = int(np.searchsorted(nears, at, side="right"))
        if ahead < len(spans):
            claimed_from[ahead] = stop.departure_s
    found = []
    for k, (near, far, block) in enumerate(spans):
        entered = min(_first_time_at(times, places, near), claimed_from.get(k, math.inf))
        left = _first_time_beyond(times, places, far + length_m)
        entered, left = max(entered, start), min(left, end)
        if entered < left:
            found.append(Occupation(service.train_id, block, entered, left))
    return found


def headway_conflicts(
    services: Sequence[Service], line: RailLine, margin_kmh: float
) -> list[HeadwayConflict]:
    """Every pair of ``services`` that the timetable has in one block section at once, the
    earliest first (module docstring); their plans keep ``margin_kmh`` below the limits."""
    by_block: dict[tuple[TravelDirection, str], list[Occupation]] = {}
    for service in services:
        for held in occupations(service, line, margin_kmh):
            by_block.setdefault((held.block.direction, held.block.id), []).append(held)
    conflicts = []
    for in_block in by_block.values():
        in_block.sort(key=lambda o: (o.start_s, o.train_id))
        for i, first in enumerate(in_block):
            for second in in_block[i + 1 :]:
                if second.start_s >= first.end_s:
                    break
                conflicts.append(HeadwayConflict(first, second))
    conflicts.sort(key=lambda c: (c.second.start_s, c.first.train_id, c.second.train_id))
    return conflicts


#: a shifted train is moved later in steps of whole multiples of this [s] (the timetable's
#: own resolution: its running times are rounded up to 10 s)
SHIFT_STEP_S = 10.0


def shifted(service: Service, by_s: float) -> Service:
    """``service`` ``by_s`` [s] later at every stop (its running times and dwells kept)."""
    stops = tuple(
        dataclasses.replace(s, arrival_s=s.arrival_s + by_s, departure_s=s.departure_s + by_s)
        for s in service.stops
    )
    return dataclasses.replace(service, stops=stops)


def shift_until_clear(
    services: Sequence[Service], line: RailLine, margin_kmh: float, latest_s: float
) -> tuple[tuple[Service, ...], dict[int, float]]:
    """``services`` with the later train of each conflict moved later until no two share
    a block section: the earliest conflict first, its later train by the overlap rounded
    up to :data:`SHIFT_STEP_S`, then the check again. Returns the services and how far
    each moved train was moved [s], by id. A train that would have to leave after
    ``latest_s`` [s since the run's start] is an error: the timetable holds more trains
    than the line can run in the run."""
    by_id = {s.train_id: s for s in services}
    moved: dict[int, float] = {}
    while conflicts := headway_conflicts(tuple(by_id.values()), line, margin_kmh):
        earliest = conflicts[0]
        later = by_id[earliest.second.train_id]
        step = SHIFT_STEP_S * math.ceil(earliest.overlap_s / SHIFT_STEP_S + 1e-9)
        if later.stops[0].departure_s + step > latest_s:
            raise ConflictsRemain(earliest)
        by_id[later.train_id] = shifted(later, step)
        moved[later.train_id] = moved.get(later.train_id, 0.0) + step
    return tuple(by_id[s.train_id] for s in services), moved


class ConflictsRemain(Exception):
    """No shift within the run clears ``conflict``."""

    def __init__(self, conflict: HeadwayConflict) -> None:
        super().__init__(conflict.describe())
        self.conflict = conflict
