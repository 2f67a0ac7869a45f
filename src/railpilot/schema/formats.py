"""Every file format a user writes, and its JSON Schema.

Each format is one model (railpilot.schema.fields); its JSON Schema is generated from it,
so the schema an editor checks a file against and the check railpilot runs when it reads
the file are the same declaration. A model is named by its module and imported when
asked for, so a format whose model needs its reader's package (which imports this one:
the eddy-current brake scenario's) is listed here all the same. The schemas are
published under ``schemas/`` at the top of the repository (``railpilot schema --write
schemas``; a test keeps them current).
"""

from __future__ import annotations

import importlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import BaseModel

#: the JSON Schema dialect pydantic writes
DIALECT = "https://json-schema.org/draft/2020-12/schema"


@dataclass(frozen=True)
class FileFormat:
    """A kind of file: its name (``railpilot schema NAME``), what it is, its model
    (``module:Class``, imported when asked for) and the manual page describing it."""

    name: str
    title: str
    model: str
    page: str

    def model_class(self) -> type[BaseModel]:
        module, _, cls = self.model.partition(":")
        model = getattr(importlib.import_module(module), cls)
        assert isinstance(model, type) and issubclass(model, BaseModel)
        return model

    @property
    def file_name(self) -> str:
        """The schema's file name under ``schemas/``."""
        return f"{self.name}.schema.json"


FORMATS: dict[str, FileFormat] = {
    f.name: f
    for f in (
        FileFormat(
            "scenario",
            "A braking scenario: a train, its brake, the line, the reference, the controller",
            "railpilot.schema.scenario:ScenarioFileTable",
            "docs/paper-000-smarc-ep.md",
        ),
        FileFormat(
            "eddy-brake",
            "An eddy-current brake scenario: a torque demand held as the train slows",
            "railpilot.eddy.scenario:EddyScenarioFile",
            "docs/paper-003-eddy-brake.md",
        ),
        FileFormat(
            "consist",
            "A consist file: a train of vehicles from the head",
            "railpilot.schema.consist:ConsistFileTable",
            "docs/consist.md",
        ),
        FileFormat(
            "line-run",
            "A line run: the line, the trains' services, the radio and what happens when",
            "railpilot.schema.line_run:LineRunFileTable",
            "docs/line-run.md",
        ),
        FileFormat(
            "keys",
            "A key file: per-train HMAC keys, readable by its owner only",
            "railpilot.schema.keys:KeyFile",
            "docs/protocol.md",
        ),
        FileFormat(
            "line",
            "A line file: stations, gradients, curves, speed limits and signals by km post",
            "railpilot.schema.line_file:LineFile",
            "docs/line-data.md",
        ),
        FileFormat(
            "timetable",
            "A timetable: planned running times between consecutive stops",
            "railpilot.schema.timetable:TimetableFile",
            "docs/onboard.md",
        ),
        FileFormat(
            "train-dynamics",
            "A train-dynamics scenario: a consist driven along a line by a script",
            "railpilot.schema.consist_run:ConsistRunFileTable",
            "docs/consist-run.md",
        ),
        FileFormat(
            "consist-library",
            "The library of vehicle types and draft gears a consist file may name",
            "railpilot.schema.consist:ConsistLibraryTable",
            "docs/consist.md",
        ),
    )
}


def json_schema(name: str) -> dict[str, Any]:
    """The JSON Schema of format ``name`` (a key of :data:`FORMATS`)."""
    fmt = FORMATS[name]
    schema = _tidy(fmt.model_class().model_json_schema())
    # a JSON file may name its schema in "$schema" (the reader drops that key)
    schema["properties"] = {"$schema": {"type": "string"}, **schema["properties"]}
    return {
        "$schema": DIALECT,
        "title": fmt.title,
        "description": f"{fmt.title}. Every key: {fmt.page} of railpilot.",
        **{k: v for k, v in schema.items() if k not in ("title", "description")},
    }


def schema_text(name: str) -> str:
    """:func:`json_schema` as the text written to ``schemas/`` (sorted keys kept in the
    models' order, two-space indent, a final newline)."""
    return json.dumps(json_schema(name), indent=2, ensure_ascii=False) + "\n"


def write_schemas(directory: str | Path) -> list[Path]:
    """Write every format's schema into ``directory``; returns the files written."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fmt in FORMATS.items():
        path = folder / fmt.file_name
        path.write_text(schema_text(name), encoding="utf-8")
        written.append(path)
    return written


def _tidy(node: Any) -> Any:
    """Drop what pydantic adds that says nothing to a user: a property's title made from
    its key (``Slack Mm``) and ``"default": null`` (a key with no default of its own);
    docstrings' double backticks become Markdown's single ones (editors show Markdown)."""
    if isinstance(node, list):
        return [_tidy(item) for item in node]
    if not isinstance(node, dict):
        return node
    out = {k: _tidy(v) for k, v in node.items() if not (k == "default" and v is None)}
    if isinstance(out.get("description"), str):  # docstrings' ``code`` as Markdown's
        out["description"] = out["description"].replace("``", "`")
    if isinstance(out.get("properties"), dict):
        out["properties"] = {
            key: {k: v for k, v in prop.items() if k != "title"}
            for key, prop in out["properties"].items()
        }
    return out
