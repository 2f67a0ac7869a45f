"""What a reproduction returns: JSON payload, tables and figures for the report."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError


@dataclass
class Table:
    """A table for the report: a title, column headers and rows of cells."""

    title: str
    columns: list[str]
    rows: list[list[Any]]
    note: str = ""

    def to_text(self) -> str:
        """Plain-text rendering for the terminal."""
        cells = [[_fmt(c) for c in row] for row in self.rows]
        widths = [len(c) for c in self.columns]
        for row in cells:
            widths = [max(w, len(c)) for w, c in zip(widths, row, strict=True)]
        line = "  ".join(h.ljust(w) for h, w in zip(self.columns, widths, strict=True))
        out = [self.title, line, "-" * len(line)]
        out += ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) for row in cells]
        if self.note:
            out.append(self.note)
        return "\n".join(out)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


@dataclass
class Reproduction:
    """The outcome of ``railpilot reproduce NAME``.

    ``payload`` is the exact object ``--json`` prints; ``tables`` and ``figures``
    (paths inside the output folder) make up the paper's section of the report,
    ``findings`` are short honest sentences about what the numbers show.
    """

    scenario: str
    title: str
    payload: dict[str, Any]
    tables: list[Table] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)


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
