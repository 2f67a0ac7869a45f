"""The dispatcher's operations: one model per operation, its fields in the dispatcher's
units (km posts in km, speeds in km/h, times in minutes from now).

The admin port, the dashboard's form, the command line and a line run's ``[[events]]``
send the same fields; a form sends text, so each field reads a number or a word from text
too, and a blank field is a field left out. A field's check, its error's words and its
JSON Schema come from one declaration (a :class:`FormField`); the km posts' bounds are
the line's, given when a request is read (``context``). The rules that need the line's
layout or several fields (a block section of the line, an end above the start, a TSR that
ends ahead) are the ground's, railpilot.ground.operations, which reads the requests.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

from pydantic import BaseModel, ConfigDict, Field, GetCoreSchemaHandler, create_model
from pydantic_core import PydanticCustomError, core_schema

from railpilot.units import mps_to_kmh

#: Longest validity a TSR may ask for [min] (30 days).
MAX_VALIDITY_MIN = 30 * 24 * 60.0
#: Longest reason [characters].
MAX_REASON_CHARS = 200
#: Longest dispatch command text [bytes of UTF-8] (the link's limit).
MAX_TEXT_BYTES = 1000
#: Highest TSR limit [km/h] (a LineTsr's 100 m/s).
MAX_LIMIT_KMH = float(mps_to_kmh(100.0))
#: Most train ids one request may name.
MAX_TRAINS = 5000
#: The largest train id, session, restriction id and command number (the link's 32 bits).
U32_MAX = 0xFFFF_FFFF
#: The reasons a dispatcher may declare a restriction for, and give a target point.
DECLARED_REASONS = ("section_fault", "switch_indication_lost")
TARGET_REASONS = ("train_ahead", "switch_indication_lost", "section_fault", "other")
#: The tracks a restriction on a span of line holds on.
TRACKS = ("up", "down", "both")

#: a field's fault: its value is refused (``expected``), or it is required (``what``)
REFUSED = "operation_refused"
REQUIRED = "operation_required"


def blank(value: object) -> bool:
    """A field left out: absent, or a form's empty text."""
    return value is None or (isinstance(value, str) and not value.strip())


def _refused(expected: str) -> PydanticCustomError:
    return PydanticCustomError(REFUSED, "{expected}", {"expected": expected})


def _required(what: str) -> PydanticCustomError:
    return PydanticCustomError(REQUIRED, "required: {what}", {"what": what})


@dataclass(frozen=True)
class FormField:
    """One field of an operation: how it is read from a request and what its error and
    its JSON Schema say. ``required``: an operation's request must give it."""

    required: bool = False

    def read(self, value: Any, context: Mapping[str, Any]) -> Any:
        raise NotImplementedError

    def json_schema(self) -> dict[str, Any]:
        raise NotImplementedError

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        def read(value: Any, info: core_schema.ValidationInfo) -> Any:
            return self.read(value, info.context or {})

        return core_schema.with_info_plain_validator_function(read)

    def __get_pydantic_json_schema__(self, schema: Any, handler: Any) -> dict[str, Any]:
        return self.json_schema()


@dataclass(frozen=True)
class Number(FormField):
    """A finite number in ``[lo, hi]``, or a form's text of one (``"12.5"``); ``default``
    for a blank field (none: the field is required). A km post's ``what`` names the line
    (``{line}``) and its bounds are the line's (``lo``, ``hi`` None)."""

    what: str = ""
    lo: float | None = None
    hi: float | None = None
    default: float | None = None

    def read(self, value: Any, context: Mapping[str, Any]) -> float:
        what = self.what.format(line=context.get("line", "?"))
        lo = self.lo if self.lo is not None else context.get("km_lo", -math.inf)
        hi = self.hi if self.hi is not None else context.get("km_hi", math.inf)
        if blank(value):
            if self.default is not None:
                return self.default
            raise _required(what)
        number: float | None = None
        if isinstance(value, int | float) and not isinstance(value, bool):
            try:  # an int no float holds (10**400) is no number either
                number = float(value)
            except OverflowError:
                number = None
        elif isinstance(value, str):
            try:
                number = float(value.strip())
            except ValueError:
                number = None
        if number is None or not math.isfinite(number):
            raise _refused(f"a number ({what}, {lo:g} to {hi:g})")
        if not lo <= number <= hi:
            raise _refused(f"{what}, {lo:g} to {hi:g}")
        return number

    def json_schema(self) -> dict[str, Any]:
        what = self.what.replace("on line {line}", "on the line")
        out: dict[str, Any] = {"type": "number", "description": what}
        if self.lo is not None and self.hi is not None:
            out |= {"minimum": self.lo, "maximum": self.hi}
        if self.default is not None:
            out["default"] = self.default
        return out


