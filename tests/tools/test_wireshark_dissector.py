"""tools/railpilot_link.lua, the Wireshark dissector, checked against railpilot.link.

The test makes its own capture: a real TCP connection between two sockets on 127.0.0.1
carries frames built by :mod:`railpilot.link` (the golden vectors of docs/protocol.md, a
frame of every message type, a frame split across two TCP segments, two frames in one
segment, garbage before a frame, a frame cut short by a header byte and a frame with a
corrupted byte). Each ``send`` is one TCP segment: the sender waits until the peer has read
it before sending the next piece.

Capture paths:

* ``loopback``: ``dumpcap -i lo`` records the connection (pcap on a pipe, so the test knows
  when every byte has been captured; a UDP probe shows when the capture is live).
* ``synthetic``: the same pieces wrapped in Ethernet/IPv4/TCP headers and written to a pcap
  file here (``struct``), with no capture privileges needed. The ``loopback`` case falls back
  to it when live capture is impossible (no dumpcap, no permission) and says so on stdout
  and in the ``capture_path`` property of the JUnit report; ``RAILPILOT_NO_LIVE_CAPTURE=1``
  forces the fallback. The ``synthetic`` case always runs.

Then ``tshark -X lua_script:tools/railpilot_link.lua -T json`` decodes the file, and every
frame the dissector shows must equal what :func:`railpilot.link.decode_stream` and the body
codec decode from the same bytes: header fields, body fields (wire values and SI values),
MAC, CRC verdict, and which TCP segment completed which frame. Skipped when ``tshark`` is
not on PATH. A further test (written pcap) sends one frame per failed check of
docs/protocol.md section 5.4 and wants exactly that check's expert info on it. Everything is
bounded in time (deadlines on waits, timeouts on subprocesses);
nothing asserts a duration.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import threading
import time
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from railpilot.link import (
    FrameDecoder,
    FrameError,
    decode_body,
    decode_stream,
    encode_body,
    encode_frame,
    parse_frame,
    stuff,
    unstuff,
)
from railpilot.link import messages as m

ROOT = Path(__file__).resolve().parents[2]
DISSECTOR = ROOT / "tools" / "railpilot_link.lua"
SPEC = ROOT / "docs" / "protocol.md"
TSHARK = shutil.which("tshark")
DUMPCAP = shutil.which("dumpcap")

pytestmark = pytest.mark.skipif(
    TSHARK is None,
    reason="tshark is not on PATH (apt-get install tshark); the Wireshark dissector test needs it",
)

TRAIN_ID = 1001
GROUND_ID = 1
KEY_ID = 1
KEY = bytes(range(32))  # the test key of docs/protocol.md section 15
T0_US = 1_700_000_000_000_000
SUBPROCESS_TIMEOUT_S = 120.0
CAPTURE_DEADLINE_S = 30.0

UP = "up"  # onboard (TCP client) -> ground (TCP server)
DOWN = "down"


# --- the traffic ---------------------------------------------------------------------------


def golden_vectors() -> list[dict[str, str]]:
    vectors = []
    for block in re.findall(r"```golden-vector\n(.*?)```", SPEC.read_text("utf-8"), re.S):
        entries = {}
        for line in block.strip().splitlines():
            key, _, value = line.partition(":")
            entries[key.strip()] = value.strip()
        vectors.append(entries)
    return vectors


@dataclass
class Direction:
    source: int
    destination: int
    sequence: int = 0
    timestamp_us: int = T0_US + 10_000_000

    def frame(self, message: m.Message, auth: bool) -> bytes:
        self.sequence += 1
        self.timestamp_us += 100_000
        return encode_frame(
            message.TYPE,
            self.source,
            self.destination,
            self.sequence,
            self.timestamp_us,
            T0_US,
            encode_body(message),
            key_id=KEY_ID if auth else 0,
            key=KEY if auth else None,
        )


UPLINK_MESSAGES: list[m.Message] = [
    m.RegisterRequest("K1234", "SS4-0123", 42, 2600.0),
    m.DeregisterRequest(m.DeregisterReason.LEAVING_MAIN_LINE),
    m.TimeOffsetReport(1_700_000_003.5, 1_700_000_003.487_655, -0.012_345),
    m.RunningInfo(42, "K1234", "SS4-0123", m.TravelDirection.DOWN, 19.44, 98_765.43),
    m.PlannedCurve(7, 8, 600.0, 634.567),
    m.TargetPointAck(5, m.TargetPointResult.ACCEPTED),
    m.TsrSetAck(77, m.TsrSetResult.EXPIRED),
    m.TsrCancelAck(77, m.TsrCancelResult.UNKNOWN_SESSION),
    m.DispatchAck(9),
    m.Heartbeat(),
]
DOWNLINK_MESSAGES: list[m.Message] = [
    m.RegisterResponse(m.RegisterResult.ACCEPTED),
    m.DeregisterResponse(),
    m.TimeCheck(1_700_000_003.5),
    m.StationStops((m.StationStop(7, 123_456.78, 120.0), m.StationStop(8, 234_567.0, 60.0))),
    m.RunningTimes((m.RunningTime(7, 8, 1234.567), m.RunningTime(8, 9, 99.0))),
    m.TargetPoint(5, 130_000.5, m.TargetReason.SWITCH_INDICATION_LOST),
    m.TsrSet(77, 2000.0, 1000.0, 12.5, 1_700_000_000.0, 1_700_003_600.0),
    m.TsrCancel(77),
    m.DispatchCommand(9, "限速 45 km/h, 注意前方施工"),
    m.Heartbeat(),
]


def corrupt(wire: bytes) -> bytes:
    """Flip one body bit of a wire frame without touching stuffing (CRC no longer matches)."""
    raw = bytearray(unstuff(wire[1:]))
    i = 40  # inside the body of a RUNNING_INFO
    assert raw[i] not in (0x7E, 0x7F)
    raw[i] ^= 0x01
    return stuff(bytes(raw))


def frame_ending_in_7e(up: Direction) -> bytes:
    """A RUNNING_INFO whose CRC ends in 0x7E (deterministic search over the position)."""
    sequence, timestamp_us = up.sequence, up.timestamp_us
    for position_cm in range(1_000_000, 1_010_000):
        up.sequence, up.timestamp_us = sequence, timestamp_us
        info = m.RunningInfo(42, "K1234", "SS4-0123", m.TravelDirection.UP, 10.0, position_cm / 100)
        wire = up.frame(info, auth=False)
        if wire.endswith(b"\x7e\x7e"):
            return wire
    raise AssertionError("no CRC ending in 0x7E found")


def traffic() -> list[tuple[str, bytes]]:
    """The pieces to send, in order; each piece becomes one TCP segment."""
    vectors = {v["name"]: bytes.fromhex(v["wire"]) for v in golden_vectors()}
    assert len(vectors) >= 4, "docs/protocol.md lost its golden vectors"
    up = Direction(TRAIN_ID, GROUND_ID)
    down = Direction(GROUND_ID, TRAIN_ID)
    pieces: list[tuple[str, bytes]] = []
    for vector in golden_vectors():
        source = int(vector["source_id"])
        pieces.append((UP if source == TRAIN_ID else DOWN, bytes.fromhex(vector["wire"])))
    for i, message in enumerate(UPLINK_MESSAGES):
        pieces.append((UP, up.frame(message, auth=i % 2 == 0)))
    for i, message in enumerate(DOWNLINK_MESSAGES):
        pieces.append((DOWN, down.frame(message, auth=i % 2 == 1)))

    # One frame split across two segments, the cut between the two bytes of a stuffed 0x7E
    # pair (the MAC of golden vector 2 holds one), and one cut inside the first 4 bytes.
    running_info = vectors["running-info-auth"]
    cut = running_info.index(b"\x7e\x7e", 1) + 1
    pieces += [(UP, running_info[:cut]), (UP, running_info[cut:])]
    tsr_set = vectors["tsr-set-auth-stuffed"]
    pieces += [(DOWN, tsr_set[:3]), (DOWN, tsr_set[3:])]
    # Two frames in one segment.
    pieces.append((UP, up.frame(m.Heartbeat(), auth=True) + up.frame(m.DispatchAck(10), False)))
    # Garbage, a frame cut short by a header byte, then a whole frame, in one segment.
    cut_short = up.frame(m.PlannedCurve(1, 2, 3.0, 4.0), auth=False)[:30]
    pieces.append((UP, b"\x00\x11\x7e\x7e\x22" + cut_short + up.frame(m.Heartbeat(), True)))
    # A frame whose last CRC byte is 0x7E (so the wire ends 7E 7E) cut between the two
    # bytes, the next frame's header byte right behind: ... 7E | 7E 7E 01 ...
    ends_in_7e = frame_ending_in_7e(up)
    tail = up.frame(m.Heartbeat(), auth=False)
    pieces += [(UP, ends_in_7e[:-1]), (UP, ends_in_7e[-1:] + tail)]
    # A corrupted frame, then the end of a frame and a whole one in the same segment.
    bad = corrupt(
        up.frame(m.RunningInfo(42, "K1234", "SS4-0123", m.TravelDirection.UP, 5, 7), False)
    )
    pieces.append((UP, bad))
    last = down.frame(m.TsrCancel(78), auth=True)
    pieces += [(DOWN, last[:20]), (DOWN, last[20:] + down.frame(m.Heartbeat(), True))]
    return pieces


# --- capture -------------------------------------------------------------------------------


def _recv_exactly(sock: socket.socket, n: int) -> None:
    got = 0
    while got < n:
        chunk = sock.recv(n - got)
        if not chunk:
            raise ConnectionError("peer closed early")
        got += len(chunk)


def run_connection(server: socket.socket, pieces: list[tuple[str, bytes]]) -> None:
    """Connect to ``server`` and send every piece in its direction, one segment each."""
    port = server.getsockname()[1]
    with socket.create_connection(("127.0.0.1", port), timeout=10.0) as client:
        conn, _ = server.accept()
        with conn:
            conn.settimeout(10.0)
            for sock in (client, conn):
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            for direction, data in pieces:
                sender, receiver = (client, conn) if direction == UP else (conn, client)
                sender.sendall(data)
                _recv_exactly(receiver, len(data))  # sent as one segment before the next
            client.shutdown(socket.SHUT_WR)
            conn.recv(1)


PCAP_GLOBAL = struct.Struct("<IHHiIII")
PCAP_RECORD = struct.Struct("<IIII")
LINKTYPE_ETHERNET = 1


class PcapPipeReader(threading.Thread):
    """Read a pcap stream (dumpcap -P -w -); count TCP payload bytes per source port."""

    def __init__(self, stream: Any) -> None:
        super().__init__(daemon=True)
        self.stream = stream
        self.header = b""
        self.records: list[bytes] = []
        self.tcp_payload: dict[int, int] = {}
        self.udp_packets = 0
        self.linktype = -1
        self.changed = threading.Condition()

    def _read(self, n: int) -> bytes | None:
        data = b""
        while len(data) < n:
            chunk = self.stream.read(n - len(data))
            if not chunk:
                return None
            data += chunk
        return data

    def run(self) -> None:
        header = self._read(PCAP_GLOBAL.size)
        if header is None:
            return
        self.header = header
        self.linktype = PCAP_GLOBAL.unpack(header)[6]
        while True:
            rec = self._read(PCAP_RECORD.size)
            if rec is None:
                break
            data = self._read(PCAP_RECORD.unpack(rec)[2])
            if data is None:
                break
            with self.changed:
                self.records.append(rec + data)
                self._count(data)
                self.changed.notify_all()

    def _count(self, packet: bytes) -> None:
        if self.linktype != LINKTYPE_ETHERNET or packet[12:14] != b"\x08\x00":
            return
        ip = packet[14:]
        ihl = (ip[0] & 0x0F) * 4
        total = struct.unpack_from(">H", ip, 2)[0]
        if ip[9] == 17:
            self.udp_packets += 1
        elif ip[9] == 6:
            tcp = ip[ihl:]
            payload = total - ihl - (tcp[12] >> 4) * 4
            sport = struct.unpack_from(">H", tcp)[0]
            self.tcp_payload[sport] = self.tcp_payload.get(sport, 0) + payload

    def wait_for(self, condition: Any, deadline_s: float) -> bool:
        end = time.monotonic() + deadline_s
        with self.changed:
            while not condition():
                left = end - time.monotonic()
                if left <= 0 or not self.is_alive():
                    return condition()
                self.changed.wait(min(left, 0.2))
        return True


def capture_loopback(path: Path, pieces: list[tuple[str, bytes]]) -> tuple[int | None, str]:
    """Capture the connection with dumpcap on lo: (server port, "") or (None, why not)."""
    if DUMPCAP is None:
        return None, "dumpcap is not on PATH"
    with (
        socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe_rx,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe_tx,
    ):
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        server.settimeout(10.0)
        probe_rx.bind(("127.0.0.1", 0))
        port, probe_port = server.getsockname()[1], probe_rx.getsockname()[1]
        proc = subprocess.Popen(
            [
                *(DUMPCAP, "-q", "-P", "-i", "lo", "-w", "-", "-a", "duration:120"),
                *("-f", f"tcp port {port} or udp port {probe_port}"),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        assert proc.stdout is not None
        reader = PcapPipeReader(proc.stdout)
        reader.start()
        captured = False
        try:
            # The capture is live once a probe datagram shows up in it.
            end = time.monotonic() + CAPTURE_DEADLINE_S
            while reader.udp_packets == 0 and proc.poll() is None and time.monotonic() < end:
                probe_tx.sendto(b"probe", ("127.0.0.1", probe_port))
                reader.wait_for(lambda: reader.udp_packets > 0, 0.2)
            if reader.udp_packets == 0 or reader.linktype != LINKTYPE_ETHERNET:
                return None, f"dumpcap did not capture on lo (linktype {reader.linktype})"
            run_connection(server, pieces)
            up_bytes = sum(len(d) for direction, d in pieces if direction == UP)
            down_bytes = sum(len(d) for direction, d in pieces if direction == DOWN)

            def complete() -> bool:
                seen = reader.tcp_payload
                return seen.get(port, 0) == down_bytes and sum(seen.values()) == (
                    up_bytes + down_bytes
                )

            if not reader.wait_for(complete, CAPTURE_DEADLINE_S):
                return None, "dumpcap missed part of the connection"
            captured = True
        finally:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=SUBPROCESS_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            reader.join(timeout=SUBPROCESS_TIMEOUT_S)
            assert proc.stderr is not None
            if not captured:
                print("dumpcap said:", proc.stderr.read().decode(errors="replace").strip())
            proc.stdout.close()
            proc.stderr.close()
        path.write_bytes(reader.header + b"".join(reader.records))
        return port, ""


def _checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\0"
    total = sum(struct.unpack(f">{len(data) // 2}H", data))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def write_synthetic_pcap(path: Path, pieces: list[tuple[str, bytes]], port: int) -> int:
    """Write the connection as a pcap file: handshake, one segment per piece, FINs."""
    client_port = 50_000
    seq = {UP: 1_000, DOWN: 5_000}
    records = []
    ident = 0

    def packet(direction: str, flags: int, payload: bytes = b"") -> None:
        nonlocal ident
        ident += 1
        sport, dport = (client_port, port) if direction == UP else (port, client_port)
        other = DOWN if direction == UP else UP
        tcp = struct.pack(
            ">HHIIBBHHH", sport, dport, seq[direction], seq[other], 5 << 4, flags, 65535, 0, 0
        )
        pseudo = struct.pack(
            ">4s4sBBH", b"\x7f\0\0\x01", b"\x7f\0\0\x01", 0, 6, len(tcp) + len(payload)
        )
        tcp = tcp[:16] + struct.pack(">H", _checksum(pseudo + tcp + payload)) + tcp[18:]
        ip = struct.pack(
            ">BBHHHBBH4s4s", 0x45, 0, 20 + len(tcp) + len(payload), ident, 0x4000, 64, 6, 0,
            b"\x7f\0\0\x01", b"\x7f\0\0\x01",
        )  # fmt: skip
        ip = ip[:10] + struct.pack(">H", _checksum(ip)) + ip[12:]
        frame = b"\0" * 12 + b"\x08\x00" + ip + tcp + payload
        sec, msec = divmod(ident, 1000)  # one packet per ms
        records.append(
            PCAP_RECORD.pack(1_700_000_000 + sec, msec * 1000, len(frame), len(frame)) + frame
        )
        seq[direction] += len(payload) + (1 if flags & 0x03 else 0)

    syn, fin, ack, psh = 0x02, 0x01, 0x10, 0x08
    packet(UP, syn)
    packet(DOWN, syn | ack)
    packet(UP, ack)
    for direction, data in pieces:
        packet(direction, psh | ack, data)
        packet(DOWN if direction == UP else UP, ack)
    packet(UP, fin | ack)
    packet(DOWN, fin | ack)
    packet(UP, ack)
    header = PCAP_GLOBAL.pack(0xA1B2C3D4, 2, 4, 0, 0, 65535, LINKTYPE_ETHERNET)
    path.write_bytes(header + b"".join(records))
    return port


# --- dissect -------------------------------------------------------------------------------


def flatten(node: Any, out: dict[str, list[str]]) -> dict[str, list[str]]:
    """Every ``railpilot.*`` field (and expert) below ``node``, in tree order."""
    if isinstance(node, list):
        for item in node:
            flatten(item, out)
    elif isinstance(node, dict):
        for key, value in node.items():
            if key.startswith("railpilot.") and not isinstance(value, dict | list):
                out.setdefault(key, []).append(value)
            elif (
                key.startswith("railpilot.")
                and isinstance(value, list)
                and all(isinstance(v, str) for v in value)
            ):
                out.setdefault(key, []).extend(value)
            else:
                flatten(value, out)
    return out


@dataclass
class Packet:
    direction: str
    payload: int
    pdus: list[dict[str, list[str]]] = field(default_factory=list)


def run_tshark(path: Path, port: int) -> list[Packet]:
    assert TSHARK is not None
    proc = subprocess.run(
        [
            *(TSHARK, "-n", "-r", str(path), "-X", f"lua_script:{DISSECTOR}"),
            *("-o", f"railpilot.tcp_port:{port}", "-o", "tcp.desegment_tcp_streams:TRUE"),
            *("-T", "json", "--no-duplicate-keys"),
        ],
        capture_output=True,
        text=True,
        timeout=SUBPROCESS_TIMEOUT_S,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Lua" not in proc.stderr and "error" not in proc.stderr.lower(), proc.stderr
    assert "Lua Error" not in proc.stdout
    packets = []
    for entry in json.loads(proc.stdout):
        layers = entry["_source"]["layers"]
        if "tcp" not in layers:
            continue
        tcp = layers["tcp"]
        direction = DOWN if int(tcp["tcp.srcport"]) == port else UP
        trees = layers.get("railpilot", [])
        trees = trees if isinstance(trees, list) else [trees]
        pdus = [flatten(tree, {}) for tree in trees]
        packets.append(Packet(direction, int(tcp["tcp.len"]), pdus))
    return packets


# --- what railpilot.link says about the same bytes -----------------------------------------


def cm(value_m: float) -> str:
    return str(round(value_m * 100))


def us(value_s: float) -> str:
    return str(round(value_s * 1_000_000))


def ms(value_s: float) -> str:
    return str(round(value_s * 1000))


def body_fields(msg: m.Message) -> dict[str, list[str | float]]:
    """The dissector fields a message's body must produce (wire values and SI values)."""
    if isinstance(msg, m.RegisterRequest):
        f: dict[str, Any] = {
            "register_request.train_number": msg.train_number,
            "register_request.loco_number": msg.loco_number,
            "register_request.driver_id": str(msg.driver_id),
            "register_request.train_length": cm(msg.train_length_m),
            "register_request.train_length_m": msg.train_length_m,
        }
    elif isinstance(msg, m.RegisterResponse):
        f = {"register_response.result": str(int(msg.result))}
    elif isinstance(msg, m.DeregisterRequest):
        f = {"deregister_request.reason": str(int(msg.reason))}
    elif isinstance(msg, m.DeregisterResponse):
        f = {"deregister_response.result": str(int(msg.result))}
    elif isinstance(msg, m.TimeCheck):
        f = {"time_check.ground_time": us(msg.ground_time_s)}
    elif isinstance(msg, m.TimeOffsetReport):
        f = {
            "time_offset_report.ground_time": us(msg.ground_time_s),
            "time_offset_report.onboard_time": us(msg.onboard_time_s),
            "time_offset_report.offset": us(msg.offset_s),
            "time_offset_report.offset_s": msg.offset_s,
        }
    elif isinstance(msg, m.RunningInfo):
        f = {
            "running_info.driver_id": str(msg.driver_id),
            "running_info.train_number": msg.train_number,
            "running_info.loco_number": msg.loco_number,
            "running_info.direction": str(int(msg.direction)),
            "running_info.speed": cm(msg.speed_mps),
            "running_info.speed_mps": msg.speed_mps,
            "running_info.speed_kmh": msg.speed_mps * 3.6,
            "running_info.position": cm(msg.position_m),
            "running_info.position_m": msg.position_m,
        }
    elif isinstance(msg, m.StationStops):
        f = {
            "station_stops.count": str(len(msg.stops)),
            "station_stops.station_id": [str(s.station_id) for s in msg.stops],
            "station_stops.position": [cm(s.stop_position_m) for s in msg.stops],
            "station_stops.position_m": [s.stop_position_m for s in msg.stops],
            "station_stops.dwell": [str(round(s.dwell_time_s)) for s in msg.stops],
        }
    elif isinstance(msg, m.RunningTimes):
        f = {
            "running_times.count": str(len(msg.times)),
            "running_times.from_station": [str(t.from_station_id) for t in msg.times],
            "running_times.to_station": [str(t.to_station_id) for t in msg.times],
            "running_times.time": [ms(t.running_time_s) for t in msg.times],
            "running_times.time_s": [t.running_time_s for t in msg.times],
        }
    elif isinstance(msg, m.PlannedCurve):
        f = {
            "planned_curve.from_station": str(msg.from_station_id),
            "planned_curve.to_station": str(msg.to_station_id),
            "planned_curve.elapsed": ms(msg.elapsed_s),
            "planned_curve.elapsed_s": msg.elapsed_s,
            "planned_curve.remaining": ms(msg.remaining_s),
            "planned_curve.remaining_s": msg.remaining_s,
        }
    elif isinstance(msg, m.TargetPoint):
        f = {
            "target_point.target_id": str(msg.target_id),
            "target_point.position": cm(msg.position_m),
            "target_point.position_m": msg.position_m,
            "target_point.reason": str(int(msg.reason)),
        }
    elif isinstance(msg, m.TargetPointAck):
        f = {
            "target_point_ack.target_id": str(msg.target_id),
            "target_point_ack.result": str(int(msg.result)),
        }
    elif isinstance(msg, m.TsrSet):
        f = {
            "tsr_set.session": str(msg.session),
            "tsr_set.start": cm(msg.start_m),
            "tsr_set.start_m": msg.start_m,
            "tsr_set.end": cm(msg.end_m),
            "tsr_set.end_m": msg.end_m,
            "tsr_set.limit": cm(msg.limit_mps),
            "tsr_set.limit_mps": msg.limit_mps,
            "tsr_set.valid_from": us(msg.valid_from_s),
            "tsr_set.valid_until": us(msg.valid_until_s),
        }
    elif isinstance(msg, m.TsrSetAck):
        f = {"tsr_set_ack.session": str(msg.session), "tsr_set_ack.result": str(int(msg.result))}
    elif isinstance(msg, m.TsrCancel):
        f = {"tsr_cancel.session": str(msg.session)}
    elif isinstance(msg, m.TsrCancelAck):
        f = {
            "tsr_cancel_ack.session": str(msg.session),
            "tsr_cancel_ack.result": str(int(msg.result)),
        }
    elif isinstance(msg, m.DispatchCommand):
        f = {
            "dispatch_command.number": str(msg.command_number),
            "dispatch_command.text_length": str(len(msg.text.encode("utf-8"))),
            "dispatch_command.text": msg.text,
        }
    elif isinstance(msg, m.DispatchAck):
        f = {
            "dispatch_ack.number": str(msg.command_number),
            "dispatch_ack.result": str(int(msg.result)),
        }
    else:
        assert isinstance(msg, m.Heartbeat)
        f = {}
    return {"railpilot." + k: v if isinstance(v, list) else [v] for k, v in f.items()}


