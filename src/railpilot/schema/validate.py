"""Check a parsed file against its format's model, with errors in the file's words.

pydantic reports where a value failed (its ``loc``) and the value; this module turns the
first failure into the reader's :class:`~railpilot.errors.ConfigError` subclass, naming the
key as the file writes it (``draft_gears.G1.slack_mm``, ``train[2].count``), the value and
what is allowed, as the model declares it (railpilot.schema.fields).
"""

from __future__ import annotations

import typing
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

import annotated_types as at
from pydantic import BaseModel, ValidationError
from pydantic.fields import FieldInfo

from railpilot.errors import MISSING, ConfigError, is_finite_number
from railpilot.schema.fields import (
    BOUND_FAULTS,
    SAYS_FAULT,
    Choice,
    FileTable,
    FloatHeld,
    OutOfBounds,
    Says,
    TagKey,
    Unit,
    WhenMissing,
    Words,
    one_of,
)

M = TypeVar("M", bound=BaseModel)

#: a key's place in a file, as pydantic gives it: keys and list indices
Loc = tuple[str | int, ...]
#: how a format writes a place: ``(loc, the parsed file) -> "train[2] (C80 x 105).load"``
Namer = Callable[[Loc, Any], str]
#: the reader's error: ``(field, value, allowed) -> error``
ErrorType = Callable[[str, Any, str], ConfigError]


def dotted(loc: Loc) -> str:
    """``("services", 2, "every_min")`` -> ``services[2].every_min``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else part)
    return out


def check(
    model: type[M],
    data: Any,
    error: ErrorType,
    *,
    name: Namer | None = None,
    top: str = "<file>",
    at: Loc = (),
) -> M:
    """``data`` (a parsed file or table) as ``model``, or ``error`` for its first fault.

    ``name`` writes a key's place (default: :func:`dotted`); ``top`` names the file itself
    when it is no table at all; ``at`` is the place of ``data`` in its file, when it is
    one table of it (``("line",)``).
    """
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        faults = exc.errors(include_url=False)
        first = _first(model, faults)
        namer = name or (lambda loc, _: dotted(loc))
        if at:
            inner, top = namer, dotted(at)
            namer = lambda loc, data: inner((*at, *loc), data)  # noqa: E731
        raise _in_file_words(model, first, faults, data, error, namer, top) from None


def _first(model: type[BaseModel], faults: list[Any]) -> Any:
    """The fault to report: the first in the model's order, unless its table also has a
    key it does not know and its words name those first (or lacks a key, and its words
    name the table then); of several unknown keys, the first in the file, or in sorted
    order where the table's words say so."""
    first = faults[0]
    table = tuple(first["loc"][:-1])
    unknown = [
        f for f in faults if f["type"] == "extra_forbidden" and tuple(f["loc"][:-1]) == table
    ]
    if not unknown:
        missing = [f for f in faults if f["type"] == "missing" and tuple(f["loc"][:-1]) == table]
        if missing and _words(_walk(model, tuple(missing[0]["loc"]))[-1].owner).missing_as_table:
            return missing[0]  # a table lacking keys is named before its keys' values
        return first
    words = _words(_walk(model, tuple(unknown[0]["loc"]))[-1].owner)
    if not words.unknown_first and first["type"] != "extra_forbidden":
        return first
    if words.first_unknown_sorted:
        return min(unknown, key=lambda f: str(f["loc"][-1]))
    return unknown[0]


