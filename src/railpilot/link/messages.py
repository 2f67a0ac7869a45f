"""The message catalogue of the train-ground link (paper 001, section 2).

Every message is a frozen dataclass that validates itself in ``__post_init__`` and raises
:class:`~railpilot.link.errors.MessageFieldError` naming the field, the value and what is
allowed. Fields are in SI units (m, m/s, s); the wire scaling (cm, cm/s, ms, us) lives in
:mod:`railpilot.link.codec` and docs/protocol.md. A value that is valid here always fits
its wire field; it is rounded to the wire resolution when encoded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, ClassVar, cast

from .errors import MessageFieldError

# --- limits shared with the codec (one place, so they never disagree) -------------------

U16_MAX = 0xFFFF
U32_MAX = 0xFFFF_FFFF
#: Largest position/km post the wire can carry here [m] (10,000 km; wire unit cm).
MAX_POSITION_M = 10_000_000.0
#: Largest speed or speed limit [m/s] (360 km/h; wire unit cm/s).
MAX_SPEED_MPS = 100.0
#: Largest duration (running time, elapsed, remaining) [s]; wire unit ms in a u32.
MAX_DURATION_S = U32_MAX / 1000.0
#: Largest absolute time [s since the Unix epoch] (year 2286); wire unit us in a u64.
MAX_EPOCH_S = 10_000_000_000.0
#: Largest clock offset magnitude reported by the onboard [s].
MAX_OFFSET_S = 1_000_000.0
#: Longest train number / loco number [ASCII characters]; NUL padded on the wire.
IDENT_LEN = 8
#: Longest dispatch command text [bytes of UTF-8].
MAX_DISPATCH_TEXT_BYTES = 1000
#: Most entries in a station-stop or running-time list.
MAX_LIST_ENTRIES = 64


class MessageType(IntEnum):
    """Wire code (one byte) of every message."""

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


class LinkDirection(IntEnum):
    """Which way a message may travel."""

    UPLINK = 1  # onboard -> ground
    DOWNLINK = 2  # ground -> onboard
    BOTH = 3


class TravelDirection(IntEnum):
    """Direction of travel along the line's km posts."""

    UNKNOWN = 0
    UP = 1  # towards increasing km posts
    DOWN = 2  # towards decreasing km posts


class RegisterResult(IntEnum):
    ACCEPTED = 0
    UNKNOWN_TRAIN = 1
    REFUSED = 2


class DeregisterReason(IntEnum):
    """Why the onboard leaves (paper 001, section 2.1)."""

    SHUNTING_MODE = 1
    MANUAL_SHUTDOWN = 2
    LEAVING_MAIN_LINE = 3


class DeregisterResult(IntEnum):
    DEREGISTERED = 0


class TargetReason(IntEnum):
    """Why the ground sets a target point (paper 001, section 2.4)."""

    TRAIN_AHEAD = 1
    SWITCH_INDICATION_LOST = 2
    SECTION_FAULT = 3
    OTHER = 255


class TargetPointResult(IntEnum):
    ACCEPTED = 0
    REJECTED = 1


class TsrSetResult(IntEnum):
    APPLIED = 0
    INVALID = 1  # start == end, or validity period empty
    EXPIRED = 2  # valid_until already passed on the onboard clock


class TsrCancelResult(IntEnum):
    CANCELLED = 0
    UNKNOWN_SESSION = 1


class DispatchResult(IntEnum):
    RECEIVED = 0


# --- validation helpers ------------------------------------------------------------------


def _fail(obj: Any, name: str, value: Any, allowed: str) -> MessageFieldError:
    return MessageFieldError(type(obj).__name__, name, value, allowed)


def _check_uint(obj: Any, name: str, lo: int, hi: int) -> None:
    value = getattr(obj, name)
    if type(value) is not int or not lo <= value <= hi:  # bool is not an id
        raise _fail(obj, name, value, f"an integer in [{lo}, {hi}]")


def _check_float(obj: Any, name: str, lo: float, hi: float) -> None:
    value = getattr(obj, name)
    if (
        not isinstance(value, int | float)
        or isinstance(value, bool)
        or not math.isfinite(value)
        or not lo <= value <= hi
    ):
        raise _fail(obj, name, value, f"a finite number in [{lo}, {hi}]")


