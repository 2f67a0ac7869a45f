"""Attacks and faults the threat suite did not catch, each over real TCP.

Every test here failed on the link before the fix (a withheld frame with echo 0 changed
state, a deregistration on a second connection ended the train's registration, random bytes
wrote a WARNING line per rejection, one future timestamp locked a train out, one time-offset
report in six was 1 us off). A *raw peer* below plays the attacker (or a second unit of the
same train): it holds the train's key, writes hand-made frames on its own TCP connection and
decodes what the ground answers. Waits are on conditions with deadlines, never on the clock.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import time

import pytest

from railpilot.link import (
    DeregisterReason,
    DeregisterRequest,
    Frame,
    FrameDecoder,
    FrameError,
    FrameRejected,
    Heartbeat,
    Message,
    MessageReceived,
    MessageType,
    PeriodicTimedOut,
    RegisterRequest,
    TimeCheck,
    TimeOffsetReport,
    TrainDeregistered,
    encode_body,
    encode_frame,
    parse_frame,
)
from railpilot.net.server import GroundServer

from .helpers import GROUND_ID, TRAIN_ID, Rig, rig, run, tsr, until

OFFLINE_TRAIN = 1002
TEN_YEARS_S = 10 * 365.25 * 86400


def now_us() -> int:
    return int(time.time() * 1e6)


class RawPeer:
    """A TCP connection to the ground that sends hand-made frames under a train's key."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        train_id: int,
        key: bytes,
    ) -> None:
        self.reader, self.writer = reader, writer
        self.train_id, self.key = train_id, key
        self.received: list[Frame] = []
        self.closed = asyncio.Event()
        self._task = asyncio.create_task(self._read())

    @classmethod
    async def open(cls, port: int, train_id: int, key: bytes) -> RawPeer:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        return cls(reader, writer, train_id, key)

    def frame(self, message: Message, *, seq: int, ts_us: int, echo_us: int) -> bytes:
        return encode_frame(
            message.TYPE,
            self.train_id,
            GROUND_ID,
            seq,
            ts_us,
            echo_us,
            encode_body(message),
            1,
            self.key,
        )

    async def send(self, *wires: bytes) -> None:
        self.writer.write(b"".join(wires))
        await self.writer.drain()

    def of(self, mtype: MessageType) -> list[Frame]:
        return [f for f in self.received if f.message_type == mtype]

    async def close(self) -> None:
        self.writer.close()
        self._task.cancel()

    async def _read(self) -> None:
        decoder = FrameDecoder()
        try:
            while data := await self.reader.read(65536):
                for item in decoder.feed(data):
                    if not isinstance(item, FrameError):
                        self.received.append(parse_frame(item))
        except ConnectionError:
            pass
        self.closed.set()


def key_of(r: Rig, train_id: int) -> bytes:
    found = r.keys.active(train_id)
    assert found is not None
    return found[1]


def rejected(server: GroundServer, check: str) -> int:
    return int(server.counters()["rejected"].get(check, 0))


async def running(r: Rig) -> None:
    """Wait until the train is registered and its running info flows."""
    await until(lambda: r.server.records.get(TRAIN_ID) is not None)
    await until(lambda: r.server.records[TRAIN_ID].registered and len(r.running_infos()) >= 3)


def infos_then(r: Rig, more: int) -> int:
    return len(r.running_infos()) + more


# --- item 1: a withheld frame, whatever its echo, never changes state later --------------


def test_a_withheld_deregister_request_with_echo_zero_does_not_deregister_a_running_train() -> None:
    async def main() -> None:
        async with rig() as r:
            await running(r)
            peer = await RawPeer.open(r.port, TRAIN_ID, key_of(r, TRAIN_ID))
            before = rejected(r.server, "delay")
            # captured 10 s ago at the set-up of a connection (hence echo 0), sent now
            withheld = peer.frame(
                DeregisterRequest(DeregisterReason.MANUAL_SHUTDOWN),
                seq=0,
                ts_us=now_us() - 10_000_000,
                echo_us=0,
            )
            await peer.send(withheld)
            await until(lambda: rejected(r.server, "delay") > before)
            target = infos_then(r, 5)
            await until(lambda: len(r.running_infos()) >= target)
            status = r.server.status()["trains"][0]
            assert status["registered"] and status["state"] == "REGISTERED"
            assert status["running_info"]["valid"]
            assert not r.ground_of(TrainDeregistered)
            await peer.close()

    run(main())