def colon_hex(data: bytes) -> str:
    return ":".join(f"{b:02x}" for b in data)


def expected_items(data: bytes) -> Iterator[tuple[str, Any]]:
    """What the reference decoder finds in ``data``, per frame or framing problem."""
    for report in decode_stream(data):
        yield ("frame" if report.raw is not None else "framing", report)


def check_frame(pdu: dict[str, list[str]], report: Any) -> None:
    frame, raw = report.frame, report.raw
    one = {k: v[0] for k, v in pdu.items() if len(v) == 1}
    assert one["railpilot.type"] == f"0x{frame.message_type:02x}"
    assert one["railpilot.version"] == "1"
    assert one["railpilot.length"] == str(len(raw))
    assert one["railpilot.src"] == str(frame.source_id)
    assert one["railpilot.dst"] == str(frame.destination_id)
    assert one["railpilot.seq"] == str(frame.sequence)
    assert one["railpilot.timestamp"] == str(frame.timestamp_us)
    assert one["railpilot.echo"] == str(frame.echo_timestamp_us)
    assert one["railpilot.key_id"] == str(frame.key_id)
    assert one["railpilot.flags.auth"] == ("1" if frame.mac is not None else "0")
    assert one["railpilot.stuffed_bytes"] == str(raw.count(b"\x7e"))
    assert int(one["railpilot.wire_length"]) == len(stuff(raw))
    if frame.mac is None:
        assert "railpilot.mac" not in pdu
    else:
        assert one["railpilot.mac"] == colon_hex(frame.mac)
    assert int(one["railpilot.crc"], 16) == frame.crc
    crc_verdict = next(v for v in report.verdicts if v.check.name == "CRC")
    assert one["railpilot.crc.status"] == ("1" if crc_verdict.ok else "0")
    assert ("railpilot.crc.bad" in pdu) is (not crc_verdict.ok)
    body = decode_body(frame.message_type, frame.body)
    assert report.message is None or body == report.message
    for key, values in body_fields(body).items():
        got = pdu.get(key)
        assert got is not None, f"{key} missing in {pdu}"
        assert len(got) == len(values), key
        for g, want in zip(got, values, strict=True):
            if isinstance(want, float):
                assert float(g) == pytest.approx(want, abs=1e-6), key
            else:
                assert g == want, key
    assert "railpilot.body.bad" not in pdu and "railpilot.length.bad" not in pdu


