"""The error hierarchy shared by the simulation side of railpilot.

Each error names the offending field, the value it got and what is allowed, so a
user can fix a scenario file without reading our code.
"""

from __future__ import annotations

import math
from typing import Any


class RailpilotError(Exception):
    """Base class of every error railpilot raises on purpose."""


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
        super().__init__(f"{field} = {value!r} is not allowed: expected {allowed}")


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


def is_finite_number(value: object) -> bool:
    """A real, finite number (an int or a float, not a bool): what a check of a number
    from a file, a form or a message starts from."""
    if type(value) is float:  # the common case, checked millions of times in a line run
        return math.isfinite(value)
    return (
        isinstance(value, int | float)
        and not isinstance(value, bool)
        and math.isfinite(float(value))
    )
