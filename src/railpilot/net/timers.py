"""One timer for many endpoints: the deadline heap (deadlines.py) driven by asyncio.

A thousand trains must not mean a thousand sleeping tasks polling every 50 ms: each
endpoint says when it next needs :meth:`~railpilot.link.Endpoint.tick`
(``next_deadline_s()``), and this scheduler keeps those deadlines in a
:class:`~railpilot.deadlines.DeadlineHeap` and arms ONE ``loop.call_at`` for the earliest
(its :class:`~railpilot.deadlines.AsyncioAlarm`). Ticks therefore happen when something is
due (a heartbeat, running info, a resend, a timeout), not on a fixed grid.

Core times are epoch seconds (a :class:`LinkClock`: ``time.time()`` unless the run is on a
simulated clock; frame timestamps derive from it); asyncio timers run on the loop's
monotonic clock. The conversion happens here and only here.
"""

from __future__ import annotations

import time
from typing import Protocol

from railpilot.deadlines import AsyncioAlarm, DeadlineHeap
from railpilot.errors import ConfigError, is_finite_number


class LinkClock:
    """What the link calls now [s since the epoch], and how long the event loop waits for
    a span of it.

    The default is the wall clock (``time.time()``). ``LinkClock(speedup, origin_s,
    wall_origin_s)`` runs ``speedup`` times faster than the wall clock and reads
    ``origin_s`` at the wall time ``wall_origin_s``: the live line run (``railpilot line
    run --speedup 60``, cosim/live.py) puts the ground and every train on one such clock,
    so the link's timers, its timestamps, TSR validity and the trains' physics all run on
    the scenario's time, and a 9-hour day passes in 9 minutes. Every process computes it
    from the same three numbers and the host's wall clock, so they agree without talking.
    """

    __slots__ = ("_wall", "origin_s", "speedup", "wall_origin_s")

    def __init__(
        self,
        speedup: float = 1.0,
        origin_s: float | None = None,
        wall_origin_s: float | None = None,
    ) -> None:
        if not is_finite_number(speedup) or not 0.0 < speedup <= 10_000.0:
            raise ConfigError("speedup", speedup, "a time scale in (0, 10000]")
        if (origin_s is None) != (wall_origin_s is None):
            raise ConfigError("origin_s", origin_s, "given with wall_origin_s, or neither")
        for name, value in (("origin_s", origin_s), ("wall_origin_s", wall_origin_s)):
            if value is not None and (not is_finite_number(value) or value <= 0.0):
                raise ConfigError(name, value, "a time > 0 [s since the epoch]")
        self.speedup = float(speedup)
        now = time.time()
        self.wall_origin_s = now if wall_origin_s is None else float(wall_origin_s)
        self.origin_s = self.wall_origin_s if origin_s is None else float(origin_s)
        # read on every frame: decided once
        self._wall = self.speedup == 1.0 and self.origin_s == self.wall_origin_s

    @property
    def is_wall(self) -> bool:
        """Is this the host's own clock (no scale, no offset)?"""
        return self._wall

    def __call__(self) -> float:
        """Now [s since the epoch] on this clock."""
        if self._wall:
            return time.time()
        return self.origin_s + (time.time() - self.wall_origin_s) * self.speedup

    def wall_s(self, span_s: float) -> float:
        """How long the event loop waits [s] for ``span_s`` seconds of this clock."""
        return span_s / self.speedup

    def __repr__(self) -> str:
        if self.is_wall:
            return "LinkClock()"
        return f"LinkClock({self.speedup:g}, {self.origin_s:.3f}, {self.wall_origin_s:.3f})"


#: The host's own clock: what the link uses unless told otherwise.
WALL_CLOCK = LinkClock()


class Tickable(Protocol):
    """What the scheduler drives: usually a connection adapter around one endpoint."""

    #: Deadline (epoch s) this item is queued for, ``None`` when not queued. Owned by the
    #: scheduler; an adapter only initialises it to ``None``.
    scheduled_s: float | None

    def next_deadline_s(self) -> float | None:
        """Latest epoch time of the next tick (``None``: nothing pending)."""
        ...

    def on_tick(self, now_s: float) -> None:
        """Tick the endpoint, write its output, handle its events."""
        ...


class TickScheduler:
    """Calls ``on_tick`` of many items at their deadlines from one timer handle.

    ``max_interval_s`` caps the wait even when an item reports no deadline, so a missed
    reschedule can only delay a tick, never lose it. ``min_interval_s`` keeps an item whose
    deadline is already past but which cannot act on it yet (a ground endpoint that does not
    know its peer) from spinning the loop.
    """

    def __init__(
        self,
        *,
        max_interval_s: float = 0.5,
        min_interval_s: float = 0.01,
        clock: LinkClock = WALL_CLOCK,
    ) -> None:
        self.clock = clock
        self.max_interval_s = max_interval_s
        self.min_interval_s = min_interval_s
        self._heap: DeadlineHeap[Tickable] = DeadlineHeap()
        self._alarm = AsyncioAlarm(self._wait_s, self._fire)
        self._closed = False
        #: Number of ``on_tick`` calls made (for the load test's report).
        self.ticks = 0

    def schedule(self, item: Tickable, *, now_s: float | None = None) -> None:
        """(Re)queue ``item`` at its next deadline; call after anything touched it."""
        if self._closed:
            return
        now = self.clock() if now_s is None else now_s
        deadline = item.next_deadline_s()
        if deadline is None:
            deadline = now + self.max_interval_s
        deadline = min(max(deadline, now + self.min_interval_s), now + self.max_interval_s)
        if item.scheduled_s is not None and item.scheduled_s <= deadline:
            return  # an earlier wake-up is already queued; it will reschedule
        item.scheduled_s = deadline
        self._heap.push(deadline, item)
        self._alarm.arm(deadline)

    def cancel(self, item: Tickable) -> None:
        """Stop ticking ``item`` (its heap entry is dropped lazily)."""
        item.scheduled_s = None

    def close(self) -> None:
        """Stop all ticking."""
        self._closed = True
        self._alarm.cancel()
        for item in self._heap.items():
            item.scheduled_s = None
        self._heap.clear()

    def __len__(self) -> int:
        return len(self._heap)

    def _wait_s(self, deadline_s: float) -> float:
        """How long the event loop waits [s] until ``deadline_s`` on the link's clock."""
        return self.clock.wall_s(deadline_s - self.clock())

    def _fire(self) -> None:
        heap = self._heap
        while (earliest := heap.earliest_s()) is not None:
            now = self.clock()
            if earliest > now:
                break
            deadline, item = heap.pop()
            if item.scheduled_s != deadline:
                continue  # stale entry: cancelled or requeued earlier
            item.scheduled_s = None
            self.ticks += 1
            # Each item gets a fresh clock reading: its frame timestamps are taken here.
            item.on_tick(now)
            if item.scheduled_s is None and not self._closed:
                self.schedule(item, now_s=now)
        earliest = heap.earliest_s()
        if earliest is not None and not self._closed:
            self._alarm.arm(earliest)