def check_capture(packets: list[Packet], pieces: list[tuple[str, bytes]]) -> dict[str, int]:
    """Compare the dissector's view of ``packets`` with railpilot.link, piece by piece."""
    counts = {"frames": 0, "crc_bad": 0, "framing": 0, "discarded": 0}
    reference_discarded = 0
    for direction in (UP, DOWN):
        sent = [data for d, data in pieces if d == direction]
        seen = [p for p in packets if p.direction == direction and p.payload > 0]
        # One TCP segment per piece, so a segment split stays split in the capture.
        assert [p.payload for p in seen] == [len(d) for d in sent]
        decoder = FrameDecoder()
        reports = iter(list(decode_stream(b"".join(sent))))
        for data, packet in zip(sent, seen, strict=True):
            completed = decoder.feed(data)  # what the reference completes with this segment
            pdus = [p for p in packet.pdus if "railpilot.discarded" not in p]
            assert len(pdus) == len(completed), (packet, completed)
            for pdu, item in zip(pdus, completed, strict=True):
                report = next(reports)
                if isinstance(item, FrameError):
                    assert report.raw is None
                    assert "railpilot.framing" in pdu and "railpilot.type" not in pdu
                    counts["framing"] += 1
                else:
                    assert report.raw == item
                    check_frame(pdu, report)
                    counts["frames"] += 1
                    counts["crc_bad"] += "railpilot.crc.bad" in pdu
            for pdu in packet.pdus:
                for garbage in pdu.get("railpilot.discarded", []):
                    counts["discarded"] += len(garbage.split(":"))
        assert next(reports, None) is None
        reference_discarded += decoder.bytes_discarded
    assert counts["discarded"] == reference_discarded
    return counts


