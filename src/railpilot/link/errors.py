"""Errors of the train-ground link (paper 001).

Every error says what the protocol does next, and none of them ever carries key
material (only train ids and key ids).

Hierarchy::

    LinkError
    +-- LocalProtocolError      our own application misused the API; nothing was sent
    +-- RemoteProtocolError     the peer broke the protocol (base of every frame check)
    |   +-- FrameError          one received frame failed one check; that frame is dropped
    |       +-- FramingError, VersionError, LengthError, CrcError, TypeCheckError,
    |           SourceIdError, DestinationIdError, AuthenticationError, BodyError,
    |           SequenceError, TimestampError, DelayError, StateError
    +-- MessageFieldError       a message field is out of range (also a ValueError)
    +-- LinkConfigError         a link configuration value is out of range (also a ValueError)
    +-- KeyFileError            a key file is unsafe or malformed; no keys were loaded
"""

from __future__ import annotations

from typing import Any, ClassVar

from railpilot.errors import RailpilotError, shown

from .checks import Check


class LinkError(RailpilotError):
    """Base class of every error the link raises on purpose."""

    #: What the protocol does after this error, in one sentence.
    what_next: ClassVar[str] = "the operation was abandoned"


class LocalProtocolError(LinkError):
    """The local application asked for something the protocol state does not allow.

    Nothing was queued for sending and the endpoint state is unchanged, so the caller can
    fix its call and go on.
    """

    what_next = "nothing was sent; the endpoint state is unchanged"

    def __init__(self, message: str) -> None:
        super().__init__(f"{message}; {self.what_next}")


class RemoteProtocolError(LinkError):
    """The peer sent something the protocol forbids."""

    what_next = "the offending frame was discarded; the link stays up"


class FrameError(RemoteProtocolError):
    """A received frame failed one safety check.

    Endpoints never raise it to the application: they turn it into the matching
    :class:`~railpilot.link.events.FrameRejected` event and count it. The stateless
    :func:`~railpilot.link.frame.parse_frame` raises it.
    """

    check: ClassVar[Check] = Check.FRAMING

    def __init__(self, detail: str) -> None:
        self.detail = detail
        super().__init__(f"{self.check.value} check failed: {detail}; {self.what_next}")


class FramingError(FrameError):
    check = Check.FRAMING


class VersionError(FrameError):
    check = Check.VERSION


class LengthError(FrameError):
    check = Check.LENGTH


class CrcError(FrameError):
    check = Check.CRC


class TypeCheckError(FrameError):
    check = Check.TYPE


class SourceIdError(FrameError):
    check = Check.SOURCE


class DestinationIdError(FrameError):
    check = Check.DESTINATION


class AuthenticationError(FrameError):
    check = Check.AUTH


class BodyError(FrameError):
    check = Check.BODY


class SequenceError(FrameError):
    check = Check.SEQUENCE


class TimestampError(FrameError):
    check = Check.TIMESTAMP


class DelayError(FrameError):
    check = Check.DELAY


class StateError(FrameError):
    check = Check.STATE


#: Check -> the FrameError subclass that reports it.
FRAME_ERROR_BY_CHECK: dict[Check, type[FrameError]] = {
    cls.check: cls
    for cls in (
        FramingError,
        VersionError,
        LengthError,
        CrcError,
        TypeCheckError,
        SourceIdError,
        DestinationIdError,
        AuthenticationError,
        BodyError,
        SequenceError,
        TimestampError,
        DelayError,
        StateError,
    )
}


class MessageFieldError(LinkError, ValueError):
    """A message field is outside what the protocol can carry or allows.

    Raised by message constructors (so a bad message is never built) and by the body
    decoder (where it becomes a ``BODY`` rejection of the frame).
    """

    what_next = "the message was not built"

    def __init__(self, message_name: str, field: str, value: Any, allowed: str) -> None:
        self.message_name = message_name
        self.field = field
        self.value = value
        self.allowed = allowed
        super().__init__(
            f"{message_name}.{field} = {value!r} is not allowed: expected {allowed}; "
            f"{self.what_next}"
        )


class LinkConfigError(LinkError, ValueError):
    """A link configuration value is outside its allowed range."""

    what_next = "the endpoint was not created"

    def __init__(
        self, field: str, value: Any, allowed: str, *, what_next: str | None = None
    ) -> None:
        self.field = field
        self.value = value
        self.allowed = allowed
        # a tool that is no endpoint (the proxy) says what did not happen to it instead
        ending = self.what_next if what_next is None else what_next
        super().__init__(f"{field} = {shown(value)} is not allowed: expected {allowed}; {ending}")


class KeyFileError(LinkError):
    """A key file is unsafe (readable by others) or malformed.

    The message names the file and the offending entry, never a key.
    """

    what_next = "no keys were loaded"

    def __init__(self, message: str) -> None:
        super().__init__(f"{message}; {self.what_next}")
