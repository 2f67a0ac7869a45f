"""What a reproduction returns (:class:`Reproduction`, with its :class:`Table` s: they are the
report's sections, defined in :mod:`railpilot.report.section`), and where the examples are."""

from __future__ import annotations

from pathlib import Path

from railpilot.errors import ConfigError
from railpilot.report.section import Reproduction, Table

__all__ = ["Reproduction", "Table", "find_example"]


def find_example(name: str) -> Path:
    """``examples/NAME`` of the source checkout (the examples are not installed with the
    package): next to ``src/``, else under the working folder."""
    candidates = [
        Path(__file__).resolve().parents[3] / "examples",
        Path.cwd() / "examples",
    ]
    for folder in candidates:
        if (folder / name).is_file():
            return folder / name
    raise ConfigError(
        f"examples/{name}",
        ", ".join(str(folder) for folder in candidates),
        "a railpilot source checkout holding the file (examples are not installed with the "
        "package): run from the repository",
    )
