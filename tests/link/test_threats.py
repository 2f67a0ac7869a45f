"""EN 50159 threat matrix: one named test per threat.

Each test injects the threat at frame level on the fake link, once with every step's bytes
in one read and once cut at arbitrary (seeded) segment boundaries, and shows that the
threat is detected (typed event), counted (endpoint counters) and that no wrong data
reached the application.

The scenario: a registered train reports running info every 1 s cycle at positions
1000, 2000, ... m; the ground sets one TSR (session 1). Legitimate application data is
therefore a known set, and anything else reaching the application would be wrong data.
"""

from __future__ import annotations

import random
from collections.abc import Callable

import pytest

from railpilot.link import (
    AuthRejected,
    Check,
    CrcRejected,
    DelayRejected,
    FrameRejected,
    LinkFailed,
    MessageReceived,
    RunningInfo,
    SequenceGap,
    SequenceRejected,
    SourceRejected,
    TsrApplied,
    TsrSet,
    encode_body,
)
from railpilot.link.messages import MessageType

from .helpers import (
    KEY_2,
    OTHER_TRAIN_ID,
    OTHER_TRAIN_KEY,
    T0,
    FakeLink,
    OnceFilter,
    frame_type,
    ground_config,
    header_of,
    registered_link,
    rewrite,
    running_info,
    timers,
)

SEGMENTATIONS = [None, 11, 12, 13]  # None: whole reads; ints: seeds of random cuts
RUNNING_INFO = MessageType.RUNNING_INFO
LEGIT_POSITIONS = [km * 1000.0 for km in range(1, 9)]
ATTACK_POSITION = 999_999.0
LEGIT_TSR = TsrSet(1, 10_000.0, 12_000.0, 12.5, T0, T0 + 3600.0)
FORGED_TSR = TsrSet(666, 0.0, 500_000.0, 0.5, T0, T0 + 3600.0)

Filter = Callable[[list[bytes]], list[bytes]]


def scenario(
    segment_seed: int | None,
    uplink: Filter | None = None,
    downlink: Filter | None = None,
    cycles: int = len(LEGIT_POSITIONS),
) -> FakeLink:
    link = registered_link(segment_seed=segment_seed)
    if uplink is not None:
        link.uplink = uplink
    if downlink is not None:
        link.downlink = downlink
    link.ground.set_tsr(LEGIT_TSR, link.now_s)
    for position in LEGIT_POSITIONS[:cycles]:
        link.onboard.update_running_info(running_info(position))
        link.run(1.0)
    return link


def positions(link: FakeLink) -> list[float]:
    return [
        e.message.position_m
        for e in link.ground_events
        if isinstance(e, MessageReceived) and isinstance(e.message, RunningInfo)
    ]


def applied_sessions(link: FakeLink) -> list[int]:
    return [e.tsr.session for e in link.onboard_events if isinstance(e, TsrApplied)]


def rejections(events: list[object], kind: type[FrameRejected]) -> list[FrameRejected]:
    return [e for e in events if isinstance(e, kind)]


def assert_no_wrong_data(link: FakeLink) -> None:
    """Only legitimate positions, each at most once, in order; only the legitimate TSR."""
    seen = positions(link)
    assert ATTACK_POSITION not in seen
    assert set(seen) <= set(LEGIT_POSITIONS)
    assert seen == sorted(set(seen))
    assert applied_sessions(link) == [1]


class Replay:
    """Pass everything; re-send the ``nth`` frame of ``mtype`` again ``later`` batches on."""

    def __init__(self, mtype: int, nth: int = 1, later: int = 5) -> None:
        self.mtype, self.nth, self.later = mtype, nth, later
        self.count = 0
        self.captured: bytes | None = None
        self.countdown = -1

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        out = list(frames)
        for wire in frames:
            if frame_type(wire) == self.mtype:
                if self.count == self.nth:
                    self.captured = wire
                    self.countdown = self.later
                    out.append(wire)  # immediate repetition too
                self.count += 1
        if self.countdown == 0 and self.captured is not None:
            out.append(self.captured)
        self.countdown -= 1
        return out


