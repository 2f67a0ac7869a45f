"""A minimal onboard peer of the railpilot train-ground link, written from docs/protocol.md only.

Standard library only (struct, zlib, hmac, hashlib, socket, select, threading, time). Nothing
here imports or reads the reference implementation: it is the "independent supplier" check
that the specification is enough to interoperate.

Section numbers in comments refer to docs/protocol.md.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import select
import socket
import struct
import threading
import time
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

# ---------------------------------------------------------------------------------------------
# Constants (sections 3, 4, 6)

HEADER_BYTE = 0x7E
VERSION = 0x01
FLAG_AUTH = 0x01
HEADER_LEN = 35
MAC_LEN = 16
CRC_LEN = 4
MIN_LENGTH = 39
DEFAULT_MAX_LENGTH = 2048

REGISTER_REQUEST = 0x01
REGISTER_RESPONSE = 0x02
DEREGISTER_REQUEST = 0x03
DEREGISTER_RESPONSE = 0x04
TIME_CHECK = 0x10
TIME_OFFSET_REPORT = 0x11
RUNNING_INFO = 0x20
STATION_STOPS = 0x21
RUNNING_TIMES = 0x22
PLANNED_CURVE = 0x23
TARGET_POINT = 0x24
TARGET_POINT_ACK = 0x25
TSR_SET = 0x30
TSR_SET_ACK = 0x31
TSR_CANCEL = 0x32
TSR_CANCEL_ACK = 0x33
DISPATCH_COMMAND = 0x40
DISPATCH_ACK = 0x41
HEARTBEAT = 0x50

UP = "up"  # direction of a message, from the onboard's point of view: onboard -> ground
DOWN = "down"
BOTH = "both"

# code -> (name, direction, fixed body size or None for variable)
CATALOGUE: dict[int, tuple[str, str, int | None]] = {
    REGISTER_REQUEST: ("REGISTER_REQUEST", UP, 24),
    REGISTER_RESPONSE: ("REGISTER_RESPONSE", DOWN, 1),
    DEREGISTER_REQUEST: ("DEREGISTER_REQUEST", UP, 1),
    DEREGISTER_RESPONSE: ("DEREGISTER_RESPONSE", DOWN, 1),
    TIME_CHECK: ("TIME_CHECK", DOWN, 8),
    TIME_OFFSET_REPORT: ("TIME_OFFSET_REPORT", UP, 24),
    RUNNING_INFO: ("RUNNING_INFO", UP, 27),
    STATION_STOPS: ("STATION_STOPS", DOWN, None),
    RUNNING_TIMES: ("RUNNING_TIMES", DOWN, None),
    PLANNED_CURVE: ("PLANNED_CURVE", UP, 16),
    TARGET_POINT: ("TARGET_POINT", DOWN, 9),
    TARGET_POINT_ACK: ("TARGET_POINT_ACK", UP, 5),
    TSR_SET: ("TSR_SET", DOWN, 30),
    TSR_SET_ACK: ("TSR_SET_ACK", UP, 5),
    TSR_CANCEL: ("TSR_CANCEL", DOWN, 4),
    TSR_CANCEL_ACK: ("TSR_CANCEL_ACK", UP, 5),
    DISPATCH_COMMAND: ("DISPATCH_COMMAND", DOWN, None),
    DISPATCH_ACK: ("DISPATCH_ACK", UP, 5),
    HEARTBEAT: ("HEARTBEAT", BOTH, 0),
}

# Enumerations (section 6)
REGISTER_ACCEPTED, REGISTER_UNKNOWN_TRAIN, REGISTER_REFUSED = 0, 1, 2
DIR_UNKNOWN, DIR_UP, DIR_DOWN = 0, 1, 2
TSR_APPLIED, TSR_INVALID, TSR_EXPIRED = 0, 1, 2
CANCEL_CANCELLED, CANCEL_UNKNOWN_SESSION = 0, 1
DEREG_SHUNTING, DEREG_MANUAL_SHUTDOWN, DEREG_LEAVING_MAIN_LINE = 1, 2, 3

_HEADER = struct.Struct(">BBHBHIIIQQ")
assert _HEADER.size == HEADER_LEN


# ---------------------------------------------------------------------------------------------
# Primitive helpers


def crc32(data: bytes) -> int:
    """CRC-32/ISO-HDLC (section 4.1)."""
    return zlib.crc32(data) & 0xFFFFFFFF


def mac16(key: bytes, data: bytes) -> bytes:
    """First 16 bytes of HMAC-SHA256(key, data) (section 4.2)."""
    return hmac.new(key, data, hashlib.sha256).digest()[:MAC_LEN]


def stuff(f: bytes) -> bytes:
    """Every 0x7E of F is sent twice; nothing else is escaped (section 3)."""
    return f.replace(b"\x7e", b"\x7e\x7e")


def char8(text: str) -> bytes:
    """char[8]: 1..8 chars in 0x21..0x7E, right-padded with 0x00 (section 2)."""
    raw = text.encode("ascii")
    if not 1 <= len(raw) <= 8 or any(not 0x21 <= b <= 0x7E for b in raw):
        raise ValueError(f"invalid char[8] value {text!r}")
    return raw.ljust(8, b"\x00")


def parse_char8(raw: bytes) -> str:
    text = raw.rstrip(b"\x00")
    if not text or b"\x00" in text or any(not 0x21 <= b <= 0x7E for b in text):
        raise BodyError(f"invalid char[8] {raw.hex()}")
    return text.decode("ascii")


def now_us() -> int:
    return time.time_ns() // 1000


class TxClock:
    """Sender timestamps, strictly increasing over every frame to one peer, across
    connections too (section 5.2). Share one instance between the connections of a train."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.last = 0

    def next(self) -> int:
        with self._lock:
            self.last = max(now_us(), self.last + 1)
            return self.last


