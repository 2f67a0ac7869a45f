"""The dispatcher's TSR form: parse, validate, and turn into a :class:`LineTsr`.

The form speaks the dispatcher's units (km posts in km, km/h, minutes from now); the
ground speaks SI (units.py). The rules are :class:`~railpilot.ground.tsr_manager.LineTsr`'s
and the manager's; this module adds only what they cannot know: that a value is a number
at all, that the km posts lie on *this* line, and the form's field names. Every error
names the field, the value and what is allowed, in the form's units, so the page can show
it next to the field (``{field: message}``).

A source calls :func:`parse_tsr_form` once per request; the admin port and the CLI are
to share this schema (issue 11 item 6).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from railpilot.errors import ConfigError, RailpilotError
from railpilot.ground.tsr_manager import LineTsr
from railpilot.line.model import RailLine
from railpilot.units import km_post_to_m, kmh_to_mps, m_to_km_post, mps_to_kmh

from .source import TSR_FORM_FIELDS

#: Longest validity a form may ask for [min] (30 days, as the admin port).
MAX_VALIDITY_MIN = 30 * 24 * 60.0
#: Longest reason [characters] (as the admin port).
MAX_REASON_CHARS = 200
#: Highest limit a LineTsr accepts [km/h] (100 m/s).
MAX_LIMIT_KMH = mps_to_kmh(100.0)

#: LineTsr / TsrManager error field -> the form field it is about.
FORM_FIELD_OF: Mapping[str, str] = {
    "tsr.start_m": "start_km",
    "tsr.end_m": "end_km",
    "tsr.limit_mps": "limit_kmh",
    "tsr.valid_from_s": "valid_from_min",
    "tsr.valid_until_s": "valid_until_min",
    "tsr.session": "form",
    "session": "session",
}


class TsrFormError(RailpilotError):
    """The form is not a valid TSR; ``errors`` maps each bad field to its message."""

    def __init__(self, errors: Mapping[str, str]) -> None:
        self.errors = dict(errors)
        super().__init__("; ".join(f"{k}: {v}" for k, v in self.errors.items()))


def _show(value: object) -> str:
    """A value as the dispatcher typed it, quoted if it is text."""
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float) and value.is_integer():
        return f"{value:g}"
    return str(value)


def _number(value: object) -> float | None:
    """``value`` as a finite float, or None (a bool is not a number)."""
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        number = float(value)
    elif isinstance(value, str):
        try:
            number = float(value.strip())
        except ValueError:
            return None
    else:
        return None
    return number if math.isfinite(number) else None


def _blank(value: object) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


def parse_tsr_form(
    fields: Mapping[str, Any],
    *,
    line: RailLine,
    session: int,
    actor: str,
    now_s: float,
) -> LineTsr:
    """The :class:`LineTsr` the form ``fields`` describe, set by ``actor`` at ``now_s`` [s].

    ``fields`` holds :data:`~railpilot.web.source.TSR_FORM_FIELDS` as strings or numbers:
    ``start_km < end_km`` on ``line``, ``limit_kmh`` in (0, 360], ``valid_from_min``
    (blank: 0, now) and ``valid_until_min`` in minutes from now, and a ``reason``. Every
    bad field is reported at once: raises :class:`TsrFormError`.
    """
    errors: dict[str, str] = {}
    if not isinstance(fields, Mapping):
        raise TsrFormError({"form": f"{_show(fields)} is not allowed: expected a JSON object"})
    for name in fields:
        if name not in TSR_FORM_FIELDS:
            errors[str(name)] = (
                f"{_show(name)} is not a field of the TSR form: expected only "
                f"{', '.join(TSR_FORM_FIELDS)}"
            )
    values: dict[str, float] = {}
    start_km, end_km = m_to_km_post(line.start_m), m_to_km_post(line.end_m)
    numeric: dict[str, tuple[float | None, float | None, str, float | None]] = {
        # name: (low, high, what is allowed, default when blank)
        "start_km": (start_km, end_km, f"a km post on line {line.name}", None),
        "end_km": (start_km, end_km, f"a km post on line {line.name}", None),
        "limit_kmh": (None, None, "a speed in km/h", None),
        "valid_from_min": (0.0, MAX_VALIDITY_MIN, "minutes from now (blank or 0: now)", 0.0),
        "valid_until_min": (None, MAX_VALIDITY_MIN, "minutes from now", None),
    }
    for name, (low, high, what, default) in numeric.items():
        raw = fields.get(name)
        if _blank(raw):
            if default is None:
                errors[name] = f"required: {what}"
            else:
                values[name] = default
            continue
        number = _number(raw)
        bounds = f", {low:g} to {high:g}" if low is not None and high is not None else ""
        if number is None:
            errors[name] = f"{_show(raw)} is not allowed: expected a number ({what}{bounds})"
        elif (low is not None and number < low) or (high is not None and number > high):
            limits = bounds or f", at most {high:g}"
            errors[name] = f"{_show(raw)} is not allowed: expected {what}{limits}"
        else:
            values[name] = number
    reason = fields.get("reason")
    if _blank(reason):
        errors["reason"] = "required: why the restriction is set (for the log), e.g. 'track work'"
    elif not isinstance(reason, str) or len(reason) > MAX_REASON_CHARS or not reason.isprintable():
        errors["reason"] = (
            f"{_show(reason)} is not allowed: expected at most {MAX_REASON_CHARS} printable "
            "characters"
        )
    if errors:
        raise TsrFormError(errors)
    assert isinstance(reason, str)
    try:
        return LineTsr(
            session=session,
            start_m=km_post_to_m(values["start_km"]),
            end_m=km_post_to_m(values["end_km"]),
            limit_mps=kmh_to_mps(values["limit_kmh"]),
            valid_from_s=now_s + 60.0 * values["valid_from_min"],
            valid_until_s=now_s + 60.0 * values["valid_until_min"],
            reason=reason.strip(),
            set_by=actor,
        )
    except ConfigError as exc:
        raise TsrFormError(dict([form_error(exc, values)])) from None


#: How each LineTsr / TsrManager rule reads in the form's units (the rule is theirs).
_EXPECTED: Mapping[str, Callable[[Mapping[str, float]], str]] = {
    "tsr.end_m": lambda v: f"a km post above start_km = {v.get('start_km', math.nan):g}",
    "tsr.limit_mps": lambda v: f"a speed above 0 and at most {MAX_LIMIT_KMH:g} km/h",
    "tsr.valid_until_s": lambda v: (
        f"more minutes than valid_from_min = {v.get('valid_from_min', 0.0):g}, and more "
        "than 0 (the end of a TSR lies ahead)"
    ),
}
_FORM_VALUE: Mapping[str, Callable[[float], float]] = {
    "tsr.start_m": m_to_km_post,
    "tsr.end_m": m_to_km_post,
    "tsr.limit_mps": mps_to_kmh,
}


def form_error(exc: ConfigError, values: Mapping[str, float]) -> tuple[str, str]:
    """``(form field, message)`` of a :class:`ConfigError` from ``LineTsr`` or the
    ``TsrManager`` (``values``: the form's parsed numbers, for the message).

    An error about a field the form does not have goes to ``"form"`` with its own message.
    """
    field = FORM_FIELD_OF.get(exc.field)
    if field is None:
        return "form", str(exc)
    expected = _EXPECTED.get(exc.field)
    if field in values:
        shown = f"{values[field]:g}"
    elif exc.field in _FORM_VALUE and isinstance(exc.value, int | float):
        shown = f"{_FORM_VALUE[exc.field](float(exc.value)):g}"
    else:
        shown = _show(exc.value)
    return (
        field,
        f"{shown} is not allowed: expected {expected(values) if expected else exc.allowed}",
    )