class Swap:
    """Hold the ``nth`` frame of ``mtype`` back and deliver it after the next one."""

    def __init__(self, mtype: int, nth: int = 1) -> None:
        self.mtype, self.nth = mtype, nth
        self.count = 0
        self.held: bytes | None = None

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        out = []
        for wire in frames:
            if frame_type(wire) == self.mtype:
                if self.count == self.nth:
                    self.held = wire
                    self.count += 1
                    continue
                self.count += 1
                out.append(wire)
                if self.held is not None:
                    out.append(self.held)
                    self.held = None
            else:
                out.append(wire)
        return out


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_repetition(segment_seed: int | None) -> None:
    link = scenario(
        segment_seed, uplink=Replay(RUNNING_INFO), downlink=Replay(MessageType.TSR_SET, nth=0)
    )
    repeated = rejections(link.ground_events, SequenceRejected)
    assert len(repeated) == 2  # the immediate copy and the later replay
    assert link.ground.counters.repeats == 2
    assert link.onboard.counters.repeats == 2
    assert_no_wrong_data(link)
    assert positions(link) == LEGIT_POSITIONS


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_deletion(segment_seed: int | None) -> None:
    link = scenario(
        segment_seed,
        uplink=OnceFilter(RUNNING_INFO, lambda w: [], nth=2),
        downlink=OnceFilter(MessageType.TSR_SET, lambda w: []),
    )
    assert [g.lost for g in link.ground_events if isinstance(g, SequenceGap)] == [1]
    assert [g.lost for g in link.onboard_events if isinstance(g, SequenceGap)] == [1]
    assert link.ground.counters.frames_lost == 1
    assert link.ground.counters.resends >= 1  # the deleted TSR was sent again
    assert_no_wrong_data(link)
    assert positions(link) == [p for p in LEGIT_POSITIONS if p != 3000.0]


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_insertion(segment_seed: int | None) -> None:
    forged_info = encode_body(running_info(ATTACK_POSITION))
    guessed_mac_key = bytes(random.Random(5).randrange(256) for _ in range(32))

    def insert_info(wire: bytes) -> list[bytes]:
        next_seq = header_of(wire).sequence
        return [
            rewrite(wire, key=None, body=forged_info),  # no MAC at all
            rewrite(wire, key=guessed_mac_key, body=forged_info, sequence=next_seq + 1),
            wire,
        ]

    def insert_tsr(wire: bytes) -> list[bytes]:
        return [wire, rewrite(wire, key=KEY_2, body=encode_body(FORGED_TSR))]

    link = scenario(
        segment_seed,
        uplink=OnceFilter(RUNNING_INFO, insert_info, nth=1),
        downlink=OnceFilter(MessageType.TSR_SET, insert_tsr),
    )
    assert len(rejections(link.ground_events, AuthRejected)) == 2
    assert len(rejections(link.onboard_events, AuthRejected)) == 1
    assert link.ground.counters.rejected[Check.AUTH] == 2
    assert_no_wrong_data(link)
    assert positions(link) == LEGIT_POSITIONS


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_resequencing(segment_seed: int | None) -> None:
    link = scenario(segment_seed, uplink=Swap(RUNNING_INFO, nth=2))
    late = rejections(link.ground_events, SequenceRejected)
    assert len(late) == 1
    assert link.ground.counters.reorders == 1
    assert_no_wrong_data(link)
    # The overtaken (older) position is dropped; everything else arrives in order.
    assert positions(link) == [p for p in LEGIT_POSITIONS if p != 3000.0]


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_corruption(segment_seed: int | None) -> None:
    rng = random.Random(segment_seed or 0)

    def random_bit_flip(wire: bytes) -> list[bytes]:
        damaged = bytearray(wire)
        index = rng.randrange(40, len(damaged) - 4)  # inside the body/MAC
        damaged[index] ^= 1 << rng.randrange(8)
        if damaged[index] == 0x7E or wire[index] == 0x7E:
            damaged[index] ^= 0x01  # keep the framing intact: this is about the CRC
        return [bytes(damaged)]

    def tamper_and_fix_crc(wire: bytes) -> list[bytes]:
        body = bytearray(header_of(wire).body)
        body[-1] ^= 0x01  # position +-1 cm; an attacker fixes the CRC but cannot the MAC
        return [_keep_mac_fix_crc(wire, body)]

    link = scenario(
        segment_seed,
        uplink=_chain(
            OnceFilter(RUNNING_INFO, random_bit_flip, nth=1),
            OnceFilter(RUNNING_INFO, tamper_and_fix_crc, nth=3),  # the 4th, 4000 m
        ),
    )
    assert len(rejections(link.ground_events, CrcRejected)) == 1
    assert len(rejections(link.ground_events, AuthRejected)) == 1
    assert link.ground.counters.rejected == {Check.CRC: 1, Check.AUTH: 1}
    assert_no_wrong_data(link)
    assert positions(link) == [p for p in LEGIT_POSITIONS if p not in (2000.0, 4000.0)]


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_delay(segment_seed: int | None) -> None:
    # Above max_round_trip_s = 3 s, yet short enough that the delayed frames arrive before
    # the ground's heartbeat timeout, so it is the delay check that must catch them. The
    # onboard sends once a cycle (its RUNNING_INFO with its HEARTBEAT), so the first
    # delayed frame left a whole cycle after the last one accepted: with the default
    # 3-cycle timeout (4 s) no delay above 3 s would arrive in time. The ground here
    # waits 5 cycles (6 s); the delay check must still catch the frames first.
    delay_s = 3.2
    holding: list[tuple[float, bytes]] = []
    link_ref: list[FakeLink] = []
    start_after_s = 2.5

    def delay_line(frames: list[bytes]) -> list[bytes]:
        now = link_ref[0].now_s
        if now < T0 + start_after_s:
            return frames
        holding.extend((now, f) for f in frames)
        due = [f for t, f in holding if now - t >= delay_s]
        holding[:] = [(t, f) for t, f in holding if now - t < delay_s]
        return due

    link = registered_link(
        segment_seed=segment_seed, ground_cfg=ground_config(timers=timers(timeout_cycles=5))
    )
    link_ref.append(link)
    link.uplink = delay_line
    for position in LEGIT_POSITIONS[:6]:
        link.onboard.update_running_info(running_info(position))
        link.run(1.0)
    link.run(3.0)
    delayed = rejections(link.ground_events, DelayRejected)
    assert delayed
    assert link.ground.counters.rejected[Check.DELAY] == len(delayed)
    # Nothing sent after the delay line was switched on reached the application...
    assert positions(link) == [1000.0, 2000.0, 3000.0]  # all sent before 2.5 s
    # ...and the lasting delay ends as a link failure (fail-safe), not as stale data.
    assert link.events_of("ground", LinkFailed)