# --- frames that each fail one check (with a correct CRC unless the CRC is the point) ------


def raw_frame(
    body: bytes,
    message_type: int = 0x20,
    *,
    version: int = 1,
    flags: int = 0,
    key_id: int = 0,
    length: int | None = None,
    mac: bytes = b"",
) -> bytes:
    """Wire bytes of a hand-built frame; fields default to a plain RUNNING_INFO."""
    n = 35 + len(body) + len(mac) + 4 if length is None else length
    head = struct.pack(
        ">BBHBHIIIQQ", version, flags, n, message_type, key_id, TRAIN_ID, GROUND_ID, 1, T0_US, 0
    )
    unsigned = head + body + mac
    return stuff(unsigned + zlib.crc32(unsigned).to_bytes(4, "big"))


RI_BODY = encode_body(m.RunningInfo(42, "K1234", "SS4-0123", m.TravelDirection.UP, 20.0, 1000.0))


def with_bytes(body: bytes, offset: int, new: bytes) -> bytes:
    return body[:offset] + new + body[offset + len(new) :]


#: name -> (wire bytes, the check of docs/protocol.md section 5.4 that must fail)
MALFORMED: dict[str, tuple[bytes, str]] = {
    "version 2": (raw_frame(RI_BODY, version=2), "VERSION"),
    "length below 39": (raw_frame(RI_BODY, length=38), "LENGTH"),
    "length above max": (raw_frame(RI_BODY, length=3000), "LENGTH"),
    "reserved flag bit": (raw_frame(RI_BODY, flags=0x02), "VERSION"),
    "key id without AUTH": (raw_frame(RI_BODY, key_id=5), "AUTH"),
    "AUTH with key id 0": (raw_frame(RI_BODY, flags=1, mac=bytes(16)), "AUTH"),
    "unknown type": (raw_frame(b"", message_type=0x99), "TYPE"),
    "body too short": (raw_frame(RI_BODY[:-1]), "LENGTH"),
    "speed above 100 m/s": (raw_frame(with_bytes(RI_BODY, 21, b"\x27\x11")), "BODY"),
    "unknown direction": (raw_frame(with_bytes(RI_BODY, 20, b"\x07")), "BODY"),
    "NUL inside train number": (raw_frame(with_bytes(RI_BODY, 4, b"K1\x0034")), "BODY"),
    "empty train number": (raw_frame(with_bytes(RI_BODY, 4, bytes(8))), "BODY"),
    "train length above 10 km": (
        raw_frame(
            encode_body(m.RegisterRequest("K1", "L1", 1, 1.0))[:20]
            + (1_000_001).to_bytes(4, "big"),
            0x01,
        ),
        "BODY",
    ),
    "TSR session 0": (
        raw_frame(
            with_bytes(encode_body(m.TsrSet(1, 0.0, 10.0, 1.0, 1.0, 2.0)), 0, bytes(4)), 0x30
        ),
        "BODY",
    ),
    "TSR limit 0": (
        raw_frame(
            with_bytes(encode_body(m.TsrSet(1, 0.0, 10.0, 1.0, 1.0, 2.0)), 12, bytes(2)), 0x30
        ),
        "BODY",
    ),
    "time check beyond 10^16 us": (raw_frame((10**16 + 1000).to_bytes(8, "big"), 0x10), "BODY"),
    "offset beyond 10^12 us": (
        raw_frame(bytes(16) + (-(10**12) - 1).to_bytes(8, "big", signed=True), 0x11),
        "BODY",
    ),
    "unknown target reason": (raw_frame(bytes(8) + b"\x04", 0x24), "BODY"),
    "unknown TSR ack result": (raw_frame(b"\0\0\0\x01\x03", 0x31), "BODY"),
    "station list count mismatch": (raw_frame(b"\x02" + bytes(10), 0x21), "LENGTH"),
    # spec 5.4 #13: a count that fits the body but is over 64 is a range (body) failure
    "station list of 65 entries": (raw_frame(b"\x41" + bytes(650), 0x21), "BODY"),
    "offset not onboard - ground": (
        raw_frame((5).to_bytes(8, "big") + (7).to_bytes(8, "big") + (3).to_bytes(8, "big"), 0x11),
        "BODY",
    ),
    "dispatch text length mismatch": (raw_frame(b"\0\0\0\x01\0\x05abc", 0x40), "LENGTH"),
    "dispatch text not UTF-8": (raw_frame(b"\0\0\0\x01\0\x02\xc3\x28", 0x40), "BODY"),
    "bad CRC": (corrupt(raw_frame(RI_BODY)), "CRC"),
}

