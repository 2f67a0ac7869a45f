"""Interoperability of an onboard peer written from docs/protocol.md alone with the real ground.

spec_peer.py is built only from docs/protocol.md; this file drives the real
`railpilot ground serve` over loopback TCP and operates it only through the CLI and the admin
JSON socket documented in docs/link-operations.md. Nothing under src/ is imported.
"""

from __future__ import annotations

import itertools
import json
import os
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import spec_peer as sp

# an independent peer process over real TCP
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
PROTOCOL_MD = ROOT / "docs" / "protocol.md"
RAILPILOT = ROOT / ".venv" / "bin" / "railpilot"
GROUND_ID = 1
KEY = bytes(range(32))  # the test key of section 15; a test server only
TRAINS = (1001, 1002, 1003, 1004, 1005, 1006)
WAIT = 8.0  # upper bound of every single wait, in seconds


# ---------------------------------------------------------------------------------------------
# Golden vectors (section 15), parsed from the document itself


def golden_vectors() -> list[dict[str, str]]:
    text = PROTOCOL_MD.read_text(encoding="utf-8")
    blocks = re.findall(r"```golden-vector\n(.*?)```", text, flags=re.S)
    vectors = []
    for block in blocks:
        fields: dict[str, str] = {}
        for line in block.strip().splitlines():
            name, _, value = line.partition(":")
            fields[name.strip()] = value.strip()
        vectors.append(fields)
    return vectors


VECTORS = golden_vectors()


def _hex(value: str) -> bytes:
    return b"" if value == "-" else bytes.fromhex(value)


def _cm(value: str) -> int:
    return round(float(value) * 100)


def _us(value: str) -> int:
    return round(float(value) * 1_000_000)


def _enum(v: dict[str, str], name: str, values: dict[str, int]) -> int:
    """Wire value of an enumeration field: `field.NAME: Enum.MEMBER` and the `wire.NAME:
    VALUE (MEMBER)` line next to it (section 15) must agree with section 6."""
    member = v[f"field.{name}"].rpartition(".")[2]
    m = re.fullmatch(r"(\d+) \((\w+)\)", v[f"wire.{name}"])
    assert m, v[f"wire.{name}"]
    assert m.group(2) == member and int(m.group(1)) == values[member]
    return values[member]


def body_from_fields(v: dict[str, str]) -> bytes:
    """Encode the body from the SI `field.*` lines (section 2: round to the wire unit)."""
    message = v["message"]
    if message == "Heartbeat":
        return b""
    if message == "RunningInfo":
        direction = {"UNKNOWN": sp.DIR_UNKNOWN, "UP": sp.DIR_UP, "DOWN": sp.DIR_DOWN}
        return sp.body_running_info(
            int(v["field.driver_id"]),
            json.loads(v["field.train_number"]),
            json.loads(v["field.loco_number"]),
            _enum(v, "direction", direction),
            _cm(v["field.speed_mps"]),
            _cm(v["field.position_m"]),
        )
    if message == "TsrSet":
        return sp.body_tsr_set(
            int(v["field.session"]),
            _cm(v["field.start_m"]),
            _cm(v["field.end_m"]),
            _cm(v["field.limit_mps"]),
            _us(v["field.valid_from_s"]),
            _us(v["field.valid_until_s"]),
        )
    if message == "TsrSetAck":
        results = {"APPLIED": sp.TSR_APPLIED, "INVALID": sp.TSR_INVALID, "EXPIRED": sp.TSR_EXPIRED}
        return sp.body_ack(int(v["field.session"]), _enum(v, "result", results))
    raise AssertionError(f"no encoder for {message}")


def test_golden_vectors_found() -> None:
    assert [v["name"] for v in VECTORS] == [
        "heartbeat-plain",
        "running-info-auth",
        "tsr-set-auth-stuffed",
        "tsr-set-ack-plain",
    ]


def test_crc32_check_value() -> None:
    assert sp.crc32(b"123456789") == 0xCBF43926  # section 4.1


