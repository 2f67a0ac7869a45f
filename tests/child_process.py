"""Run Python code in a fresh process, as a user's next command is, and read the JSON
object it prints last (the tests of Numba's on-disk cache)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def run_python_json(code: str, *args: str, env: dict[str, str] | None = None) -> Any:
    """``python -c code args...`` from the project's root; the last line of its output,
    as JSON. Its errors are raised (``CalledProcessError`` with its output)."""
    done = subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
        env=os.environ | (env or {}),
        timeout=600,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])
