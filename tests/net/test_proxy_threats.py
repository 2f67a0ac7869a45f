"""EN 50159 threats injected by the fault proxy over real loopback TCP.

Each test runs one train through :class:`~railpilot.net.FaultProxy` with one kind of fault,
waits (bounded) until the ground has detected and counted it, and checks that nothing
wrong reached the application: running info arrives at most once, in order, intact and
fresh, and forged frames never get through. The full threat matrix on a fake clock is
tests/link/test_threats.py; these show the same defences on real sockets, with frames also
split across TCP segments.
"""

from __future__ import annotations

import time
from dataclasses import replace

from railpilot.link import (
    Event,
    MessageReceived,
    MessageType,
    RunningInfo,
    TravelDirection,
    encode_body,
    encode_frame,
)
from railpilot.net import ProxyOptions

from .helpers import FAST, GROUND_ID, SPEED_MPS, TRAIN_ID, Rig, rig, run, until


def _rejected(r: Rig, *checks: str) -> int:
    rejected = r.server.counters()["rejected"]
    return sum(rejected.get(c, 0) for c in checks)


def _timestamps(r: Rig) -> list[int]:
    return [e.timestamp_us for e in r.running_infos()]


def _assert_in_order_once(r: Rig) -> None:
    stamps = _timestamps(r)
    assert stamps == sorted(set(stamps)), "running info delivered twice or out of order"


def test_repetition_duplicated_frames_are_rejected_and_counted() -> None:
    async def scenario() -> None:
        async with rig(proxy=ProxyOptions(duplicate=0.3, split=True, seed=1)) as r:
            await until(lambda: r.server.counters()["repeats"] >= 3)
            assert _rejected(r, "sequence") >= 3
            assert r.proxy is not None and r.proxy.stats["up"]["duplicated"] >= 3
            _assert_in_order_once(r)

    run(scenario())


def test_deletion_dropped_frames_are_detected_as_sequence_gaps() -> None:
    async def scenario() -> None:
        async with rig(proxy=ProxyOptions(drop=0.2, seed=2)) as r:
            await until(lambda: r.server.counters()["frames_lost"] >= 3)
            assert r.server.counters()["sequence_gaps"] >= 1
            assert r.proxy is not None and r.proxy.stats["up"]["dropped"] >= 3
            _assert_in_order_once(r)

    run(scenario())


def test_resequencing_late_frames_are_rejected_as_reordered() -> None:
    async def scenario() -> None:
        async with rig(proxy=ProxyOptions(reorder=0.2, split=True, seed=3)) as r:
            await until(lambda: r.server.counters()["reorders"] >= 2)
            assert _rejected(r, "sequence") >= 2
            _assert_in_order_once(r)

    run(scenario())


def test_corruption_is_caught_and_only_intact_running_info_is_delivered() -> None:
    async def scenario() -> None:
        async with rig(proxy=ProxyOptions(corrupt=0.2, split=True, seed=4)) as r:
            await until(lambda: _rejected(r, "crc", "framing", "length", "version") >= 3)
            await until(lambda: len(r.running_infos()) >= 5)
            for event in r.running_infos():
                info = event.message
                assert isinstance(info, RunningInfo)
                assert (info.train_number, info.driver_id, info.speed_mps) == (
                    f"K{TRAIN_ID}",
                    42,
                    SPEED_MPS,
                )
            _assert_in_order_once(r)

    run(scenario())


def test_delay_stale_frames_are_rejected_and_only_fresh_data_is_delivered() -> None:
    ages: list[float] = []

    def record_age(train: int | None, event: Event, now_s: float) -> None:
        if isinstance(event, MessageReceived) and isinstance(event.message, RunningInfo):
            ages.append(now_s - event.timestamp_us / 1e6)

    async def scenario() -> None:
        # The hold-back (0.6 s) exceeds the round-trip bound (0.4 s) but not the periodic
        # timeout (1.1 s): the link stays up and the delay check has to catch it.
        timers = replace(FAST, timeout_cycles=10, max_round_trip_s=0.4)
        options = ProxyOptions(delay_ms=600.0, delay_p=0.1, directions=("up",), seed=5)
        async with rig(proxy=options, timers=timers) as r:
            r.server.add_listener(record_age)
            await until(lambda: _rejected(r, "delay") >= 1)
            await until(lambda: len(ages) >= 3)
            # The echoed-timestamp bound keeps held-back data out of the application.
            assert max(ages) <= timers.max_round_trip_s

    run(scenario())


def _forged_running_info(key: bytes | None) -> bytes:
    body = encode_body(
        RunningInfo(42, f"K{TRAIN_ID}", "SS4-0123", TravelDirection.UP, 50.0, 999_000.0)
    )
    now_us = int(time.time() * 1e6)
    return encode_frame(
        MessageType.RUNNING_INFO,
        TRAIN_ID,
        GROUND_ID,
        sequence=1_000,
        timestamp_us=now_us + 10_000_000,
        echo_timestamp_us=0,
        body=body,
        key_id=1 if key else 0,
        key=key,
    )


def _no_forged_position(r: Rig) -> bool:
    return all(
        isinstance(e.message, RunningInfo) and e.message.position_m != 999_000.0
        for e in r.running_infos()
    )


def test_masquerade_frame_under_a_wrong_key_is_rejected_by_auth() -> None:
    async def scenario() -> None:
        forged = _forged_running_info(bytes(range(100, 132)))  # not the train's key
        async with rig(proxy=ProxyOptions(inject=forged, inject_after=5, seed=6)) as r:
            await until(lambda: _rejected(r, "auth") >= 1)
            await until(lambda: len(r.running_infos()) >= 3)
            assert r.proxy is not None and r.proxy.stats["up"]["injected"] == 1
            assert _no_forged_position(r)

    run(scenario())


def test_insertion_of_an_unauthenticated_frame_is_rejected() -> None:
    async def scenario() -> None:
        forged = _forged_running_info(None)  # CRC right, no MAC
        async with rig(proxy=ProxyOptions(inject=forged, inject_after=5, seed=7)) as r:
            await until(lambda: _rejected(r, "auth") >= 1)
            await until(lambda: len(r.running_infos()) >= 3)
            assert _no_forged_position(r)

    run(scenario())