# ---------------------------------------------------------------------------------------------
# Frames (sections 3, 4)


@dataclass(frozen=True)
class Frame:
    msg_type: int
    source: int
    destination: int
    seq: int
    timestamp_us: int
    echo_us: int
    body: bytes
    key_id: int = 0
    mac: bytes = b""
    crc: int = 0
    unstuffed: bytes = b""

    @property
    def name(self) -> str:
        return CATALOGUE.get(self.msg_type, (f"0x{self.msg_type:02x}", "", None))[0]


def encode_unstuffed(
    msg_type: int,
    body: bytes,
    *,
    source: int,
    destination: int,
    seq: int,
    timestamp_us: int,
    echo_us: int,
    key_id: int = 0,
    key: bytes | None = None,
) -> bytes:
    """Build F (section 4): header, body, optional MAC, CRC."""
    auth = key is not None
    if auth and not 1 <= key_id <= 0xFFFF:
        raise ValueError("key id must be 1..65535 with AUTH")
    if not auth:
        key_id = 0
    length = HEADER_LEN + len(body) + (MAC_LEN if auth else 0) + CRC_LEN
    f = _HEADER.pack(
        VERSION,
        FLAG_AUTH if auth else 0,
        length,
        msg_type,
        key_id,
        source,
        destination,
        seq,
        timestamp_us,
        echo_us,
    )
    f += body
    if auth:
        assert key is not None
        f += mac16(key, f)
    f += crc32(f).to_bytes(4, "big")
    assert len(f) == length
    return f


def encode_wire(msg_type: int, body: bytes, **kw: Any) -> bytes:
    return bytes([HEADER_BYTE]) + stuff(encode_unstuffed(msg_type, body, **kw))


class Rejected(Exception):
    """A received frame failed check `check` (section 5.4)."""

    def __init__(self, check: str, detail: str = "") -> None:
        super().__init__(f"{check}: {detail}")
        self.check = check
        self.detail = detail


class BodyError(Exception):
    pass


class FrameDecoder:
    """Streaming decoder following the receiver rules of section 3.

    feed(data) returns complete unstuffed frames F; framing/version/length rejections found
    while delimiting frames are appended to self.rejections.
    """

    def __init__(self, max_length: int = DEFAULT_MAX_LENGTH) -> None:
        self.max_length = max_length
        self.buf = bytearray()
        self.rejections: list[str] = []
        self.discarded = 0

    def feed(self, data: bytes) -> list[bytes]:
        self.buf += data
        out: list[bytes] = []
        while True:
            f = self._next()
            if f is None:
                return out
            out.append(f)

    def _next(self) -> bytes | None:
        buf = self.buf
        while True:
            # 1. hunting
            j = 0
            while True:
                if j >= len(buf):
                    self.discarded += j
                    del buf[:j]
                    return None
                if buf[j] != HEADER_BYTE:
                    j += 1
                    continue
                if j + 1 >= len(buf):
                    self.discarded += j
                    del buf[:j]
                    return None
                if buf[j + 1] == HEADER_BYTE:  # a data 0x7E of a frame whose start we missed
                    j += 2
                    continue
                break
            self.discarded += j
            del buf[:j]
            # buf[0] is the header byte; unstuff from buf[1]
            f = bytearray()
            k = 1
            need = 4
            restart = False
            while len(f) < need:
                if k >= len(buf):
                    return None  # incomplete, keep everything from the header byte
                b = buf[k]
                if b == HEADER_BYTE:
                    if k + 1 >= len(buf):
                        return None
                    if buf[k + 1] == HEADER_BYTE:
                        f.append(HEADER_BYTE)
                        k += 2
                    else:
                        # 4. cut short: that 0x7E starts the next frame
                        self.rejections.append("framing")
                        del buf[:k]
                        restart = True
                        break
                else:
                    f.append(b)
                    k += 1
                if need == 4 and len(f) == 4:
                    # 2. version and length
                    length = int.from_bytes(f[2:4], "big")
                    if f[0] != VERSION or not MIN_LENGTH <= length <= self.max_length:
                        self.rejections.append("version" if f[0] != VERSION else "length")
                        del buf[:1]  # resume hunting after this header byte
                        restart = True
                        break
                    need = length
            if restart:
                continue
            del buf[:k]
            return bytes(f)


