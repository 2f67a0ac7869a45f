"""railpilot/gc_tuning.py: pausing automatic garbage collection across awaits, and freezing
what start-up left alive."""

from __future__ import annotations

import asyncio
import gc

import pytest

from railpilot.gc_tuning import collection_paused, freeze_startup


@pytest.fixture(autouse=True)
def _collector_enabled():  # type: ignore[no-untyped-def]
    was = gc.isenabled()
    gc.enable()
    yield
    (gc.enable if was else gc.disable)()


def test_a_pause_holds_collection_and_gives_it_back() -> None:
    with collection_paused():
        assert not gc.isenabled()
    assert gc.isenabled()


def test_interleaved_pauses_resume_collection_only_when_the_last_one_ends() -> None:
    async def main() -> None:
        first_in, first_may_leave, first_left = asyncio.Event(), asyncio.Event(), asyncio.Event()

        async def first() -> None:
            with collection_paused():
                first_in.set()
                await first_may_leave.wait()
            # the second pause is still in force
            assert not gc.isenabled()
            first_left.set()

        async def second() -> None:
            await first_in.wait()
            with collection_paused():
                first_may_leave.set()
                await first_left.wait()  # the first pause ended inside this one
                assert not gc.isenabled()
            assert gc.isenabled()

        await asyncio.gather(first(), second())

    asyncio.run(main())
    assert gc.isenabled()


def test_a_pause_ending_in_an_error_still_resumes_collection() -> None:
    with pytest.raises(RuntimeError), collection_paused():
        raise RuntimeError("the snapshot failed")
    assert gc.isenabled()


def test_a_pause_leaves_collection_off_when_it_was_off() -> None:
    gc.disable()
    with collection_paused():
        pass
    assert not gc.isenabled()


def test_freezing_moves_what_is_alive_out_of_the_collectors_reach() -> None:
    survivor = [{"a": 1}]  # a container alive at the freeze
    try:
        frozen = freeze_startup()
        assert frozen == gc.get_freeze_count() > 0
        assert not any(o is survivor for o in gc.get_objects())  # no longer walked
    finally:
        gc.unfreeze()
    assert any(o is survivor for o in gc.get_objects())
