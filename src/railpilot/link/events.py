"""Events the link core hands to the application (h11 style: plain frozen dataclasses).

Three families:

* :class:`FrameRejected` and one subclass per safety check: a received frame was
  discarded, saying which check failed. Nothing from a rejected frame reaches the
  application.
* diagnostics that do not discard data: :class:`SequenceGap`.
* application events: accepted messages (:class:`MessageReceived`) and the outcomes of
  the endpoint state machines (registration, TSR, dispatch, timeouts, link failure).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import ClassVar

from .checks import Check
from .messages import (
    DeregisterReason,
    DispatchCommand,
    Message,
    MessageType,
    RegisterRequest,
    RegisterResult,
    TargetPoint,
    TargetPointResult,
    TravelDirection,
    TsrCancelResult,
    TsrSet,
    TsrSetResult,
)


@dataclass(frozen=True, slots=True)
class Event:
    """Base of every event."""


# --- rejections ----------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class FrameRejected(Event):
    """A received frame was discarded because ``check`` failed.

    ``message_type``, ``source_id`` and ``sequence`` are what the frame claimed (``None``
    when the frame was too broken to tell); never trust them.
    """

    check: ClassVar[Check] = Check.FRAMING
    detail: str
    message_type: int | None = None
    source_id: int | None = None
    sequence: int | None = None


@dataclass(frozen=True, slots=True)
class FramingRejected(FrameRejected):
    check = Check.FRAMING


@dataclass(frozen=True, slots=True)
class VersionRejected(FrameRejected):
    check = Check.VERSION


@dataclass(frozen=True, slots=True)
class LengthRejected(FrameRejected):
    check = Check.LENGTH


@dataclass(frozen=True, slots=True)
class CrcRejected(FrameRejected):
    check = Check.CRC


@dataclass(frozen=True, slots=True)
class TypeRejected(FrameRejected):
    check = Check.TYPE


@dataclass(frozen=True, slots=True)
class SourceRejected(FrameRejected):
    check = Check.SOURCE


@dataclass(frozen=True, slots=True)
class DestinationRejected(FrameRejected):
    check = Check.DESTINATION


@dataclass(frozen=True, slots=True)
class AuthRejected(FrameRejected):
    check = Check.AUTH


@dataclass(frozen=True, slots=True)
class BodyRejected(FrameRejected):
    check = Check.BODY


@dataclass(frozen=True, slots=True)
class SequenceRejected(FrameRejected):
    check = Check.SEQUENCE


@dataclass(frozen=True, slots=True)
class TimestampRejected(FrameRejected):
    check = Check.TIMESTAMP


@dataclass(frozen=True, slots=True)
class DelayRejected(FrameRejected):
    check = Check.DELAY


@dataclass(frozen=True, slots=True)
class StateRejected(FrameRejected):
    check = Check.STATE


#: Check -> its rejection event class.
REJECTION_BY_CHECK: dict[Check, type[FrameRejected]] = {
    cls.check: cls
    for cls in (
        FramingRejected,
        VersionRejected,
        LengthRejected,
        CrcRejected,
        TypeRejected,
        SourceRejected,
        DestinationRejected,
        AuthRejected,
        BodyRejected,
        SequenceRejected,
        TimestampRejected,
        DelayRejected,
        StateRejected,
    )
}


# --- diagnostics ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SequenceGap(Event):
    """Frames were lost (deletion): the frame was accepted, ``lost`` frames never came."""

    expected: int
    received: int
    lost: int


# --- accepted data and state-machine outcomes ---------------------------------------------


@dataclass(frozen=True, slots=True)
class MessageReceived(Event):
    """An accepted data message the application consumes as is.

    Used for running info, planned curves, station stops, running times, time offset
    reports. For periodic messages only the newest of each receive cycle is delivered.
    """

    message: Message
    source_id: int
    timestamp_us: int


@dataclass(frozen=True, slots=True)
class PeriodicTimedOut(Event):
    """A periodic message missed more cycles than allowed; its held value is now invalid."""

    message_type: MessageType
    missed_cycles: int


@dataclass(frozen=True, slots=True)
class LinkFailed(Event):
    """The link is unusable; the adapter should close the connection.

    The onboard then reconnects with backoff (``reconnect_delay_s``) and registers again;
    the ground keeps the train's pending deliveries for the next connection.
    """

    reason: str


# onboard side ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Registered(Event):
    """The ground accepted our registration; running info now flows."""


@dataclass(frozen=True, slots=True)
class RegistrationRefused(Event):
    """The ground refused our registration; the endpoint retries after the retry interval."""

    result: RegisterResult


@dataclass(frozen=True, slots=True)
class Deregistered(Event):
    """The ground confirmed our deregistration."""

    reason: DeregisterReason


@dataclass(frozen=True, slots=True)
class TimeChecked(Event):
    """The ground sent its time; ``offset_s`` = onboard clock - ground clock (reported back)."""

    ground_time_s: float
    offset_s: float


@dataclass(frozen=True, slots=True)
class AppliedTsr:
    """A TSR as the onboard enforces it: the received zone extended by one train length.

    ``zone_start_m``..``zone_end_m`` (``zone_start_m < zone_end_m``) is the restricted
    stretch in km-post metres; the extension is on the exit side for the direction of
    travel, or on both sides when the direction is unknown.
    """

    session: int
    start_m: float
    end_m: float
    zone_start_m: float
    zone_end_m: float
    limit_mps: float
    valid_from_s: float
    valid_until_s: float

    @classmethod
    def of(cls, tsr: TsrSet, train_length_m: float, direction: TravelDirection) -> AppliedTsr:
        """The received ``tsr`` with its zone extended by :func:`tsr_zone`."""
        low, high = tsr_zone(tsr.start_m, tsr.end_m, train_length_m, direction)
        return cls(
            tsr.session,
            tsr.start_m,
            tsr.end_m,
            low,
            high,
            tsr.limit_mps,
            tsr.valid_from_s,
            tsr.valid_until_s,
        )


def tsr_zone(
    start_m: float, end_m: float, train_length_m: float, direction: TravelDirection
) -> tuple[float, float]:
    """The zone ``(low_m, high_m)`` [m] a TSR on ``start_m..end_m`` is enforced on.

    The stretch (either order) extended by ``train_length_m`` [m] on its exit side so the
    tail obeys the limit too (paper 001, 2.5): going UP the high end moves up, going DOWN
    the low end moves down (not below km 0); direction UNKNOWN: both ends, the safe side.
    The one rule for the link's onboard endpoint and the onboard's MRSP.
    """
    low, high = sorted((start_m, end_m))
    if direction is not TravelDirection.DOWN:  # UP, or UNKNOWN: both ends
        high += train_length_m
    if direction is not TravelDirection.UP:
        low = max(0.0, low - train_length_m)
    return low, high


@dataclass(frozen=True, slots=True)
class TsrApplied(Event):
    """A TSR was applied (once per session, however often it is resent)."""

    tsr: AppliedTsr


@dataclass(frozen=True, slots=True)
class TsrRefused(Event):
    """A TSR failed the onboard's plausibility check and was not applied."""

    session: int
    result: TsrSetResult


