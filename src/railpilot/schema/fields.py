"""The pieces a file format's models are written with, and the words their errors use.

A format is a tree of :class:`FileTable` models (pydantic v2): a key's type and bounds are
declared once, and give both the check when a file is read and the key's JSON Schema. What
the error says is allowed is derived from the same declaration (``a finite number >= 0 and
<= 1000 [mm]``, ``one of wagon, locomotive``); :class:`Unit` adds the unit to it and
:class:`Says` replaces it where a format words a key its own way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Union

from pydantic import BaseModel, ConfigDict, Discriminator, GetCoreSchemaHandler, Tag
from pydantic_core import PydanticCustomError, core_schema

from railpilot.errors import is_finite_number


class Words:
    """How a format's errors word what is allowed (the consist file's way: the bounds in
    every message; :class:`ScenarioWords` for the scenario files' way)."""

    #: what an unknown key is told; ``{key}`` is the key, ``{keys}`` the table's keys
    unknown_key = "a known key instead of '{key}' (allowed here: {keys})"
    flag = "true or false"
    #: list the table's keys sorted (else in the model's order)
    sorted_keys = False
    #: of several unknown keys, name the first in sorted order (else the first in the file)
    first_unknown_sorted = False
    #: of a table's faults, name an unknown key first (a misspelt key is also a missing
    #: one: the misspelling is the fault to name); else the first in the model's order
    unknown_first = True
    #: what a value that is no number at all (a string, a flag) is told where a number
    #: belongs, if the format words it apart from nan (else :meth:`number`'s words)
    not_a_number: str | None = None
    #: quote a whole number given for a float key as the float it is read as (``-1.0``)
    float_values = False
    #: a key a table leaves out is named as the table, with every key it lacks (``dead_zones[0]
    #: = {...}``: ``a table with end_km``); else as the key (``... (the key is required)``)
    missing_as_table = False

    @staticmethod
    def number(fault: str, gt: float | None, ge: float | None, le: float | None, unit: str) -> str:
        return number_words(gt, ge, le, unit)

    @staticmethod
    def whole(ge: float | None, le: float | None) -> str:
        if ge is not None and le is not None:
            return f"a whole number from {ge} to {le}"
        return "a whole number" + (f" >= {ge}" if ge is not None else "")

    @staticmethod
    def string(non_empty: bool) -> str:
        return "a non-empty string" if non_empty else "a string"

    @staticmethod
    def table(keys: Sequence[str]) -> str:
        return "a table with keys " + ", ".join(keys) if keys else "a table"

    @staticmethod
    def tables() -> str:
        return "a list of tables"

    @staticmethod
    def choice(options: Sequence[object], value: Any) -> str:
        """What a key that names one of ``options`` is told of ``value``."""
        return one_of(options)

    @staticmethod
    def named_tables() -> str:
        return "a table of named tables"

    @staticmethod
    def required(allowed: str) -> str:
        return f"{allowed} (the key is required)"


#: the bounds pydantic reports a number outside of (the value is a number)
BOUND_FAULTS = frozenset({"greater_than", "greater_than_equal", "less_than", "less_than_equal"})


class PlainWords(Words):
    """A format that names a key's kind without its bounds: "an integer", "a string",
    "a table"."""

    @staticmethod
    def whole(ge: float | None, le: float | None) -> str:
        return "an integer"

    @staticmethod
    def string(non_empty: bool) -> str:
        return "a string"

    @staticmethod
    def table(keys: Sequence[str]) -> str:
        return "a table"


class ScenarioWords(PlainWords):
    """The scenario files' way: a wrong type or nan is "a finite number", a number out of
    bounds "a number > 0"; unknown keys list the table's keys sorted."""

    unknown_key = "a known key instead of '{key}' (known here: {keys})"
    sorted_keys = True
    first_unknown_sorted = True
    unknown_first = False

    @staticmethod
    def number(fault: str, gt: float | None, ge: float | None, le: float | None, unit: str) -> str:
        if fault in BOUND_FAULTS:
            return "a number " + bounds_words(gt, ge, le)
        return "a finite number"

    @staticmethod
    def named_tables() -> str:
        return "a table"

    @staticmethod
    def required(allowed: str) -> str:
        if allowed.startswith("a finite number"):
            allowed = "a number"
        return f"{allowed} (the key is required)"