@pytest.mark.parametrize("segment_seed", SEGMENTATIONS)
def test_masquerade(segment_seed: int | None) -> None:
    def impersonate_train(wire: bytes) -> list[bytes]:
        forged = encode_body(running_info(ATTACK_POSITION))
        return [
            # Another train's valid key, claiming to be train 1001.
            rewrite(wire, key=OTHER_TRAIN_KEY, body=forged),
            # Another train, honestly signed as itself, on train 1001's connection.
            rewrite(wire, key=OTHER_TRAIN_KEY, body=forged, source_id=OTHER_TRAIN_ID),
            wire,
        ]

    def impersonate_ground(wire: bytes) -> list[bytes]:
        return [rewrite(wire, key=OTHER_TRAIN_KEY, body=encode_body(FORGED_TSR)), wire]

    link = scenario(
        segment_seed,
        uplink=OnceFilter(RUNNING_INFO, impersonate_train, nth=1),
        downlink=OnceFilter(MessageType.TSR_SET, impersonate_ground),
    )
    assert len(rejections(link.ground_events, AuthRejected)) == 1
    assert len(rejections(link.ground_events, SourceRejected)) == 1
    assert len(rejections(link.onboard_events, AuthRejected)) == 1
    assert link.onboard.counters.rejected[Check.AUTH] == 1
    assert_no_wrong_data(link)
    assert positions(link) == LEGIT_POSITIONS


# --- helpers local to the corruption test -------------------------------------------------


def _chain(*filters: Filter) -> Filter:
    def run(frames: list[bytes]) -> list[bytes]:
        for f in filters:
            frames = f(frames)
        return frames

    return run


def _keep_mac_fix_crc(wire: bytes, body: bytearray) -> bytes:
    """Change the body but keep the original MAC; recompute only the CRC (attacker)."""
    import struct
    import zlib

    from railpilot.link import stuff, unstuff

    raw = bytearray(unstuff(wire[1:]))
    raw[35 : 35 + len(body)] = body
    raw[-4:] = struct.pack(">I", zlib.crc32(bytes(raw[:-4])))
    return stuff(bytes(raw))
