"""The summary of the frame rejections held back is written when the suppression window
ends, not only when the connection closes (docs/link-operations.md, "Rejected frames in
the log"). Time is passed in: a virtual clock, never a sleep."""

from __future__ import annotations

import asyncio
import logging

import pytest

from railpilot.link import CrcRejected, GroundConfig, LengthRejected, Registered
from railpilot.net import OnboardClient, Trajectory
from railpilot.net.rejections import RejectionLog

from .fake_wire import T0, ManualScheduler, VirtualClock, wire_to_ground
from .helpers import FAST, GROUND_ID, TRAIN_ID, make_keys, onboard_config, run

BURST = 2
INTERVAL_S = 10.0


class _Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__()
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())

    def of(self, event: str) -> list[str]:
        return [x for x in self.lines if x.startswith(f"event={event} ")]


@pytest.fixture
def lines() -> _Lines:
    return _Lines()


def _log(lines: _Lines) -> RejectionLog:
    logger = logging.getLogger("test.rejection_summary")
    logger.handlers[:] = [lines]
    logger.setLevel(logging.INFO)
    logger.propagate = False
    return RejectionLog(logger, burst=BURST, interval_s=INTERVAL_S)


def _crc(n: int) -> CrcRejected:
    return CrcRejected(f"bad crc #{n}")


def test_the_summary_is_written_when_the_window_ends(lines: _Lines) -> None:
    rejections = _log(lines)
    flood = 7
    for n in range(flood):
        rejections.record(_crc(n), T0 + 0.1 * n, train=TRAIN_ID)
    assert len(lines.of("frame_rejected")) == BURST
    rejections.tick(T0 + INTERVAL_S - 0.001, train=TRAIN_ID)
    assert lines.of("frame_rejections_suppressed") == []
    rejections.tick(T0 + INTERVAL_S, train=TRAIN_ID)
    [summary] = lines.of("frame_rejections_suppressed")
    assert f"train={TRAIN_ID} check=crc suppressed={flood - BURST} " in summary + " "


def test_the_timer_is_told_when_the_summary_is_due(lines: _Lines) -> None:
    rejections = _log(lines)
    for n in range(BURST):
        rejections.record(_crc(n), T0 + n, train=TRAIN_ID)
    assert rejections.next_deadline_s() is None  # nothing held back: nothing to say
    rejections.record(_crc(BURST), T0 + 3.0, train=TRAIN_ID)
    assert rejections.next_deadline_s() == T0 + INTERVAL_S  # the window opened at T0
    rejections.tick(T0 + INTERVAL_S, train=TRAIN_ID)
    assert rejections.next_deadline_s() is None


def test_a_rejection_of_another_check_brings_the_time_along(lines: _Lines) -> None:
    rejections = _log(lines)
    for n in range(BURST + 3):
        rejections.record(_crc(n), T0, train=TRAIN_ID)
    rejections.record(LengthRejected("short"), T0 + INTERVAL_S + 1.0, train=TRAIN_ID)
    [summary] = lines.of("frame_rejections_suppressed")
    assert "check=crc suppressed=3 " in summary + " "


def test_a_window_summarised_is_not_summarised_again_at_close(lines: _Lines) -> None:
    rejections = _log(lines)
    for n in range(BURST + 4):
        rejections.record(_crc(n), T0, train=TRAIN_ID)
    rejections.tick(T0 + INTERVAL_S, train=TRAIN_ID)
    # a new window: logged in full again, then held back again
    for n in range(BURST + 1):
        rejections.record(_crc(n), T0 + INTERVAL_S + 1.0, train=TRAIN_ID)
    assert len(lines.of("frame_rejected")) == 2 * BURST
    rejections.close(train=TRAIN_ID)
    summaries = lines.of("frame_rejections_suppressed")
    assert ["suppressed=4" in summaries[0], "suppressed=1" in summaries[1]] == [True, True]
    assert len(summaries) == 2
    [total] = lines.of("frame_rejections_total")
    assert f"rejected={2 * BURST + 5} logged={2 * BURST} " in total + " "


def test_the_onboard_writes_the_summary_from_its_timer_while_connected(lines: _Lines) -> None:
    """A ground that sent garbage once and then behaves: the onboard's summary comes when
    the window ends, from its timer, on a live connection (before any close)."""
    logger = logging.getLogger("railpilot.net.client")
    previous = logger.level
    logger.addHandler(lines)
    logger.setLevel(logging.INFO)
    garbage = 8  # below the 16 rejections in a row that close a connection
    try:
        connected, waited_s, lines_at_summary = run(_garbage_then_quiet(garbage, lines))
    finally:
        logger.removeHandler(lines)
        logger.setLevel(previous)
    [summary] = [x for x in lines_at_summary if x.startswith("event=frame_rejections_suppressed")]
    assert f"train={TRAIN_ID} " in summary
    assert f"suppressed={garbage - 5} " in summary + " "  # 5: the default burst
    assert connected
    assert not any("frame_rejections_total" in x for x in lines_at_summary)  # not the close
    # the window opened with the garbage and lasts 10 s; the timer ticks once a cycle
    assert 10.0 - FAST.cycle_s <= waited_s <= 10.0 + FAST.cycle_s


async def _garbage_then_quiet(garbage: int, lines: _Lines) -> tuple[bool, float, list[str]]:
    """Register, take ``garbage`` broken frames, then tick once a cycle until the summary
    is written: (still connected?, virtual seconds since the garbage, log lines so far)."""
    keys = make_keys()
    clock = VirtualClock()
    log: list[tuple[str, bytes]] = []
    wires = wire_to_ground(clock, GroundConfig(ground_id=GROUND_ID, timers=FAST), keys, log)
    client = OnboardClient(
        onboard_config(TRAIN_ID),
        keys,
        "127.0.0.1",
        1,
        trajectory=Trajectory(),
        trajectory_start_s=T0,
        scheduler=ManualScheduler(clock),  # type: ignore[arg-type]
        clock=clock,
    )
    registered = asyncio.Event()
    client.add_listener(lambda e, now: registered.set() if isinstance(e, Registered) else None)
    stop = asyncio.Event()
    task = asyncio.create_task(client.run(stop))
    await registered.wait()
    # a frame of the ground with one body byte changed: a CRC rejection each
    frame = next(data for direction, data in log if direction == "down")
    broken = bytearray(frame)
    broken[len(broken) // 2] ^= 0x01
    flooded_s = clock()
    wires[0].inject(bytes(broken) * garbage)
    # the host's timer: one tick a link cycle, the ground answering in between
    while not lines.of("frame_rejections_suppressed") and clock() < flooded_s + 20.0:
        clock.advance(FAST.cycle_s)
        client.on_tick(clock())
        await wires[0].quiet()  # the ground's answers, and the client's replies to them
    outcome = (client.connected, clock() - flooded_s, list(lines.lines))
    stop.set()
    await task
    return outcome