def _check_enum(obj: Any, name: str, enum: type[IntEnum]) -> None:
    value = getattr(obj, name)
    if not isinstance(value, enum):
        raise _fail(obj, name, value, f"a {enum.__name__} ({', '.join(m.name for m in enum)})")


def _check_ident(obj: Any, name: str) -> None:
    value = getattr(obj, name)
    # isascii + isprintable + no space == every character in 0x21..0x7E, without a loop.
    if (
        not isinstance(value, str)
        or not 1 <= len(value) <= IDENT_LEN
        or not value.isascii()
        or not value.isprintable()
        or " " in value
    ):
        raise _fail(obj, name, value, f"1 to {IDENT_LEN} printable ASCII characters, no spaces")


# --- the catalogue -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Message:
    """Base of every message; ``TYPE`` is its wire code and ``DIRECTION`` who sends it.

    A ground-to-train message the train must acknowledge names its acknowledgement in
    ``ACK`` and the field both carry in ``KEY``: the ground resends it until the answer
    comes. One that the ground also keeps per train (in its records and its store, so it
    is resent after a reconnect or a restart of the ground) names its kind in ``KIND``;
    the link's endpoints, the ground's journal and its store derive everything they do
    with such a message from these four attributes (:data:`KEPT_KINDS`). Its
    acknowledgement's other fields must have defaults: they are the train's answer
    (:func:`acknowledgement`).
    """

    TYPE: ClassVar[MessageType]
    DIRECTION: ClassVar[LinkDirection]
    #: Sent every cycle and supervised with a timeout on the receiver (paper 1.2 (2)).
    PERIODIC: ClassVar[bool] = False
    #: The acknowledgement that answers this message (None: not acknowledged).
    ACK: ClassVar[type[Message] | None] = None
    #: The field that identifies one delivery, in this message and in its ``ACK``.
    KEY: ClassVar[str] = ""
    #: The name under which the ground keeps it per train ("": not kept that way).
    KIND: ClassVar[str] = ""
    #: Kept: a new message under a used ``KEY`` replaces the old one (else a key names
    #: one message for good, and another message under it is refused).
    REPLACES: ClassVar[bool] = False


@dataclass(frozen=True, slots=True)
class RegisterRequest(Message):
    """Onboard asks to be managed by the ground (after start-up and every reconnect)."""

    TYPE = MessageType.REGISTER_REQUEST
    DIRECTION = LinkDirection.UPLINK
    train_number: str
    loco_number: str
    driver_id: int
    train_length_m: float

    def __post_init__(self) -> None:
        _check_ident(self, "train_number")
        _check_ident(self, "loco_number")
        _check_uint(self, "driver_id", 0, U32_MAX)
        _check_float(self, "train_length_m", 0.0, 10_000.0)


@dataclass(frozen=True, slots=True)
class RegisterResponse(Message):
    TYPE = MessageType.REGISTER_RESPONSE
    DIRECTION = LinkDirection.DOWNLINK
    result: RegisterResult

    def __post_init__(self) -> None:
        _check_enum(self, "result", RegisterResult)


@dataclass(frozen=True, slots=True)
class DeregisterRequest(Message):
    TYPE = MessageType.DEREGISTER_REQUEST
    DIRECTION = LinkDirection.UPLINK
    reason: DeregisterReason

    def __post_init__(self) -> None:
        _check_enum(self, "reason", DeregisterReason)


@dataclass(frozen=True, slots=True)
class DeregisterResponse(Message):
    TYPE = MessageType.DEREGISTER_RESPONSE
    DIRECTION = LinkDirection.DOWNLINK
    result: DeregisterResult = DeregisterResult.DEREGISTERED

    def __post_init__(self) -> None:
        _check_enum(self, "result", DeregisterResult)


@dataclass(frozen=True, slots=True)
class TimeCheck(Message):
    """Ground tells the onboard its time (paper 001, section 2.2)."""

    TYPE = MessageType.TIME_CHECK
    DIRECTION = LinkDirection.DOWNLINK
    ground_time_s: float  # [s since the Unix epoch, ground clock]

    def __post_init__(self) -> None:
        _check_float(self, "ground_time_s", 0.0, MAX_EPOCH_S)