def test_a_deregister_request_echoing_another_connection_is_refused() -> None:
    async def main() -> None:
        async with rig() as r:
            await running(r)
            record = r.server.records[TRAIN_ID]
            peer = await RawPeer.open(r.port, TRAIN_ID, key_of(r, TRAIN_ID))
            before = rejected(r.server, "delay")
            # a frame made on the train's live connection (it echoes a fresh ground
            # timestamp sent there), captured and played on another connection
            captured = peer.frame(
                DeregisterRequest(DeregisterReason.MANUAL_SHUTDOWN),
                seq=0,
                ts_us=now_us(),
                echo_us=record.history.last_sent_timestamp_us,
            )
            await peer.send(captured)
            await until(lambda: rejected(r.server, "delay") > before)
            target = infos_then(r, 5)
            await until(lambda: len(r.running_infos()) >= target)
            assert record.registered
            assert not r.ground_of(TrainDeregistered)
            await peer.close()

    run(main())


def test_a_withheld_registration_of_an_offline_train_registers_nothing() -> None:
    async def main() -> None:
        async with rig(TRAIN_ID, OFFLINE_TRAIN, start=False) as r:
            r.server.set_tsr([OFFLINE_TRAIN], tsr(9))  # waits for the train to register
            peer = await RawPeer.open(r.port, OFFLINE_TRAIN, key_of(r, OFFLINE_TRAIN))
            captured_at = now_us() - 10_000_000  # withheld for 10 s by the attacker
            request = RegisterRequest("K1002", "SS4-0123", 42, 800.0)
            await peer.send(
                peer.frame(request, seq=0, ts_us=captured_at, echo_us=0),
                peer.frame(Heartbeat(), seq=1, ts_us=captured_at + 1000, echo_us=0),
            )
            # the opening HEARTBEAT may pass (it carries nothing); the ground answers it
            # with its own heartbeats, and the request is refused for its echo 0
            await until(lambda: rejected(r.server, "delay") >= 1)
            await until(lambda: len(peer.of(MessageType.HEARTBEAT)) >= 3)
            record = r.server.records[OFFLINE_TRAIN]
            assert not record.registered
            assert record.tsrs[9].state.name == "PENDING_SET"
            assert not peer.of(MessageType.REGISTER_RESPONSE)
            assert not peer.of(MessageType.TSR_SET)
            await peer.close()

    run(main())


# --- item 2: only the connection holding the registration can end it --------------------


def test_a_deregistration_on_a_second_connection_leaves_the_registration_standing() -> None:
    async def main() -> None:
        async with rig() as r:
            await running(r)
            peer = await RawPeer.open(r.port, TRAIN_ID, key_of(r, TRAIN_ID))
            # a fresh, well-formed exchange on a second connection of the same train: the
            # opening HEARTBEAT, the ground's answer, a DEREGISTER_REQUEST echoing it
            ts = now_us() + 20_000  # newer than the live connection's last heartbeat
            await peer.send(peer.frame(Heartbeat(), seq=0, ts_us=ts, echo_us=0))
            await until(lambda: bool(peer.of(MessageType.HEARTBEAT)))
            challenge = peer.of(MessageType.HEARTBEAT)[0].timestamp_us
            deregister = DeregisterRequest(DeregisterReason.SHUNTING_MODE)
            await peer.send(peer.frame(deregister, seq=1, ts_us=ts + 1000, echo_us=challenge))
            await until(lambda: bool(peer.of(MessageType.DEREGISTER_RESPONSE)))
            target = infos_then(r, 5)
            await until(lambda: len(r.running_infos()) >= target)
            status = r.server.status()["trains"][0]
            assert status["registered"], "the registration on the live connection stands"
            assert status["state"] == "REGISTERED"
            assert status["running_info"]["valid"]
            assert not r.ground_of(TrainDeregistered)
            assert r.clients[0].endpoint.state.name == "REGISTERED"
            await peer.close()

    run(main())


# --- item 3: a flood of rejections is logged in bounded lines and the connection closed ---