def parse_frame(f: bytes) -> Frame:
    """Split F into fields without any judgement (used by the golden-vector tests)."""
    (_version, flags, _length, msg_type, key_id, src, dst, seq, ts, echo) = _HEADER.unpack_from(f)
    auth = bool(flags & FLAG_AUTH)
    body_end = len(f) - CRC_LEN - (MAC_LEN if auth else 0)
    return Frame(
        msg_type=msg_type,
        source=src,
        destination=dst,
        seq=seq,
        timestamp_us=ts,
        echo_us=echo,
        body=f[HEADER_LEN:body_end],
        key_id=key_id,
        mac=f[body_end : len(f) - CRC_LEN] if auth else b"",
        crc=int.from_bytes(f[-4:], "big"),
        unstuffed=f,
    )


# ---------------------------------------------------------------------------------------------
# Message bodies (section 6)


def body_register_request(train_number: str, loco_number: str, driver_id: int, length_cm: int):
    if not 0 <= length_cm <= 1_000_000:
        raise ValueError("train length out of range")
    return char8(train_number) + char8(loco_number) + struct.pack(">II", driver_id, length_cm)


def body_running_info(
    driver_id: int,
    train_number: str,
    loco_number: str,
    direction: int,
    speed_cms: int,
    position_cm: int,
) -> bytes:
    if direction not in (DIR_UNKNOWN, DIR_UP, DIR_DOWN):
        raise ValueError("direction")
    if not 0 <= speed_cms <= 10_000 or not 0 <= position_cm <= 10**9:
        raise ValueError("speed or position out of range")
    return (
        struct.pack(">I", driver_id)
        + char8(train_number)
        + char8(loco_number)
        + struct.pack(">BHI", direction, speed_cms, position_cm)
    )


def body_time_offset_report(ground_us: int, onboard_us: int) -> bytes:
    offset = onboard_us - ground_us
    offset = max(-(10**12), min(10**12, offset))
    return struct.pack(">QQq", ground_us, onboard_us, offset)


def body_ack(number: int, result: int) -> bytes:
    """TARGET_POINT_ACK, TSR_SET_ACK, TSR_CANCEL_ACK, DISPATCH_ACK (section 6.12)."""
    return struct.pack(">IB", number, result)


def body_tsr_set(
    session: int, start_cm: int, end_cm: int, limit_cms: int, from_us: int, until_us: int
) -> bytes:
    return struct.pack(">IIIHQQ", session, start_cm, end_cm, limit_cms, from_us, until_us)


def body_deregister_request(reason: int) -> bytes:
    return bytes([reason])


@dataclass(frozen=True)
class TsrSet:
    session: int
    start_cm: int
    end_cm: int
    limit_cms: int
    valid_from_us: int
    valid_until_us: int


def _range(name: str, value: int, lo: int, hi: int) -> int:
    if not lo <= value <= hi:
        raise BodyError(f"{name} = {value} outside {lo}..{hi}")
    return value