@dataclass(frozen=True)
class Whole(FormField):
    """An integer in ``[lo, hi]``, or a form's digits; None for a blank field."""

    what: str = ""
    lo: int = 1
    hi: int = U32_MAX

    def read(self, value: Any, context: Mapping[str, Any]) -> int | None:
        if blank(value):
            if self.required:
                raise _required(self.what)
            return None
        if isinstance(value, str) and value.strip().isdigit():
            value = int(value.strip())
        if type(value) is not int or not self.lo <= value <= self.hi:
            raise _refused(f"{self.what}, an integer in [{self.lo}, {self.hi}]")
        return value

    def json_schema(self) -> dict[str, Any]:
        return {"type": "integer", "minimum": self.lo, "maximum": self.hi, "description": self.what}


@dataclass(frozen=True)
class Text(FormField):
    """Printable text of at most ``max_len`` characters, stripped; "" for a blank field."""

    what: str = ""
    max_len: int = MAX_REASON_CHARS

    def read(self, value: Any, context: Mapping[str, Any]) -> str:
        if blank(value):
            if self.required:
                raise _required(self.what)
            return ""
        if not isinstance(value, str) or len(value) > self.max_len or not value.isprintable():
            raise _refused(f"{self.what}, at most {self.max_len} printable characters")
        return value.strip()

    def json_schema(self) -> dict[str, Any]:
        return {"type": "string", "maxLength": self.max_len, "description": self.what}


@dataclass(frozen=True)
class Word(FormField):
    """One of ``options``, in any case, ``-`` for ``_``; ``default`` for a blank field
    (none: the field is required)."""

    options: tuple[str, ...] = ()
    default: str | None = None

    def read(self, value: Any, context: Mapping[str, Any]) -> str:
        if blank(value) and self.default is not None:
            return self.default
        word = value.strip().lower().replace("-", "_") if isinstance(value, str) else None
        if word is None or word not in self.options:
            if blank(value):
                raise _required(f"one of {', '.join(self.options)}")
            raise _refused(f"one of {', '.join(self.options)}")
        return word

    def json_schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"enum": list(self.options)}
        if self.default is not None:
            out["default"] = self.default
        return out


@dataclass(frozen=True)
class Trains(FormField):
    """Train ids, each once (a list, or a form's ``"1001, 1002"``); ``"all"`` where
    ``allow_all`` (every train the ground knows); ``()`` for a field left out."""

    allow_all: bool = False

    def read(self, value: Any, context: Mapping[str, Any]) -> tuple[int, ...]:
        raw = value
        if raw is None:
            if self.required and not self.allow_all:
                raise _required("a list of train ids")
            return ()
        if self.allow_all and raw == "all":
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
            also = "'all' or " if self.allow_all else ""
            raise _refused(f"{also}a list of train ids in [1, {U32_MAX}]")
        return tuple(dict.fromkeys(raw))

    def json_schema(self) -> dict[str, Any]:
        ids = {
            "type": "array",
            "items": {"type": "integer", "minimum": 1, "maximum": U32_MAX},
            "minItems": 1,
            "maxItems": MAX_TRAINS,
        }
        return {"anyOf": [ids, {"const": "all"}]} if self.allow_all else ids


