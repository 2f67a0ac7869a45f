"""Byte-level framing: header byte, byte stuffing and a streaming, bounded decoder.

On the wire every frame is ``0x7E`` followed by the *stuffed* frame bytes. Stuffing
(paper 001, section 1.2 (5)): every ``0x7E`` inside the frame is sent twice. So on the
wire a single ``0x7E`` followed by anything other than ``0x7E`` always starts a frame, and
``0x7E 0x7E`` is always one data byte. The first frame byte (the version, 0x01) is never
0x7E, which keeps the start of a frame unambiguous.

The length field (frame bytes 2-3) counts the *unstuffed* frame bytes from the version byte
to the last CRC byte; it does not count the header byte or the stuffing.

:class:`FrameDecoder` never raises on input: it returns complete unstuffed frames as
``bytes`` and problems as :class:`~railpilot.link.errors.FrameError` values, and resyncs on
the next header byte.
"""

from __future__ import annotations

from .errors import FrameError, FramingError, LengthError, VersionError

HEADER_BYTE = 0x7E
HEADER = b"\x7e"
_STUFFED = b"\x7e\x7e"

#: The only protocol version this code speaks.
PROTOCOL_VERSION = 1
#: Bytes before the end of the length field: version (1), flags (1), length (2).
PREFIX_LENGTH = 4
#: Fixed header: version, flags, length, type, key id, source, destination, sequence,
#: timestamp, echo timestamp.
HEADER_LENGTH = 35
CRC_LENGTH = 4
MAC_LENGTH = 16
#: Shortest legal frame (a heartbeat without MAC) [unstuffed bytes].
MIN_FRAME_LENGTH = HEADER_LENGTH + CRC_LENGTH
#: Default and hard upper bound of the unstuffed frame length (the field is a u16).
DEFAULT_MAX_FRAME_LENGTH = 2048
ABSOLUTE_MAX_FRAME_LENGTH = 0xFFFF

_NEED_MORE = -1


def stuff(frame: bytes) -> bytes:
    """Wire bytes of one unstuffed frame: header byte + frame with every 0x7E doubled."""
    return HEADER + frame.replace(HEADER, _STUFFED)


def unstuff(data: bytes) -> bytes:
    """Inverse of the stuffing alone (without header byte); for tools and tests."""
    return data.replace(_STUFFED, HEADER)


