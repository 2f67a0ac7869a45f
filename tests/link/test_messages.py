"""Message catalogue: self-validation, body codec, and hypothesis round trips."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.link import (
    BodyError,
    LengthError,
    MessageFieldError,
    TypeCheckError,
    decode_body,
    encode_body,
)
from railpilot.link.codec import BODY_LENGTH, MAX_BODY_LENGTH
from railpilot.link.messages import (
    MESSAGE_CLASSES,
    DeregisterReason,
    DeregisterRequest,
    DeregisterResponse,
    DeregisterResult,
    DispatchAck,
    DispatchCommand,
    DispatchResult,
    Heartbeat,
    Message,
    MessageType,
    PlannedCurve,
    RegisterRequest,
    RegisterResponse,
    RegisterResult,
    RunningInfo,
    RunningTime,
    RunningTimes,
    StationStop,
    StationStops,
    TargetPoint,
    TargetPointAck,
    TargetPointResult,
    TargetReason,
    TimeCheck,
    TimeOffsetReport,
    TravelDirection,
    TsrCancel,
    TsrCancelAck,
    TsrCancelResult,
    TsrSet,
    TsrSetAck,
    TsrSetResult,
)

# --- self-validation -------------------------------------------------------------------------


def test_out_of_range_speed_names_message_field_value_and_range() -> None:
    with pytest.raises(MessageFieldError) as info:
        RunningInfo(1, "K1", "L1", TravelDirection.UP, 101.0, 0.0)
    assert info.value.field == "speed_mps"
    assert "RunningInfo.speed_mps = 101.0" in str(info.value)
    assert "[0.0, 100.0]" in str(info.value)


def test_message_field_error_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        TsrCancel(0)


def test_train_number_with_a_space_is_refused() -> None:
    with pytest.raises(MessageFieldError, match="train_number"):
        RunningInfo(1, "K 1", "L1", TravelDirection.UP, 1.0, 0.0)


def test_train_number_longer_than_eight_characters_is_refused() -> None:
    with pytest.raises(MessageFieldError, match="train_number"):
        RegisterRequest("K12345678", "L1", 1, 100.0)


def test_plain_int_where_an_enum_is_required_is_refused() -> None:
    with pytest.raises(MessageFieldError, match="direction"):
        RunningInfo(1, "K1", "L1", 1, 1.0, 0.0)  # type: ignore[arg-type]


def test_nan_position_is_refused() -> None:
    with pytest.raises(MessageFieldError, match="position_m"):
        TargetPoint(1, float("nan"), TargetReason.TRAIN_AHEAD)


def test_bool_is_not_an_id() -> None:
    with pytest.raises(MessageFieldError, match="session"):
        TsrCancel(True)


def test_dispatch_text_over_1000_utf8_bytes_is_refused() -> None:
    with pytest.raises(MessageFieldError, match="text"):
        DispatchCommand(1, "限" * 334)  # 1002 bytes of UTF-8


def test_messages_are_frozen() -> None:
    message = TsrCancel(5)
    with pytest.raises(AttributeError):
        message.session = 6  # type: ignore[misc]


# --- body decoding errors ------------------------------------------------------------------


def test_unknown_type_code_is_a_type_error() -> None:
    with pytest.raises(TypeCheckError, match="0x99"):
        decode_body(0x99, b"")


def test_wrong_fixed_body_length_is_a_length_error() -> None:
    with pytest.raises(LengthError):
        decode_body(MessageType.TSR_CANCEL, b"\x00\x00\x01")


def test_list_count_disagreeing_with_body_is_a_length_error() -> None:
    with pytest.raises(LengthError):
        decode_body(MessageType.STATION_STOPS, b"\x02" + bytes(10))


def test_dispatch_text_length_disagreeing_with_body_is_a_length_error() -> None:
    with pytest.raises(LengthError):
        decode_body(MessageType.DISPATCH_COMMAND, b"\x00\x00\x00\x01\x00\x05abc")


def test_invalid_utf8_is_a_body_error() -> None:
    with pytest.raises(BodyError):
        decode_body(MessageType.DISPATCH_COMMAND, b"\x00\x00\x00\x01\x00\x02\xff\xfe")


def test_unknown_enum_value_is_a_body_error() -> None:
    with pytest.raises(BodyError, match="direction"):
        decode_body(MessageType.RUNNING_INFO, bytearray(20) + b"\x09" + bytes(6))


def test_speed_over_the_range_on_the_wire_is_a_body_error() -> None:
    body = bytearray(encode_body(RunningInfo(1, "K1", "L1", TravelDirection.UP, 1.0, 0.0)))
    body[21:23] = (10_001).to_bytes(2, "big")
    with pytest.raises(BodyError, match="speed_mps"):
        decode_body(MessageType.RUNNING_INFO, bytes(body))


def test_nul_inside_an_identifier_is_a_body_error() -> None:
    body = bytearray(encode_body(RunningInfo(1, "K1", "L1", TravelDirection.UP, 1.0, 0.0)))
    body[4:12] = b"K\x001\x00\x00\x00\x00\x00"
    with pytest.raises(BodyError, match="train_number"):
        decode_body(MessageType.RUNNING_INFO, bytes(body))


def test_encoding_rounds_to_the_wire_resolution() -> None:
    info = RunningInfo(1, "K1", "L1", TravelDirection.UP, 12.345678, 1.004)
    decoded = decode_body(MessageType.RUNNING_INFO, encode_body(info))
    assert isinstance(decoded, RunningInfo)
    assert (decoded.speed_mps, decoded.position_m) == (12.35, 1.0)


def test_every_fixed_body_fits_the_largest_body() -> None:
    assert all(n is None or n <= MAX_BODY_LENGTH for n in BODY_LENGTH.values())
    assert set(BODY_LENGTH) == set(MessageType) == set(MESSAGE_CLASSES)


# --- hypothesis round trips: every message type ------------------------------------------

u32 = st.integers(0, 0xFFFF_FFFF)
nonzero_u32 = st.integers(1, 0xFFFF_FFFF)
cm = st.integers(0, 1_000_000_000).map(lambda v: v / 100)
cm_per_s = st.integers(0, 10_000).map(lambda v: v / 100)
ms = st.integers(0, 0xFFFF_FFFF).map(lambda v: v / 1000)
us = st.integers(0, 10**16).map(lambda v: v / 1e6)
ident = st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), min_size=1, max_size=8)


def enum_of(cls: type) -> st.SearchStrategy:  # type: ignore[type-arg]
    return st.sampled_from(list(cls))


MESSAGES: dict[MessageType, st.SearchStrategy] = {  # type: ignore[type-arg]
    MessageType.REGISTER_REQUEST: st.builds(
        RegisterRequest, ident, ident, u32, st.integers(0, 1_000_000).map(lambda v: v / 100)
    ),
    MessageType.REGISTER_RESPONSE: st.builds(RegisterResponse, enum_of(RegisterResult)),
    MessageType.DEREGISTER_REQUEST: st.builds(DeregisterRequest, enum_of(DeregisterReason)),
    MessageType.DEREGISTER_RESPONSE: st.builds(DeregisterResponse, enum_of(DeregisterResult)),
    MessageType.TIME_CHECK: st.builds(TimeCheck, us),
    # the offset is the difference of the two times (spec 6.6), so it is drawn as one; times
    # up to 4e15 us (year 2096): beyond 2^32 s a double no longer holds every us of an epoch
    # time, so the seconds of two such times can differ from their wire values by 1 us
    MessageType.TIME_OFFSET_REPORT: st.tuples(
        st.integers(0, 4 * 10**15), st.integers(-(10**12), 10**12)
    )
    .filter(lambda t: 0 <= t[0] + t[1] <= 4 * 10**15)
    .map(lambda t: TimeOffsetReport.from_us(t[0], t[0] + t[1])),
    MessageType.RUNNING_INFO: st.builds(
        RunningInfo, u32, ident, ident, enum_of(TravelDirection), cm_per_s, cm
    ),
    MessageType.STATION_STOPS: st.builds(
        StationStops,
        st.lists(
            st.builds(StationStop, u32, cm, st.integers(0, 0xFFFF).map(float)), max_size=64
        ).map(tuple),
    ),
    MessageType.RUNNING_TIMES: st.builds(
        RunningTimes, st.lists(st.builds(RunningTime, u32, u32, ms), max_size=64).map(tuple)
    ),
    MessageType.PLANNED_CURVE: st.builds(PlannedCurve, u32, u32, ms, ms),
    MessageType.TARGET_POINT: st.builds(TargetPoint, u32, cm, enum_of(TargetReason)),
    MessageType.TARGET_POINT_ACK: st.builds(TargetPointAck, u32, enum_of(TargetPointResult)),
    MessageType.TSR_SET: st.builds(
        TsrSet, nonzero_u32, cm, cm, st.integers(1, 10_000).map(lambda v: v / 100), us, us
    ),
    MessageType.TSR_SET_ACK: st.builds(TsrSetAck, nonzero_u32, enum_of(TsrSetResult)),
    MessageType.TSR_CANCEL: st.builds(TsrCancel, nonzero_u32),
    MessageType.TSR_CANCEL_ACK: st.builds(TsrCancelAck, nonzero_u32, enum_of(TsrCancelResult)),
    MessageType.DISPATCH_COMMAND: st.builds(
        DispatchCommand,
        nonzero_u32,
        st.text(max_size=250).filter(lambda t: len(t.encode("utf-8", "surrogatepass")) <= 1000),
    ),
    MessageType.DISPATCH_ACK: st.builds(DispatchAck, nonzero_u32, enum_of(DispatchResult)),
    MessageType.HEARTBEAT: st.just(Heartbeat()),
}

any_message = st.one_of(*MESSAGES.values())


def test_every_message_type_has_a_round_trip_strategy() -> None:
    assert set(MESSAGES) == set(MessageType)


@settings(max_examples=300, deadline=None)
@given(any_message)
def test_body_round_trip_gives_the_same_message(message: Message) -> None:
    assert decode_body(message.TYPE, encode_body(message)) == message


@settings(max_examples=300, deadline=None)
@given(any_message)
def test_body_length_matches_the_catalogue(message: Message) -> None:
    expected = BODY_LENGTH[message.TYPE]
    assert expected is None or len(encode_body(message)) == expected