@pytest.mark.parametrize("v", VECTORS, ids=[v["name"] for v in VECTORS])
def test_golden_vector_encode(v: dict[str, str]) -> None:
    body = body_from_fields(v)
    assert body.hex() == ("" if v["body"] == "-" else v["body"])
    key = None if v["key"] == "-" else _hex(v["key"])
    f = sp.encode_unstuffed(
        int(v["message_type"], 16),
        body,
        source=int(v["source_id"]),
        destination=int(v["destination_id"]),
        seq=int(v["sequence"]),
        timestamp_us=int(v["timestamp_us"]),
        echo_us=int(v["echo_timestamp_us"]),
        key_id=int(v["key_id"]),
        key=key,
    )
    assert f.hex() == v["unstuffed"]
    frame = sp.parse_frame(f)
    assert frame.mac.hex() == ("" if v["mac"] == "-" else v["mac"])
    assert f"{frame.crc:08x}" == v["crc"]
    assert (b"\x7e" + sp.stuff(f)).hex() == v["wire"]


@pytest.mark.parametrize("v", VECTORS, ids=[v["name"] for v in VECTORS])
def test_golden_vector_decode(v: dict[str, str]) -> None:
    wire = _hex(v["wire"])
    # one read, and one byte per read (section 1: segment boundaries mean nothing)
    assert sp.FrameDecoder().feed(wire) == [_hex(v["unstuffed"])]
    dec = sp.FrameDecoder()
    frames = [f for b in wire for f in dec.feed(bytes([b]))]
    assert frames == [_hex(v["unstuffed"])]
    frame = sp.parse_frame(frames[0])
    assert frame.msg_type == int(v["message_type"], 16)
    assert (frame.source, frame.destination) == (int(v["source_id"]), int(v["destination_id"]))
    assert (frame.seq, frame.timestamp_us) == (int(v["sequence"]), int(v["timestamp_us"]))
    assert frame.echo_us == int(v["echo_timestamp_us"]) and frame.key_id == int(v["key_id"])
    assert frame.body == _hex(v["body"])
    if v["key"] != "-":
        assert sp.mac16(_hex(v["key"]), frames[0][:-20]) == frame.mac
    assert sp.crc32(frames[0][:-4]) == frame.crc
    if v["message"] == "TsrSet":
        tsr = sp.decode_body(sp.TSR_SET, frame.body)["tsr"]
        assert tsr == sp.TsrSet(
            126, 100_000, 200_000, 1250, 1_700_000_000_000_000, 1_700_003_600_000_000
        )


def test_decoder_resynchronises_on_garbage_and_split_frames() -> None:
    wires = [_hex(v["wire"]) for v in VECTORS]
    stream = b"\x00\x7e\x7e\x11" + wires[0] + b"garbage" + wires[1] + wires[2][:20] + wires[3]
    dec = sp.FrameDecoder()
    got = [f for i in range(0, len(stream), 7) for f in dec.feed(stream[i : i + 7])]
    # the cut-short vector 3 is a framing rejection; its header byte-less tail is not a frame
    assert got == [_hex(VECTORS[i]["unstuffed"]) for i in (0, 1, 3)]
    assert dec.rejections == ["framing"]


# ---------------------------------------------------------------------------------------------
# The real ground server


