"""The dispatcher's operations: one schema for the admin port, the HTTP API and the CLI.

Every way a dispatcher acts on the ground sends the same request: an operation name and
its fields, in the dispatcher's units (km posts in km, speeds in km/h, times in minutes
from now). :func:`parse_operation` validates it once, against the line, and returns a
typed operation for :class:`~railpilot.ground.dispatch.GroundDispatch` to carry out:

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

from railpilot.errors import ConfigError, RailpilotError, is_finite_number, readable, shown
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link.messages import U32_MAX, TargetReason, TravelDirection
from railpilot.units import km_post_to_m, kmh_to_mps, m_to_km_post, mps_to_kmh

from .occupancy import blocks_by_id
from .targets import DECLARED_REASONS, DeclaredRestriction
from .tsr_manager import LineTsr

#: Longest validity a TSR may ask for [min] (30 days).
MAX_VALIDITY_MIN = 30 * 24 * 60.0
#: Longest reason [characters].
MAX_REASON_CHARS = 200
#: Longest dispatch command text [bytes of UTF-8] (the link's limit).
MAX_TEXT_BYTES = 1000
#: Highest TSR limit [km/h] (a LineTsr's 100 m/s).
MAX_LIMIT_KMH = mps_to_kmh(100.0)
#: Most train ids one request may name.
MAX_TRAINS = 5000


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

#: Each operation's fields: (required, optional).
FIELDS: Mapping[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "tsr_set": (
        ("start_km", "end_km", "limit_kmh", "valid_until_min", "reason"),
        ("valid_from_min", "session", "trains"),
    ),
    "tsr_cancel": (("session",), ()),
    "restriction_set": (("reason",), ("block", "start_km", "end_km", "track", "id")),
    "restriction_clear": (("id",), ()),
    "target": (("trains", "km"), ("reason",)),
    "dispatch": (("trains", "text"), ("command",)),
    "status": ((), ()),
}
OPS = tuple(FIELDS)


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


def _blank(value: object) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


class _Fields:
    """Reads one request's fields, collecting an error per bad field."""

    def __init__(self, fields: Mapping[str, Any]) -> None:
        self.fields = fields
        self.errors: dict[str, str] = {}

    def bad(self, name: str, value: object, expected: str) -> None:
        self.errors.setdefault(name, f"{_show(value)} is not allowed: expected {expected}")

    def present(self, name: str) -> bool:
        return not _blank(self.fields.get(name))

    def number(
        self, name: str, what: str, lo: float, hi: float, default: float | None = None
    ) -> float:
        """A finite number in [lo, hi]; a form's text is accepted ("12.5")."""
        raw = self.fields.get(name)
        if _blank(raw):
            if default is not None:
                return default
            self.errors.setdefault(name, f"required: {what}")
            return math.nan
        value: float | None = None
        if isinstance(raw, int | float) and not isinstance(raw, bool):
            # an int no float holds (10**400) is no number either
            value = float(raw) if is_finite_number(raw) else None
        elif isinstance(raw, str):
            try:
                value = float(raw.strip())
            except ValueError:
                value = None
        if value is None or not math.isfinite(value):
            self.bad(name, raw, f"a number ({what}, {lo:g} to {hi:g})")
            return math.nan
        if not lo <= value <= hi:
            self.bad(name, raw, f"{what}, {lo:g} to {hi:g}")
            return math.nan
        return value

    def integer(self, name: str, what: str, lo: int, hi: int) -> int | None:
        raw = self.fields.get(name)
        if _blank(raw):
            return None
        value = raw
        if isinstance(raw, str) and raw.strip().isdigit():
            value = int(raw.strip())
        if type(value) is not int or not lo <= value <= hi:
            self.bad(name, raw, f"{what}, an integer in [{lo}, {hi}]")
            return None
        return value

    def text(self, name: str, what: str, max_len: int, *, required: bool) -> str:
        raw = self.fields.get(name)
        if _blank(raw):
            if required:
                self.errors.setdefault(name, f"required: {what}")
            return ""
        if not isinstance(raw, str) or len(raw) > max_len or not raw.isprintable():
            self.bad(name, raw, f"{what}, at most {max_len} printable characters")
            return ""
        return raw.strip()

    def choice(self, name: str, choices: Mapping[str, Any], default: str | None) -> Any:
        raw = self.fields.get(name)
        if _blank(raw) and default is not None:
            return choices[default]
        key = raw.strip().lower().replace("-", "_") if isinstance(raw, str) else None
        if key is None or key not in choices:
            if _blank(raw):
                self.errors.setdefault(name, f"required: one of {', '.join(choices)}")
            else:
                self.bad(name, raw, f"one of {', '.join(choices)}")
            return None
        return choices[key]

    def trains(self, *, allow_all: bool) -> tuple[int, ...]:
        """Train ids (``()`` for ``"all"`` where allowed, or when absent)."""
        raw = self.fields.get("trains")
        if raw is None:
            return ()
        if allow_all and raw == "all":
            return ()
        if isinstance(raw, str):  # a form's "1001, 1002"
            parts = [p for p in raw.replace(",", " ").split() if p]
            raw = [int(p) if p.isdigit() else p for p in parts]
        if (
            not isinstance(raw, list | tuple)
            or not raw
            or len(raw) > MAX_TRAINS
            or not all(type(t) is int and 1 <= t <= U32_MAX for t in raw)
        ):
            also = "'all' or " if allow_all else ""
            self.bad(
                "trains", self.fields.get("trains"), f"{also}a list of train ids in [1, {U32_MAX}]"
            )
            return ()
        return tuple(dict.fromkeys(raw))


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
    if not isinstance(op, str) or op not in FIELDS:  # JSON gives lists and objects too
        raise OperationError(
            {"op": f"{_show(op)} is not allowed: expected one of {', '.join(OPS)}"}
        )
    if not isinstance(fields, Mapping):
        raise OperationError({"form": f"{_show(fields)} is not allowed: expected a JSON object"})
    required, optional = FIELDS[op]
    f = _Fields(fields)
    for name in fields:
        if name not in required and name not in optional:
            allowed = ", ".join(required + optional) or "none"
            f.errors[str(name)] = f"{_show(name)} is not a field of {op}: expected only {allowed}"
    result = _PARSERS[op](f, line, now_s)
    if f.errors:
        raise OperationError(f.errors)
    return result


