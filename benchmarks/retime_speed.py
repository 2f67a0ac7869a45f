"""Benchmark: the ground's re-timing LP for 100 trains x 30 sections.

A synthetic but realistic problem: 100 loaded trains queued at the origin of a 30-section
route, departing every 10 min, a fixed-block headway of 8 min, 2 min stops; per section a
minimum running time of 1,400-2,300 s, a timetable 4-8 % above it and a convex,
non-increasing energy-time curve of 4-6 pieces up to 30 % above the minimum, steep up to
the timetable's time (1.5-6 kWh/s) and shallow beyond it (0.2-1.5 kWh/s), like the planner's
on the heavy-haul line (docs/retiming.md); train 10 held 10 minutes.
Seeded: the same problem every run.

Prints one JSON object: ``solve_ms`` (the median of ``--repeat`` calls of ``retime``:
building the sparse matrices, HiGHS, reading the answer), ``solve_ms_min``/``_max``,
``lp_ms`` (HiGHS alone, median), ``build_ms`` (constructing and validating the problem,
median), the LP's size, and what it found against the fixed plan. Not a test: the goal
(under 1 s) is reported, never asserted.

Usage: python benchmarks/retime_speed.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from railpilot.ground.running_time_lp import (
    EnergyCurve,
    RetimeProblem,
    Section,
    TrainPlan,
    fixed_plan,
    retime,
)

TRAINS = 100
SECTIONS = 30
INTERVAL_S = 600.0
HEADWAY_S = 480.0
DWELL_S = 120.0
DELAYED = 10
DELAY_S = 600.0
ENERGY_WEIGHT_S_PER_KWH = 0.5


def route(rng: np.random.Generator) -> tuple[Section, ...]:
    sections = []
    for j in range(SECTIONS):
        t_min = float(rng.uniform(1400.0, 2300.0))
        pieces = int(rng.integers(4, 7))
        planned = t_min * float(rng.uniform(1.04, 1.08))
        # knots: the fastest run, 1-2 between it and the timetable (steep: 1.5-6 kWh/s), the
        # timetable, and the rest up to 30 % above the fastest (shallow: 0.2-1.5 kWh/s)
        before = int(rng.integers(1, 3))
        after = pieces - before
        inner = np.sort(rng.uniform(t_min + 1.0, planned - 1.0, before - 1))
        outer = np.sort(rng.uniform(planned + 1.0, 1.3 * t_min - 1.0, after - 1))
        times = np.concatenate([[t_min], inner, [planned], outer, [1.3 * t_min]])
        slopes = -np.concatenate(
            [
                np.sort(rng.uniform(1.5, 6.0, before))[::-1],
                np.sort(rng.uniform(0.2, 1.5, after))[::-1],
            ]
        )
        energy = rng.uniform(-2000.0, 2500.0) + np.concatenate(
            [[0.0], np.cumsum(slopes * np.diff(times))]
        )
        sections.append(
            Section(j + 1, j + 2, t_min, planned, EnergyCurve(tuple(times), tuple(energy)))
        )
    return tuple(sections)


def problem(sections: tuple[Section, ...]) -> RetimeProblem:
    run = np.array([s.planned_running_s for s in sections])
    base = np.concatenate([[0.0], np.cumsum(run + DWELL_S)[:-1]])
    trains = tuple(
        TrainPlan(
            f"T{k:03d}",
            sections,
            tuple(base + k * INTERVAL_S),
            (DWELL_S,) * (SECTIONS - 1),
            k * INTERVAL_S + (DELAY_S if k == DELAYED else 0.0),
        )
        for k in range(TRAINS)
    )
    return RetimeProblem(trains, HEADWAY_S, 0.0, ENERGY_WEIGHT_S_PER_KWH)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=7)
    args = parser.parse_args()
    sections = route(np.random.default_rng(2016))
    retime(problem(sections))  # warm-up: imports, HiGHS loading
    build, solve, lp = [], [], []
    result = None
    for _ in range(args.repeat):
        started = time.perf_counter()
        p = problem(sections)
        build.append((time.perf_counter() - started) * 1e3)
        result = retime(p)
        solve.append(result.solve_ms)
        lp.append(result.lp_ms)
    assert result is not None
    fixed = fixed_plan(problem(sections))
    n = TRAINS * SECTIONS
    pieces = sum(len(s.energy.times_s) for s in sections) * TRAINS
    print(
        json.dumps(
            {
                "benchmark": "retime_speed",
                "trains": TRAINS,
                "sections": SECTIONS,
                "solve_ms": statistics.median(solve),
                "solve_ms_min": min(solve),
                "solve_ms_max": max(solve),
                "lp_ms": statistics.median(lp),
                "build_ms": statistics.median(build),
                "repeat": args.repeat,
                "variables": 3 * n + TRAINS,
                "energy_pieces": pieces,
                "status": result.status,
                "lateness_total_s": float(np.sum(result.lateness_s)),
                "lateness_total_fixed_s": float(np.sum(fixed.lateness_s)),
                "energy_kwh": result.total_energy_kwh,
                "energy_fixed_kwh": fixed.total_energy_kwh,
                "goal_ms": 1000.0,
            }
        )
    )


if __name__ == "__main__":
    main()