EXPERT_OF_CHECK = {
    "VERSION": "railpilot.version.bad",
    "LENGTH": "railpilot.length.bad",
    "AUTH": "railpilot.auth.bad",
    "TYPE": "railpilot.type.unknown",
    "BODY": "railpilot.body.bad",
    "CRC": "railpilot.crc.bad",
    "FRAMING": "railpilot.framing",
}
INFORMATIVE_EXPERTS = {"railpilot.hunting", "railpilot.auth.none"}


def reference_check(wire: bytes) -> str | None:
    """The first check railpilot.link's core fails on one wire frame (None: all pass)."""
    items = FrameDecoder().feed(wire)
    if not items:
        return None
    item = items[0]
    try:
        if isinstance(item, FrameError):
            raise item
        frame = parse_frame(item)
        decode_body(frame.message_type, frame.body)
    except FrameError as exc:
        return exc.check.name
    return None


# --- the tests -----------------------------------------------------------------------------


def expected_counts(pieces: list[tuple[str, bytes]]) -> dict[str, int]:
    frames = crc_bad = framing = 0
    for direction in (UP, DOWN):
        for kind, report in expected_items(b"".join(d for x, d in pieces if x == direction)):
            if kind == "framing":
                framing += 1
            else:
                frames += 1
                crc_bad += any(v.check.name == "CRC" and v.ok is False for v in report.verdicts)
    return {"frames": frames, "crc_bad": crc_bad, "framing": framing}


