"""Benchmark: wall time of a 100 km heavy-haul run, at a 0.1 s step.

The example's train and locomotive (examples/heavy_haul_run.toml) on a 100 km line with two
12 per mille descents, from rest to a station stop, PID on the locomotive drive, with the
recorder on (what `railpilot simulate` does). Prints one JSON object; the goal (< 0.2 s
after compilation) is reported, never asserted.
Usage: python benchmarks/drive_speed.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from dataclasses import replace
from pathlib import Path

from railpilot.scenario import load_scenario
from railpilot.scenario.model import DriveSpec
from railpilot.sim.run import simulate
from railpilot.vehicle.line import Line, Segment

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "heavy_haul_run.toml"
LINE_KM = 100.0


def scenario_100_km():  # type: ignore[no-untyped-def]
    base = load_scenario(EXAMPLE)
    stop_m = LINE_KM * 1000.0 - 500.0
    line = Line(
        gradients=(Segment(20_000.0, 28_000.0, -12.0), Segment(60_000.0, 70_000.0, -12.0)),
        speed_limits=(Segment(0.0, LINE_KM * 1000.0, 80.0 / 3.6),),
    )
    reference = DriveSpec(stop_m=stop_m, accel_mps2=0.05, decel_mps2=0.1).build(line, base.train)
    return replace(
        base,
        line=line,
        reference=reference,
        sim=replace(base.sim, duration_s=reference.duration_s + 600.0),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    scenario = scenario_100_km()
    started = time.perf_counter()
    first = simulate(scenario)  # compile (or load from Numba's cache)
    first_s = time.perf_counter() - started
    runs = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        simulate(scenario)
        runs.append(time.perf_counter() - t0)
    print(
        json.dumps(
            {
                "benchmark": "drive_speed",
                "line_km": LINE_KM,
                "dt_s": scenario.sim.dt_s,
                "steps": scenario.sim.n_steps,
                "running_time_s": first.metrics["running_time_s"],
                "stop_error_m": first.metrics["stop_error_m"],
                "run_s": statistics.median(runs),
                "first_run_incl_compile_s": first_s,
                "goal_run_s": 0.2,
                "repeat": args.repeat,
                "python": platform.python_version(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