@dataclass(frozen=True, slots=True)
class TimeOffsetReport(Message):
    """Onboard answers a time check with its clock offset: ``onboard - ground`` [s]."""

    TYPE = MessageType.TIME_OFFSET_REPORT
    DIRECTION = LinkDirection.UPLINK
    ground_time_s: float
    onboard_time_s: float
    offset_s: float

    def __post_init__(self) -> None:
        _check_float(self, "ground_time_s", 0.0, MAX_EPOCH_S)
        _check_float(self, "onboard_time_s", 0.0, MAX_EPOCH_S)
        _check_float(self, "offset_s", -MAX_OFFSET_S, MAX_OFFSET_S)
        # The offset IS the difference of the two times (6.6): only the rounding of the
        # seconds may separate them; on the wire it is their exact difference in us.
        difference_s = self.onboard_time_s - self.ground_time_s
        rounding_s = 1e-6 + 4 * math.ulp(max(self.onboard_time_s, self.ground_time_s))
        if abs(self.offset_s - difference_s) > rounding_s:
            raise _fail(
                self, "offset_s", self.offset_s, f"onboard_time_s - ground_time_s = {difference_s}"
            )

    @classmethod
    def from_us(cls, ground_time_us: int, onboard_time_us: int) -> TimeOffsetReport:
        """The report of two clock readings in whole us; the offset is their exact difference."""
        return cls(
            ground_time_us / 1e6,
            onboard_time_us / 1e6,
            (onboard_time_us - ground_time_us) / 1e6,
        )

    @property
    def offset_us(self) -> int:
        """Onboard minus ground in whole us, exactly as on the wire (integer difference)."""
        return round(self.onboard_time_s * 1e6) - round(self.ground_time_s * 1e6)


@dataclass(frozen=True, slots=True)
class RunningInfo(Message):
    """Periodic train state (paper 001, section 2.3)."""

    TYPE = MessageType.RUNNING_INFO
    DIRECTION = LinkDirection.UPLINK
    PERIODIC = True
    driver_id: int
    train_number: str
    loco_number: str
    direction: TravelDirection
    speed_mps: float
    position_m: float  # km post position along the line [m]

    def __post_init__(self) -> None:
        _check_uint(self, "driver_id", 0, U32_MAX)
        _check_ident(self, "train_number")
        _check_ident(self, "loco_number")
        _check_enum(self, "direction", TravelDirection)
        _check_float(self, "speed_mps", 0.0, MAX_SPEED_MPS)
        _check_float(self, "position_m", 0.0, MAX_POSITION_M)


@dataclass(frozen=True, slots=True)
class StationStop:
    """One stop the onboard shall make."""

    station_id: int
    stop_position_m: float
    dwell_time_s: float

    def __post_init__(self) -> None:
        _check_uint(self, "station_id", 0, U32_MAX)
        _check_float(self, "stop_position_m", 0.0, MAX_POSITION_M)
        _check_float(self, "dwell_time_s", 0.0, float(U16_MAX))  # whole seconds on the wire


@dataclass(frozen=True, slots=True)
class StationStops(Message):
    TYPE = MessageType.STATION_STOPS
    DIRECTION = LinkDirection.DOWNLINK
    stops: tuple[StationStop, ...] = field(default=())

    def __post_init__(self) -> None:
        if (
            not isinstance(self.stops, tuple)
            or len(self.stops) > MAX_LIST_ENTRIES
            or not all(isinstance(s, StationStop) for s in self.stops)
        ):
            raise _fail(self, "stops", self.stops, f"a tuple of <= {MAX_LIST_ENTRIES} StationStop")


@dataclass(frozen=True, slots=True)
class RunningTime:
    """Planned running time between two stations."""

    from_station_id: int
    to_station_id: int
    running_time_s: float

    def __post_init__(self) -> None:
        _check_uint(self, "from_station_id", 0, U32_MAX)
        _check_uint(self, "to_station_id", 0, U32_MAX)
        _check_float(self, "running_time_s", 0.0, MAX_DURATION_S)


@dataclass(frozen=True, slots=True)
class RunningTimes(Message):
    TYPE = MessageType.RUNNING_TIMES
    DIRECTION = LinkDirection.DOWNLINK
    times: tuple[RunningTime, ...] = field(default=())

    def __post_init__(self) -> None:
        if (
            not isinstance(self.times, tuple)
            or len(self.times) > MAX_LIST_ENTRIES
            or not all(isinstance(t, RunningTime) for t in self.times)
        ):
            raise _fail(self, "times", self.times, f"a tuple of <= {MAX_LIST_ENTRIES} RunningTime")


