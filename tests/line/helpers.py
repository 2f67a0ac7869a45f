"""A small valid line as a dict, and a TOML writer for it (tests write bad files from it)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

#: km 10-13; gradients +5 then -2 per mille; one curve; category "a" with a limit that
#: differs by direction on km 12-13, category "b" one limit; one station; signals both ways.
TINY: dict[str, Any] = {
    "name": "tiny",
    "start_km": 10.0,
    "end_km": 13.0,
    "start_elevation_m": 100.0,
    "categories": ["a", "b"],
    "stations": [
        {
            "id": 1,
            "name": "S",
            "km": 12.5,
            "loop_length_m": 400.0,
            "stop_up_km": 12.65,
            "stop_down_km": 12.35,
        }
    ],
    "gradients": [
        {"start_km": 10.0, "end_km": 11.0, "permille": 5.0},
        {"start_km": 11.0, "end_km": 13.0, "permille": -2.0},
    ],
    "curves": [{"start_km": 11.5, "end_km": 12.0, "radius_m": 500.0}],
    "speed_limits": [
        {"category": "a", "start_km": 10.0, "end_km": 12.0, "limit_kmh": 80.0},
        {"category": "a", "direction": "up", "start_km": 12.0, "end_km": 13.0, "limit_kmh": 60.0},
        {
            "category": "a",
            "direction": "down",
            "start_km": 12.0,
            "end_km": 13.0,
            "limit_kmh": 40.0,
        },
        {"category": "b", "start_km": 10.0, "end_km": 13.0, "limit_kmh": 50.0},
    ],
    "signals": [
        {"id": "U1", "km": 10.5, "direction": "up", "kind": "block"},
        {"id": "D1", "km": 11.0, "direction": "down", "kind": "block"},
        {"id": "U2", "km": 12.0, "direction": "up", "kind": "home"},
        {"id": "D2", "km": 12.3, "direction": "down", "kind": "exit"},
        {"id": "U3", "km": 12.7, "direction": "up", "kind": "exit"},
        {"id": "D3", "km": 12.9, "direction": "down", "kind": "home"},
    ],
}


def tiny() -> dict[str, Any]:
    """A fresh deep copy of :data:`TINY` to mutate."""
    return copy.deepcopy(TINY)


def _value(value: Any) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    return repr(value)


def dumps(data: dict[str, Any]) -> str:
    """TOML text of ``data`` (scalars, lists, lists of flat tables)."""
    return "\n".join(f"{key} = {_value(value)}" for key, value in data.items()) + "\n"


def write(tmp_path: Path, data: dict[str, Any], name: str = "line.toml") -> Path:
    path = tmp_path / name
    path.write_text(dumps(data), encoding="utf-8")
    return path
