"""What a section of the report holds: a reproduction's outcome (JSON payload, tables,
figures and findings). Every reproduction (:mod:`railpilot.reproduce`) returns one; the
HTML page (:mod:`railpilot.report.html`) lays them out."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


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
    ``findings`` are short honest sentences about what the numbers show. ``rerun``: the
    commands that give the section again, for a section no ``railpilot reproduce NAME``
    gives (empty: ``railpilot reproduce`` of ``scenario``).
    """

    scenario: str
    title: str
    payload: dict[str, Any]
    tables: list[Table] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    rerun: tuple[str, ...] = ()