@dataclass(frozen=True)
class BlockId(FormField):
    """A block section's id, as given: that it names one of the line's is the ground's
    rule."""

    def read(self, value: Any, context: Mapping[str, Any]) -> Any:
        return value

    def json_schema(self) -> dict[str, Any]:
        return {"type": "string", "description": "the id of a block section of the line"}


class OperationFields(BaseModel):
    """An operation's fields; a field it does not have is refused."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    #: the operation's name (``op``)
    OP: ClassVar[str] = ""

    @classmethod
    def field_kinds(cls) -> dict[str, FormField]:
        """Each field's :class:`FormField`, in the order the operation lists them."""
        kinds = {
            name: [m for m in info.metadata if isinstance(m, FormField)]
            for name, info in cls.model_fields.items()
        }
        # a line run's event adds at_min and op, which are no form's fields
        return {name: found[0] for name, found in kinds.items() if found}

    @classmethod
    def __get_pydantic_json_schema__(cls, schema: Any, handler: Any) -> dict[str, Any]:
        out: dict[str, Any] = handler(schema)
        out = handler.resolve_ref_schema(out)
        required = [name for name, kind in cls.field_kinds().items() if kind.required]
        if required:
            out["required"] = [*out.get("required", []), *required]
        return out


def _field(kind: FormField) -> Any:
    return Annotated[Any, kind, Field(default=None, validate_default=True)]


def _operation(op: str, doc: str, **fields: FormField) -> type[OperationFields]:
    model: type[OperationFields] = create_model(  # type: ignore[call-overload]
        "".join(part.title() for part in op.split("_")) + "Fields",
        __base__=OperationFields,
        __doc__=doc,
        **{name: (_field(kind), None) for name, kind in fields.items()},
    )
    model.OP = op
    return model


KM_POST = "a km post on line {line}"
MINUTES = "minutes from now"

#: Every operation's fields, in the order the operation lists them (required first).
OPERATIONS: dict[str, type[OperationFields]] = {
    model.OP: model
    for model in (
        _operation(
            "tsr_set",
            "Set a temporary speed restriction on a span of line.",
            start_km=Number(True, KM_POST),
            end_km=Number(True, KM_POST),
            limit_kmh=Number(True, "a speed in km/h", 0.0, MAX_LIMIT_KMH),
            valid_until_min=Number(True, MINUTES, 0.0, MAX_VALIDITY_MIN),
            reason=Text(True, "why the restriction is set, e.g. 'track work'"),
            valid_from_min=Number(
                False, f"{MINUTES} (blank or 0: now)", 0.0, MAX_VALIDITY_MIN, default=0.0
            ),
            session=Whole(False, "a TSR session number"),
            trains=Trains(False),
        ),
        _operation("tsr_cancel", "Cancel a TSR.", session=Whole(True, "a TSR session number")),
        _operation(
            "restriction_set",
            "Declare a section fault or a lost switch indication, on a block section "
            "(``block``) or a span of line (``start_km``, ``end_km``, ``track``).",
            reason=Word(True, DECLARED_REASONS),
            block=BlockId(False),
            start_km=Number(False, KM_POST),
            end_km=Number(False, KM_POST),
            track=Word(False, TRACKS, default="both"),
            id=Whole(False, "a restriction id"),
        ),
        _operation("restriction_clear", "Clear a restriction.", id=Whole(True, "a restriction id")),
        _operation(
            "target",
            "Give trains a target point by hand.",
            trains=Trains(True),
            km=Number(True, "the red signal's km post on line {line}"),
            reason=Word(False, TARGET_REASONS, default="other"),
        ),
        _operation(
            "dispatch",
            "Send a dispatch command.",
            trains=Trains(True, allow_all=True),
            text=Text(True, "the command's text", MAX_TEXT_BYTES),
            command=Whole(False, "a command number"),
        ),
        _operation("status", "The ground's status."),
    )
}
#: The operations' names.
OPS = tuple(OPERATIONS)


def expected_fields(op: str) -> Sequence[str]:
    """The fields of operation ``op``, as an error lists them."""
    return tuple(OPERATIONS[op].model_fields)
