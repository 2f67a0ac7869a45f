"""Every receive-side check rejects a bad frame with its own typed event and counts it.

Each test damages exactly one aspect of one running-info frame on the uplink (the MAC and
CRC recomputed where needed, so only the targeted check can notice) and shows: the typed
rejection event, the per-check counter, and that the damaged content never reached the
application.
"""

from __future__ import annotations

import pytest

from railpilot.link import (
    AuthRejected,
    BodyRejected,
    Check,
    CrcRejected,
    DelayRejected,
    DestinationRejected,
    FrameRejected,
    FramingRejected,
    LengthRejected,
    MessageReceived,
    RunningInfo,
    SequenceGap,
    SequenceRejected,
    SourceRejected,
    StateRejected,
    TimestampRejected,
    TsrSet,
    TypeRejected,
    VersionRejected,
    encode_body,
)
from railpilot.link.messages import MessageType

from .helpers import (
    KEY_1,
    KEY_2,
    OTHER_TRAIN_ID,
    OTHER_TRAIN_KEY,
    FakeLink,
    OnceFilter,
    header_of,
    registered_link,
    rewrite,
    running_info,
    unstuff,
)

RUNNING_INFO = MessageType.RUNNING_INFO


def run_with_uplink_damage(action, nth: int = 1) -> FakeLink:  # type: ignore[no-untyped-def]
    """Registered link sending running info at 1 km steps; damage the ``nth`` frame."""
    link = registered_link()
    link.uplink = OnceFilter(RUNNING_INFO, action, nth=nth)
    for km in range(1, 6):
        link.onboard.update_running_info(running_info(km * 1000.0))
        link.run(1.0)
    return link


def delivered_positions(link: FakeLink) -> list[float]:
    return [
        e.message.position_m
        for e in link.ground_events
        if isinstance(e, MessageReceived) and isinstance(e.message, RunningInfo)
    ]


def assert_rejected_once(link: FakeLink, event_type: type[FrameRejected], check: Check) -> None:
    rejections = [e for e in link.ground_events if isinstance(e, FrameRejected)]
    assert [type(e) for e in rejections] == [event_type]
    assert rejections[0].check is check
    assert link.ground.counters.rejected == {check: 1}


def test_undamaged_run_delivers_every_position_in_order() -> None:
    link = run_with_uplink_damage(lambda w: [w])
    assert delivered_positions(link) == [1000.0, 2000.0, 3000.0, 4000.0, 5000.0]
    assert not [e for e in link.ground_events if isinstance(e, FrameRejected)]


def test_crc_check_rejects_a_flipped_bit() -> None:
    def flip(wire: bytes) -> list[bytes]:
        damaged = bytearray(wire)
        damaged[30] ^= 0x10
        return [bytes(damaged)]

    link = run_with_uplink_damage(flip)
    assert_rejected_once(link, CrcRejected, Check.CRC)
    assert 2000.0 not in delivered_positions(link)


def test_length_check_rejects_a_body_too_short_for_its_type() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, body=header_of(w).body[:-1])])
    assert_rejected_once(link, LengthRejected, Check.LENGTH)
    assert 2000.0 not in delivered_positions(link)


def test_version_check_rejects_version_two() -> None:
    link = run_with_uplink_damage(lambda w: [w[:1] + b"\x02" + w[2:]])
    assert_rejected_once(link, VersionRejected, Check.VERSION)
    assert 2000.0 not in delivered_positions(link)


def test_framing_check_rejects_a_frame_cut_short_by_a_header_byte() -> None:
    link = run_with_uplink_damage(lambda w: [w[: len(w) // 2]])
    assert_rejected_once(link, FramingRejected, Check.FRAMING)
    assert 2000.0 not in delivered_positions(link)


def test_type_check_rejects_a_downlink_type_sent_uplink() -> None:
    tsr = TsrSet(1, 0.0, 10.0, 5.0, 0.0, 1.0)
    link = run_with_uplink_damage(
        lambda w: [rewrite(w, message_type=MessageType.TSR_SET, body=encode_body(tsr))]
    )
    assert_rejected_once(link, TypeRejected, Check.TYPE)


def test_type_check_rejects_an_unknown_type() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, message_type=0x99)])
    assert_rejected_once(link, TypeRejected, Check.TYPE)


def test_destination_check_rejects_a_frame_for_another_device() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, destination_id=999)])
    assert_rejected_once(link, DestinationRejected, Check.DESTINATION)
    assert 2000.0 not in delivered_positions(link)


def test_source_check_rejects_another_train_on_this_connection() -> None:
    link = run_with_uplink_damage(
        lambda w: [rewrite(w, key=OTHER_TRAIN_KEY, source_id=OTHER_TRAIN_ID)]
    )
    assert_rejected_once(link, SourceRejected, Check.SOURCE)
    assert 2000.0 not in delivered_positions(link)


def test_auth_check_rejects_a_frame_without_mac() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, key=None)])
    assert_rejected_once(link, AuthRejected, Check.AUTH)
    assert 2000.0 not in delivered_positions(link)


