"""Stateless decoding for tools (``railpilot link decode``, dissector tests).

:func:`decode_stream` takes any bytes (a capture, a hex dump turned into bytes) and yields
one :class:`FrameReport` per frame or framing problem, with a verdict for every check that
can be judged without connection state. Sequence, timestamp-order and delay checks need
the connection history and are reported as skipped. It never raises on any input.

The input is taken as complete: when it ends inside a frame, the last report says so
(:attr:`FrameReport.truncated`). Reports are produced one at a time and the input is fed
to the frame decoder in small slices, so memory does not grow with the number of frames.
"""

from __future__ import annotations

import hmac
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

from .codec import BODY_LENGTH, decode_body
from .errors import FrameError
from .events import Check
from .frame import FLAG_AUTH, Frame, compute_mac
from .framing import (
    CRC_LENGTH,
    DEFAULT_MAX_FRAME_LENGTH,
    HEADER_LENGTH,
    MAC_LENGTH,
    PROTOCOL_VERSION,
    FrameDecoder,
)
from .keys import KeyStore
from .messages import MESSAGE_CLASSES, LinkDirection, Message, MessageType

_HEADER = struct.Struct(">BBHBHIIIQQ")
#: Input bytes fed to the frame decoder at a time. A slice yields at most one framing
#: problem per 2 bytes, so this bounds what is held at once whatever the input size.
_FEED_BYTES = 4096


@dataclass(frozen=True, slots=True)
class Verdict:
    """Outcome of one check: ``ok`` is True (passed), False (failed) or None (skipped)."""

    check: Check
    ok: bool | None
    detail: str = ""


@dataclass(frozen=True, slots=True)
class FrameReport:
    """One frame (or framing problem) found in a byte stream."""

    raw: bytes | None  # the unstuffed frame, None for a framing problem
    frame: Frame | None  # header fields, when the header could be read
    message: Message | None  # decoded body, when the body checks passed
    verdicts: tuple[Verdict, ...]
    #: The input ended inside this frame (only ever the last report; a FRAMING failure).
    truncated: bool = False

    @property
    def ok(self) -> bool:
        """True when no check failed (skipped checks do not count)."""
        return all(v.ok is not False for v in self.verdicts)

    def verdict(self, check: Check) -> Verdict | None:
        return next((v for v in self.verdicts if v.check is check), None)


def decode_stream(
    data: bytes,
    keys: KeyStore | None = None,
    *,
    expect_source: int | None = None,
    expect_destination: int | None = None,
    max_frame_length: int = DEFAULT_MAX_FRAME_LENGTH,
) -> Iterator[FrameReport]:
    """Yield a :class:`FrameReport` for every frame or framing problem in ``data``.

    ``data`` is the whole input: if it ends inside a frame, the last report is that frame,
    ``truncated``, with a failed FRAMING verdict "truncated: input ends after K of L bytes"
    (unstuffed bytes received of the length field's total; "... after K bytes, before the
    length field" when fewer than 4 came).
    """
    decoder = FrameDecoder(max_frame_length)
    for start in range(0, len(data), _FEED_BYTES):
        for item in decoder.feed(data[start : start + _FEED_BYTES]):
            if isinstance(item, FrameError):
                yield FrameReport(None, None, None, (Verdict(item.check, False, item.detail),))
            else:
                yield inspect_frame(
                    item, keys, expect_source=expect_source, expect_destination=expect_destination
                )
    pending = decoder.pending_frame()
    if pending is not None:
        yield _truncated_report(*pending)


def _truncated_report(received: int, length: int | None) -> FrameReport:
    if length is None:
        detail = f"truncated: input ends after {received} bytes, before the length field"
    else:
        detail = f"truncated: input ends after {received} of {length} bytes"
    return FrameReport(None, None, None, (Verdict(Check.FRAMING, False, detail),), truncated=True)


