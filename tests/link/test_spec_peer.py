"""An onboard peer written from docs/protocol.md alone talks to our ground endpoint.

The peer below uses only ``struct``, ``zlib`` and ``hmac`` and the layouts of the
specification (sections 3, 4, 5.3, 6.1, 6.2, 6.7, 6.16) - no railpilot encoding code - so a drift
between the specification and the implementation shows up here as a failed handshake.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import zlib

from railpilot.link import (
    GroundEndpoint,
    MessageReceived,
    RunningInfo,
    TrainRegistered,
    TravelDirection,
)

from .helpers import GROUND_ID, KEY_1, T0, TRAIN_ID, ground_config, make_keys


class SpecPeer:
    """Minimal onboard side per the specification: send frames, parse frames."""

    def __init__(self) -> None:
        self.sequence = 0
        self.timestamp_us = int(T0 * 1e6)
        self.echo_us = 0

    def frame(self, message_type: int, body: bytes) -> bytes:
        self.timestamp_us += 1000
        length = 35 + len(body) + 16 + 4
        head = struct.pack(
            ">BBHBHIIIQQ",
            1,  # version
            0x01,  # flags: AUTH
            length,
            message_type,
            1,  # key id
            TRAIN_ID,
            GROUND_ID,
            self.sequence,
            self.timestamp_us,
            self.echo_us,
        )
        self.sequence += 1
        unsigned = head + body
        unsigned += hmac.new(KEY_1, unsigned, hashlib.sha256).digest()[:16]
        unsigned += struct.pack(">I", zlib.crc32(unsigned))
        return b"\x7e" + unsigned.replace(b"\x7e", b"\x7e\x7e")

    def parse(self, wire: bytes) -> list[tuple[int, bytes]]:
        """Split a byte stream into (type, body) pairs, verifying CRC and MAC."""
        out = []
        i = 0
        while i < len(wire):
            assert wire[i] == 0x7E
            j, raw = i + 1, bytearray()
            while True:  # unstuff until a lone 0x7E (next frame) or the end
                if j == len(wire) or (wire[j] == 0x7E and wire[j + 1 : j + 2] != b"\x7e"):
                    break
                raw.append(wire[j])
                j += 2 if wire[j] == 0x7E else 1
            version, flags, length, mtype = struct.unpack_from(">BBHB", raw)
            assert (version, flags, length) == (1, 0x01, len(raw))  # authenticated
            assert struct.unpack_from(">I", raw, length - 4)[0] == zlib.crc32(raw[:-4])
            mac = raw[-20:-4]
            assert hmac.compare_digest(
                mac, hmac.new(KEY_1, bytes(raw[:-20]), hashlib.sha256).digest()[:16]
            )
            self.echo_us = max(self.echo_us, struct.unpack_from(">Q", raw, 19)[0])
            out.append((mtype, bytes(raw[35:-20])))
            i = j
        return out


def test_a_peer_built_from_the_specification_registers_and_reports_running_info() -> None:
    peer = SpecPeer()
    ground = GroundEndpoint(ground_config(), make_keys())
    ground.connection_made(T0)

    # 6.16: a HEARTBEAT with echo 0 opens the connection; the ground answers with its own
    ground.receive_data(peer.frame(0x50, b""), T0)
    assert peer.parse(ground.data_to_send()) == [(0x50, b"")]
    # 5.3: the REGISTER_REQUEST echoes that ground timestamp
    register = struct.pack(">8s8sII", b"K1234", b"SS4-0123", 42, 260_000)  # 6.1
    ground.receive_data(peer.frame(0x01, register), T0)
    answers = peer.parse(ground.data_to_send())
    assert (0x02, b"\x00") in answers  # 6.2 REGISTER_RESPONSE ACCEPTED

    info = struct.pack(">I8s8sBHI", 42, b"K1234", b"SS4-0123", 1, 2222, 12_345_678)  # 6.7
    ground.receive_data(peer.frame(0x20, info), T0 + 0.01)
    events = list(ground.events())
    assert any(isinstance(e, TrainRegistered) for e in events)
    [received] = [e for e in events if isinstance(e, MessageReceived)]
    assert received.message == RunningInfo(
        42, "K1234", "SS4-0123", TravelDirection.UP, 22.22, 123_456.78
    )
