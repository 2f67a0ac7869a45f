"""The one deadline heap (deadlines.py) and its two drivers."""

from __future__ import annotations

import asyncio

from railpilot.deadlines import AsyncioAlarm, DeadlineHeap, run_until


def test_entries_leave_by_deadline_and_ties_in_the_order_pushed() -> None:
    heap: DeadlineHeap[str] = DeadlineHeap()
    for at_s, item in ((2.0, "c"), (1.0, "a"), (2.0, "d"), (1.0, "b")):
        heap.push(at_s, item)
    assert heap.earliest_s() == 1.0
    assert [heap.pop() for _ in range(len(heap))] == [
        (1.0, "a"),
        (1.0, "b"),
        (2.0, "c"),
        (2.0, "d"),
    ]
    assert heap.earliest_s() is None


def test_virtual_time_runs_what_is_due_including_what_it_pushes_and_stops_there() -> None:
    heap: DeadlineHeap[int] = DeadlineHeap()
    seen: list[tuple[float, int]] = []

    def handle(at_s: float, n: int) -> None:
        seen.append((at_s, n))
        heap.push(at_s + 1.0, n + 1)  # each entry schedules the next, a second later

    heap.push(0.0, 0)
    run_until(heap, 3.0, handle)
    assert seen == [(0.0, 0), (1.0, 1), (2.0, 2), (3.0, 3)]
    assert heap.earliest_s() == 4.0  # not due yet: left for the next run


def test_the_asyncio_alarm_rings_once_for_the_earliest_deadline() -> None:
    rung: list[float] = []

    async def main() -> None:
        done = asyncio.Event()
        waits: list[float] = []

        def wait_s(deadline_s: float) -> float:
            waits.append(deadline_s)
            return 0.0  # every deadline already due: the loop runs it on its next turn

        alarm = AsyncioAlarm(wait_s, lambda: (rung.append(len(waits)), done.set()))
        alarm.arm(5.0)
        alarm.arm(7.0)  # later than the armed time: nothing to re-arm
        alarm.arm(3.0)  # earlier: re-armed for it
        await done.wait()

    asyncio.run(main())
    assert rung == [2]  # armed twice (5 s, then 3 s), rang once