class Ground:
    def __init__(self, tmp: Path) -> None:
        keys = tmp / "keys.toml"
        keys.write_text(
            "".join(
                f'[[train]]\nid = {t}\nactive_key = 1\n[train.keys]\n1 = "{KEY.hex()}"\n\n'
                for t in TRAINS
            )
        )
        os.chmod(keys, 0o600)
        self.lines: list[str] = []
        # notified for every line the server logs (and at its end): waits wake on events
        self._logged = threading.Condition()
        self.proc = subprocess.Popen(
            [
                str(RAILPILOT),
                "ground",
                "serve",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--keys",
                str(keys),
                "--admin-port",
                "0",
                "--ground-id",
                str(GROUND_ID),
                "--seconds",
                "120",  # a safety net only; the fixture stops it
                "--db",
                str(tmp / "ground.db"),  # not ./ground.db: every run starts afresh
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.port = self._logged_port(r"event=listening\b.*\bport=(\d+)")
        self.admin_port = self._logged_port(r"event=admin_listening\b.*\bport=(\d+)")

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            with self._logged:
                self.lines.append(line)
                self._logged.notify_all()
        with self._logged:
            self._logged.notify_all()

    def _logged_port(self, pattern: str) -> int:
        deadline = time.monotonic() + WAIT
        with self._logged:
            while True:
                for line in self.lines:
                    m = re.search(pattern, line)
                    if m:
                        return int(m.group(1))
                left = deadline - time.monotonic()
                if left <= 0 or self.proc.poll() is not None:
                    break
                self._logged.wait(left)  # the next line the server logs
        raise RuntimeError("ground server did not start:\n" + "".join(self.lines))

    def admin(self, request: dict[str, Any]) -> dict[str, Any]:
        with socket.create_connection(("127.0.0.1", self.admin_port), timeout=WAIT) as s:
            s.sendall((json.dumps(request) + "\n").encode())
            line = s.makefile("r", encoding="utf-8").readline()
        return json.loads(line)

    def cli(self, *args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(RAILPILOT), "ground", *args, "--admin-port", str(self.admin_port)],
            capture_output=True,
            text=True,
            timeout=WAIT,
        )

    def status(self) -> dict[str, Any]:
        answer = self.admin({"op": "status"})
        assert answer["ok"], answer
        return answer["result"]

    def train(self, train_id: int) -> dict[str, Any]:
        for t in self.status()["trains"]:
            if t["train_id"] == train_id:
                return t
        return {}

    def poll(self, predicate: Any, what: str) -> Any:
        """Re-check ``predicate`` (an admin query) until it holds or WAIT passes.

        The server's state is only visible through queries, so this polls a condition with
        a deadline; a line the server logs (an acknowledgement, a registration) wakes it at
        once, and a silent change (a TSR re-confirmed) is seen within 50 ms.
        """
        deadline = time.monotonic() + WAIT
        while True:
            value = predicate()
            if value:
                return value
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"ground: timed out waiting for {what}")
            with self._logged:
                self._logged.wait(min(0.05, left))

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait(timeout=WAIT)


@pytest.fixture(scope="module")
def ground(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Ground]:
    g = Ground(tmp_path_factory.mktemp("ground"))
    try:
        yield g
    finally:
        rc = g.stop()
        assert rc == 0, "".join(g.lines)  # link-operations.md: SIGTERM stops it with exit 0


def make_peer(ground: Ground, train_id: int, **kw: Any) -> sp.OnboardPeer:
    return sp.OnboardPeer(
        "127.0.0.1",
        ground.port,
        train_id=train_id,
        ground_id=GROUND_ID,
        keys={1: KEY},
        active_key_id=1,
        length_cm=60_000,  # 600 m
        cycle_s=0.5,
        **kw,
    )


@pytest.fixture(scope="module")
def peer(ground: Ground) -> Iterator[sp.OnboardPeer]:
    p = make_peer(ground, 1001)
    p.set_running(sp.DIR_UP, 2222, 12_345_678)
    p.connect()
    try:
        p.wait_for(lambda: p.state == "REGISTERED", WAIT, "registration")
        yield p
    finally:
        p.close()


def delta(before: dict[str, Any], after: dict[str, Any], name: str) -> int:
    return int(after.get(name, 0)) - int(before.get(name, 0))


# ---------------------------------------------------------------------------------------------
# Registration, running info, link-layer behaviour of the ground


def test_registration_accepted_and_time_check_answered(
    ground: Ground, peer: sp.OnboardPeer
) -> None:
    assert peer.register_results[0] == sp.REGISTER_ACCEPTED
    # 8.2: on registration the ground answers ACCEPTED and sends a TIME_CHECK
    peer.wait_for(lambda: peer.time_checks, WAIT, "TIME_CHECK")
    names = [f.name for f in peer.received if f.name != "HEARTBEAT"]
    assert names[:2] == ["REGISTER_RESPONSE", "TIME_CHECK"]
    train = ground.poll(lambda: ground.train(1001).get("registered") and ground.train(1001), "reg")
    assert train["connected"] and train["state"] == "REGISTERED"
    assert train["registrations"] == 1
    assert (train["train_number"], train["loco_number"]) == ("K1234", "SS4-0123")
    assert train["train_length_m"] == pytest.approx(600.0)
    ground_us, onboard_us = peer.time_checks[0]
    off = ground.poll(lambda: ground.train(1001).get("time_offset_s") is not None, "offset")
    assert off
    assert ground.train(1001)["time_offset_s"] == pytest.approx(
        (onboard_us - ground_us) / 1e6, abs=1e-6
    )