def decode_body(msg_type: int, body: bytes) -> dict[str, Any]:
    """Decode and range-check a body (check #13). Raises BodyError / Rejected('length')."""
    if msg_type == REGISTER_RESPONSE:
        return {"result": _range("result", body[0], 0, 2)}
    if msg_type == DEREGISTER_RESPONSE:
        return {"result": _range("result", body[0], 0, 0)}
    if msg_type == TIME_CHECK:
        (g,) = struct.unpack(">Q", body)
        return {"ground_us": _range("ground time", g, 0, 10**16)}
    if msg_type == TSR_SET:
        s, a, b, lim, vf, vu = struct.unpack(">IIIHQQ", body)
        _range("session", s, 1, 2**32 - 1)
        _range("start", a, 0, 10**9)
        _range("end", b, 0, 10**9)
        _range("limit", lim, 1, 10_000)
        _range("valid from", vf, 0, 10**16)
        _range("valid until", vu, 0, 10**16)
        return {"tsr": TsrSet(s, a, b, lim, vf, vu)}
    if msg_type == TSR_CANCEL:
        (s,) = struct.unpack(">I", body)
        return {"session": _range("session", s, 1, 2**32 - 1)}
    if msg_type == TARGET_POINT:
        tid, pos, reason = struct.unpack(">IIB", body)
        _range("position", pos, 0, 10**9)
        if reason not in (1, 2, 3, 255):
            raise BodyError(f"reason {reason}")
        return {"target_id": tid, "position_cm": pos, "reason": reason}
    if msg_type == DISPATCH_COMMAND:
        if len(body) < 6:
            raise Rejected("length", "dispatch body shorter than 6")
        num, t = struct.unpack_from(">IH", body)
        _range("command", num, 1, 2**32 - 1)
        _range("text length", t, 0, 1000)
        if len(body) != 6 + t:
            raise Rejected("length", "text length inconsistent")
        try:
            text = body[6:].decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BodyError("invalid UTF-8") from exc
        return {"command": num, "text": text}
    if msg_type in (STATION_STOPS, RUNNING_TIMES):
        size = 10 if msg_type == STATION_STOPS else 12
        if not body:
            raise Rejected("length", "empty list body")
        k = body[0]
        if len(body) != 1 + size * k:  # 5.4 #13: inconsistent with the body is *length*
            raise Rejected("length", "list count inconsistent")
        _range("count", k, 0, 64)  # a consistent count out of range is *body*
        return {"count": k}
    if msg_type == HEARTBEAT:
        return {}
    raise BodyError(f"no decoder for 0x{msg_type:02x}")


# ---------------------------------------------------------------------------------------------
# The onboard endpoint (sections 5, 7, 8.1, 8.3, 8.5)


@dataclass
class TsrRecord:
    tsr: TsrSet
    zone_cm: tuple[int, int]
    applied_at_us: int
    state: str = "active"  # active / cancelled / expired


@dataclass
class PeerStats:
    sent: dict[str, int] = field(default_factory=dict)
    received: dict[str, int] = field(default_factory=dict)
    rejections: dict[str, int] = field(default_factory=dict)
    sequence_gaps: int = 0
    frames_lost: int = 0


