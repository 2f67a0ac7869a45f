"""Reading a file the user named: its text, or an error naming the option and the path.

A path that is no readable file (missing, a directory, under a regular file, an empty
name) or a file that is not UTF-8 is a :class:`~railpilot.errors.ConfigError` (or the
subclass the caller gives), never an ``OSError`` or ``UnicodeDecodeError`` traceback.
"""

from __future__ import annotations

import os
import sys
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError

#: what tomllib cannot read: an integer of more digits than Python converts to text
#: (``sys.set_int_max_str_digits``); tomllib raises a plain ValueError for it
TOO_MANY_DIGITS = f"integers of at most {sys.get_int_max_str_digits()} digits"


def read_text(
    path: str | os.PathLike[str],
    field: str,
    what: str,
    error: Callable[[str, Any, str], ConfigError] = ConfigError,
) -> str:
    """The UTF-8 text of the file at ``path``; ``what`` names the kind of file in the
    error ("line-run file")."""
    try:
        return Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(field, str(path), f"an existing {what}") from None
    except OSError as exc:
        raise error(field, str(path), f"a readable {what} ({exc.strerror})") from None
    except UnicodeDecodeError as exc:
        raise error(field, str(path), f"a UTF-8 text {what} ({exc.reason})") from None


def read_toml(
    path: str | os.PathLike[str],
    field: str,
    what: str,
    error: type[ConfigError] = ConfigError,
) -> dict[str, Any]:
    """:func:`read_text`, parsed as TOML (a syntax error names the line and column)."""
    text = read_text(path, field, what, error)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(field, str(path), f"valid TOML ({exc})") from None
    except ValueError:  # tomllib's int() of a literal past Python's digit limit
        raise error(field, str(path), f"valid TOML ({TOO_MANY_DIGITS})") from None
