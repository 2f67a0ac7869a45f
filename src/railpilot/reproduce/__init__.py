"""Reproductions of the papers' published results, one module per result.

Each module listed in :data:`REPRODUCTIONS` has
``run(out_dir: pathlib.Path) -> railpilot.reproduce.base.Reproduction``:
it simulates, writes its figures into ``out_dir`` and returns the JSON payload
and the tables for the report.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: ``railpilot reproduce NAME`` -> module implementing it
REPRODUCTIONS: dict[str, str] = {
    "smarc-ep": "railpilot.reproduce.smarc_ep",
    "qsmc-stop": "railpilot.reproduce.qsmc_stop",
    "eddy-torque": "railpilot.reproduce.eddy_torque",
    "link-demo": "railpilot.reproduce.link_demo",
    "precise-stop": "railpilot.reproduce.precise_stop",
    "heavy-haul-ltd": "railpilot.reproduce.heavy_haul_ltd",
    "retiming": "railpilot.reproduce.retiming_vs_fixed_plan",
    "line-day": "railpilot.reproduce.line_day",
    "line-live": "railpilot.reproduce.line_live",
    # last: Playwright's sync API leaves an event loop marked running in this thread
    "dashboard": "railpilot.reproduce.dashboard",
}


def load(name: str) -> ModuleType:
    """Import the module that reproduces ``name``; KeyError if unknown."""
    return importlib.import_module(REPRODUCTIONS[name])
