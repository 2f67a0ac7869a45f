"""Benchmark: planning one section's energy-efficient curve.

A 45 km heavy-haul section (10,000 t, 1,600 m, HXD1) with an 8 km descent of 12 per mille,
a 4 per mille ascent and a 45 km/h restriction; the running time is the fastest run's plus
10 %. Prints one JSON object: ``plan_ms`` (the median of ``--repeat`` plans after one
compiling run), ``plan_ms_min``, ``plan_ms_max``, ``compile_s``, the section's length and
grid points, and what the plan found (``running_time_s``, ``energy_net_kwh``,
``strategy``). Not a test: the goal (under 50 ms) is reported, never asserted.

Usage: python benchmarks/plan_speed.py [--repeat 20]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from railpilot.onboard.drive import heavy_haul_loaded
from railpilot.onboard.planner import fastest, plan, section
from railpilot.units import kmh_to_mps
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import elevation_table

LENGTH_M = 45_000.0


def heavy_haul_section():  # type: ignore[no-untyped-def]
    preset = heavy_haul_loaded()
    line = Line(gradients=(Segment(10_000.0, 18_000.0, -12.0), Segment(25_000.0, 31_000.0, 4.0)))
    ceiling = (
        np.array([0.0, 34_000.0, 36_000.0, LENGTH_M]),
        np.array([kmh_to_mps(80.0), kmh_to_mps(45.0), kmh_to_mps(80.0)]),
    )
    sec = section(LENGTH_M, ceiling, elevation_table(line), train_length_m=preset.train.length_m)
    return preset.driving, sec


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    drive, sec = heavy_haul_section()
    started = time.perf_counter()
    target = 1.10 * fastest(drive, sec).running_time_s
    plan(drive, sec, target)
    compile_s = time.perf_counter() - started
    times = []
    curve = None
    for _ in range(args.repeat):
        started = time.perf_counter()
        curve = plan(drive, sec, target)
        times.append((time.perf_counter() - started) * 1e3)
    assert curve is not None
    print(
        json.dumps(
            {
                "plan_ms": statistics.median(times),
                "plan_ms_min": min(times),
                "plan_ms_max": max(times),
                "compile_s": compile_s,
                "section_km": LENGTH_M / 1000.0,
                "grid_points": int(sec.s_m.size),
                "running_time_s": curve.running_time_s,
                "requested_time_s": target,
                "energy_net_kwh": curve.energy_net_kwh,
                "strategy": curve.strategy,
                "goal_ms": 50.0,
            }
        )
    )


if __name__ == "__main__":
    main()