@dataclass(frozen=True, slots=True)
class TsrCancelled(Event):
    """A TSR was removed (once per session)."""

    session: int


@dataclass(frozen=True, slots=True)
class TsrExpired(Event):
    """A TSR's validity period ended; it is no longer enforced."""

    session: int


@dataclass(frozen=True, slots=True)
class TargetPointReceived(Event):
    """The target point in force changed: a newer id than every one before, or new content
    under the newest (once per content, however often it is resent). An older id arriving
    late changes nothing and raises no event (protocol.md 8.4)."""

    target: TargetPoint


@dataclass(frozen=True, slots=True)
class DispatchCommandReceived(Event):
    """A dispatch command (once per command number)."""

    command: DispatchCommand


@dataclass(frozen=True, slots=True)
class DeliveryReceived(Event):
    """A message the ground keeps for the train (``Message.KIND``) and that has no event
    of its own here (dispatch commands and target points do): once per key, however often
    it is resent."""

    message: Message


# ground side -------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TrainRegistered(Event):
    train_id: int
    request: RegisterRequest


@dataclass(frozen=True, slots=True)
class TrainDeregistered(Event):
    train_id: int
    reason: DeregisterReason


@dataclass(frozen=True, slots=True)
class TsrAcknowledged(Event):
    """The train confirmed it applied the TSR (first confirmation only)."""

    train_id: int
    session: int


@dataclass(frozen=True, slots=True)
class TsrRefusedByTrain(Event):
    """The train refused the TSR as implausible or expired; it is not resent."""

    train_id: int
    session: int
    result: TsrSetResult


@dataclass(frozen=True, slots=True)
class TsrCancelAcknowledged(Event):
    train_id: int
    session: int
    result: TsrCancelResult


@dataclass(frozen=True, slots=True)
class TargetPointAcknowledged(Event):
    train_id: int
    target_id: int
    result: TargetPointResult


@dataclass(frozen=True, slots=True)
class DispatchAcknowledged(Event):
    train_id: int
    command_number: int


@dataclass(frozen=True, slots=True)
class DeliveryAcknowledged(Event):
    """The train acknowledged a kept message (``Message.KIND``) of a kind that has no event
    of its own here (first acknowledgement only): ``ident`` is its key, ``result`` the
    train's answer."""

    train_id: int
    kind: str
    ident: int
    result: IntEnum


#: Every event that reports a train's answer to a delivery of the ground.
ACKNOWLEDGEMENTS = (
    TsrAcknowledged,
    TsrCancelAcknowledged,
    TsrRefusedByTrain,
    DispatchAcknowledged,
    TargetPointAcknowledged,
    DeliveryAcknowledged,
)


def event_name(event: Event) -> str:
    """What the ground's logs call an event: its class name (``TsrAcknowledged``), or, for
    a :class:`DeliveryAcknowledged`, its kind's in the same form (a kind ``speed_advice``:
    ``SpeedAdviceAcknowledged``)."""
    if isinstance(event, DeliveryAcknowledged):
        return "".join(part.capitalize() for part in event.kind.split("_")) + "Acknowledged"
    return type(event).__name__
