"""Encoding and decoding of message bodies, kept apart from the message classes.

Byte order is big-endian (network order) throughout. Wire units: positions and km posts
in cm (u32), speeds in cm/s (u16), durations in ms (u32), absolute times in us since the
Unix epoch (u64), clock offsets in us (i64), identifiers (train and loco numbers) as 8
bytes of ASCII padded with NUL. docs/protocol.md gives every layout.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from enum import IntEnum
from typing import Any, TypeVar

from .errors import BodyError, LengthError, MessageFieldError, TypeCheckError
from .messages import (
    IDENT_LEN,
    MAX_DISPATCH_TEXT_BYTES,
    MAX_EPOCH_S,
    MAX_LIST_ENTRIES,
    MAX_OFFSET_S,
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

_U32_MAX = 0xFFFF_FFFF
_U64_MAX = 0xFFFF_FFFF_FFFF_FFFF

E = TypeVar("E", bound=IntEnum)


# --- scaling (SI <-> wire integers); clamped so a valid message always fits ----------------


def _cm(value_m: float) -> int:
    return min(round(value_m * 100.0), _U32_MAX)


def _cm_per_s(value_mps: float) -> int:
    return min(round(value_mps * 100.0), 0xFFFF)


def _ms(value_s: float) -> int:
    return min(round(value_s * 1000.0), _U32_MAX)


def _us(value_s: float) -> int:
    return min(round(value_s * 1_000_000.0), _U64_MAX)


MAX_EPOCH_US = round(MAX_EPOCH_S * 1e6)
MAX_OFFSET_US = round(MAX_OFFSET_S * 1e6)


def _seconds(value_us: int, name: str, limit_us: int = MAX_EPOCH_US) -> float:
    """Wire microseconds to seconds, range-checked on the integer.

    Checking after the conversion would let ``limit + 1`` us through: it rounds to
    exactly the limit in floating point.
    """
    if abs(value_us) > limit_us:
        raise MessageFieldError("time", name, value_us, f"|value| <= {limit_us} us")
    return value_us / 1e6


def _ident(text: str) -> bytes:
    return text.encode("ascii").ljust(IDENT_LEN, b"\0")


def _unident(raw: bytes) -> str:
    # Only trailing NULs are padding; a NUL inside stays and fails validation.
    return raw.rstrip(b"\0").decode("ascii")


_ENUM_MEMBERS: dict[type[IntEnum], dict[int, IntEnum]] = {}


def _enum(enum: type[E], value: int, name: str) -> E:
    # A dict lookup instead of Enum.__call__: this is on the per-frame hot path.
    members = _ENUM_MEMBERS.get(enum)
    if members is None:
        members = _ENUM_MEMBERS[enum] = {int(m): m for m in enum}
    member = members.get(value)
    if member is None:
        raise MessageFieldError(enum.__name__, name, value, f"one of {sorted(members)}")
    return member  # type: ignore[return-value]


# --- layouts --------------------------------------------------------------------------------

_REGISTER_REQUEST = struct.Struct(">8s8sII")
_U8 = struct.Struct(">B")
_TIME_CHECK = struct.Struct(">Q")
_TIME_OFFSET = struct.Struct(">QQq")
_RUNNING_INFO = struct.Struct(">I8s8sBHI")
_STATION_STOP = struct.Struct(">IIH")
_RUNNING_TIME = struct.Struct(">III")
_PLANNED_CURVE = struct.Struct(">IIII")
_TARGET_POINT = struct.Struct(">IIB")
_ID_RESULT = struct.Struct(">IB")
_TSR_SET = struct.Struct(">IIIHQQ")
_U32 = struct.Struct(">I")
_DISPATCH_HEAD = struct.Struct(">IH")

#: Fixed body length per type; ``None`` marks a variable-length body.
BODY_LENGTH: dict[MessageType, int | None] = {
    MessageType.REGISTER_REQUEST: _REGISTER_REQUEST.size,
    MessageType.REGISTER_RESPONSE: 1,
    MessageType.DEREGISTER_REQUEST: 1,
    MessageType.DEREGISTER_RESPONSE: 1,
    MessageType.TIME_CHECK: _TIME_CHECK.size,
    MessageType.TIME_OFFSET_REPORT: _TIME_OFFSET.size,
    MessageType.RUNNING_INFO: _RUNNING_INFO.size,
    MessageType.STATION_STOPS: None,
    MessageType.RUNNING_TIMES: None,
    MessageType.PLANNED_CURVE: _PLANNED_CURVE.size,
    MessageType.TARGET_POINT: _TARGET_POINT.size,
    MessageType.TARGET_POINT_ACK: _ID_RESULT.size,
    MessageType.TSR_SET: _TSR_SET.size,
    MessageType.TSR_SET_ACK: _ID_RESULT.size,
    MessageType.TSR_CANCEL: _U32.size,
    MessageType.TSR_CANCEL_ACK: _ID_RESULT.size,
    MessageType.DISPATCH_COMMAND: None,
    MessageType.DISPATCH_ACK: _ID_RESULT.size,
    MessageType.HEARTBEAT: 0,
}

#: Largest body any message can have [bytes].
MAX_BODY_LENGTH = max(
    1 + MAX_LIST_ENTRIES * _STATION_STOP.size,
    1 + MAX_LIST_ENTRIES * _RUNNING_TIME.size,
    _DISPATCH_HEAD.size + MAX_DISPATCH_TEXT_BYTES,
)


def _encode(message: Any) -> bytes:
    m = message
    if isinstance(m, RunningInfo):  # the hot path first
        return _RUNNING_INFO.pack(
            m.driver_id,
            _ident(m.train_number),
            _ident(m.loco_number),
            m.direction,
            _cm_per_s(m.speed_mps),
            _cm(m.position_m),
        )
    if isinstance(m, Heartbeat):
        return b""
    if isinstance(m, RegisterRequest):
        return _REGISTER_REQUEST.pack(
            _ident(m.train_number), _ident(m.loco_number), m.driver_id, _cm(m.train_length_m)
        )
    if isinstance(m, RegisterResponse | DeregisterResponse):
        return _U8.pack(m.result)
    if isinstance(m, DeregisterRequest):
        return _U8.pack(m.reason)
    if isinstance(m, TimeCheck):
        return _TIME_CHECK.pack(_us(m.ground_time_s))
    if isinstance(m, TimeOffsetReport):
        ground_us, onboard_us = _us(m.ground_time_s), _us(m.onboard_time_s)
        # the offset is the exact difference of the two fields as sent (6.6), never a
        # separately rounded float that can be 1 us off
        return _TIME_OFFSET.pack(ground_us, onboard_us, onboard_us - ground_us)
    if isinstance(m, StationStops):
        return _U8.pack(len(m.stops)) + b"".join(
            _STATION_STOP.pack(
                s.station_id, _cm(s.stop_position_m), min(round(s.dwell_time_s), 0xFFFF)
            )
            for s in m.stops
        )
    if isinstance(m, RunningTimes):
        return _U8.pack(len(m.times)) + b"".join(
            _RUNNING_TIME.pack(t.from_station_id, t.to_station_id, _ms(t.running_time_s))
            for t in m.times
        )
    if isinstance(m, PlannedCurve):
        return _PLANNED_CURVE.pack(
            m.from_station_id, m.to_station_id, _ms(m.elapsed_s), _ms(m.remaining_s)
        )
    if isinstance(m, TargetPoint):
        return _TARGET_POINT.pack(m.target_id, _cm(m.position_m), m.reason)
    if isinstance(m, TargetPointAck):
        return _ID_RESULT.pack(m.target_id, m.result)
    if isinstance(m, TsrSet):
        return _TSR_SET.pack(
            m.session,
            _cm(m.start_m),
            _cm(m.end_m),
            _cm_per_s(m.limit_mps),
            _us(m.valid_from_s),
            _us(m.valid_until_s),
        )
    if isinstance(m, TsrSetAck | TsrCancelAck):
        return _ID_RESULT.pack(m.session, m.result)
    if isinstance(m, TsrCancel):
        return _U32.pack(m.session)
    if isinstance(m, DispatchCommand):
        text = m.text.encode("utf-8")
        return _DISPATCH_HEAD.pack(m.command_number, len(text)) + text
    if isinstance(m, DispatchAck):
        return _ID_RESULT.pack(m.command_number, m.result)
    raise TypeError(f"{type(message).__name__} is not a link message")


def encode_body(message: Message) -> bytes:
    """Body bytes of ``message`` (without frame header, MAC and CRC)."""
    return _encode(message)


# --- decoding ------------------------------------------------------------------------------


def _dec_running_info(b: bytes) -> Message:
    driver, train, loco, direction, speed, pos = _RUNNING_INFO.unpack(b)
    return RunningInfo(
        driver,
        _unident(train),
        _unident(loco),
        _enum(TravelDirection, direction, "direction"),
        speed / 100.0,
        pos / 100.0,
    )


def _dec_register_request(b: bytes) -> Message:
    train, loco, driver, length_cm = _REGISTER_REQUEST.unpack(b)
    return RegisterRequest(_unident(train), _unident(loco), driver, length_cm / 100.0)


def _dec_station_stops(b: bytes) -> Message:
    count = _count_entries(b, _STATION_STOP.size)
    stops = tuple(
        StationStop(sid, pos / 100.0, float(dwell))
        for sid, pos, dwell in _STATION_STOP.iter_unpack(b[1 : 1 + count * _STATION_STOP.size])
    )
    return StationStops(stops)


def _dec_running_times(b: bytes) -> Message:
    count = _count_entries(b, _RUNNING_TIME.size)
    times = tuple(
        RunningTime(a, z, ms / 1000.0)
        for a, z, ms in _RUNNING_TIME.iter_unpack(b[1 : 1 + count * _RUNNING_TIME.size])
    )
    return RunningTimes(times)


def _count_entries(b: bytes, entry_size: int) -> int:
    if not b:
        raise LengthError("list body is empty; expected a count byte")
    count = b[0]
    # Spec 5.4 #13: a count that disagrees with the body length is a *length* failure; a
    # count that agrees but is out of its range is a *body* failure, like any other field.
    if len(b) != 1 + count * entry_size:
        raise LengthError(
            f"list of {count} entries needs {1 + count * entry_size} bytes, got {len(b)}"
        )
    if count > MAX_LIST_ENTRIES:
        raise BodyError(f"list of {count} entries; at most {MAX_LIST_ENTRIES} allowed")
    return count


def _dec_dispatch(b: bytes) -> Message:
    if len(b) < _DISPATCH_HEAD.size:
        raise LengthError(f"dispatch command body of {len(b)} bytes is shorter than 6")
    number, text_len = _DISPATCH_HEAD.unpack_from(b)
    if text_len > MAX_DISPATCH_TEXT_BYTES or len(b) != _DISPATCH_HEAD.size + text_len:
        raise LengthError(
            f"dispatch text length {text_len} does not match body length {len(b)} "
            f"(text at most {MAX_DISPATCH_TEXT_BYTES} bytes)"
        )
    return DispatchCommand(number, b[_DISPATCH_HEAD.size :].decode("utf-8"))


def _dec_time_offset(b: bytes) -> Message:
    ground, onboard, offset = _TIME_OFFSET.unpack(b)
    if offset != onboard - ground:
        raise BodyError(
            f"offset {offset} us is not onboard time - ground time = {onboard - ground} us"
        )
    return TimeOffsetReport(
        _seconds(ground, "ground_time_s"),
        _seconds(onboard, "onboard_time_s"),
        _seconds(offset, "offset_s", MAX_OFFSET_US),
    )


def _dec_tsr_set(b: bytes) -> Message:
    session, start, end, limit, v_from, v_until = _TSR_SET.unpack(b)
    return TsrSet(
        session,
        start / 100.0,
        end / 100.0,
        limit / 100.0,
        _seconds(v_from, "valid_from_s"),
        _seconds(v_until, "valid_until_s"),
    )


def _dec_planned_curve(b: bytes) -> Message:
    a, z, elapsed, remaining = _PLANNED_CURVE.unpack(b)
    return PlannedCurve(a, z, elapsed / 1000.0, remaining / 1000.0)


def _dec_target_point(b: bytes) -> Message:
    tid, pos, reason = _TARGET_POINT.unpack(b)
    return TargetPoint(tid, pos / 100.0, _enum(TargetReason, reason, "reason"))


def _dec_id_result(
    cls: Callable[[int, Any], Message], enum: type[IntEnum]
) -> Callable[[bytes], Message]:
    def decode(b: bytes) -> Message:
        ident, result = _ID_RESULT.unpack(b)
        return cls(ident, _enum(enum, result, "result"))

    return decode


_DECODERS: dict[MessageType, Callable[[bytes], Message]] = {
    MessageType.RUNNING_INFO: _dec_running_info,
    MessageType.HEARTBEAT: lambda b: Heartbeat(),
    MessageType.REGISTER_REQUEST: _dec_register_request,
    MessageType.REGISTER_RESPONSE: lambda b: RegisterResponse(
        _enum(RegisterResult, b[0], "result")
    ),
    MessageType.DEREGISTER_REQUEST: lambda b: DeregisterRequest(
        _enum(DeregisterReason, b[0], "reason")
    ),
    MessageType.DEREGISTER_RESPONSE: lambda b: DeregisterResponse(
        _enum(DeregisterResult, b[0], "result")
    ),
    MessageType.TIME_CHECK: lambda b: TimeCheck(
        _seconds(_TIME_CHECK.unpack(b)[0], "ground_time_s")
    ),
    MessageType.TIME_OFFSET_REPORT: _dec_time_offset,
    MessageType.STATION_STOPS: _dec_station_stops,
    MessageType.RUNNING_TIMES: _dec_running_times,
    MessageType.PLANNED_CURVE: _dec_planned_curve,
    MessageType.TARGET_POINT: _dec_target_point,
    MessageType.TARGET_POINT_ACK: _dec_id_result(TargetPointAck, TargetPointResult),
    MessageType.TSR_SET: _dec_tsr_set,
    MessageType.TSR_SET_ACK: _dec_id_result(TsrSetAck, TsrSetResult),
    MessageType.TSR_CANCEL: lambda b: TsrCancel(_U32.unpack(b)[0]),
    MessageType.TSR_CANCEL_ACK: _dec_id_result(TsrCancelAck, TsrCancelResult),
    MessageType.DISPATCH_COMMAND: _dec_dispatch,
    MessageType.DISPATCH_ACK: _dec_id_result(DispatchAck, DispatchResult),
}


_TYPES: dict[int, MessageType] = {int(t): t for t in MessageType}


def check_type(message_type: int) -> MessageType:
    """The :class:`MessageType` of a wire code, or :class:`TypeCheckError`."""
    mtype = _TYPES.get(message_type)
    if mtype is None:
        raise TypeCheckError(f"unknown message type 0x{message_type:02x}")
    return mtype


def decode_body(message_type: int, body: bytes) -> Message:
    """Decode a body of a known type.

    Raises :class:`TypeCheckError` for an unknown type, :class:`LengthError` when the body
    length does not fit the type and :class:`BodyError` when a field is out of range.
    """
    mtype = check_type(message_type)
    expected = BODY_LENGTH[mtype]
    if expected is not None and len(body) != expected:
        raise LengthError(f"{mtype.name} body must be {expected} bytes, got {len(body)}")
    try:
        return _DECODERS[mtype](body)
    except MessageFieldError as exc:
        raise BodyError(f"{exc.message_name}.{exc.field} = {exc.value!r}: {exc.allowed}") from None
    except UnicodeDecodeError as exc:
        raise BodyError(f"{mtype.name} text is not valid ({exc.reason})") from None
