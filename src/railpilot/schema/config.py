"""Tables read straight into a config dataclass: the model derived from its fields.

A brake's or an air brake's parameters are the fields of its frozen config dataclass
(railpilot.brakes); a file writes each under its own name, except the keys the class
lists in ``FILE_KEYS`` (written in another unit, e.g. ``fade_rate_kn_per_s``) and
``FILE_LISTS`` (one list filling several fields, e.g. ``beta = [b1, b2, b3]``). The
model checks each key's type; the dataclass checks the values (railpilot.checks) and
keeps the defaults: a key the file leaves out is not passed to it.
"""

from __future__ import annotations

import dataclasses
import functools
import typing
from collections.abc import Callable
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field, create_model

from railpilot.schema.fields import NOT_GIVEN, FileTable, FloatHeld, Says, ScenarioWords, Words


class ConfigTable(FileTable):
    """A table derived from a config dataclass (scenario files' wording)."""

    WORDS: ClassVar[type[Words]] = ScenarioWords


def _file_keys(cls: type) -> dict[str, tuple[str, Callable[[float], Any], Callable[[Any], Any]]]:
    keys: dict[str, tuple[str, Callable[[float], Any], Callable[[Any], Any]]] = getattr(
        cls, "FILE_KEYS", {}
    )
    return keys


def _file_lists(cls: type) -> dict[str, tuple[str, ...]]:
    lists: dict[str, tuple[str, ...]] = getattr(cls, "FILE_LISTS", {})
    return lists


def _written_otherwise(cls: type) -> set[str]:
    fields = {field for field, _, _ in _file_keys(cls).values()}
    return fields | {field for fields in _file_lists(cls).values() for field in fields}


def _shown_default(value: Any) -> dict[str, Any]:
    """The dataclass's default for the schema (a number, a flag or a string)."""
    if isinstance(value, bool | int | float | str) and value == value:  # not nan
        return {"default": value}
    return {}


@functools.cache
def config_table(
    cls: type, exclude: frozenset[str] = frozenset(), words: type[Words] = ScenarioWords
) -> type[ConfigTable]:
    """The model of the table that configures dataclass ``cls`` (``exclude``: fields a
    file may not set here; ``words``: how its errors are worded)."""
    hints = typing.get_type_hints(cls)
    fields: dict[str, Any] = {}
    skip = _written_otherwise(cls) | exclude
    for f in dataclasses.fields(cls):
        if not f.init or f.name in skip:
            continue
        kind = _scalar(hints[f.name])
        if kind is None:
            continue  # a field no file writes (a tuple of commands, a callable)
        if dataclasses.is_dataclass(kind) and isinstance(kind, type):
            fields[f.name] = (config_table(kind) | None, NOT_GIVEN)
            continue
        default = f.default if f.default is not dataclasses.MISSING else None
        fields[f.name] = (kind, Field(NOT_GIVEN, json_schema_extra=_shown_default(default)))
    for key, (field, _, back) in _file_keys(cls).items():
        default = next(g.default for g in dataclasses.fields(cls) if g.name == field)
        shown = _shown_default(back(default)) if isinstance(default, int | float) else {}
        fields[key] = (float, Field(NOT_GIVEN, json_schema_extra=shown))
    for key, names in _file_lists(cls).items():
        size = Field(min_length=len(names), max_length=len(names))
        fields[key] = (
            # a nan or an inf among them is the dataclass's to refuse, in its own words
            Annotated[
                list[Annotated[float, Field(allow_inf_nan=True)]],
                size,
                Says(f"a list of {len(names)} numbers", whole=True),
            ],
            NOT_GIVEN,
        )
    model: type[ConfigTable] = create_model(
        f"{cls.__name__}Config", __base__=ConfigTable, __doc__=_summary(cls), **fields
    )
    model.WORDS = words
    return model


def _scalar(hint: Any) -> Any:
    """The type a file gives for a field of type ``hint``, or None if no file does."""
    options = [a for a in typing.get_args(hint) if a is not type(None)]
    if typing.get_origin(hint) in (typing.Union, type(int | None)) and len(options) == 1:
        hint = options[0]
    if hint is int:
        return Annotated[int, FloatHeld()]
    if hint in (float, bool, str) or typing.get_origin(hint) is Literal:
        return hint
    if dataclasses.is_dataclass(hint):
        return hint
    return None


def _summary(cls: type) -> str:
    return (cls.__doc__ or cls.__name__).strip().split("\n\n")[0]


def config_kwargs(
    table: ConfigTable, cls: type, nested: Callable[[str, ConfigTable, type], Any]
) -> dict[str, Any]:
    """Keyword arguments of ``cls`` from the keys ``table`` gives (only those: the
    dataclass's defaults apply to the rest), converted to the dataclass's units; a
    sub-table becomes ``nested(name, sub_table, field_type)``."""
    hints = typing.get_type_hints(cls)
    kw: dict[str, Any] = {}
    for name in table.model_fields_set:
        value = getattr(table, name)
        if name not in hints and name not in _file_keys(cls) and name not in _file_lists(cls):
            continue  # a key of the table's own, not the dataclass's (a brake's model)
        if name in _file_keys(cls):
            field, convert, _ = _file_keys(cls)[name]
            kw[field] = convert(value)
        elif name in _file_lists(cls):
            kw.update(zip(_file_lists(cls)[name], (float(v) for v in value), strict=True))
        elif isinstance(value, ConfigTable):
            kw[name] = nested(name, value, _scalar(hints[name]))
        elif hints[name] is float or float in typing.get_args(hints[name]):
            kw[name] = float(value)
        else:
            kw[name] = value
    return kw


def given_values(table: FileTable, *keys: str) -> dict[str, Any]:
    """``{key: value}`` of the ``keys`` the file gives (only those: the dataclass's
    defaults apply to the rest); a number of a ``float`` key as a float."""
    out: dict[str, Any] = {}
    for key in keys:
        if table.given(key):
            value = getattr(table, key)
            is_float = type(table).model_fields[key].annotation is float
            out[key] = float(value) if is_float else value
    return out