class FrameDecoder:
    """Streaming frame decoder with a bounded buffer.

    >>> decoder = FrameDecoder()
    >>> for item in decoder.feed(data):
    ...     if isinstance(item, FrameError): ...   # framing/version/length problem
    ...     else: ...                              # item: one unstuffed frame (bytes)

    Between calls the decoder keeps at most :attr:`max_buffered_bytes` bytes (one partial,
    maximally stuffed frame); garbage between frames is counted in
    :attr:`bytes_discarded` and dropped.
    """

    def __init__(self, max_frame_length: int = DEFAULT_MAX_FRAME_LENGTH) -> None:
        if not MIN_FRAME_LENGTH + MAC_LENGTH <= max_frame_length <= ABSOLUTE_MAX_FRAME_LENGTH:
            raise ValueError(
                f"max_frame_length = {max_frame_length!r} is not allowed: expected an integer "
                f"in [{MIN_FRAME_LENGTH + MAC_LENGTH}, {ABSOLUTE_MAX_FRAME_LENGTH}]"
            )
        self.max_frame_length = max_frame_length
        #: Worst case of one partial frame: header byte + every byte stuffed.
        self.max_buffered_bytes = 1 + 2 * max_frame_length
        self._buffer = bytearray()
        self.bytes_discarded = 0

    @property
    def buffered_bytes(self) -> int:
        """Bytes held for an incomplete frame."""
        return len(self._buffer)

    def reset(self) -> None:
        """Forget any partial frame (call on a new connection)."""
        self._buffer.clear()

    def pending_frame(self) -> tuple[int, int | None] | None:
        """The incomplete frame held for more data, for a caller that knows the input ended.

        Returns ``(received, length)``: the unstuffed frame bytes received so far (a trailing
        lone ``0x7E``, which may be the first half of a stuffed pair, is not counted) and the
        frame's length field, or ``None`` for it while fewer than 4 bytes are in. Returns
        ``None`` when no frame was started. Read-only: the decoder's state is unchanged.
        """
        buf = self._buffer
        if not buf:
            return None
        # After feed() a non-empty buffer always starts at a frame's header byte.
        stuffed = bytes(buf[1:])
        if (len(stuffed) - len(stuffed.rstrip(HEADER))) % 2:
            stuffed = stuffed[:-1]
        frame = unstuff(stuffed)
        length = (frame[2] << 8) | frame[3] if len(frame) >= PREFIX_LENGTH else None
        return len(frame), length

    def feed(self, data: bytes) -> list[bytes | FrameError]:
        """Take received bytes; return the complete frames and framing problems in order."""
        out: list[bytes | FrameError] = []
        step = self.max_buffered_bytes
        # Feed in bounded slices so even one huge read never grows the buffer past
        # max_buffered_bytes + step.
        for start in range(0, len(data), step):
            self._buffer += data[start : start + step]
            self._extract(out)
        return out

    def _extract(self, out: list[bytes | FrameError]) -> None:
        buf = self._buffer
        n = len(buf)
        pos = 0
        while pos < n:
            h = buf.find(HEADER, pos)
            if h < 0:
                self.bytes_discarded += n - pos
                pos = n
                break
            if h + 1 >= n:  # cannot yet tell a header from the first half of a stuffed pair
                self.bytes_discarded += h - pos
                pos = h
                break
            if buf[h + 1] == HEADER_BYTE:  # stuffed data byte of a frame we missed: garbage
                self.bytes_discarded += h + 2 - pos
                pos = h + 2
                continue
            self.bytes_discarded += h - pos
            status, prefix = self._unstuff(buf, h + 1, PREFIX_LENGTH)
            if status == _NEED_MORE:
                pos = h
                break
            if prefix is None:  # a header byte cut the frame short; resync there
                out.append(FramingError("frame truncated by a header byte inside its length"))
                pos = status
                continue
            if prefix[0] != PROTOCOL_VERSION:
                out.append(VersionError(f"version {prefix[0]} (this code speaks 1)"))
                pos = h + 1
                continue
            length = (prefix[2] << 8) | prefix[3]
            if not MIN_FRAME_LENGTH <= length <= self.max_frame_length:
                out.append(
                    LengthError(
                        f"length field {length} outside [{MIN_FRAME_LENGTH}, "
                        f"{self.max_frame_length}]"
                    )
                )
                pos = h + 1
                continue
            status, frame = self._unstuff(buf, h + 1, length)
            if status == _NEED_MORE:
                pos = h
                break
            if frame is None:
                out.append(FramingError(f"frame of {length} bytes truncated by a header byte"))
                pos = status
                continue
            out.append(frame)
            pos = status
        if pos:
            del buf[:pos]

    @staticmethod
    def _unstuff(buf: bytearray, start: int, need: int) -> tuple[int, bytes | None]:
        """Read ``need`` unstuffed bytes from ``buf[start:]``.

        Returns ``(end, bytes)`` on success, ``(_NEED_MORE, None)`` when the buffer ends
        first, and ``(index, None)`` when a lone header byte at ``index`` interrupts.
        """
        end = start + need
        chunk = buf[start:end]
        if len(chunk) == need and HEADER_BYTE not in chunk:  # the common case: no stuffing
            return end, bytes(chunk)
        n = len(buf)
        out = bytearray()
        i = start
        while len(out) < need:
            remaining = need - len(out)
            j = buf.find(HEADER, i, i + remaining)
            if j < 0:
                out += buf[i : i + remaining]
                i += remaining
                if i > n:
                    return _NEED_MORE, None
                continue
            out += buf[i:j]
            if j + 1 >= n:
                return _NEED_MORE, None
            if buf[j + 1] != HEADER_BYTE:
                return j, None
            out.append(HEADER_BYTE)
            i = j + 2
        return i, bytes(out)
