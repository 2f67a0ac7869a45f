"""One HTML page with every reproduction's figures, tables and findings."""

from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any

from railpilot import __version__
from railpilot.report.section import Reproduction, Table

STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1150px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.6em 0 1.4em; font-size: 0.92em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th { background: #f0f3f7; } td:first-child, th:first-child { text-align: left; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.4em 0; }
.note { color: #555; font-size: 0.88em; } li { margin: 0.3em 0; }
"""


def _cell(value: Any) -> str:
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.4g}"
    if value is None:
        return "—"
    return html.escape(str(value))


def _table(table: Table) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in table.columns)
    rows = "".join(
        "<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in row) + "</tr>" for row in table.rows
    )
    note = f'<p class="note">{html.escape(table.note)}</p>' if table.note else ""
    return f"<h3>{html.escape(table.title)}</h3><table><tr>{head}</tr>{rows}</table>{note}"


def write_report(sections: list[Reproduction], out_dir: Path) -> Path:
    """Write ``out_dir/index.html``; figures are linked relative to it."""
    out_dir.mkdir(parents=True, exist_ok=True)
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>railpilot report"
        f"</title><style>{STYLE}</style></head><body>",
        f"<h1>railpilot report</h1><p class='note'>railpilot {__version__}. Every number "
        "below was measured by this run; see docs/results.md for definitions.</p>",
    ]
    parts.append(
        "<ul>"
        + "".join(f"<li><a href='#{s.scenario}'>{html.escape(s.title)}</a></li>" for s in sections)
        + "</ul>"
    )
    for s in sections:
        parts.append(f"<h2 id='{s.scenario}'>{html.escape(s.title)}</h2>")
        commands = s.rerun or (f"railpilot reproduce {s.scenario} --json",)
        parts.append(
            "<p class='note'>Rerun this section alone: "
            + "; ".join(f"<code>{html.escape(c)}</code>" for c in commands)
            + "</p>"
        )
        if s.findings:
            parts.append(
                "<ul>" + "".join(f"<li>{html.escape(f)}</li>" for f in s.findings) + "</ul>"
            )
        parts += [_table(t) for t in s.tables]
        for fig in s.figures:
            rel = Path(fig).resolve().relative_to(out_dir.resolve())
            parts.append(f"<img src='{html.escape(str(rel))}' alt='{html.escape(rel.stem)}'>")
    parts.append("</body></html>")
    index = out_dir / "index.html"
    index.write_text("\n".join(parts), encoding="utf-8")
    return index
