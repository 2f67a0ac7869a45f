"""One deadline heap, with a virtual-time and an asyncio driver.

Both transports of the ground wait for the same kind of thing: a time at which something
is due (an endpoint's next tick, a packet's arrival, the dispatch core's tick, a train's
reconnect attempt). :class:`DeadlineHeap` keeps those times in order; entries due at the
same time come out in the order they were pushed, so a run is the same event for event.

What moves time differs, and only that:

- **virtual time** (the co-simulation): :func:`run_until` pops every entry due up to a
  time and hands it over; nothing waits, a day runs as fast as its events;
- **asyncio** (the live server and clients): :class:`AsyncioAlarm` arms ONE
  ``loop.call_at`` for the heap's earliest deadline, however many entries it holds.

A cancelled or moved entry stays in the heap until it comes out: its owner knows whether
it is still wanted (cheaper than removing it from the middle of the heap).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class DeadlineHeap(Generic[T]):
    """Items by deadline [s]; ties leave in the order they were pushed."""

    __slots__ = ("_entries", "_order")

    def __init__(self) -> None:
        self._entries: list[tuple[float, int, T]] = []
        self._order = itertools.count()

    def push(self, at_s: float, item: T) -> None:
        """Queue ``item`` for ``at_s``."""
        heapq.heappush(self._entries, (at_s, next(self._order), item))

    def earliest_s(self) -> float | None:
        """The earliest deadline queued (None: none)."""
        return self._entries[0][0] if self._entries else None

    def pop(self) -> tuple[float, T]:
        """The earliest entry, taken out: ``(deadline, item)``."""
        at_s, _, item = heapq.heappop(self._entries)
        return at_s, item

    def clear(self) -> None:
        self._entries.clear()

    def items(self) -> Iterator[T]:
        """The items queued, in no particular order."""
        return (item for _, _, item in self._entries)

    def __len__(self) -> int:
        return len(self._entries)


def run_until(heap: DeadlineHeap[T], until_s: float, handle: Callable[[float, T], None]) -> None:
    """The virtual-time driver: ``handle(deadline, item)`` for every entry due at or before
    ``until_s``, in order, including those ``handle`` pushes meanwhile."""
    entries = heap._entries  # the co-simulation's inner loop: millions of entries a day
    pop = heapq.heappop
    while entries and entries[0][0] <= until_s:
        at_s, _, item = pop(entries)
        handle(at_s, item)


class AsyncioAlarm:
    """The asyncio driver: one ``loop.call_at`` armed for the earliest deadline of a heap.

    ``wait_s(deadline)`` is how long the event loop waits [s] until ``deadline`` (the
    deadlines' clock may run faster than the loop's, or be offset from it); ``fire`` is
    called when the alarm rings, and re-arms it for what remains.
    """

    __slots__ = ("_armed_s", "_fire", "_handle", "_wait_s")

    def __init__(self, wait_s: Callable[[float], float], fire: Callable[[], None]) -> None:
        self._wait_s = wait_s
        self._fire = fire
        self._handle: asyncio.TimerHandle | None = None
        self._armed_s = float("inf")

    def arm(self, deadline_s: float) -> None:
        """Ring at ``deadline_s`` if that is earlier than the time already armed."""
        if deadline_s >= self._armed_s:
            return
        loop = asyncio.get_running_loop()
        if self._handle is not None:
            self._handle.cancel()
        self._armed_s = deadline_s
        self._handle = loop.call_at(loop.time() + self._wait_s(deadline_s), self._ring)

    def cancel(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None
        self._armed_s = float("inf")

    def _ring(self) -> None:
        self._handle = None
        self._armed_s = float("inf")
        self._fire()


__all__ = ["AsyncioAlarm", "DeadlineHeap", "run_until"]
