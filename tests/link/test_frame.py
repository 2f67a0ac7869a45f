"""Frame header, CRC-32 and MAC: each frame-level check rejects with its typed error."""

from __future__ import annotations

import struct
import zlib

import pytest

from railpilot.link import (
    AuthenticationError,
    CrcError,
    LengthError,
    TypeCheckError,
    VersionError,
    parse_frame,
    unstuff,
    verify_mac,
)
from railpilot.link.codec import encode_body
from railpilot.link.frame import compute_mac, encode_frame, hmac_sha256
from railpilot.link.messages import RunningInfo, TravelDirection

from .helpers import GROUND_ID, KEY_1, KEY_2, TRAIN_ID

INFO = RunningInfo(42, "K1234", "SS4-0123", TravelDirection.UP, 22.22, 123_456.78)


def raw_frame(key: bytes | None = None, body: bytes | None = None, mtype: int = 0x20) -> bytes:
    wire = encode_frame(
        mtype,
        TRAIN_ID,
        GROUND_ID,
        7,
        1_700_000_000_000_000,
        0,
        encode_body(INFO) if body is None else body,
        1 if key else 0,
        key,
    )
    return unstuff(wire[1:])


def with_crc(frame: bytes) -> bytes:
    """Recompute the CRC after tampering, as an attacker would."""
    body = frame[:-4]
    return body + struct.pack(">I", zlib.crc32(body))


def reference_crc32(data: bytes) -> int:
    """Bit-by-bit CRC-32/ISO-HDLC, written from its parameters, to cross-check zlib."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)  # 0x04C11DB7 reflected
    return crc ^ 0xFFFFFFFF


def test_crc_parameters_give_the_standard_check_value() -> None:
    assert reference_crc32(b"123456789") == 0xCBF43926


def test_frame_crc_matches_the_reference_crc_over_all_bytes_before_it() -> None:
    frame = raw_frame(KEY_1)
    assert int.from_bytes(frame[-4:], "big") == reference_crc32(frame[:-4])


def test_parse_returns_the_encoded_header_fields() -> None:
    frame = parse_frame(raw_frame())
    assert (frame.message_type, frame.source_id, frame.destination_id, frame.sequence) == (
        0x20,
        TRAIN_ID,
        GROUND_ID,
        7,
    )
    assert frame.body == encode_body(INFO)
    assert frame.mac is None


def test_flipped_bit_fails_crc() -> None:
    frame = bytearray(raw_frame())
    frame[40] ^= 0x04
    with pytest.raises(CrcError):
        parse_frame(bytes(frame))


def test_length_field_disagreeing_with_frame_size_fails_length() -> None:
    frame = bytearray(raw_frame())
    frame[2:4] = (len(frame) + 1).to_bytes(2, "big")
    with pytest.raises(LengthError):
        parse_frame(with_crc(bytes(frame)))


def test_reserved_flag_bit_fails_version() -> None:
    frame = bytearray(raw_frame())
    frame[1] |= 0x80
    with pytest.raises(VersionError):
        parse_frame(with_crc(bytes(frame)))


def test_unknown_message_type_fails_type() -> None:
    frame = bytearray(raw_frame())
    frame[4] = 0x99
    with pytest.raises(TypeCheckError):
        parse_frame(with_crc(bytes(frame)))


def test_body_length_wrong_for_the_type_fails_length() -> None:
    with pytest.raises(LengthError, match="RUNNING_INFO"):
        parse_frame(raw_frame(body=encode_body(INFO)[:-1]))


def test_key_id_without_auth_flag_fails_auth() -> None:
    frame = bytearray(raw_frame())
    frame[5:7] = (3).to_bytes(2, "big")
    with pytest.raises(AuthenticationError):
        parse_frame(with_crc(bytes(frame)))


def test_mac_is_truncated_hmac_sha256_over_everything_before_it() -> None:
    import hashlib
    import hmac

    frame = raw_frame(KEY_1)
    expected = hmac.new(KEY_1, frame[:-20], hashlib.sha256).digest()[:16]
    assert frame[-20:-4] == expected == compute_mac(KEY_1, frame)


@pytest.mark.parametrize("key_length", [0, 1, 16, 32, 63, 64, 65, 200])
def test_hmac_with_kept_pad_states_is_the_standard_library_s(key_length: int) -> None:
    import hmac
    import random

    draw = random.Random(key_length)
    key = draw.randbytes(key_length)
    for data_length in (0, 1, 55, 56, 64, 100, 1000):
        data = draw.randbytes(data_length)
        # twice: the kept pad states must not change with use
        for _ in range(2):
            assert hmac_sha256(key, data) == hmac.digest(key, data, "sha256")


def test_mac_verifies_under_the_right_key() -> None:
    frame = raw_frame(KEY_1)
    verify_mac(KEY_1, frame, parse_frame(frame))


def test_mac_fails_under_another_key() -> None:
    frame = raw_frame(KEY_1)
    with pytest.raises(AuthenticationError):
        verify_mac(KEY_2, frame, parse_frame(frame))


def test_tampered_body_with_recomputed_crc_fails_mac() -> None:
    frame = bytearray(raw_frame(KEY_1))
    frame[40] ^= 0x01
    tampered = with_crc(bytes(frame))
    with pytest.raises(AuthenticationError):
        verify_mac(KEY_1, tampered, parse_frame(tampered))


def test_encoding_refuses_a_key_id_without_a_key() -> None:
    with pytest.raises(ValueError, match="key_id"):
        encode_frame(0x50, 1, 2, 0, 1, 0, b"", key_id=1, key=None)