def _in_file_words(
    model: type[BaseModel],
    fault: Any,
    faults: list[Any],
    data: Any,
    error: ErrorType,
    name: Namer,
    top: str,
) -> ConfigError:
    kind: str = fault["type"]
    steps = _walk(model, tuple(fault["loc"]))
    loc = tuple(step.key for step in steps if not step.tag)
    where = name(loc, data) if loc else top
    last = steps[-1] if steps else _Step("", model, [], None, tag=False, owner=model)
    words = _words(last.owner)
    if kind == "extra_forbidden":
        keys = _keys(last.owner)
        if words.sorted_keys:
            keys = sorted(keys)
        text = words.unknown_key.format(key=loc[-1], keys=", ".join(keys))
        return error(where, fault["input"], text)
    if kind in ("union_tag_invalid", "union_tag_not_found"):
        tag = last.discriminator or "kind"
        if not isinstance(fault["input"], Mapping):
            return error(where, fault["input"], words.table([]))
        value = fault["input"].get(tag)
        return error(name((*loc, tag), data), value, one_of(_tags(last.annotation, tag)))
    if len(steps) > 1 and _is_not_a_number(kind, fault["input"]):
        listed = next((m for m in steps[-2].metadata if isinstance(m, Says) and m.whole), None)
        if listed is not None:
            # a list of numbers with a word of its own (``a list of 3 numbers``): a thing
            # in it that is no number at all is named as the whole list
            return error(name(loc[:-1], data), _value_at(data, steps[:-1]), listed.allowed)
    if kind == SAYS_FAULT:  # a validator's own words
        return error(where, fault["input"], fault["ctx"]["allowed"])
    if kind == "missing" and words.missing_as_table:
        table = tuple(fault["loc"][:-1])
        lacks = sorted(
            str(f["loc"][-1])
            for f in faults
            if f["type"] == "missing" and tuple(f["loc"][:-1]) == table
        )
        value = _value_at(data, steps[:-1])
        return error(
            name(loc[:-1], data) if loc[:-1] else top, value, f"a table with {', '.join(lacks)}"
        )
    if kind == "missing":
        told = next((m.allowed for m in last.metadata if isinstance(m, WhenMissing)), None)
        return error(where, MISSING, told or words.required(_allowed(last, kind, words, None)))
    value = fault["input"]
    if words.float_values and last.annotation is float and _is_whole(value):
        value = float(value)  # the value as the reader reads it: -1 is -1.0
    return error(where, value, _allowed(last, kind, words, fault["input"]))


def _words(owner: Any) -> type[Words]:
    return getattr(owner, "WORDS", FileTable.WORDS)


class _Step:
    """One step down a model along a ``loc``: the key, the type found there."""

    def __init__(
        self,
        key: str | int,
        annotation: Any,
        metadata: list[Any],
        discriminator: Any,
        *,
        tag: bool,
        owner: Any,
    ) -> None:
        self.key = key
        self.annotation = annotation
        self.metadata = metadata
        self.discriminator = discriminator if isinstance(discriminator, str) else None
        self.tag = tag
        #: the table (model) the key belongs to: its words are the error's
        self.owner = owner


def _unwrap(annotation: Any, metadata: list[Any]) -> tuple[Any, list[Any]]:
    """Strip ``Annotated`` (its metadata joins ``metadata``) and ``X | None``."""
    while True:
        if get_origin(annotation) is typing.Annotated:
            base, *extra = get_args(annotation)
            for item in extra:
                if isinstance(item, FieldInfo):
                    metadata = [*metadata, *_marked(item.metadata, item.discriminator)]
                else:
                    metadata = [*metadata, *_marked([item], None)]
            annotation = base
            continue
        if get_origin(annotation) in (Union, _UnionType) and not _is_tagged(metadata):
            options = [a for a in get_args(annotation) if a is not type(None)]
            if len(options) == 1:
                annotation = options[0]
                continue
        return annotation, metadata


class _Discriminator:
    def __init__(self, key: Any) -> None:
        self.key = key


_UnionType = type(int | None)


def _marked(metadata: list[Any], discriminator: Any) -> list[Any]:
    """``metadata`` with the key that picks a tagged union's variant marked, whether
    pydantic's (a string) or railpilot's (:class:`TagKey`)."""
    out = list(metadata)
    if isinstance(discriminator, str):
        out.append(_Discriminator(discriminator))
    out += [_Discriminator(m.key) for m in metadata if isinstance(m, TagKey)]
    return out


def _is_tagged(metadata: list[Any]) -> bool:
    return any(isinstance(m, _Discriminator) for m in metadata)


def _walk(model: type[BaseModel], loc: Loc) -> list[_Step]:
    steps: list[_Step] = []
    annotation: Any = model
    metadata: list[Any] = []
    owner: Any = model
    for key in loc:
        annotation, metadata = _unwrap(annotation, metadata)
        disc = next((m.key for m in metadata if isinstance(m, _Discriminator)), None)
        if disc is not None and isinstance(key, str):
            # a tagged union: the tag pydantic puts in the loc picks the variant
            variant = _variant(annotation, disc, key)
            steps.append(_Step(key, variant, [], None, tag=True, owner=owner))
            annotation, metadata = variant, []
            continue
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            owner = annotation
            field = _field(annotation, key)
            if field is None:  # a key the table does not have
                steps.append(_Step(key, Any, [], None, tag=False, owner=owner))
                annotation, metadata = Any, []
                continue
            annotation = field.annotation
            metadata = _marked(list(field.metadata), field.discriminator)
        else:
            args = get_args(annotation)
            origin = get_origin(annotation)
            if origin is dict and len(args) == 2:
                annotation = args[1]
            elif origin is tuple and isinstance(key, int) and Ellipsis not in args:
                annotation = args[key] if key < len(args) else Any
            elif origin in (list, tuple) and args:
                annotation = args[0]
            else:
                annotation = Any
            metadata = []
        annotation, metadata = _unwrap(annotation, metadata)
        disc = next((m.key for m in metadata if isinstance(m, _Discriminator)), None)
        steps.append(_Step(key, annotation, metadata, disc, tag=False, owner=owner))
    return steps