class FileTable(BaseModel):
    """A table of a file: unknown keys are refused, numbers are checked strictly (a bool,
    a string or nan is no number; an int is one), the model is frozen."""

    model_config = ConfigDict(
        extra="forbid", strict=True, allow_inf_nan=False, frozen=True, populate_by_name=False
    )
    WORDS: ClassVar[type[Words]] = Words

    def given(self, key: str) -> bool:
        """Whether the file gave ``key`` (a field's default applies to any it left out)."""
        return key in self.model_fields_set


@dataclass(frozen=True)
class Unit:
    """The unit a number is written in; quoted in the error (``[mm]``) and the schema."""

    symbol: str

    def __get_pydantic_json_schema__(self, schema: Any, handler: Any) -> Any:
        out = handler(schema)
        out["x-unit"] = self.symbol
        return out


@dataclass(frozen=True)
class Says:
    """What an error says is allowed here, in the format's own words. ``whole``: this is
    a list of numbers, and an item that is no number at all is named as the whole list
    (``train.davis = [1, 'x', 2]``: a list of 3 numbers)."""

    allowed: str
    whole: bool = False


@dataclass(frozen=True)
class OutOfBounds:
    """What an error says is allowed when a number is out of this key's bounds, in the
    format's own words (``a torque in (0, 1e+05] N m``); a value of the wrong type gets
    the words of its type."""

    allowed: str


@dataclass(frozen=True)
class WhenMissing:
    """What an error says is allowed when the file leaves this key out, in full
    (``a scenario name (the key is required)``)."""

    allowed: str


@dataclass(frozen=True)
class Choice:
    """A string that is one of ``options``: an ``enum`` in the schema, and ``one of a, b``
    in the error. (``typing.Literal`` does the same for options known when writing.)"""

    options: tuple[str, ...]

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.literal_schema(list(self.options))


def bounds_words(gt: float | None = None, ge: float | None = None, le: float | None = None) -> str:
    """``> 0 and <= 1000``: the bounds as the errors write them."""
    parts = [f"{op} {b:g}" for op, b in ((">", gt), (">=", ge), ("<=", le)) if b is not None]
    return " and ".join(parts)


def number_words(
    gt: float | None = None, ge: float | None = None, le: float | None = None, unit: str = ""
) -> str:
    """``a finite number >= 0 and <= 1000 [mm]``."""
    bounds = bounds_words(gt, ge, le)
    return "a finite number" + (f" {bounds}" if bounds else "") + (f" [{unit}]" if unit else "")


def one_of(options: Sequence[object]) -> str:
    return "one of " + ", ".join(str(o) for o in options)


#: the default of a key a file may leave out that has no value of its own: the attribute
#: is None, and the reader asks :meth:`FileTable.given` (a key the file gives is never
#: None: a null in a JSON file is refused like any other wrong type)
NOT_GIVEN: Any = None


#: the fault of a validator that words what is allowed itself (:func:`says`)
SAYS_FAULT = "railpilot_says"


def says(allowed: str) -> PydanticCustomError:
    """The error a validator raises for a value it refuses, saying what is allowed in the
    format's words (the error names the key and the value as for any other fault)."""
    return PydanticCustomError(SAYS_FAULT, "{allowed}", {"allowed": allowed})


@dataclass(frozen=True)
class FloatHeld:
    """An integer a float holds: the brakes' packed parameters are floats, so ``10**400``
    is refused here rather than when the run is packed."""

    allowed: ClassVar[str] = "an integer a float can hold (below 1.8e308 in size)"
    fault: ClassVar[str] = "float_held"

    def __get_pydantic_core_schema__(
        self, source: Any, handler: GetCoreSchemaHandler
    ) -> core_schema.CoreSchema:
        return core_schema.no_info_after_validator_function(_float_held, handler(source))


def _float_held(value: int) -> int:
    if not is_finite_number(value):
        raise PydanticCustomError(FloatHeld.fault, FloatHeld.allowed)
    return value


@dataclass(frozen=True)
class TagKey:
    """The key that picks a table's variant (``model`` of a brake, ``shape`` of a
    reference) and the variant a table that leaves it out is: see :func:`tagged`."""

    key: str
    default: str


def tagged(key: str, default: str, variants: Mapping[str, type[FileTable]]) -> Any:
    """A table that is one of ``variants``, picked by its key ``key`` (``default`` when
    the table leaves it out); each variant declares ``key`` as its own ``Literal``."""

    def tag_of(value: Any) -> str | None:
        if not isinstance(value, Mapping):
            return None
        tag = value.get(key, default)
        return tag if isinstance(tag, str) else "<not a name>"

    options = tuple(Annotated[model, Tag(name)] for name, model in variants.items())
    return Annotated[Union[options], Discriminator(tag_of), TagKey(key, default)]  # noqa: UP007