def _km_range(f: _Fields, line: RailLine) -> tuple[float, float]:
    lo, hi = m_to_km_post(line.start_m), m_to_km_post(line.end_m)
    what = f"a km post on line {line.name}"
    start = f.number("start_km", what, lo, hi)
    end = f.number("end_km", what, lo, hi)
    # in whole cm, as the link carries km posts: 1 mm apart is the same post on the wire
    if math.isfinite(start) and math.isfinite(end) and round(end * 1e5) <= round(start * 1e5):
        f.bad(
            "end_km", f.fields.get("end_km"), f"a km post at least 1 cm above start_km = {start:g}"
        )
    return km_post_to_m(start), km_post_to_m(end)


def _tsr_set(f: _Fields, line: RailLine, now_s: float) -> SetTsr:
    start_m, end_m = _km_range(f, line)
    limit = f.number("limit_kmh", "a speed in km/h", 0.0, MAX_LIMIT_KMH)
    if limit == 0.0:
        above = f"a speed above 0 and at most {MAX_LIMIT_KMH:g} km/h"
        f.bad("limit_kmh", f.fields.get("limit_kmh"), above)
    minutes = "minutes from now"
    valid_from = f.number(
        "valid_from_min", f"{minutes} (blank or 0: now)", 0.0, MAX_VALIDITY_MIN, 0.0
    )
    valid_until = f.number("valid_until_min", minutes, 0.0, MAX_VALIDITY_MIN)
    if math.isfinite(valid_from) and math.isfinite(valid_until) and not valid_until > valid_from:
        f.bad(
            "valid_until_min",
            f.fields.get("valid_until_min"),
            f"more minutes than valid_from_min = {valid_from:g} (the end of a TSR lies ahead)",
        )
    reason = f.text(
        "reason", "why the restriction is set, e.g. 'track work'", MAX_REASON_CHARS, required=True
    )
    session = f.integer("session", "a TSR session number", 1, U32_MAX)
    trains = f.trains(allow_all=False)
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
    session = f.integer("session", "a TSR session number", 1, U32_MAX)
    if session is None:
        f.errors.setdefault("session", "required: a TSR session number")
    return CancelTsr(session or 0)


def _restriction_set(f: _Fields, line: RailLine, now_s: float) -> SetRestriction:
    reason = f.choice("reason", _DECLARED, None)
    ident = f.integer("id", "a restriction id", 1, U32_MAX)
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
        track = f.choice("track", _TRACKS, "both")
        if reason is not None and not f.errors:
            restriction = DeclaredRestriction.on_span(start_m, end_m, reason, track)
    if restriction is None:  # every way here has recorded its error
        return SetRestriction(DeclaredRestriction.on_block("-", DECLARED_REASONS[0]), ident)
    return SetRestriction(restriction, ident)


def _restriction_clear(f: _Fields, line: RailLine, now_s: float) -> ClearRestriction:
    ident = f.integer("id", "a restriction id", 1, U32_MAX)
    if ident is None:
        f.errors.setdefault("id", "required: a restriction id")
    return ClearRestriction(ident or 0)


def _target(f: _Fields, line: RailLine, now_s: float) -> SendTarget:
    trains = f.trains(allow_all=False)
    if not trains:
        f.errors.setdefault("trains", "required: a list of train ids")
    lo, hi = m_to_km_post(line.start_m), m_to_km_post(line.end_m)
    km = f.number("km", f"the red signal's km post on line {line.name}", lo, hi)
    reason = f.choice("reason", _TARGET_REASONS, "other")
    return SendTarget(trains, km_post_to_m(km), reason or TargetReason.OTHER)


def _dispatch(f: _Fields, line: RailLine, now_s: float) -> SendDispatch:
    trains = f.trains(allow_all=True)
    text = f.text("text", "the command's text", MAX_TEXT_BYTES, required=True)
    if len(text.encode()) > MAX_TEXT_BYTES:
        f.bad("text", text, f"at most {MAX_TEXT_BYTES} bytes of UTF-8")
    command = f.integer("command", "a command number", 1, U32_MAX)
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