class OnboardPeer:
    """One onboard unit on one TCP connection. A background thread does all the I/O.

    The application side (the test) only calls set_running(), wait_for(), snapshot() and
    close(); every ground message is answered automatically as section 8 prescribes.
    """

    def __init__(
        self,
        host: str,
        port: int,
        *,
        train_id: int,
        ground_id: int,
        keys: dict[int, bytes] | None,
        active_key_id: int = 1,
        train_number: str = "K1234",
        loco_number: str = "SS4-0123",
        driver_id: int = 42,
        length_cm: int = 60_000,
        cycle_s: float = 1.0,
        resend_interval_s: float = 2.0,
        max_round_trip_s: float = 3.0,
        max_length: int = DEFAULT_MAX_LENGTH,
        clock: TxClock | None = None,
    ) -> None:
        if train_id == 0 or ground_id == 0:
            raise ValueError("device id 0 is reserved")
        self.host, self.port = host, port
        self.train_id, self.ground_id = train_id, ground_id
        self.keys = keys
        self.active_key_id = active_key_id
        self.train_number, self.loco_number = train_number, loco_number
        self.driver_id, self.length_cm = driver_id, length_cm
        self.cycle_s = cycle_s
        self.resend_interval_s = resend_interval_s
        self.max_round_trip_s = max_round_trip_s

        self.lock = threading.RLock()
        self.cond = threading.Condition(self.lock)
        self.decoder = FrameDecoder(max_length)
        self.sock: socket.socket | None = None
        self.thread: threading.Thread | None = None
        self.stopping = False
        self.closed = False

        # connection state (5.1, 5.3)
        self.state = "DISCONNECTED"
        self.tx_seq = 0
        self.rx_next = 0
        self.rx_seen: list[int] = []
        self.clock = clock or TxClock()  # strictly increasing, across connections (5.2)
        self.max_tx_ts = 0  # newest timestamp sent to the ground (delay check, 5.3)
        self.rx_last_ts_by_type: dict[int, int] = {}  # kept across connections (5.2)
        self.echo_us = 0  # newest timestamp accepted from the ground on this connection
        self.ground_hb_at = 0.0
        # 5.3: first and newest timestamp sent on this connection (a valid echo lies between),
        # when it started, and whether the ground has echoed us yet (then echo 0 is refused)
        self.conn_first_tx_ts = 0
        self.conn_last_tx_ts = 0
        self.conn_started_us = 0
        self.ground_echoed = False
        self.requests_sent = 0  # REGISTER/DEREGISTER_REQUEST copies on this connection
        self.deregister_reason = DEREG_MANUAL_SHUTDOWN
        # 5.2: the ground's clock minus ours, from the last TIME_CHECK on this connection
        self.ground_ahead_us: int | None = None
        self.max_clock_skew_s = 10.0

        # application state
        self.direction = DIR_UNKNOWN
        self.speed_cms = 0
        self.position_cm = 0
        self.tsrs: dict[int, TsrRecord] = {}
        self.cancelled_unknown: set[int] = set()
        self.register_results: list[int] = []
        self.time_checks: list[tuple[int, int]] = []  # (ground_us, onboard_us)
        self.events: list[tuple[str, Any]] = []
        self.received: list[Frame] = []
        self.sent: list[Frame] = []
        self.stats = PeerStats()
        self.last_register_sent = 0.0
        self.next_tick = 0.0
        # test hook: message type -> number of its next frames "lost in the network"
        # (numbered and timestamped as usual, but never written)
        self.lose: dict[int, int] = {}
        self.paused = False  # test hook: stop sending periodic messages (simulated hang)
        self.wire_log: list[bytes] = []  # every frame written, as wire bytes

    # ---- public API ---------------------------------------------------------------------

    def connect(self, timeout: float = 5.0) -> None:
        self.sock = socket.create_connection((self.host, self.port), timeout=timeout)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.sock.setblocking(False)
        with self.lock:
            # a new connection restarts sequence numbers and echoes (5.1, 5.3)
            self.tx_seq = 0
            self.rx_next = 0
            self.rx_seen = []
            self.echo_us = 0
            self.conn_first_tx_ts = self.conn_last_tx_ts = 0
            self.conn_started_us = now_us()
            self.ground_echoed = False
            self.requests_sent = 0
            self.ground_ahead_us = None
            self.state = "REGISTERING"
            self.ground_hb_at = time.monotonic()
            # 6.16: a HEARTBEAT (echo 0) opens the connection; REGISTER_REQUEST waits until a
            # ground frame was accepted, so that it echoes a fresh ground timestamp (5.3)
            self._send(HEARTBEAT, b"")
            self.next_tick = time.monotonic() + self.cycle_s
        self.thread = threading.Thread(target=self._run, name="spec-peer", daemon=True)
        self.thread.start()

    def set_running(self, direction: int, speed_cms: int, position_cm: int) -> None:
        with self.lock:
            self.direction, self.speed_cms, self.position_cm = direction, speed_cms, position_cm

    def wait_for(self, predicate: Callable[[], Any], timeout: float, what: str = "") -> Any:
        deadline = time.monotonic() + timeout
        with self.cond:
            while True:
                value = predicate()
                if value:
                    return value
                left = deadline - time.monotonic()
                if left <= 0 or self.closed:
                    raise TimeoutError(f"timed out after {timeout} s waiting for {what}")
                self.cond.wait(min(left, 0.1))

    def register(self) -> None:
        """Application registers again on this connection (8.1 DEREGISTERED row)."""
        with self.lock:
            self.state = "REGISTERING"
            self.requests_sent = 0
            self._send_request()

    def deregister(self, reason: int = DEREG_MANUAL_SHUTDOWN) -> None:
        """Application deregisters (8.1): send DEREGISTER_REQUEST, resent until answered."""
        with self.lock:
            self.state = "DEREGISTERING"
            self.deregister_reason = reason
            self.requests_sent = 0
            self._send_request()

    def send_raw(self, wire: bytes) -> None:
        """Write bytes as they are (for negative tests)."""
        with self.lock:
            self._write(wire)

    def build(self, msg_type: int, body: bytes, **override: Any) -> bytes:
        """Encode a frame as the next one this peer would send, without sending it."""
        with self.lock:
            kw = self._frame_kwargs()
            kw.update(override)
            return encode_wire(msg_type, body, **kw)

    def close(self) -> None:
        self.stopping = True
        if self.thread is not None:
            self.thread.join(timeout=5)
        if self.sock is not None:
            with contextlib.suppress(OSError):
                self.sock.close()
        with self.cond:
            self.closed = True
            self.cond.notify_all()

    # ---- sending ------------------------------------------------------------------------

    def _next_ts(self) -> int:
        ts = self.clock.next()
        self.max_tx_ts = max(self.max_tx_ts, ts)
        if self.conn_first_tx_ts == 0:
            self.conn_first_tx_ts = ts
        self.conn_last_tx_ts = ts
        return ts

    def _frame_kwargs(self) -> dict[str, Any]:
        key = None
        key_id = 0
        if self.keys is not None:
            key_id = self.active_key_id
            key = self.keys[key_id]
        return {
            "source": self.train_id,
            "destination": self.ground_id,
            "seq": self.tx_seq,
            "timestamp_us": self._next_ts(),
            "echo_us": self.echo_us,
            "key_id": key_id,
            "key": key,
        }

    def _send(self, msg_type: int, body: bytes) -> Frame:
        kw = self._frame_kwargs()
        f = encode_unstuffed(msg_type, body, **kw)
        if self.tx_seq >= 0xFFFFFFFF:
            raise RuntimeError("sequence number exhausted: close the connection (5.1)")
        self.tx_seq += 1
        frame = parse_frame(f)
        self.sent.append(frame)
        name = frame.name
        self.stats.sent[name] = self.stats.sent.get(name, 0) + 1
        if self.lose.get(msg_type, 0) > 0:
            self.lose[msg_type] -= 1
            self.events.append(("lost_on_purpose", frame))
            return frame
        wire = bytes([HEADER_BYTE]) + stuff(f)
        self.wire_log.append(wire)
        self._write(wire)
        return frame

    def _write(self, data: bytes) -> None:
        assert self.sock is not None
        view = memoryview(data)
        deadline = time.monotonic() + 5
        while view:
            try:
                n = self.sock.send(view)
                view = view[n:]
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise TimeoutError("socket send blocked") from None
                select.select([], [self.sock], [], 0.1)

    def _send_request(self) -> None:
        """REGISTER/DEREGISTER_REQUEST of the current state; only once the ground was heard
        on this connection (5.3: nothing but a HEARTBEAT carries echo 0)."""
        if self.echo_us == 0:
            return
        if self.state == "REGISTERING":
            body = body_register_request(
                self.train_number, self.loco_number, self.driver_id, self.length_cm
            )
            self._send(REGISTER_REQUEST, body)
        elif self.state == "DEREGISTERING":
            self._send(DEREGISTER_REQUEST, body_deregister_request(self.deregister_reason))
        else:
            return
        self.requests_sent += 1
        self.last_register_sent = time.monotonic()

    def _send_running_info(self) -> None:
        body = body_running_info(
            self.driver_id,
            self.train_number,
            self.loco_number,
            self.direction,
            self.speed_cms,
            self.position_cm,
        )
        self._send(RUNNING_INFO, body)

    # ---- I/O loop -----------------------------------------------------------------------

    def _run(self) -> None:
        assert self.sock is not None
        try:
            while not self.stopping:
                timeout = max(0.0, min(0.1, self.next_tick - time.monotonic()))
                readable, _, _ = select.select([self.sock], [], [], timeout)
                if readable:
                    try:
                        data = self.sock.recv(65536)
                    except BlockingIOError:
                        data = None
                    if data == b"":
                        with self.cond:
                            self.state = "DISCONNECTED"
                            self.events.append(("connection_lost", None))
                            self.cond.notify_all()
                        return
                    if data:
                        self._on_data(data)
                if time.monotonic() >= self.next_tick:
                    self._tick()
        except OSError as exc:
            with self.cond:
                self.state = "DISCONNECTED"
                self.events.append(("connection_lost", repr(exc)))
                self.cond.notify_all()

    def _tick(self) -> None:
        with self.cond:
            now = time.monotonic()
            self.next_tick += self.cycle_s
            if self.next_tick < now:
                self.next_tick = now + self.cycle_s
            if self.paused:
                return
            self._send(HEARTBEAT, b"")
            if self.state == "REGISTERED":  # 8.1: none after DEREGISTER_REQUEST
                self._send_running_info()
            if (
                self.state in ("REGISTERING", "DEREGISTERING")
                and now - self.last_register_sent >= self.resend_interval_s
            ):
                self._send_request()
            # supervision of the ground heartbeat (section 7); default timeout_cycles = 3
            missed = int((now - self.ground_hb_at) // 1.0)  # the ground's cycle_s = 1 s
            if missed > 3:
                self.events.append(("ground_heartbeat_timeout", missed))
            self.cond.notify_all()

    def _on_data(self, data: bytes) -> None:
        with self.cond:
            before = len(self.decoder.rejections)
            frames = self.decoder.feed(data)
            for check in self.decoder.rejections[before:]:
                self._reject(check, "decoder")
            for f in frames:
                try:
                    frame, fields = self._check(f)
                except Rejected as rej:
                    self._reject(rej.check, rej.detail)
                    continue
                self._handle(frame, fields)
            self.cond.notify_all()

    def _reject(self, check: str, detail: str) -> None:
        self.stats.rejections[check] = self.stats.rejections.get(check, 0) + 1
        self.events.append(("rejected", (check, detail)))

    # ---- receive checks, in the order of section 5.4 ------------------------------------

    def _check(self, f: bytes) -> tuple[Frame, dict[str, Any]]:
        # 1-3 framing/version/length(range) were done by the decoder; 3 (frame size):
        length = int.from_bytes(f[2:4], "big")
        if length != len(f):
            raise Rejected("length", "length field != frame size")
        # 4 crc
        if crc32(f[:-4]) != int.from_bytes(f[-4:], "big"):
            raise Rejected("crc")
        flags = f[1]
        # 5 reserved flag bits
        if flags & 0xFE:
            raise Rejected("version", "reserved flag bit set")
        auth = bool(flags & FLAG_AUTH)
        frame = parse_frame(f)
        # 6 AUTH / key id consistency
        if auth != (frame.key_id != 0):
            raise Rejected("auth", "AUTH flag and key id inconsistent")
        # 7 type
        if frame.msg_type not in CATALOGUE:
            raise Rejected("type", f"unknown type 0x{frame.msg_type:02x}")
        _, direction, size = CATALOGUE[frame.msg_type]
        # 8 fixed body length
        if size is not None and len(frame.body) != size:
            raise Rejected("length", f"body {len(frame.body)} != {size}")
        if auth and len(f) < HEADER_LEN + MAC_LEN + CRC_LEN:
            raise Rejected("length", "too short for a MAC")
        # 9 direction
        if direction == UP:
            raise Rejected("type", "uplink type received by the onboard")
        # 10 destination
        if frame.destination != self.train_id:
            raise Rejected("destination", str(frame.destination))
        # 11 source: the onboard knows its ground id
        if frame.source != self.ground_id:
            raise Rejected("source", str(frame.source))
        # 12 auth: the key is looked up by (train id = destination of a downlink frame, key id)
        if self.keys is not None:
            if not auth:
                raise Rejected("auth", "AUTH clear while authentication is required")
            key = self.keys.get(frame.key_id)
            if key is None:
                raise Rejected("auth", f"unknown key id {frame.key_id}")
            if not hmac.compare_digest(mac16(key, f[: len(f) - 20]), frame.mac):
                raise Rejected("auth", "MAC wrong")
        elif auth:
            raise Rejected("auth", "AUTH set but this peer has no keys")
        # 13 body
        try:
            fields = decode_body(frame.msg_type, frame.body)
        except BodyError as exc:
            raise Rejected("body", str(exc)) from exc
        # 14 sequence
        if frame.seq < self.rx_next:
            kind = "repetition" if frame.seq in self.rx_seen else "reordering"
            raise Rejected("sequence", kind)
        # 15 timestamp, per message type, and plausible against our clock (5.2)
        if frame.timestamp_us <= self.rx_last_ts_by_type.get(frame.msg_type, 0):
            raise Rejected("timestamp", "not newer than the last of this type")
        now = now_us()
        if self.ground_ahead_us is None:
            latest = now + self.max_clock_skew_s * 1e6
        else:
            latest = now + self.ground_ahead_us + self.max_round_trip_s * 1e6
        if frame.timestamp_us > latest:
            raise Rejected("timestamp", "implausibly far ahead of our clock")
        # 16 delay (5.3)
        if frame.echo_us == 0:
            if frame.msg_type != HEARTBEAT:
                raise Rejected("delay", "echo 0 on a frame other than a HEARTBEAT")
            if self.ground_echoed:
                raise Rejected("delay", "echo 0 after the ground has echoed us")
            if now - self.conn_started_us > self.max_round_trip_s * 1e6:
                raise Rejected("delay", "echo 0 after the set-up window")
        else:
            if not self.conn_first_tx_ts <= frame.echo_us <= self.conn_last_tx_ts:
                raise Rejected("delay", "echo of a timestamp not sent on this connection")
            if now - frame.echo_us > self.max_round_trip_s * 1e6:
                raise Rejected("delay", "echo too old")
        # accepted at link level: consume sequence number and timestamp
        if frame.seq > self.rx_next:
            self.stats.sequence_gaps += 1
            self.stats.frames_lost += frame.seq - self.rx_next
            self.events.append(("sequence_gap", frame.seq - self.rx_next))
        self.rx_next = frame.seq + 1
        self.rx_seen = [*self.rx_seen[-63:], frame.seq]
        self.rx_last_ts_by_type[frame.msg_type] = frame.timestamp_us
        self.echo_us = max(self.echo_us, frame.timestamp_us)
        self.ground_echoed = self.ground_echoed or frame.echo_us != 0
        # 17 state
        if not self._allowed(frame.msg_type):
            raise Rejected("state", f"{frame.name} in {self.state}")
        return frame, fields

    def _allowed(self, msg_type: int) -> bool:
        s = self.state
        if msg_type == HEARTBEAT:
            return True
        if msg_type == REGISTER_RESPONSE:
            return s in ("REGISTERING", "REGISTERED", "DEREGISTERING")
        if msg_type == DEREGISTER_RESPONSE:
            return s in ("DEREGISTERING", "DEREGISTERED")
        # ground data messages (6.5, 6.8, 6.9, 6.11, 6.13-6.15)
        return s in ("REGISTERED", "DEREGISTERING")

    # ---- application handling (8.1, 8.3, 8.5) ---------------------------------------------

    def _handle(self, frame: Frame, fields: dict[str, Any]) -> None:
        self.received.append(frame)
        name = frame.name
        self.stats.received[name] = self.stats.received.get(name, 0) + 1
        t = frame.msg_type
        if t == HEARTBEAT:
            self.ground_hb_at = time.monotonic()
            if self.requests_sent == 0:  # the ground was heard: the request may go (5.3)
                self._send_request()
        elif t == REGISTER_RESPONSE:
            result = fields["result"]
            self.register_results.append(result)
            self.events.append(("register_response", result))
            if self.state == "REGISTERING" and result == REGISTER_ACCEPTED:
                self.state = "REGISTERED"
                self._send_running_info()
        elif t == DEREGISTER_RESPONSE:
            self.state = "DEREGISTERED"
            self.events.append(("deregistered", fields["result"]))
        elif t == TIME_CHECK:
            onboard = now_us()
            self.time_checks.append((fields["ground_us"], onboard))
            self.ground_ahead_us = fields["ground_us"] - onboard  # 5.2 plausibility bound
            self._send(TIME_OFFSET_REPORT, body_time_offset_report(fields["ground_us"], onboard))
        elif t == TSR_SET:
            tsr: TsrSet = fields["tsr"]
            result = self._apply_tsr(tsr)
            self.events.append(("tsr_set", (tsr, result)))
            self._send(TSR_SET_ACK, body_ack(tsr.session, result))
        elif t == TSR_CANCEL:
            session = fields["session"]
            rec = self.tsrs.get(session)
            if rec is None:
                self.cancelled_unknown.add(session)
                result = CANCEL_UNKNOWN_SESSION
            else:
                rec.state = "cancelled"
                result = CANCEL_CANCELLED
            self.events.append(("tsr_cancel", (session, result)))
            self._send(TSR_CANCEL_ACK, body_ack(session, result))
        elif t == TARGET_POINT:
            self.events.append(("target_point", fields))
            self._send(TARGET_POINT_ACK, body_ack(fields["target_id"], 0))
        elif t == DISPATCH_COMMAND:
            self.events.append(("dispatch", fields))
            self._send(DISPATCH_ACK, body_ack(fields["command"], 0))
        else:
            self.events.append((name.lower(), fields))

    def _apply_tsr(self, tsr: TsrSet) -> int:
        """Onboard handling of TSR_SET (section 8.3, first matching row)."""
        now = now_us()
        rec = self.tsrs.get(tsr.session)
        if rec is not None and rec.state == "active" and rec.tsr.valid_until_us <= now:
            rec.state = "expired"
        if rec is not None and rec.state == "active":
            return TSR_APPLIED if rec.tsr == tsr else TSR_INVALID
        if (rec is not None and rec.state != "active") or tsr.session in self.cancelled_unknown:
            return TSR_EXPIRED
        if tsr.start_cm == tsr.end_cm or tsr.valid_until_us <= tsr.valid_from_us:
            return TSR_INVALID
        if tsr.valid_until_us <= now:
            return TSR_EXPIRED
        low, high = sorted((tsr.start_cm, tsr.end_cm))
        length = self.length_cm
        if self.direction == DIR_UP:
            zone = (low, high + length)
        elif self.direction == DIR_DOWN:
            zone = (max(0, low - length), high)
        else:
            zone = (max(0, low - length), high + length)
        self.tsrs[tsr.session] = TsrRecord(tsr, zone, now)
        return TSR_APPLIED

    # ---- inspection ---------------------------------------------------------------------

    def events_of(self, kind: str) -> Iterator[Any]:
        return (value for k, value in self.events if k == kind)
