"""Hex text of wire bytes, as people paste it: into ``railpilot link decode`` and the proxy's
``--inject``.

:func:`parse_hex` turns hex text into bytes and says exactly where it is not hex (line and
column); :func:`looks_hex` and :func:`holds_frame_start` tell hex text from raw wire bytes.
"""

from __future__ import annotations

import re

from .errors import LinkError


class DecodeInputError(LinkError, ValueError):
    """The input of a link tool cannot be read as asked: an unreadable file or bad hex text.

    The message names the input, where the problem is (line and column, both 1-based, for
    hex text) and what is allowed there; it is raised before anything is printed.
    """

    def __init__(self, field: str, problem: str, what_next: str = "nothing was decoded") -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}; {what_next}")


#: The characters of hex text once comments are gone (see :func:`looks_hex`).
_HEX_CHARS = frozenset(b"0123456789abcdefABCDEF \t\r\n:xX")
#: Every frame on the wire starts with the header byte 0x7E and the version byte 0x01.
#: Hex text never holds that pair (0x01 is a control character), a raw capture of any
#: frame always does.
_FRAME_START = b"\x7e\x01"
_HEX_ALLOWED = "allowed: 0-9 a-f A-F, whitespace, ':', '0x' prefixes, '#' comments"
_WHITESPACE = " \t\r\n\f\v"
_COMMENT = re.compile(r"#[^\n]*")
#: Anything but a hex digit, whitespace or ':', and an 'x' that does not follow a '0'
#: starting a token (the '0x' prefix). The text is searched with a '\n' in front.
_BAD_HEX = re.compile(rf"[^0-9a-fA-F{_WHITESPACE}:xX]|(?<![{_WHITESPACE}:]0)[xX]")
_PREFIX = re.compile(rf"(?<=[{_WHITESPACE}:])0[xX]")
_DIGIT_RUN = re.compile(r"[0-9a-fA-F]+")
_NOT_DIGITS = str.maketrans("", "", _WHITESPACE + ":")


def parse_hex(
    data: bytes, field: str = "input", *, what_next: str = "nothing was decoded", hint: str = ""
) -> bytes:
    """Hex text -> bytes.

    Allowed: hex digits, whitespace (space, tab, CR, LF, FF, VT), ':', a '0x' / '0X' prefix
    at the start of a token, and '#' comments to the end of the line; a UTF-8 byte-order mark
    is skipped. Digits pair up in order across separators and lines. Anything else, or an
    odd number of digits, raises :class:`DecodeInputError` naming the line and column
    (1-based, counted in characters) of the offending character or the unpaired last
    digit. ``hint`` is appended to the message when the offending character is not
    printable or is '~' (0x7E), both signs of raw bytes.
    """
    # The '\n' in front makes every line, the first included, start after a newline.
    text = "\n" + data.decode("utf-8-sig", "surrogateescape")
    if "#" in text:  # blank comments out, keeping every position
        text = _COMMENT.sub(lambda m: " " * len(m.group()), text)
    bad = _BAD_HEX.search(text)
    if bad is not None:
        i = bad.start()
        # A control character, a byte that is not UTF-8 or a '~' (0x7E, the header byte)
        # suggests a raw capture without a frame start: say why it was read as hex.
        extra = hint if not text[i].isprintable() or text[i] == "~" else ""
        raise DecodeInputError(
            field,
            f"{_position(text, i)}: {_show_char(text[i])} is not a hex digit "
            f"({_HEX_ALLOWED}){extra}",
            what_next,
        )
    if "x" in text or "X" in text:
        text = _PREFIX.sub("  ", text)
    digits = text.translate(_NOT_DIGITS)
    if len(digits) % 2:
        raise DecodeInputError(field, _odd_digits(text, len(digits)), what_next)
    return bytes.fromhex(digits)


def _position(text: str, i: int) -> str:
    """'line L, column C' of ``text[i]`` (``text`` starts with an extra '\n')."""
    return f"line {text.count(chr(10), 0, i)}, column {i - text.rfind(chr(10), 0, i)}"


def _show_char(char: str) -> str:
    if "\udc80" <= char <= "\udcff":  # a byte that is not UTF-8 (surrogateescape)
        return f"byte 0x{ord(char) - 0xDC00:02x}"
    return repr(char)


def _odd_digits(text: str, count: int) -> str:
    """The error for an odd number of digits: where the unpaired last digit is, and where
    the first run of an odd number of digits starts (often where a digit went missing)."""
    first_odd: int | None = None
    last = (0, 0)
    for run in _DIGIT_RUN.finditer(text):
        if first_odd is None and len(run.group()) % 2:
            first_odd = run.start()
        last = run.span()
    i = last[1] - 1
    message = (
        f"{_position(text, i)}: odd number of hex digits ({count}): {_show_char(text[i])} "
        "has no partner; expected hex digits in pairs"
    )
    if first_odd is not None and first_odd != last[0]:
        message += (
            " (digits pair up across separators; the first run of an odd number of digits "
            f"starts at {_position(text, first_odd)})"
        )
    return message


def looks_hex(data: bytes) -> bool:
    """Whether ``data`` is hex text: only hex digits, separators and comments (the
    fault-injection proxy's ``--inject FILE|HEX`` rule)."""
    body = b"\n".join(line.split(b"#", 1)[0] for line in data.splitlines())
    return bool(body.strip()) and all(b in _HEX_CHARS for b in body)


def holds_frame_start(data: bytes) -> bool:
    """Whether ``data`` holds a frame start, so is raw wire bytes rather than hex text (the
    decode tool's rule)."""
    return _FRAME_START in data