@dataclass(frozen=True, slots=True)
class PlannedCurve(Message):
    """Onboard's plan for the current station pair: time already run + time remaining."""

    TYPE = MessageType.PLANNED_CURVE
    DIRECTION = LinkDirection.UPLINK
    from_station_id: int
    to_station_id: int
    elapsed_s: float
    remaining_s: float

    def __post_init__(self) -> None:
        _check_uint(self, "from_station_id", 0, U32_MAX)
        _check_uint(self, "to_station_id", 0, U32_MAX)
        _check_float(self, "elapsed_s", 0.0, MAX_DURATION_S)
        _check_float(self, "remaining_s", 0.0, MAX_DURATION_S)


@dataclass(frozen=True, slots=True)
class TargetPointAck(Message):
    TYPE = MessageType.TARGET_POINT_ACK
    DIRECTION = LinkDirection.UPLINK
    target_id: int
    result: TargetPointResult = TargetPointResult.ACCEPTED

    def __post_init__(self) -> None:
        _check_uint(self, "target_id", 0, U32_MAX)
        _check_enum(self, "result", TargetPointResult)


@dataclass(frozen=True, slots=True)
class TargetPoint(Message):
    """Position of a red signal the train must stop before (paper 001, section 2.4)."""

    TYPE = MessageType.TARGET_POINT
    DIRECTION = LinkDirection.DOWNLINK
    ACK = TargetPointAck
    KEY = "target_id"
    KIND = "target_point"
    REPLACES = True
    target_id: int
    position_m: float
    reason: TargetReason

    def __post_init__(self) -> None:
        _check_uint(self, "target_id", 0, U32_MAX)
        _check_float(self, "position_m", 0.0, MAX_POSITION_M)
        _check_enum(self, "reason", TargetReason)


@dataclass(frozen=True, slots=True)
class TsrSetAck(Message):
    TYPE = MessageType.TSR_SET_ACK
    DIRECTION = LinkDirection.UPLINK
    session: int
    result: TsrSetResult

    def __post_init__(self) -> None:
        _check_uint(self, "session", 1, U32_MAX)
        _check_enum(self, "result", TsrSetResult)


@dataclass(frozen=True, slots=True)
class TsrSet(Message):
    """Temporary speed restriction as the dispatcher set it (paper 001, section 2.5)."""

    TYPE = MessageType.TSR_SET
    DIRECTION = LinkDirection.DOWNLINK
    ACK = TsrSetAck
    KEY = "session"
    session: int
    start_m: float  # km post where the restriction starts [m]
    end_m: float  # km post where it ends [m]
    limit_mps: float
    valid_from_s: float  # [s since the Unix epoch, ground clock]
    valid_until_s: float

    def __post_init__(self) -> None:
        _check_uint(self, "session", 1, U32_MAX)
        _check_float(self, "start_m", 0.0, MAX_POSITION_M)
        _check_float(self, "end_m", 0.0, MAX_POSITION_M)
        _check_float(self, "limit_mps", 0.01, MAX_SPEED_MPS)
        _check_float(self, "valid_from_s", 0.0, MAX_EPOCH_S)
        _check_float(self, "valid_until_s", 0.0, MAX_EPOCH_S)


@dataclass(frozen=True, slots=True)
class TsrCancelAck(Message):
    TYPE = MessageType.TSR_CANCEL_ACK
    DIRECTION = LinkDirection.UPLINK
    session: int
    result: TsrCancelResult

    def __post_init__(self) -> None:
        _check_uint(self, "session", 1, U32_MAX)
        _check_enum(self, "result", TsrCancelResult)


@dataclass(frozen=True, slots=True)
class TsrCancel(Message):
    TYPE = MessageType.TSR_CANCEL
    DIRECTION = LinkDirection.DOWNLINK
    ACK = TsrCancelAck
    KEY = "session"
    session: int

    def __post_init__(self) -> None:
        _check_uint(self, "session", 1, U32_MAX)


