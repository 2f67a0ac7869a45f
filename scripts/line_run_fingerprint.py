"""The line runs' fingerprint: every KPI and a hash of every train's trace, on the short day
and on the heavy-haul day cut to its first 12 trains over 3 hours, advised and baseline.

A reshaping that means to keep behaviour keeps this fingerprint to the bit. Print it for
the tree you stand on, or compare it with another revision's (checked out beside this one
in a temporary git worktree and run with the same interpreter)::

    python scripts/line_run_fingerprint.py                 # JSON on stdout
    python scripts/line_run_fingerprint.py --against main  # exit 1 where they differ

The trace hash is SHA-256 over each train's trackside samples (time, km post, speed) as
little-endian float64 bytes, trains in id order.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
HEAVY_HAUL_TRAINS = 12
HEAVY_HAUL_HOURS = 3.0


def _runs() -> dict[str, Any]:
    import numpy as np

    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_scenario

    short = load_scenario(ROOT / "examples" / "line_short_day.toml")
    day = load_scenario(ROOT / "examples" / "heavy_haul_day.toml")
    first = sorted(day.services, key=lambda s: s.stops[0].departure_s)[:HEAVY_HAUL_TRAINS]
    cut = day.with_(services=tuple(first), duration_s=HEAVY_HAUL_HOURS * 3600.0)
    out: dict[str, Any] = {}
    for name, scenario in (("short_day", short), ("heavy_haul_12_trains_3h", cut)):
        for advised in (True, False):
            result = run_line(scenario, advised=advised)
            traces = {}
            for train, rows in sorted(result.trace.items()):
                data = np.ascontiguousarray(np.asarray(rows, dtype="<f8"))
                traces[str(train)] = hashlib.sha256(data.tobytes()).hexdigest()
            key = f"{name}/{'advised' if advised else 'baseline'}"
            out[key] = {"kpis": result.kpis(), "trace_sha256": traces}
    return out


def _diff(ours: Any, theirs: Any, path: str = "") -> list[str]:
    if isinstance(ours, dict) and isinstance(theirs, dict):
        lines = []
        for key in sorted(set(ours) | set(theirs), key=str):
            if key not in ours or key not in theirs:
                lines.append(f"{path}/{key}: only in {'ours' if key in ours else 'theirs'}")
            else:
                lines += _diff(ours[key], theirs[key], f"{path}/{key}")
        return lines
    if isinstance(ours, list) and isinstance(theirs, list) and len(ours) == len(theirs):
        return [
            line
            for k, (a, b) in enumerate(zip(ours, theirs, strict=True))
            for line in _diff(a, b, f"{path}[{k}]")
        ]
    return [] if ours == theirs else [f"{path}: ours {ours!r}, theirs {theirs!r}"]


def _theirs(revision: str) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), revision],
            check=True,
            capture_output=True,
        )
        try:
            env = {**os.environ, "PYTHONPATH": str(tree / "src")}
            script = tree / "scripts" / "line_run_fingerprint.py"
            if not script.exists():  # a revision before this script: run ours on its tree
                script = Path(__file__).resolve()
                env["RAILPILOT_FINGERPRINT_ROOT"] = str(tree)
            done = subprocess.run(
                [sys.executable, str(script)], env=env, check=True, capture_output=True, text=True
            )
            return json.loads(done.stdout)
        finally:
            subprocess.run(
                ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True
            )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--against", metavar="REV", help="compare with this git revision's fingerprint"
    )
    args = parser.parse_args()
    ours = json.loads(json.dumps(_runs(), sort_keys=True))  # as JSON would carry it
    if args.against is None:
        json.dump(ours, sys.stdout, indent=1, sort_keys=True)
        print()
        return 0
    differences = _diff(ours, _theirs(args.against))
    for line in differences:
        print(line)
    print(f"{len(differences)} difference(s) against {args.against}")
    return 1 if differences else 0


if __name__ == "__main__":
    ROOT = Path(os.environ.get("RAILPILOT_FINGERPRINT_ROOT", ROOT))
    sys.exit(main())
