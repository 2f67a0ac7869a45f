"""The line runs' fingerprint: every KPI and a hash of every train's trace, on the short day
and on the heavy-haul day cut to its first 12 trains over 3 hours, advised and baseline.

A reshaping that means to keep behaviour keeps this fingerprint to the bit. Print it for
the tree you stand on, or compare it with another revision's (checked out beside this one
in a temporary git worktree and run with the same interpreter)::

    python scripts/line_run_fingerprint.py                 # JSON on stdout
    python scripts/line_run_fingerprint.py --against main  # exit 1 where they differ

What the wall clock gives (``wall_s``, ``realtime_factor``, a re-timing's ``solve_ms``) is
left out. The trace hash is SHA-256 over each train's trackside samples (time, km post, speed) as
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


#: what the run's wall clock gives: not part of the fingerprint
WALL_CLOCK_KEYS = frozenset({"wall_s", "realtime_factor", "solve_ms"})


def _heavy_haul_cut(tmp: Path) -> Path:
    """The heavy-haul day (its line, radio and events) with a train each way every 15
    minutes, six each way, over 3 hours: 12 trains; its train failure and its ground
    restart brought within the 3 hours."""
    text = (ROOT / "examples" / "heavy_haul_day.toml").read_text()
    for old, new in (
        ("duration_h = 9.0", f"duration_h = {HEAVY_HAUL_HOURS}"),
        ("every_min = 60.0", "every_min = 15.0"),
        ("count = 4", f"count = {HEAVY_HAUL_TRAINS // 2}"),
        ("at_min = 180.0", "at_min = 100.0"),  # train 102 fails
        ("at_min = 185.0", "at_min = 150.0"),  # the ground restarts
    ):
        if old not in text:
            raise SystemExit(f"examples/heavy_haul_day.toml has no {old!r} any more")
        text = text.replace(old, new)
    path = tmp / "heavy_haul_cut.toml"
    path.write_text(text)
    return path


def _without_wall_clock(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_wall_clock(v) for k, v in value.items() if k not in WALL_CLOCK_KEYS}
    if isinstance(value, list):
        return [_without_wall_clock(v) for v in value]
    return value


def _runs() -> dict[str, Any]:
    import numpy as np

    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_line_scenario

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        scenarios = (
            ("short_day", load_line_scenario(ROOT / "examples" / "line_short_day.toml")),
            ("heavy_haul_12_trains_3h", load_line_scenario(_heavy_haul_cut(Path(tmp)))),
        )
    for name, scenario in scenarios:
        for advised in (True, False):
            result = run_line(scenario, advised=advised)
            traces = {}
            for train, rows in sorted(result.trace.items()):
                data = np.ascontiguousarray(np.asarray(rows, dtype="<f8"))
                traces[str(train)] = hashlib.sha256(data.tobytes()).hexdigest()
            key = f"{name}/{'advised' if advised else 'baseline'}"
            out[key] = {"kpis": _without_wall_clock(result.kpis()), "trace_sha256": traces}
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
