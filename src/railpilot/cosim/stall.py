"""A line run that stands still: trains that should be moving and are not.

A line run moves its trains by their timetables and the trackside's signals. If trains
hold one another's block sections (a timetable whose trains start on top of one another),
or a train stops short of its station where nothing it knows of holds it, they stand for
the rest of the day and the KPIs, read alone, hide it. :class:`StallWatch` looks once a
second (a run's trackside watch hands it every train's head) and names the trains that
have stood ``stall_s`` or longer although nothing the run knows of holds them:

* a train waiting for its timetable's departure, or stood by a scenario's train failure,
  is held (``due`` False, TrainDriver.due_to_move);
* a train that moved less than ``stall_s`` ago is not standing still;
* a train standing behind another of its direction (at a red signal) is held if that
  train is: moving, waiting for its timetable, failed, or itself held so.

No I/O and no clock: time is passed in.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass

from railpilot.link.messages import TravelDirection
from railpilot.onboard.mrsp import direction_sign

#: a train standing this long while nothing holds it stops the run [s]: longer than any
#: wait at a red signal behind a train that runs (a few minutes), shorter than a day
DEFAULT_STALL_S = 1_800.0
#: a head that moved less than this [m] has not moved (odometry noise is far below it)
MOVED_M = 1.0


@dataclass(frozen=True)
class TrainAt:
    """A train as the watch sees it: its head [km post, m], its direction, and whether its
    timetable and the scenario want it moving (``due``)."""

    head_m: float
    direction: TravelDirection
    due: bool


@dataclass(frozen=True)
class Standing:
    """A train standing still with nothing holding it: where its head is [m] and since
    when [s]."""

    train_id: int
    head_m: float
    since_s: float


class StallWatch:
    """Where each train last moved, and which stand with nothing holding them (module
    docstring)."""

    def __init__(self, stall_s: float = DEFAULT_STALL_S) -> None:
        self.stall_s = stall_s
        self._last: dict[int, tuple[float, float]] = {}  # train -> (head [m], since [s])

    def look(self, t: float, trains: Mapping[int, TrainAt]) -> list[Standing]:
        """The trains on the line at ``t`` [s] (``trains``: by id) that stand still with
        nothing holding them, by id."""
        for train_id, at in trains.items():
            last = self._last.get(train_id)
            if last is None or abs(at.head_m - last[0]) >= MOVED_M:
                self._last[train_id] = (at.head_m, t)
        for gone in self._last.keys() - trains.keys():
            del self._last[gone]
        held: dict[int, bool] = {}
        ahead = _train_ahead(trains)

        def is_held(train_id: int) -> bool:
            # a chain of trains behind one another ends: ``ahead`` only goes forward
            if train_id not in held:
                at = trains[train_id]
                moved = t - self._last[train_id][1] < self.stall_s
                front = ahead.get(train_id)
                held[train_id] = not at.due or moved or (front is not None and is_held(front))
            return held[train_id]

        return [
            Standing(i, trains[i].head_m, self._last[i][1])
            for i in sorted(trains)
            if not is_held(i)
        ]


def _train_ahead(trains: Mapping[int, TrainAt]) -> dict[int, int]:
    """Each train's next train ahead of it in its own direction (one track each way), by
    id; none for the first."""
    ahead: dict[int, int] = {}
    for direction in {at.direction for at in trains.values()}:
        sign = direction_sign(direction)
        order = sorted(
            (i for i, at in trains.items() if at.direction is direction),
            key=lambda i: (sign * trains[i].head_m, i),
        )
        for behind, front in itertools.pairwise(order):
            ahead[behind] = front
    return ahead
