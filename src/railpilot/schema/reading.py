"""Reading a user's file into a mapping: the one place that opens and parses them.

A file is TOML, or JSON when its name ends in ``.json`` (the same keys and tables; an
editor validates either against the format's JSON Schema, docs/file-formats.md). A file
that cannot be read or parsed is the reader's :class:`~railpilot.errors.ConfigError`
subclass naming the option, the path and the parser's line and column.
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError
from railpilot.textfile import TOO_MANY_DIGITS, read_text

#: the reader's error: ``(field, value, allowed) -> error``
ErrorType = Callable[[str, Any, str], ConfigError]


def parse_text(
    text: str, source: str, field: str, error: ErrorType, *, json_text: bool = False
) -> Any:
    """The document ``text`` (TOML, or JSON if ``json_text``); ``source`` names it in an
    error (``field = source is not allowed: expected valid TOML (... at line 3, column 7)``)."""
    if json_text:
        try:
            document = json.loads(text)
        except json.JSONDecodeError as exc:
            raise error(
                field, source, f"valid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})"
            ) from None
        except ValueError:  # int() of a literal past Python's digit limit
            raise error(field, source, f"valid JSON ({TOO_MANY_DIGITS})") from None
        if isinstance(document, dict) and isinstance(document.get("$schema"), str):
            del document["$schema"]  # the editor's pointer to the format's schema
        return document
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(field, source, f"valid TOML ({exc})") from None
    except ValueError:  # tomllib's int() of a literal past Python's digit limit
        raise error(field, source, f"valid TOML ({TOO_MANY_DIGITS})") from None


def read_document(
    path: str | os.PathLike[str],
    field: str,
    what: str,
    error: ErrorType,
    *,
    parse_error: ErrorType | None = None,
) -> Any:
    """The parsed file at ``path``: JSON if its name ends in ``.json``, else TOML.
    ``field`` is the option that named the file (``CONSIST``), ``what`` the kind of file
    (``consist TOML file``); ``parse_error`` (default ``error``) is raised for a file that
    was read but does not parse."""
    text = read_text(path, field, what, error)
    json_text = Path(path).suffix.lower() == ".json"
    return parse_text(text, str(path), field, parse_error or error, json_text=json_text)