def inspect_frame(
    raw: bytes,
    keys: KeyStore | None = None,
    *,
    expect_source: int | None = None,
    expect_destination: int | None = None,
) -> FrameReport:
    """Judge every stateless check of one unstuffed frame independently."""
    verdicts: list[Verdict] = [Verdict(Check.FRAMING, True)]
    n = len(raw)
    if n < HEADER_LENGTH + CRC_LENGTH:
        verdicts.append(Verdict(Check.LENGTH, False, f"frame of {n} bytes is too short"))
        return FrameReport(raw, None, None, tuple(verdicts))
    version, flags, length, mtype, key_id, src, dst, seq, ts, echo = _HEADER.unpack_from(raw)
    auth = bool(flags & FLAG_AUTH)
    body_end = n - CRC_LENGTH - (MAC_LENGTH if auth else 0)
    frame = Frame(
        mtype,
        src,
        dst,
        seq,
        ts,
        echo,
        key_id,
        raw[HEADER_LENGTH : max(HEADER_LENGTH, body_end)],
        raw[body_end : n - CRC_LENGTH] if auth and body_end >= HEADER_LENGTH else None,
        int.from_bytes(raw[n - CRC_LENGTH :], "big"),
    )
    version_ok = version == PROTOCOL_VERSION and not flags & ~FLAG_AUTH
    verdicts.append(Verdict(Check.VERSION, version_ok, f"version {version}, flags 0x{flags:02x}"))
    crc_ok = zlib.crc32(raw[: n - CRC_LENGTH]) == frame.crc
    verdicts.append(Verdict(Check.CRC, crc_ok, f"0x{frame.crc:08x}"))
    try:
        message_type: MessageType | None = MessageType(mtype)
    except ValueError:
        message_type = None
    verdicts.append(
        Verdict(
            Check.TYPE,
            message_type is not None,
            message_type.name if message_type is not None else f"unknown 0x{mtype:02x}",
        )
    )
    expected = BODY_LENGTH.get(message_type) if message_type is not None else None
    body_length = body_end - HEADER_LENGTH
    length_ok = length == n and body_length >= 0 and (expected is None or expected == body_length)
    verdicts.append(Verdict(Check.LENGTH, length_ok, f"length field {length}, {n} bytes"))
    if expect_source is not None:
        verdicts.append(Verdict(Check.SOURCE, src == expect_source, f"source {src}"))
    if expect_destination is not None:
        verdicts.append(Verdict(Check.DESTINATION, dst == expect_destination, f"dest {dst}"))
    verdicts.append(_auth_verdict(raw, frame, auth, keys, message_type))
    message = None
    if message_type is not None and length_ok:
        try:
            message = decode_body(mtype, frame.body)
            verdicts.append(Verdict(Check.BODY, True))
        except FrameError as exc:
            if exc.check is Check.LENGTH:
                # a list count or text length that disagrees with the body is a length
                # failure (spec 5.4 #13): it replaces the frame-length verdict
                verdicts[:] = [
                    Verdict(Check.LENGTH, False, exc.detail) if v.check is Check.LENGTH else v
                    for v in verdicts
                ]
                verdicts.append(Verdict(Check.BODY, None, "not decoded: length failed"))
            else:
                verdicts.append(Verdict(Check.BODY, False, exc.detail))
    else:
        verdicts.append(Verdict(Check.BODY, None, "not decoded: type or length failed"))
    for check in (Check.SEQUENCE, Check.TIMESTAMP, Check.DELAY):
        verdicts.append(Verdict(check, None, "needs connection state"))
    trusted = all(v.ok is not False for v in verdicts)
    return FrameReport(raw, frame, message if trusted else None, tuple(verdicts))


def _auth_verdict(
    raw: bytes, frame: Frame, auth: bool, keys: KeyStore | None, mtype: MessageType | None
) -> Verdict:
    """The AUTH verdict without connection state, which means choosing the train's key.

    The train is the source of an uplink frame and the destination of a downlink frame. A
    HEARTBEAT (allowed both ways) and a frame of unknown type have no fixed direction: the
    source id is tried as the train first, then the destination id, and the first of them
    that has key id ``frame.key_id`` in ``keys`` is the train; the MAC is checked with that
    key only. The ground id is never a train id, so in a well-formed key file at most one of
    the two has keys. The detail names the train whose key verified (or failed) the MAC.
    """
    if not auth:
        return Verdict(Check.AUTH, None if frame.key_id == 0 else False, "not authenticated")
    if frame.key_id == 0 or frame.mac is None:
        return Verdict(Check.AUTH, False, "AUTH flag with key id 0")
    if keys is None:
        return Verdict(Check.AUTH, None, f"key id {frame.key_id}; no key store given")
    direction = MESSAGE_CLASSES[mtype].DIRECTION if mtype is not None else LinkDirection.BOTH
    candidates = {
        LinkDirection.UPLINK: (frame.source_id,),
        LinkDirection.DOWNLINK: (frame.destination_id,),
        LinkDirection.BOTH: (frame.source_id, frame.destination_id),
    }[direction]
    for train in candidates:
        key = keys.lookup(train, frame.key_id)
        if key is not None:
            if hmac.compare_digest(compute_mac(key, raw), frame.mac):
                return Verdict(
                    Check.AUTH, True, f"verified with key id {frame.key_id} of train {train}"
                )
            return Verdict(
                Check.AUTH, False, f"MAC does not match key id {frame.key_id} of train {train}"
            )
    trains = " or ".join(str(t) for t in dict.fromkeys(candidates))
    return Verdict(Check.AUTH, False, f"no key id {frame.key_id} for train {trains}")