class _Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def test_random_bytes_are_logged_in_a_bounded_number_of_lines_and_the_connection_closed() -> None:
    handler = _Lines()
    logger = logging.getLogger("railpilot.net.server")
    logger.addHandler(handler)
    previous = logger.level
    logger.setLevel(logging.INFO)

    async def main() -> tuple[int, int]:
        async with rig(start=False) as r:
            flood = random.Random(8).randbytes(10 * 1024 * 1024)
            reader, writer = await asyncio.open_connection("127.0.0.1", r.port)
            writer.write(flood)
            # the server closes the connection under our feet (a reset is expected); we
            # read until end-of-file
            with contextlib.suppress(ConnectionError):
                await writer.drain()
            with contextlib.suppress(ConnectionError):
                async with asyncio.timeout(8.0):
                    while await reader.read(65536):
                        pass
            writer.close()
            await until(lambda: r.server.counters()["link_failures"] >= 1)
            await until(lambda: any("frame_rejections_total" in x for x in handler.lines))
            events = len(r.ground_of(FrameRejected))
            counted = sum(r.server.counters()["rejected"].values())
            return events, counted

    try:
        events, counted = run(main())
    finally:
        logger.removeHandler(handler)
        logger.setLevel(previous)
    rejections = [x for x in handler.lines if "frame_rejected" in x]
    assert counted == events >= 16  # the counters are exact
    assert len(rejections) <= 5 * 6  # at most 5 lines per check (version, length, ...)
    assert len(handler.lines) <= 60
    [total] = [x for x in handler.lines if "frame_rejections_total" in x]
    assert f"rejected={counted}" in total  # the summary's count is the exact one
    assert any("not speaking the protocol" in x for x in handler.lines)


# --- item 4: a frame timestamped far ahead is refused and locks nobody out --------------


def test_a_heartbeat_ten_years_ahead_is_refused_and_the_train_keeps_running() -> None:
    async def main() -> None:
        async with rig() as r:
            await running(r)
            peer = await RawPeer.open(r.port, TRAIN_ID, key_of(r, TRAIN_ID))
            before = rejected(r.server, "timestamp")
            future = now_us() + int(TEN_YEARS_S * 1e6)
            await peer.send(peer.frame(Heartbeat(), seq=0, ts_us=future, echo_us=0))
            await until(lambda: rejected(r.server, "timestamp") > before)
            history = r.server.records[TRAIN_ID].history
            assert history.newest_timestamp_us < future  # never advanced by it
            target = infos_then(r, 10)
            await until(lambda: len(r.running_infos()) >= target)
            # (the attacker's own connection, bound to no train, times out: not the train)
            assert not [
                e for t, e in r.ground_events if t == TRAIN_ID and isinstance(e, PeriodicTimedOut)
            ]
            # and after a reconnect the train registers again at once
            r.clients[0].drop_connection()
            await until(lambda: r.server.views[TRAIN_ID].registrations >= 2)
            target = infos_then(r, 5)
            await until(lambda: len(r.running_infos()) >= target)
            assert rejected(r.server, "timestamp") == before + 1
            await peer.close()

    run(main())


# --- item 5: the reported offset is exactly onboard time - ground time ------------------


@pytest.mark.parametrize("checks", [300])
def test_every_time_offset_report_is_exactly_the_difference_of_its_two_times(
    checks: int,
) -> None:
    async def main() -> list[TimeOffsetReport]:
        async with rig() as r:
            await running(r)
            conn = r.server.live[TRAIN_ID]

            def reports() -> list[TimeOffsetReport]:
                return [
                    e.message
                    for e in r.ground_of(MessageReceived)
                    if isinstance(e.message, TimeOffsetReport)
                ]

            # one at a time, so each is answered at another instant of the onboard's clock
            for _ in range(checks):
                done = len(reports()) + 1
                now = time.time()
                conn.endpoint.send(TimeCheck(now), now)
                conn._after(now)
                await until(lambda done=done: len(reports()) >= done)  # type: ignore[misc]
            assert r.server.counters()["rejected"] == {}
            return reports()

    for report in run(main()):
        # integer microseconds as on the wire
        ground_us = round(report.ground_time_s * 1e6)
        onboard_us = round(report.onboard_time_s * 1e6)
        assert round(report.offset_s * 1e6) == onboard_us - ground_us, report