def test_traffic_covers_every_message_type() -> None:
    pieces = traffic()
    types = set()
    for direction in (UP, DOWN):
        for kind, report in expected_items(b"".join(d for x, d in pieces if x == direction)):
            if kind == "frame":
                types.add(report.frame.message_type)
    assert types == {int(t) for t in m.MessageType}
    assert expected_counts(pieces) == {"frames": 34, "crc_bad": 1, "framing": 1}


@pytest.mark.parametrize("path_kind", ["loopback", "synthetic"])
def test_dissector_matches_reference_decoder(
    path_kind: str, tmp_path: Path, record_property: Any
) -> None:
    pieces = traffic()
    capture = tmp_path / "railpilot.pcap"
    port = None
    used = "synthetic pcap written by the test"
    if path_kind == "loopback":
        why = "RAILPILOT_NO_LIVE_CAPTURE is set"
        if not os.environ.get("RAILPILOT_NO_LIVE_CAPTURE"):
            port, why = capture_loopback(capture, pieces)
        if port is not None:
            used = "live dumpcap capture on lo"
        else:
            print(f"live capture on lo impossible ({why}); falling back to a written pcap")
    if port is None:
        port = write_synthetic_pcap(capture, pieces, port=7400)
    print(f"capture path: {used}")
    record_property("capture_path", used)

    packets = run_tshark(capture, port)
    counts = check_capture(packets, pieces)

    expected = expected_counts(pieces)
    assert {k: counts[k] for k in expected} == expected
    assert counts["crc_bad"] == 1  # the deliberately corrupted frame, and only it
    assert counts["discarded"] > 0


def test_dissector_flags_each_failed_check(tmp_path: Path) -> None:
    """One frame per failed check, each in its own segment, with a good frame after it."""
    pieces = []
    good = Direction(TRAIN_ID, GROUND_ID)
    for name, (wire, check) in MALFORMED.items():
        assert reference_check(wire) == check, name
        pieces.append((UP, wire + good.frame(m.Heartbeat(), auth=False)))
    capture = tmp_path / "malformed.pcap"
    port = write_synthetic_pcap(capture, pieces, port=7400)
    seen = [p for p in run_tshark(capture, port) if p.payload > 0]
    assert len(seen) == len(MALFORMED)
    for (name, (_, check)), packet in zip(MALFORMED.items(), seen, strict=True):
        experts = {
            key
            for pdu in packet.pdus[:-1]
            for key in pdu
            if key.startswith("railpilot.")
            and key in set(EXPERT_OF_CHECK.values()) | INFORMATIVE_EXPERTS
        }
        assert experts - INFORMATIVE_EXPERTS == {EXPERT_OF_CHECK[check]}, name
        last = packet.pdus[-1]  # the dissector found the good frame behind it
        assert last["railpilot.type"] == ["0x50"], name
        assert last["railpilot.crc.status"] == ["1"], name
