"""The dispatcher's operations: one schema for the admin port, the HTTP API and the CLI.

Every way a dispatcher acts on the ground sends the same request: an operation name and
its fields, in the dispatcher's units (km posts in km, speeds in km/h, times in minutes
from now). Each operation's fields are one model (railpilot.schema.operations, also the
JSON Schema of a line run's ``[[events]]``); :func:`parse_operation` reads a request by it,
checks the rules that need the line or several fields, and returns a typed operation for
:class:`~railpilot.ground.dispatch.GroundDispatch` to carry out:

=====================  =========================================================================
operation              fields (``?``: optional)
=====================  =========================================================================
``tsr_set``            ``start_km``, ``end_km``, ``limit_kmh``, ``valid_until_min``,
                       ``valid_from_min?`` (0: now), ``reason``, ``session?`` (the ground's next
                       otherwise), ``trains?`` (ids that get it whatever the ground's view of
                       them; the ground adds every train it concerns)
``tsr_cancel``         ``session``
``restriction_set``    ``reason`` (``section_fault`` or ``switch_indication_lost``) and either
                       ``block`` (a block section id) or ``start_km``, ``end_km`` and
                       ``track?`` (``up``, ``down``, ``both``: the default); ``id?``
``restriction_clear``  ``id``
``target``             ``trains``, ``km``, ``reason?`` (``other``): a target point by hand
``dispatch``           ``trains`` (ids or ``"all"``), ``text``, ``command?`` (the next number)
``status``             none
=====================  =========================================================================

Errors are collected for every field at once and raised as one :class:`OperationError`,
whose ``errors`` maps each bad field to "<value> is not allowed: expected <what>" (the
dashboard shows each next to its field; the admin port and the CLI print them).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic_core import PydanticCustomError

from railpilot.errors import ConfigError, RailpilotError, readable, shown
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link.messages import TargetReason, TravelDirection
from railpilot.schema.operations import (
    MAX_LIMIT_KMH,
    MAX_REASON_CHARS,
    MAX_TEXT_BYTES,
    MAX_TRAINS,
    MAX_VALIDITY_MIN,
    OPERATIONS,
    OPS,
    REFUSED,
    blank,
    expected_fields,
)
from railpilot.units import km_post_to_m, kmh_to_mps, m_to_km_post

from .occupancy import blocks_by_id
from .targets import DECLARED_REASONS, DeclaredRestriction
from .tsr_manager import LineTsr

__all__ = [
    "FIELDS",
    "MAX_LIMIT_KMH",
    "MAX_REASON_CHARS",
    "MAX_TEXT_BYTES",
    "MAX_TRAINS",
    "MAX_VALIDITY_MIN",
    "OPS",
    "CancelTsr",
    "ClearRestriction",
    "Operation",
    "OperationError",
    "SendDispatch",
    "SendTarget",
    "SetRestriction",
    "SetTsr",
    "Status",
    "config_error_field",
    "parse_operation",
]


class OperationError(RailpilotError):
    """A request that is not a valid operation; ``errors`` maps each bad field to why."""

    def __init__(self, errors: Mapping[str, str]) -> None:
        self.errors = dict(errors)
        super().__init__("; ".join(f"{k}: {v}" for k, v in self.errors.items()))


# ---------------------------------------------------------------------------- operations


@dataclass(frozen=True)
class SetTsr:
    """Set a TSR for the line (SI; times on the ground clock [s])."""

    start_m: float
    end_m: float
    limit_mps: float
    valid_from_s: float
    valid_until_s: float
    reason: str
    session: int | None = None
    trains: tuple[int, ...] = ()

    def line_tsr(self, session: int, set_by: str) -> LineTsr:
        return LineTsr(
            session,
            self.start_m,
            self.end_m,
            self.limit_mps,
            self.valid_from_s,
            self.valid_until_s,
            self.reason,
            set_by,
        )


@dataclass(frozen=True)
class CancelTsr:
    session: int


@dataclass(frozen=True)
class SetRestriction:
    """Declare a section fault or a lost switch indication (holds signals at red)."""

    restriction: DeclaredRestriction
    restriction_id: int | None = None


@dataclass(frozen=True)
class ClearRestriction:
    restriction_id: int


@dataclass(frozen=True)
class SendTarget:
    """A target point by hand (the ground computes its own from occupancy)."""

    trains: tuple[int, ...]
    position_m: float
    reason: TargetReason


@dataclass(frozen=True)
class SendDispatch:
    """A dispatch command; ``trains`` empty means every train the ground knows."""

    trains: tuple[int, ...]
    text: str
    command: int | None = None


@dataclass(frozen=True)
class Status:
    pass


Operation = (
    SetTsr | CancelTsr | SetRestriction | ClearRestriction | SendTarget | SendDispatch | Status
)

#: Each operation's fields: (required, optional), from its model.
FIELDS: Mapping[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    op: (
        tuple(name for name, kind in model.field_kinds().items() if kind.required),
        tuple(name for name, kind in model.field_kinds().items() if not kind.required),
    )
    for op, model in OPERATIONS.items()
}

# ---------------------------------------------------------------------------- parsing


def _show(value: object) -> str:
    """A value as the dispatcher typed it: a number as is (a form and the CLI send text),
    other text quoted; readable however long (errors.readable)."""
    return readable(_as_typed(value))


def _as_typed(value: object) -> str:
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return repr(value)
        return value.strip()
    if isinstance(value, float) and value.is_integer():
        return f"{value:g}"
    if isinstance(value, int) and not isinstance(value, bool):
        return shown(value)  # as written; a 400-digit one as 1.000e+400
    return repr(value) if value is None or isinstance(value, bool) else str(value)


class _Fields:
    """One request's fields as read by the operation's model, collecting an error per bad
    field as the operation reads it (so they come in the operation's order)."""

    def __init__(self, fields: Mapping[str, Any], read: Mapping[str, Any]) -> None:
        self.fields = fields
        self.read = read
        self.errors: dict[str, str] = {}

    def bad(self, name: str, value: object, expected: str) -> None:
        self.errors.setdefault(name, f"{_show(value)} is not allowed: expected {expected}")

    def present(self, name: str) -> bool:
        return not blank(self.fields.get(name))

    def get(self, name: str, fallback: Any) -> Any:
        """The field's value, or ``fallback`` once its error is recorded."""
        value = self.read[name]
        if isinstance(value, _Fault):
            self.errors.setdefault(name, value.message)
            return fallback
        return value

    def number(self, name: str) -> float:
        value: float = self.get(name, math.nan)
        return value

    def integer(self, name: str) -> int | None:
        value: int | None = self.get(name, None)
        return value

    def text(self, name: str) -> str:
        value: str = self.get(name, "")
        return value

    def choice(self, name: str, choices: Mapping[str, Any]) -> Any:
        word = self.get(name, None)
        return None if word is None else choices[word]

    def trains(self) -> tuple[int, ...]:
        value: tuple[int, ...] = self.get("trains", ())
        return value


@dataclass(frozen=True)
class _Fault:
    """A field its kind refused: the error's message."""

    message: str


def _read(op: str, fields: Mapping[str, Any], line: RailLine) -> dict[str, Any]:
    """Each field of operation ``op`` read from ``fields`` by its kind (railpilot.schema.
    operations), or the :class:`_Fault` it refused it for."""
    context = {
        "line": line.name,
        "km_lo": m_to_km_post(line.start_m),
        "km_hi": m_to_km_post(line.end_m),
    }
    out: dict[str, Any] = {}
    for name, kind in OPERATIONS[op].field_kinds().items():
        raw = fields.get(name)
        try:
            out[name] = kind.read(raw, context)
        except PydanticCustomError as fault:
            if fault.type == REFUSED:
                expected = (fault.context or {})["expected"]
                out[name] = _Fault(f"{_show(raw)} is not allowed: expected {expected}")
            else:
                out[name] = _Fault(fault.message())
    return out


_TARGET_REASONS = {r.name.lower(): r for r in TargetReason}
_DECLARED = {r.name.lower(): r for r in DECLARED_REASONS}
_TRACKS: Mapping[str, TravelDirection | None] = {"up": UP, "down": DOWN, "both": None}


def parse_operation(
    op: object, fields: Mapping[str, Any], *, line: RailLine, now_s: float
) -> Operation:
    """The operation ``op`` with ``fields`` asks for, checked against ``line`` at ``now_s``.

    Raises :class:`OperationError` naming every bad field; unknown fields are errors too
    (a misspelt optional field must not be silently ignored).
    """
    if not isinstance(op, str) or op not in OPERATIONS:  # JSON gives lists and objects too
        raise OperationError(
            {"op": f"{_show(op)} is not allowed: expected one of {', '.join(OPS)}"}
        )
    if not isinstance(fields, Mapping):
        raise OperationError({"form": f"{_show(fields)} is not allowed: expected a JSON object"})
    known = expected_fields(op)
    f = _Fields(fields, _read(op, fields, line))
    for name in fields:
        if name not in known:
            allowed = ", ".join(known) or "none"
            f.errors[str(name)] = f"{_show(name)} is not a field of {op}: expected only {allowed}"
    result = _PARSERS[op](f, line, now_s)
    if f.errors:
        raise OperationError(f.errors)
    return result


def _km_range(f: _Fields, line: RailLine) -> tuple[float, float]:
    start = f.number("start_km")
    end = f.number("end_km")
    # in whole cm, as the link carries km posts: 1 mm apart is the same post on the wire
    if math.isfinite(start) and math.isfinite(end) and round(end * 1e5) <= round(start * 1e5):
        f.bad(
            "end_km", f.fields.get("end_km"), f"a km post at least 1 cm above start_km = {start:g}"
        )
    return km_post_to_m(start), km_post_to_m(end)


def _tsr_set(f: _Fields, line: RailLine, now_s: float) -> SetTsr:
    start_m, end_m = _km_range(f, line)
    limit = f.number("limit_kmh")
    if limit == 0.0:
        above = f"a speed above 0 and at most {MAX_LIMIT_KMH:g} km/h"
        f.bad("limit_kmh", f.fields.get("limit_kmh"), above)
    valid_from = f.number("valid_from_min")
    valid_until = f.number("valid_until_min")
    if math.isfinite(valid_from) and math.isfinite(valid_until) and not valid_until > valid_from:
        f.bad(
            "valid_until_min",
            f.fields.get("valid_until_min"),
            f"more minutes than valid_from_min = {valid_from:g} (the end of a TSR lies ahead)",
        )
    reason = f.text("reason")
    session = f.integer("session")
    trains = f.trains()
    return SetTsr(
        start_m,
        end_m,
        kmh_to_mps(limit),
        now_s + 60.0 * valid_from,
        now_s + 60.0 * valid_until,
        reason,
        session,
        trains,
    )


def _tsr_cancel(f: _Fields, line: RailLine, now_s: float) -> CancelTsr:
    session = f.integer("session")
    return CancelTsr(session or 0)


def _restriction_set(f: _Fields, line: RailLine, now_s: float) -> SetRestriction:
    reason = f.choice("reason", _DECLARED)
    ident = f.integer("id")
    has_block, has_span = f.present("block"), f.present("start_km") or f.present("end_km")
    restriction: DeclaredRestriction | None = None
    if has_block == has_span:
        f.errors.setdefault(
            "block",
            "required: either a block section id or start_km and end_km (not both)",
        )
    elif has_block:
        if f.present("track"):
            f.bad("track", f.fields.get("track"), "no track with a block (a block has its own)")
        block = f.fields.get("block")
        if not isinstance(block, str) or block.strip() not in blocks_by_id(line):
            f.bad("block", block, f"the id of a block section of line {line.name}")
        elif reason is not None:
            restriction = DeclaredRestriction.on_block(block.strip(), reason)
    else:
        start_m, end_m = _km_range(f, line)
        track = f.choice("track", _TRACKS)
        if reason is not None and not f.errors:
            restriction = DeclaredRestriction.on_span(start_m, end_m, reason, track)
    if restriction is None:  # every way here has recorded its error
        return SetRestriction(DeclaredRestriction.on_block("-", DECLARED_REASONS[0]), ident)
    return SetRestriction(restriction, ident)


def _restriction_clear(f: _Fields, line: RailLine, now_s: float) -> ClearRestriction:
    ident = f.integer("id")
    return ClearRestriction(ident or 0)


def _target(f: _Fields, line: RailLine, now_s: float) -> SendTarget:
    trains = f.trains()
    km = f.number("km")
    reason = f.choice("reason", _TARGET_REASONS)
    return SendTarget(trains, km_post_to_m(km), reason or TargetReason.OTHER)


def _dispatch(f: _Fields, line: RailLine, now_s: float) -> SendDispatch:
    trains = f.trains()
    text = f.text("text")
    if len(text.encode()) > MAX_TEXT_BYTES:
        f.bad("text", text, f"at most {MAX_TEXT_BYTES} bytes of UTF-8")
    command = f.integer("command")
    return SendDispatch(trains, text, command)


def _status(f: _Fields, line: RailLine, now_s: float) -> Status:
    return Status()


_PARSERS: Mapping[str, Callable[[_Fields, RailLine, float], Operation]] = {
    "tsr_set": _tsr_set,
    "tsr_cancel": _tsr_cancel,
    "restriction_set": _restriction_set,
    "restriction_clear": _restriction_clear,
    "target": _target,
    "dispatch": _dispatch,
    "status": _status,
}


def config_error_field(exc: ConfigError) -> str:
    """The request field a core rule's :class:`ConfigError` is about (``form``: none)."""
    return {
        "tsr.session": "session",
        "session": "session",
        "tsr.valid_until_s": "valid_until_min",
    }.get(exc.field, "form")
