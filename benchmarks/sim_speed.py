"""Benchmark: wall time of one paper-000 run (70 s simulated at a 10 ms step, SMARC).

Prints one JSON object. Not a test: the goal (< 50 ms) is reported, never asserted.
Usage: python benchmarks/sim_speed.py [--repeat 20]
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time

from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import bind
from railpilot.reproduce.smarc_ep import paper_scenario
from railpilot.sim.inputs import run_inputs
from railpilot.sim.run import make_controller, run_once, simulate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    scenario = paper_scenario()
    started = time.perf_counter()
    simulate(scenario, "smarc")  # compile (or load from Numba's cache)
    first_s = time.perf_counter() - started
    full, kernel = [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        simulate(scenario, "smarc")  # everything: packing, kernel, recording 7000 samples
        full.append(time.perf_counter() - t0)
        binding = bind(make_controller(scenario, "smarc"))
        inputs = run_inputs(scenario, binding)
        brake_step = brake_entry_of(scenario.brake).step
        t0 = time.perf_counter()
        run_once(inputs, binding, brake_step)  # the compiled kernel alone, metrics only
        kernel.append(time.perf_counter() - t0)
    print(
        json.dumps(
            {
                "benchmark": "sim_speed",
                "scenario": scenario.name,
                "simulated_s": scenario.sim.duration_s,
                "dt_s": scenario.sim.dt_s,
                "steps": scenario.sim.n_steps,
                "repeat": args.repeat,
                "single_run_ms": statistics.median(full) * 1e3,
                "kernel_only_ms": statistics.median(kernel) * 1e3,
                "first_run_incl_compile_s": first_s,
                "goal_single_run_ms": 50.0,
                "python": platform.python_version(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
