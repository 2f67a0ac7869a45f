"""The stateless decoder behind ``railpilot link decode``: a verdict per check."""

from __future__ import annotations

import pytest

from railpilot.link import Check, KeyStore, Verdict, decode_stream, encode_body, encode_frame
from railpilot.link.messages import Heartbeat, StationStop, StationStops, TsrCancel

from .helpers import GROUND_ID, KEY_1, KEY_2, OTHER_TRAIN_ID, TRAIN_ID, running_info

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


# --- a frame cut off by the end of the input ------------------------------------------------


def test_a_frame_cut_off_by_the_end_of_the_input_is_the_last_report() -> None:
    good = wire(None)
    *frames, last = decode_stream(good + good[:50])
    assert [r.ok for r in frames] == [True]
    assert last.truncated and not last.ok and last.raw is None and last.frame is None
    [verdict] = last.verdicts
    assert verdict.check is Check.FRAMING and verdict.ok is False
    assert verdict.detail == f"truncated: input ends after 49 of {len(good) - 1} bytes"


def test_a_cut_before_the_length_field_says_so() -> None:
    [report] = decode_stream(wire(None)[:3])
    assert report.truncated
    assert (
        report.verdicts[0].detail == "truncated: input ends after 2 bytes, before the length field"
    )


def test_a_complete_input_has_no_truncated_report() -> None:
    assert not any(r.truncated for r in decode_stream(wire() + b"\x00trailing garbage"))


def test_frames_across_the_decoders_feed_slices_decode_as_when_fed_alone() -> None:
    # 300 frames of 86..87 bytes: many straddle the 4096-byte slices decode_stream feeds.
    wires = [
        encode_frame(
            INFO.TYPE, TRAIN_ID, GROUND_ID, s, 1_700_000_000_000_000 + s, 0, encode_body(INFO)
        )
        for s in range(300)
    ]
    alone = [r for w in wires for r in decode_stream(w)]
    together = list(decode_stream(b"".join(wires)))
    assert together == alone and len(together) == 300 and all(r.ok for r in together)


# --- whose key verifies a HEARTBEAT (allowed in both directions) ------------------------------


def heartbeat(source: int, destination: int, key: bytes = KEY_1) -> bytes:
    return encode_frame(
        Heartbeat.TYPE, source, destination, 7, 1_700_000_000_000_000, 0, b"", 1, key
    )


@pytest.mark.parametrize(
    ("source", "destination"),
    [(TRAIN_ID, GROUND_ID), (GROUND_ID, TRAIN_ID)],
    ids=["uplink: train is the source", "downlink: train is the destination"],
)
def test_a_heartbeat_is_verified_with_the_key_of_whichever_end_is_the_train(
    source: int, destination: int
) -> None:
    [report] = decode_stream(heartbeat(source, destination), keys())
    auth = report.verdict(Check.AUTH)
    assert auth == Verdict(Check.AUTH, True, f"verified with key id 1 of train {TRAIN_ID}")
    assert report.ok and report.message == Heartbeat()


def test_a_heartbeat_tries_the_source_as_train_before_the_destination() -> None:
    # Both ends have key id 1 (not a well-formed key file): the source's key is the one used.
    store = keys()
    store.add_key(OTHER_TRAIN_ID, 1, KEY_2)
    [report] = decode_stream(heartbeat(OTHER_TRAIN_ID, TRAIN_ID, KEY_2), store)
    assert report.verdict(Check.AUTH) == Verdict(
        Check.AUTH, True, f"verified with key id 1 of train {OTHER_TRAIN_ID}"
    )
    [report] = decode_stream(heartbeat(OTHER_TRAIN_ID, TRAIN_ID, KEY_1), store)
    assert report.verdict(Check.AUTH) == Verdict(
        Check.AUTH, False, f"MAC does not match key id 1 of train {OTHER_TRAIN_ID}"
    )


def test_a_heartbeat_without_a_key_for_either_end_names_both() -> None:
    [report] = decode_stream(heartbeat(OTHER_TRAIN_ID, GROUND_ID), keys())
    assert report.verdict(Check.AUTH) == Verdict(
        Check.AUTH, False, f"no key id 1 for train {OTHER_TRAIN_ID} or {GROUND_ID}"
    )


def tsr_cancel(source: int, destination: int) -> bytes:
    body = encode_body(TsrCancel(5))
    return encode_frame(
        TsrCancel.TYPE, source, destination, 1, 1_700_000_000_000_000, 0, body, 1, KEY_1
    )


def test_a_downlink_frame_is_verified_with_the_destinations_key_only() -> None:
    [report] = decode_stream(tsr_cancel(GROUND_ID, TRAIN_ID), keys())
    assert report.verdict(Check.AUTH) == Verdict(
        Check.AUTH, True, f"verified with key id 1 of train {TRAIN_ID}"
    )
    # The same downlink type sent the wrong way: the destination (ground id) has no key, and
    # the source's key is not tried.
    [report] = decode_stream(tsr_cancel(TRAIN_ID, GROUND_ID), keys())
    assert report.verdict(Check.AUTH) == Verdict(
        Check.AUTH, False, f"no key id 1 for train {GROUND_ID}"
    )