def test_auth_check_rejects_a_mac_under_the_wrong_key() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, key=KEY_2)])
    assert_rejected_once(link, AuthRejected, Check.AUTH)


def test_auth_check_rejects_an_unknown_key_id() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, key=KEY_1, key_id=9)])
    assert_rejected_once(link, AuthRejected, Check.AUTH)


def test_body_check_rejects_a_speed_beyond_range() -> None:
    def too_fast(wire: bytes) -> list[bytes]:
        body = bytearray(header_of(wire).body)
        body[21:23] = (10_001).to_bytes(2, "big")
        return [rewrite(wire, body=bytes(body))]

    link = run_with_uplink_damage(too_fast)
    assert_rejected_once(link, BodyRejected, Check.BODY)
    assert 2000.0 not in delivered_positions(link)


def test_sequence_check_rejects_a_repeated_frame_and_counts_a_repetition() -> None:
    link = run_with_uplink_damage(lambda w: [w, w])
    assert_rejected_once(link, SequenceRejected, Check.SEQUENCE)
    assert link.ground.counters.repeats == 1
    assert delivered_positions(link).count(2000.0) == 1


def test_sequence_gap_is_accepted_counted_and_reported() -> None:
    link = run_with_uplink_damage(lambda w: [])
    gaps = [e for e in link.ground_events if isinstance(e, SequenceGap)]
    assert [g.lost for g in gaps] == [1]
    assert link.ground.counters.frames_lost == 1
    assert delivered_positions(link) == [1000.0, 3000.0, 4000.0, 5000.0]


def test_timestamp_check_rejects_a_running_info_not_newer_than_the_last() -> None:
    first_timestamp: list[int] = []

    def remember(wire: bytes) -> list[bytes]:
        first_timestamp.append(header_of(wire).timestamp_us)
        return [wire]

    link = registered_link()
    link.uplink = OnceFilter(RUNNING_INFO, remember, nth=0)
    link.onboard.update_running_info(running_info(1000.0))
    link.run(1.0)
    link.uplink = OnceFilter(
        RUNNING_INFO, lambda w: [rewrite(w, timestamp_us=first_timestamp[0])], nth=0
    )
    link.onboard.update_running_info(running_info(2000.0))
    link.run(1.0)
    assert_rejected_once(link, TimestampRejected, Check.TIMESTAMP)
    assert 2000.0 not in delivered_positions(link)


def test_delay_check_rejects_an_echo_older_than_the_round_trip_bound() -> None:
    def stale_echo(wire: bytes) -> list[bytes]:
        frame = header_of(wire)
        return [rewrite(wire, echo_timestamp_us=frame.echo_timestamp_us - 5_000_000)]

    link = run_with_uplink_damage(stale_echo)
    assert_rejected_once(link, DelayRejected, Check.DELAY)
    assert 2000.0 not in delivered_positions(link)


def test_delay_check_rejects_an_echo_the_receiver_never_sent() -> None:
    def future_echo(wire: bytes) -> list[bytes]:
        frame = header_of(wire)
        return [rewrite(wire, echo_timestamp_us=frame.timestamp_us + 60_000_000)]

    link = run_with_uplink_damage(future_echo)
    assert_rejected_once(link, DelayRejected, Check.DELAY)


def test_state_check_rejects_data_before_registration() -> None:
    link = FakeLink()
    info_body = encode_body(running_info(7000.0))
    link.uplink = OnceFilter(
        MessageType.REGISTER_REQUEST,
        lambda w: [rewrite(w, message_type=RUNNING_INFO, body=info_body)],
    )
    link.connect()
    link.step()
    rejections = [e for e in link.ground_events if isinstance(e, FrameRejected)]
    assert [type(e) for e in rejections] == [StateRejected]
    assert 7000.0 not in delivered_positions(link)


@pytest.mark.parametrize("check", list(Check))
def test_every_check_has_a_rejection_event_and_an_error_class(check: Check) -> None:
    from railpilot.link.errors import FRAME_ERROR_BY_CHECK
    from railpilot.link.events import REJECTION_BY_CHECK

    assert REJECTION_BY_CHECK[check].check is check
    assert FRAME_ERROR_BY_CHECK[check].check is check


def test_rejection_event_carries_the_claimed_header_fields() -> None:
    link = run_with_uplink_damage(lambda w: [rewrite(w, destination_id=999)])
    [rejection] = [e for e in link.ground_events if isinstance(e, FrameRejected)]
    assert rejection.message_type == RUNNING_INFO
    assert rejection.source_id == 1001


def test_unstuff_helper_is_the_inverse_used_by_the_surgery() -> None:
    # Guards the helpers: a rewrite without changes reproduces the frame exactly.
    link = registered_link()
    wire = link.onboard._channel.encode(running_info(1.0), link.now_s)
    assert rewrite(wire) == wire
    assert unstuff(wire[1:])[0] == 1
