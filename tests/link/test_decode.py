"""The stateless decoder behind ``railpilot link decode``: a verdict per check."""

from __future__ import annotations

from railpilot.link import Check, KeyStore, decode_stream, encode_body, encode_frame
from railpilot.link.messages import StationStop, StationStops

from .helpers import GROUND_ID, KEY_1, KEY_2, TRAIN_ID, running_info

INFO = running_info(123_456.78)


def wire(key: bytes | None = KEY_1) -> bytes:
    return encode_frame(
        INFO.TYPE,
        TRAIN_ID,
        GROUND_ID,
        3,
        1_700_000_000_000_000,
        0,
        encode_body(INFO),
        1 if key else 0,
        key,
    )


def keys() -> KeyStore:
    store = KeyStore()
    store.add_key(TRAIN_ID, 1, KEY_1)
    return store


def test_good_authenticated_frame_passes_and_decodes() -> None:
    [report] = decode_stream(wire(), keys())
    assert report.ok
    assert report.message == INFO
    assert report.verdict(Check.AUTH).ok is True  # type: ignore[union-attr]
    assert report.verdict(Check.SEQUENCE).ok is None  # type: ignore[union-attr]


def test_auth_is_skipped_without_a_key_store() -> None:
    [report] = decode_stream(wire())
    assert report.verdict(Check.AUTH).ok is None  # type: ignore[union-attr]
    assert report.ok


def test_wrong_key_fails_auth_and_withholds_the_message() -> None:
    store = KeyStore()
    store.add_key(TRAIN_ID, 1, KEY_2)
    [report] = decode_stream(wire(), store)
    assert report.verdict(Check.AUTH).ok is False  # type: ignore[union-attr]
    assert report.message is None
    assert report.frame is not None and report.frame.source_id == TRAIN_ID


def test_crc_failure_still_shows_the_header_fields() -> None:
    damaged = bytearray(wire(None))
    damaged[40] ^= 0x01
    [report] = decode_stream(bytes(damaged))
    assert report.verdict(Check.CRC).ok is False  # type: ignore[union-attr]
    assert report.frame is not None and report.frame.sequence == 3
    assert report.message is None


def test_truncated_frame_is_reported_as_a_framing_problem() -> None:
    good = wire(None)
    reports = list(decode_stream(good[:30] + good))
    assert reports[0].verdicts[0].check is Check.FRAMING and reports[0].verdicts[0].ok is False
    assert reports[1].ok


def test_expected_addresses_are_checked_when_given() -> None:
    [report] = decode_stream(wire(None), expect_source=TRAIN_ID, expect_destination=99)
    assert report.verdict(Check.SOURCE).ok is True  # type: ignore[union-attr]
    assert report.verdict(Check.DESTINATION).ok is False  # type: ignore[union-attr]


def test_pure_garbage_gives_no_reports() -> None:
    assert list(decode_stream(b"\x00\x01\x02 no frames here \x7e\x7e")) == []


def test_list_count_disagreeing_with_the_body_is_a_length_failure() -> None:
    # spec 5.4 #13: a list count that does not match the body length is a length check
    stops = StationStops((StationStop(7, 1000.0, 30.0), StationStop(8, 2000.0, 45.0)))
    body = bytearray(encode_body(stops))
    body[0] += 1  # claim one stop more than the body carries
    raw = encode_frame(stops.TYPE, GROUND_ID, TRAIN_ID, 1, 1_700_000_000_000_000, 0, bytes(body))
    [report] = decode_stream(raw)
    assert report.verdict(Check.LENGTH).ok is False  # type: ignore[union-attr]
    assert report.message is None