@dataclass(frozen=True, slots=True)
class DispatchAck(Message):
    TYPE = MessageType.DISPATCH_ACK
    DIRECTION = LinkDirection.UPLINK
    command_number: int
    result: DispatchResult = DispatchResult.RECEIVED

    def __post_init__(self) -> None:
        _check_uint(self, "command_number", 1, U32_MAX)
        _check_enum(self, "result", DispatchResult)


@dataclass(frozen=True, slots=True)
class DispatchCommand(Message):
    TYPE = MessageType.DISPATCH_COMMAND
    DIRECTION = LinkDirection.DOWNLINK
    ACK = DispatchAck
    KEY = "command_number"
    KIND = "dispatch_command"
    command_number: int
    text: str

    def __post_init__(self) -> None:
        _check_uint(self, "command_number", 1, U32_MAX)
        if not isinstance(self.text, str) or (
            len(self.text.encode("utf-8", "surrogatepass")) > MAX_DISPATCH_TEXT_BYTES
            or any(0xD800 <= ord(ch) <= 0xDFFF for ch in self.text)
        ):
            raise _fail(
                self, "text", self.text, f"a str of <= {MAX_DISPATCH_TEXT_BYTES} bytes of UTF-8"
            )


@dataclass(frozen=True, slots=True)
class Heartbeat(Message):
    """Sent by both ends every cycle; its timeout is the link-failure detector."""

    TYPE = MessageType.HEARTBEAT
    DIRECTION = LinkDirection.BOTH
    PERIODIC = True


#: Wire code -> message class; the single catalogue the codec and the checks use.
MESSAGE_CLASSES: dict[MessageType, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        RegisterRequest,
        RegisterResponse,
        DeregisterRequest,
        DeregisterResponse,
        TimeCheck,
        TimeOffsetReport,
        RunningInfo,
        StationStops,
        RunningTimes,
        PlannedCurve,
        TargetPoint,
        TargetPointAck,
        TsrSet,
        TsrSetAck,
        TsrCancel,
        TsrCancelAck,
        DispatchCommand,
        DispatchAck,
        Heartbeat,
    )
}


#: Acknowledgement class -> the message class it answers.
ANSWERS: dict[type[Message], type[Message]] = {
    cls.ACK: cls for cls in MESSAGE_CLASSES.values() if cls.ACK is not None
}

#: Kind -> message class of every message the ground keeps per train and resends until
#: it is acknowledged (TSRs excepted: their set and cancel have a machine of their own),
#: in wire-code order: the order the ground's records, journal and store go through them.
KEPT_KINDS: dict[str, type[Message]] = {
    cls.KIND: cls for cls in MESSAGE_CLASSES.values() if cls.KIND
}


def key_of(message: Message) -> int:
    """The ``KEY`` field's value of an acknowledged message or of its acknowledgement."""
    cls = ANSWERS.get(type(message), type(message))
    return cast(int, getattr(message, cls.KEY))


def acknowledgement(message: Message) -> Message:
    """The train's acknowledgement of ``message``: its ``ACK`` with the same key and the
    other fields at their defaults (the positive answer)."""
    ack = type(message).ACK
    if ack is None:
        raise TypeError(f"{type(message).__name__} is not acknowledged")
    return cast(Any, ack)(**{type(message).KEY: key_of(message)})


__all__ = [
    "ANSWERS",
    "KEPT_KINDS",
    "MESSAGE_CLASSES",
    "DeregisterReason",
    "DeregisterRequest",
    "DeregisterResponse",
    "DeregisterResult",
    "DispatchAck",
    "DispatchCommand",
    "DispatchResult",
    "Heartbeat",
    "LinkDirection",
    "Message",
    "MessageType",
    "PlannedCurve",
    "RegisterRequest",
    "RegisterResponse",
    "RegisterResult",
    "RunningInfo",
    "RunningTime",
    "RunningTimes",
    "StationStop",
    "StationStops",
    "TargetPoint",
    "TargetPointAck",
    "TargetPointResult",
    "TargetReason",
    "TimeCheck",
    "TimeOffsetReport",
    "TravelDirection",
    "TsrCancel",
    "TsrCancelAck",
    "TsrCancelResult",
    "TsrSet",
    "TsrSetAck",
    "TsrSetResult",
    "acknowledgement",
    "key_of",
]