def test_status_shows_latest_running_info(ground: Ground, peer: sp.OnboardPeer) -> None:
    for km_cm, speed in ((12_345_678, 2222), (12_350_000, 2000), (12_360_000, 1500)):
        peer.set_running(sp.DIR_UP, speed, km_cm)
        n = peer.stats.sent.get("RUNNING_INFO", 0)
        peer.wait_for(lambda n=n: peer.stats.sent.get("RUNNING_INFO", 0) >= n + 1, WAIT, "cycle")
    # km 123.600, 15 m/s = 54 km/h
    info = ground.poll(
        lambda: (
            (ri := ground.train(1001).get("running_info"))
            and ri["position_km"] == pytest.approx(123.6)
            and ri
        ),
        "running info",
    )
    assert info["speed_kmh"] == pytest.approx(54.0, abs=0.01)
    assert info["direction"] == "UP" and info["valid"] is True
    assert info["age_s"] < 2.0


def test_ground_frames_follow_section_5(ground: Ground, peer: sp.OnboardPeer) -> None:
    # the ground heartbeats (section 9; its every-cycle_s cadence is tested on a fake
    # clock: tests/link/test_ground.py, test_ground_heartbeats_every_cycle)
    n0 = peer.stats.received.get("HEARTBEAT", 0)
    peer.wait_for(lambda: peer.stats.received.get("HEARTBEAT", 0) >= n0 + 2, WAIT, "heartbeats")
    with peer.lock:
        frames = list(peer.received)
        sent_ts = [f.timestamp_us for f in peer.sent]
    seqs = [f.seq for f in frames]
    assert seqs == list(range(len(seqs)))  # 5.1: 0, 1, 2, ... on a new connection
    ts = [f.timestamp_us for f in frames]
    assert all(a < b for a, b in itertools.pairwise(ts))  # 5.2
    echoes = [f.echo_us for f in frames]
    assert all(a <= b for a, b in itertools.pairwise(echoes))
    assert all(e == 0 or e in sent_ts for e in echoes)  # 5.3: echoes our own timestamps
    assert all(f.key_id == 1 and len(f.mac) == 16 for f in frames)  # 4.2
    assert peer.stats.rejections == {}
    assert peer.stats.sequence_gaps == 0
    assert not list(peer.events_of("ground_heartbeat_timeout"))


# ---------------------------------------------------------------------------------------------
# TSR set / cancel through the documented operator interfaces


def _tsr_sets(peer: sp.OnboardPeer, session: int) -> list[tuple[sp.TsrSet, int]]:
    return [(t, r) for t, r in peer.events_of("tsr_set") if t.session == session]


