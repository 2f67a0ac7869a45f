"""Small helpers shared by the command modules."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from pathlib import Path
from typing import Any


def _clean(value: Any) -> Any:
    """JSON cannot hold NaN/inf: they become null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def json_text(obj: Any) -> str:
    """``obj`` as :func:`print_json` prints it (NaN/inf as null), for a file."""
    return json.dumps(_clean(obj), indent=2, default=str) + "\n"


def print_json(obj: Any) -> None:
    """Print exactly one JSON object on stdout."""
    sys.stdout.write(json_text(obj))


def json_line(obj: Any) -> str:
    """``obj`` as compact one-line JSON (NaN/inf as null), for output written piece by piece."""
    try:
        return json.dumps(obj, default=str, allow_nan=False)
    except ValueError:  # a NaN or inf somewhere (rare): only then walk the whole object
        return json.dumps(_clean(obj), default=str)


def log(message: str) -> None:
    """Progress and logs go to stderr, never stdout."""
    print(message, file=sys.stderr, flush=True)


def file_stem(*parts: str) -> str:
    """A file name stem from a scenario name (and a controller name...): ``a_b``.

    Each part keeps letters, digits, ``.``, ``-`` and ``_``; any other run of
    characters (spaces, ``/``, ``:``) becomes one ``-``, so a scenario named
    ``"eddy case 1: 3500 N m"`` with controller ``pid`` gives ``eddy-case-1-3500-N-m_pid``.
    Every file a command writes for one run starts with this stem, so runs of other
    scenarios or controllers into the same folder never overwrite each other.
    """
    cleaned = [re.sub(r"[^A-Za-z0-9._-]+", "-", part).strip("-.") for part in parts]
    return "_".join(c for c in cleaned if c) or "run"


def controller_argument(value: str) -> str:
    """``--controller``: a built-in's name (braking or eddy-brake) or ``module:Name``."""
    from railpilot.control.registry import CONTROLLERS
    from railpilot.eddy.scenario import CONTROLLERS as EDDY_CONTROLLERS

    if value in CONTROLLERS or value in EDDY_CONTROLLERS or ":" in value:
        return value
    raise argparse.ArgumentTypeError(
        f"controller = {value!r} is not allowed: expected one of "
        f"{', '.join(CONTROLLERS)} (braking), {', '.join(EDDY_CONTROLLERS)} (eddy brake), "
        "or module:Name / path/to/file.py:Name (your own controller, docs/architecture.md)"
    )


def out_dir_argument(value: str) -> Path:
    """``--out``: a folder that is there or can be made, checked when the command line is
    read (a run that fails only when it writes its results has wasted its time, and may
    have written half of them). Nothing is created here."""
    path = Path(value)
    existing = path
    while not existing.exists():  # the nearest part of the path that is there
        existing = existing.parent
    if not existing.is_dir():
        what = "it is a file" if existing == path else f"{existing} is a file"
        raise argparse.ArgumentTypeError(
            f"--out = {value!r} is not allowed: expected a folder ({what})"
        )
    if not os.access(existing, os.W_OK | os.X_OK):
        raise argparse.ArgumentTypeError(
            f"--out = {value!r} is not allowed: expected a folder we may write in "
            f"({existing} is not writable)"
        )
    return path
