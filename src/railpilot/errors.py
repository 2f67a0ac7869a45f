"""The error hierarchy shared by the simulation side of railpilot.

Each error names the offending field, the value it got and what is allowed, so a
user can fix a scenario file without reading our code.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal
from typing import Any

#: a run of more digits than this is no number a reader takes in (``10**400`` written out)
_LONG_DIGITS = re.compile(r"\d{31,}")


class RailpilotError(Exception):
    """Base class of every error railpilot raises on purpose."""


class _Missing:
    """The value of a key a file leaves out (:data:`MISSING`)."""

    def __repr__(self) -> str:
        return "<missing>"


#: the value a :class:`ConfigError` names for a required key that is not there: its
#: message says the key is missing instead of showing a value the file never wrote
MISSING: Any = _Missing()


class ConfigError(RailpilotError, ValueError):
    """A parameter is out of its allowed range.

    Parameters
    ----------
    field
        Dotted path of the parameter, e.g. ``"brake.air.lag_s"``.
    value
        The rejected value.
    allowed
        Human-readable statement of what is allowed, e.g. ``"a number > 0"``.
    """

    def __init__(self, field: str, value: Any, allowed: str) -> None:
        self.field = field
        self.value = value
        self.allowed = allowed
        # field and allowed may quote the file too (an entry's label, a neighbour's value)
        if value is MISSING:
            message = f"{field} is missing: expected {allowed}"
        else:
            message = f"{field} = {shown(value)} is not allowed: expected {allowed}"
        super().__init__(_shorter_numbers(message))

    def in_file(self, name: str, kind: type[ConfigError] | None = None) -> ConfigError:
        """This error named with the file it is in (``name: field = value is not
        allowed...``), as a ``kind`` (default: this error's own class); its message is
        kept as it was made (a line file's error keeps the name of the line file)."""
        named = (kind or type(self))(f"{name}: {self.field}", self.value, self.allowed)
        named.args = (f"{name}: {self}",)
        return named


class RunFailed(RailpilotError):
    """A run that cannot finish (its trains stand still for good): the command line says
    why and exits 1, writing nothing."""

    exit_code = 1


class ScenarioError(ConfigError):
    """A scenario file is malformed (unknown key, wrong type, out of range)."""


class LineError(ConfigError):
    """A line file or line model is malformed (railpilot.line).

    ``field`` names the entry as the file writes it, e.g.
    ``"gradients[3] (km 12.400-11.900).end_km"``; ``source`` (optional) is the file the
    entry came from and prefixes the message.
    """

    def __init__(self, field: str, value: Any, allowed: str, source: str | None = None) -> None:
        super().__init__(field, value, allowed)
        self.source = source
        if source is not None:
            self.args = (f"{source}: {self.args[0]}",)


#: longest value an error message quotes whole [characters]; a longer one is cut, and
#: its length said (a 10,000-character string or list in a file is a mistake to point at,
#: not to print)
MAX_SHOWN_CHARS = 200


def shown(value: object) -> str:
    """``repr(value)`` for an error message, every integer of more than 30 digits in it
    written as ``1.000e+400``: TOML integers are unbounded, and an error must stay readable;
    and cut to :data:`MAX_SHOWN_CHARS`."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**30:
        return f"{Decimal(value):.3e}"  # also past repr's limit of 4300 digits
    try:
        return readable(repr(value))
    except ValueError:  # a container holding an int past repr's limit of 4300 digits
        return f"<a {type(value).__name__} holding a number too long to write out>"


def readable(text: str) -> str:
    """A value written out, for an error message: every run of more than 30 digits as
    ``1.000e+400``, and only its start and its length if longer than
    :data:`MAX_SHOWN_CHARS`."""
    text = _shorter_numbers(text)
    if len(text) > MAX_SHOWN_CHARS:
        return f"{text[: MAX_SHOWN_CHARS - 40]}... ({len(text):,} characters)"
    return text


def _shorter_numbers(text: str) -> str:
    """``text`` with every run of more than 30 digits written as ``1.000e+400``."""
    return _LONG_DIGITS.sub(lambda digits: f"{Decimal(digits.group()):.3e}", text)


def is_finite_number(value: object) -> bool:
    """A real, finite number (an int or a float, not a bool): what a check of a number
    from a file, a form or a message starts from. An int too large for a float (TOML's
    ``10**400``) is none: every use of the number reads it as a float."""
    if type(value) is float:  # the common case, checked millions of times in a line run
        return math.isfinite(value)
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False