def _field(model: type[BaseModel], key: str | int) -> FieldInfo | None:
    for field_name, field in model.model_fields.items():
        if key in (field.alias, field_name):
            return field
    return None


def _keys(model: Any) -> list[str]:
    if isinstance(model, type) and issubclass(model, BaseModel):
        return [field.alias or name for name, field in model.model_fields.items()]
    return []


def _variant(annotation: Any, disc: str, tag: str) -> Any:
    for option in get_args(annotation):
        option, _ = _unwrap(option, [])
        if tag in _tags(option, disc):
            return option
    return Any


def _tags(annotation: Any, disc: str) -> list[str]:
    """The tags a tagged union (or one of its variants) takes."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        field = annotation.model_fields.get(disc)
        return list(get_args(field.annotation)) if field is not None else []
    return [tag for option in get_args(annotation) for tag in _tags(_unwrap(option, [])[0], disc)]


def _allowed(step: _Step, fault: str, words: type[Words], value: Any) -> str:
    """What the model allows at ``step``, in the owner's words (``fault``: pydantic's
    error type, and ``value`` the file's, for words that depend on them)."""
    annotation, meta = step.annotation, step.metadata
    for item in meta:
        if isinstance(item, Says):
            return item.allowed
    if fault == FloatHeld.fault:
        return FloatHeld.allowed
    if fault in BOUND_FAULTS:
        for item in meta:
            if isinstance(item, OutOfBounds):
                return item.allowed
    if annotation is float and words.not_a_number and _is_not_a_number(fault, value):
        return words.not_a_number
    for item in meta:
        if isinstance(item, Choice):
            return words.choice(item.options, value)
    if step.discriminator is not None:
        tags = _tags(annotation, step.discriminator)
        return f"a table whose {step.discriminator} is {one_of(tags)}"
    if get_origin(annotation) is Literal:
        return words.choice(get_args(annotation), value)
    gt = _bound(m.gt for m in meta if isinstance(m, at.Gt))
    ge = _bound(m.ge for m in meta if isinstance(m, at.Ge))
    le = _bound(m.le for m in meta if isinstance(m, at.Le))
    if annotation is bool:
        return words.flag
    if annotation is int:
        return words.whole(ge, le)
    if annotation is float:
        unit = next((m.symbol for m in meta if isinstance(m, Unit)), "")
        return words.number(fault, gt, ge, le, unit)
    if annotation is str:
        return words.string(any(isinstance(m, at.MinLen) and m.min_length for m in meta))
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return words.table(_keys(annotation))
    origin = get_origin(annotation)
    if origin is dict:
        return words.named_tables()
    if origin in (list, tuple):
        item = _unwrap(get_args(annotation)[0], [])[0] if get_args(annotation) else Any
        if isinstance(item, type) and issubclass(item, BaseModel):
            return words.tables()
        return "a list"
    return "a valid value"


def _bound(values: Iterable[object]) -> float | None:
    """The first of a constraint's values (a number in these models), or None."""
    for value in values:
        assert isinstance(value, int | float)
        return value
    return None


def _is_not_a_number(fault: str, value: Any) -> bool:
    """A type fault on a value that is no number (a string, a flag, a table), as opposed to
    a number no float holds (``10**400``)."""
    is_int = isinstance(value, int) and not isinstance(value, bool)
    return fault in ("float_type", "int_type") and not is_int


def _is_whole(value: Any) -> bool:
    """An int (not a flag) that a float holds."""
    return isinstance(value, int) and not isinstance(value, bool) and is_finite_number(value)


def _value_at(data: Any, steps: list[_Step]) -> Any:
    """The value the file gives at ``steps`` (tags of tagged unions are no keys)."""
    for step in steps:
        if not step.tag:
            data = data[step.key]
    return data