def test_tsr_set_via_cli_is_decoded_applied_and_acknowledged(
    ground: Ground, peer: sp.OnboardPeer
) -> None:
    peer.set_running(sp.DIR_UP, 1500, 12_360_000)
    before_us = sp.now_us()
    r = ground.cli(
        "tsr",
        "set",
        "--train",
        "1001",
        "--session",
        "7",
        "--start-km",
        "120.0",
        "--end-km",
        "121.5",
        "--limit-kmh",
        "45",
        "--valid-until-min",
        "60",
        "--reason",
        "interop",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["result"]["deliveries"] == {"1001": "sending"}
    (tsr, result), *_ = peer.wait_for(lambda: _tsr_sets(peer, 7), WAIT, "TSR_SET")
    assert result == sp.TSR_APPLIED
    assert (tsr.start_cm, tsr.end_cm, tsr.limit_cms) == (12_000_000, 12_150_000, 1250)
    assert tsr.valid_until_us - tsr.valid_from_us == 3_600_000_000
    assert abs(tsr.valid_from_us - before_us) < 5_000_000  # "default now" (ground clock)
    # 8.3 extension: UP -> [low, high + L]
    assert peer.tsrs[7].zone_cm == (12_000_000, 12_150_000 + 60_000)
    ack = [f for f in peer.sent if f.msg_type == sp.TSR_SET_ACK]
    assert ack and ack[-1].body == sp.body_ack(7, sp.TSR_APPLIED)
    ground.poll(lambda: ground.train(1001)["tsrs"].get("7") == "ACTIVE", "TSR 7 ACTIVE")
    assert len(_tsr_sets(peer, 7)) == 1  # acknowledged at once: no resend


def test_tsr_cancel_via_cli_is_decoded_and_acknowledged(
    ground: Ground, peer: sp.OnboardPeer
) -> None:
    # set through the admin JSON socket, cancel through the CLI
    answer = ground.admin(
        {
            "op": "tsr_set",
            "trains": [1001],
            "session": 8,
            "start_km": 129.0,
            "end_km": 130.0,
            "limit_kmh": 30,
            "valid_until_min": 10,
            "reason": "interop",
        }
    )
    assert answer["ok"] and answer["result"]["deliveries"] == {"1001": "sending"}
    peer.wait_for(lambda: _tsr_sets(peer, 8), WAIT, "TSR_SET 8")
    ground.poll(lambda: ground.train(1001)["tsrs"].get("8") == "ACTIVE", "TSR 8 ACTIVE")
    assert peer.tsrs[8].zone_cm == (12_900_000, 13_000_000 + 60_000)  # either order (6.13)
    r = ground.cli("tsr", "cancel", "--session", "8", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["result"]["deliveries"] == {"1001": "sending"}
    _session, result = peer.wait_for(
        lambda: [c for c in peer.events_of("tsr_cancel") if c[0] == 8], WAIT, "TSR_CANCEL 8"
    )[0]
    assert result == sp.CANCEL_CANCELLED and peer.tsrs[8].state == "cancelled"
    ack = [f for f in peer.sent if f.msg_type == sp.TSR_CANCEL_ACK]
    assert ack[-1].body == sp.body_ack(8, sp.CANCEL_CANCELLED)
    ground.poll(lambda: ground.train(1001)["tsrs"].get("8") == "CANCELLED", "TSR 8 CANCELLED")
    text = ground.cli("status")
    assert text.returncode == 0 and "TSR 8: CANCELLED" in text.stdout


def test_tsr_set_resent_until_acknowledged(ground: Ground, peer: sp.OnboardPeer) -> None:
    before = ground.status()["counters"]
    with peer.lock:
        peer.lose[sp.TSR_SET_ACK] = 1  # the first acknowledgement is lost on the way
    answer = ground.admin(
        {
            "op": "tsr_set",
            "trains": [1001],
            "session": 9,
            "start_km": 140.0,
            "end_km": 141.0,
            "limit_kmh": 60,
            "valid_until_min": 10,
            "reason": "interop",
        }
    )
    assert answer["ok"], answer
    # 8.3: resent every resend_interval_s (2 s) while not acknowledged
    copies = peer.wait_for(lambda: len(_tsr_sets(peer, 9)) >= 2 and _tsr_sets(peer, 9), WAIT, "")
    assert copies[0][0] == copies[1][0]  # same content
    assert [r for _, r in copies[:2]] == [sp.TSR_APPLIED, sp.TSR_APPLIED]  # idempotent
    ground.poll(lambda: ground.train(1001)["tsrs"].get("9") == "ACTIVE", "TSR 9 ACTIVE")
    after = ground.poll(
        lambda: (c := ground.status()["counters"])["sequence_gaps"] > before["sequence_gaps"] and c,
        "gap counted",
    )
    assert delta(before, after, "resends") >= 1
    assert delta(before, after, "frames_lost") >= 1  # 5.1: the lost ack is a gap of 1


def _heartbeats(peer: sp.OnboardPeer) -> int:
    with peer.lock:
        return sum(1 for f in peer.received if f.msg_type == sp.HEARTBEAT)


VALID = ("--valid-until-min", "10", "--reason", "interop")


def test_tsr_session_reuse_for_other_restriction_refused(
    ground: Ground, peer: sp.OnboardPeer
) -> None:
    common = ["--train", "1001", "--session", "10", "--start-km", "150", "--end-km", "151"]
    r = ground.cli("tsr", "set", *common, "--limit-kmh", "40", *VALID)
    assert r.returncode == 0, r.stderr
    peer.wait_for(lambda: _tsr_sets(peer, 10), WAIT, "TSR_SET 10")
    r = ground.cli("tsr", "set", *common, "--limit-kmh", "50", *VALID)
    assert r.returncode == 2  # link-operations.md: refused for a train
    assert "error" in (r.stdout + r.stderr)
    # a delivery would leave at once, before the ground's next heartbeats: after two more
    # of them, nothing of the refused TSR can still be on its way
    beats = _heartbeats(peer)
    peer.wait_for(lambda: _heartbeats(peer) >= beats + 2, WAIT, "two more ground heartbeats")
    assert {t.limit_cms for t, _ in _tsr_sets(peer, 10)} == {round(40 / 3.6 * 100)}


# ---------------------------------------------------------------------------------------------
# Receive checks of the ground (5.4): rejected frames are silent and the link stays up


def test_bad_frames_are_rejected_silently_and_link_stays_up(ground: Ground) -> None:
    p = make_peer(ground, 1002, train_number="K2002", loco_number="HXD1-002")
    p.set_running(sp.DIR_DOWN, 1000, 50_000_000)
    p.connect()
    try:
        p.wait_for(lambda: p.state == "REGISTERED", WAIT, "registration")
        before = ground.status()["counters"]
        with p.lock:
            # (a) repetition of the last frame written
            p.send_raw(p.wire_log[-1])
            # (b) MAC made with another key
            p.send_raw(p.build(sp.HEARTBEAT, b"", key=bytes(32)))
            # (c) AUTH clear while authentication is required
            p.send_raw(p.build(sp.HEARTBEAT, b"", key=None, key_id=0))
            # (d) CRC corrupted
            f = sp.encode_unstuffed(sp.HEARTBEAT, b"", **_kwargs(p))
            p.send_raw(b"\x7e" + sp.stuff(f[:-1] + bytes([f[-1] ^ 1])))
            # (e) a frame addressed to another ground id
            p.send_raw(p.build(sp.HEARTBEAT, b"", destination=99))
            # (f) garbage between frames
            p.send_raw(b"\x00\x01\x02")
            # (g) an acknowledgement for a session never sent: a *state* rejection, which
            # consumes its sequence number (5.4), so the same number again is a repetition
            state_rej = p.build(sp.TSR_SET_ACK, sp.body_ack(777, sp.TSR_APPLIED))
            p.send_raw(state_rej)
            p.send_raw(p.build(sp.HEARTBEAT, b""))  # same sequence number as (g)
            p.tx_seq += 1
        after = ground.poll(
            lambda: (
                sum((c := ground.status()["counters"])["rejected"].values())
                >= sum(before["rejected"].values()) + 7
                and c
            ),
            "7 rejections",
        )
        rej_b, rej_a = before["rejected"], after["rejected"]
        assert delta(rej_b, rej_a, "sequence") == 2
        assert delta(before, after, "repeats") == 2
        assert delta(rej_b, rej_a, "state") == 1
        assert delta(rej_b, rej_a, "auth") == 2
        assert delta(rej_b, rej_a, "crc") == 1
        assert delta(rej_b, rej_a, "destination") == 1
        assert delta(before, after, "bytes_discarded") >= 3
        # nothing answered on the wire, the link is still up, the train still registered
        n = p.stats.received.get("HEARTBEAT", 0)
        p.wait_for(lambda: p.stats.received.get("HEARTBEAT", 0) > n, WAIT, "heartbeat")
        assert p.stats.rejections == {} and p.state == "REGISTERED"
        assert ground.train(1002)["registered"] and ground.train(1002)["connected"]
        assert ground.train(1002)["running_info"]["direction"] == "DOWN"
    finally:
        p.close()


def _kwargs(p: sp.OnboardPeer) -> dict[str, Any]:
    return p._frame_kwargs()


# ---------------------------------------------------------------------------------------------
# Reconnect (8.2): old connection closed, active TSR reconfirmed, old frames cannot be replayed


def test_reconnect_reconfirms_active_tsr_and_replay_is_rejected(ground: Ground) -> None:
    clock = sp.TxClock()  # one onboard unit: timestamps increase across its connections
    a = make_peer(ground, 1003, clock=clock, train_number="K3003", loco_number="HXD1-003")
    a.set_running(sp.DIR_UNKNOWN, 0, 20_000_000)
    a.connect()
    b = make_peer(ground, 1003, clock=clock, train_number="K3003", loco_number="HXD1-003")
    try:
        a.wait_for(lambda: a.state == "REGISTERED", WAIT, "registration A")
        answer = ground.admin(
            {
                "op": "tsr_set",
                "trains": [1003],
                "session": 30,
                "start_km": 200.0,
                "end_km": 201.0,
                "limit_kmh": 20,
                "valid_until_min": 10,
                "reason": "interop",
            }
        )
        assert answer["ok"], answer
        a.wait_for(lambda: _tsr_sets(a, 30), WAIT, "TSR 30 on A")
        assert a.tsrs[30].zone_cm == (20_000_000 - 60_000, 20_100_000 + 60_000)  # unknown
        ground.poll(lambda: ground.train(1003)["tsrs"].get("30") == "ACTIVE", "TSR 30 ACTIVE")
        first_wire = a.wire_log[0]  # A's opening HEARTBEAT, sequence 0 (6.16)

        # a restarted onboard unit (no TSR memory) registers on a new connection
        b.set_running(sp.DIR_UNKNOWN, 0, 20_000_000)
        b.connect()
        b.wait_for(lambda: b.state == "REGISTERED", WAIT, "registration B")
        a.wait_for(lambda: a.state == "DISCONNECTED", WAIT, "old connection closed")
        (tsr, result), *_ = b.wait_for(lambda: _tsr_sets(b, 30), WAIT, "TSR 30 reconfirmed")
        assert result == sp.TSR_APPLIED and tsr == a.tsrs[30].tsr
        ground.poll(lambda: ground.train(1003)["registrations"] == 2, "2 registrations")
        ground.poll(lambda: ground.train(1003)["tsrs"].get("30") == "ACTIVE", "reconfirmed")
        # 5.1: the new connection numbers from 0 again; 5.2: the ground's timestamps to this
        # train keep increasing across connections (they interleave while both are open: the
        # ground answers B's opening HEARTBEAT before B registers and A is closed)
        with b.lock:
            b_frames = list(b.received)
        assert [f.seq for f in b_frames] == list(range(len(b_frames)))
        registered_at = next(f.timestamp_us for f in b_frames if f.msg_type == sp.REGISTER_RESPONSE)
        assert registered_at > max(f.timestamp_us for f in a.received)
        assert not {f.timestamp_us for f in b_frames} & {f.timestamp_us for f in a.received}

        # replay A's first frame on a fresh connection: sequence 0 is fine there, the
        # per-type timestamp kept across connections (5.2) is not
        before = ground.status()["counters"]
        with socket.create_connection(("127.0.0.1", ground.port), timeout=WAIT) as s:
            s.sendall(first_wire)
            ground.poll(
                lambda: (
                    delta(
                        before["rejected"],
                        (c := ground.status()["counters"])["rejected"],
                        "timestamp",
                    )
                    == 1
                    and c
                ),
                "timestamp rejection",
            )
            readable, _, _ = select.select([s], [], [], 1.2)
            assert not readable  # no answer at all (5.4), not even a heartbeat
        assert ground.train(1003)["registrations"] == 2
        assert b.stats.rejections == {} and a.stats.rejections == {}
    finally:
        b.close()
        a.close()


# ---------------------------------------------------------------------------------------------
# Deregistration (8.1, 8.2) and periodic timeout (7)


def _deregistered_peer(ground: Ground, train_id: int) -> sp.OnboardPeer:
    p = make_peer(ground, train_id, train_number=f"K{train_id}", loco_number="HXD1-004")
    p.set_running(sp.DIR_UP, 500, 30_000_000)
    p.connect()
    p.wait_for(lambda: p.state == "REGISTERED", WAIT, "registration")
    ground.poll(lambda: ground.train(train_id).get("running_info"), "running info")
    p.deregister(sp.DEREG_MANUAL_SHUTDOWN)
    assert p.wait_for(lambda: list(p.events_of("deregistered")), WAIT, "DEREG") == [0]
    ground.poll(lambda: not ground.train(train_id)["registered"], "deregistered")
    return p


def test_deregistration_keeps_link_and_allows_registering_again(ground: Ground) -> None:
    p = _deregistered_peer(ground, 1004)
    try:
        assert p.state == "DEREGISTERED"
        # 8.2: DEREGISTERED keeps the connection: HEARTBEAT both ways, no RUNNING_INFO
        n = p.stats.received.get("HEARTBEAT", 0)
        p.wait_for(lambda: p.stats.received.get("HEARTBEAT", 0) >= n + 2, WAIT, "heartbeats")
        # 8.1/8.2: DEREGISTERED + REGISTER_REQUEST -> REGISTERED on the same connection
        p.register()
        p.wait_for(lambda: p.state == "REGISTERED", WAIT, "registration again")
        train = ground.poll(lambda: (t := ground.train(1004))["registered"] and t, "registered")
        assert train["registrations"] == 2
        assert p.stats.rejections == {}
    finally:
        p.close()


def test_status_connected_while_deregistered_link_is_up(ground: Ground) -> None:
    p = _deregistered_peer(ground, 1006)
    try:
        n = p.stats.received.get("HEARTBEAT", 0)
        p.wait_for(lambda: p.stats.received.get("HEARTBEAT", 0) > n, WAIT, "heartbeat")
        assert p.state == "DEREGISTERED"  # the link is demonstrably up
        # link-operations.md: connected = the socket is open; state = 8.2 ground state
        train = ground.train(1006)
        assert train["connected"] is True and train["state"] == "DEREGISTERED"
        assert train["registered"] is False
        # the last position is kept but no longer valid: the train is not managed
        assert train["running_info"]["valid"] is False
        assert train["running_info"]["timed_out"] is False
    finally:
        p.close()
    train = ground.poll(lambda: (t := ground.train(1006)) and not t["connected"] and t, "closed")
    assert train["state"] is None


def test_periodic_timeout_closes_link_and_invalidates_running_info(ground: Ground) -> None:
    p = make_peer(ground, 1005, train_number="K5005", loco_number="HXD1-005")
    p.set_running(sp.DIR_DOWN, 700, 40_000_000)
    p.connect()
    try:
        p.wait_for(lambda: p.state == "REGISTERED", WAIT, "registration")
        ground.poll(
            lambda: (ground.train(1005).get("running_info") or {}).get("valid"), "valid info"
        )
        before = ground.status()["counters"]
        with p.lock:
            p.paused = True  # the onboard hangs: no HEARTBEAT, no RUNNING_INFO
        # 7: the ground times the link out and closes it (that it waits exactly
        # timeout_cycles whole cycles is tested on a fake clock: tests/link/test_ground.py,
        # test_running_info_is_held_between_cycles_then_invalid_after_timeout)
        p.wait_for(lambda: p.state == "DISCONNECTED", WAIT, "ground closes the link")
        train = ground.poll(lambda: (t := ground.train(1005)) and not t["connected"] and t, "")
        assert train["running_info"]["valid"] is False
        assert train["running_info"]["timed_out"] is True
        after = ground.status()["counters"]
        assert delta(before, after, "timeouts") >= 1
        assert delta(before, after, "link_failures") == 1
    finally:
        p.close()


# ---------------------------------------------------------------------------------------------
# Operator interfaces: key-file permissions, admin error format


def test_key_file_readable_by_others_is_refused(tmp_path: Path) -> None:
    keys = tmp_path / "keys.toml"
    keys.write_text(f'[[train]]\nid = 1001\nactive_key = 1\n[train.keys]\n1 = "{KEY.hex()}"\n')
    os.chmod(keys, 0o644)
    r = subprocess.run(
        [
            str(RAILPILOT),
            "ground",
            "serve",
            "--port",
            "0",
            "--admin-port",
            "-1",
            "--keys",
            str(keys),
            "--seconds",
            "2",
        ],
        capture_output=True,
        text=True,
        timeout=WAIT,
    )
    assert r.returncode == 2
    assert str(keys) in r.stderr + r.stdout and "644" in r.stderr + r.stdout
    assert KEY.hex() not in r.stderr + r.stdout


def test_admin_error_format(ground: Ground) -> None:
    answer = ground.admin(
        {
            "op": "tsr_set",
            "trains": [1001],
            "session": 0,
            "start_km": 1,
            "end_km": 2,
            "limit_kmh": 10,
            "valid_until_min": 1,
            "reason": "interop",
        }
    )
    assert answer["ok"] is False
    assert re.fullmatch(r"session: 0 is not allowed: expected .+", answer["error"]), answer
