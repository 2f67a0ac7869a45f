"""Benchmark: Monte Carlo runs of the paper-002 scenario with QSMC (10 ms plant step).

Prints one JSON object with ``runs``, ``wall_s`` (after the one-off compilation,
reported as ``compile_s``), ``runs_per_s`` and ``peak_rss_mb`` (the process's peak
resident memory, which includes Python, NumPy and Numba themselves), and the compiled
loop alone on a prepared chunk (``kernel_only``: preparation and kernel seconds, and
``steps_per_s_per_core``, plant steps per second per core; a Monte Carlo run ends at its
stop, so the steps counted are the ones the runs took). ``prepare_s`` and ``kernel_s`` at
the top are that chunk's seconds scaled to ``runs``. Not a test: the goal --
10,000 runs in under 1.5 s on 2 cores, memory under 1 GB -- is reported, never
asserted. ``--scaling`` also times 1,000, 10,000 and 100,000 runs.

Usage: python benchmarks/montecarlo_speed.py [--runs 10000] [--scaling]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import time

from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import bind
from railpilot.reproduce.qsmc_stop import paper_scenario, random_disturbance
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.batch import _chunk_inputs, freeze_ato, run_batch, run_montecarlo
from railpilot.sim.engine import M_STEPS
from railpilot.sim.inputs import reference_inputs
from railpilot.sim.run import resolve_controller


def spec(runs: int) -> MonteCarloSpec:
    """Paper 002's sigma range and the +/-2.3 % random disturbance, per-run seeds."""
    return MonteCarloSpec(
        runs=runs, seed=1, chunk=1000, vary=(Distribution("brake.delay_s", "uniform", 1.05, 1.35),)
    )


def timed(runs: int) -> dict[str, float]:
    scenario = random_disturbance(paper_scenario())
    started = time.perf_counter()
    result = run_montecarlo(scenario, "qsmc", spec(runs), progress=False)
    wall = time.perf_counter() - started
    stats = result.stats()
    return {
        "runs": runs,
        "wall_s": wall,
        "runs_per_s": runs / wall,
        "max_abs_stop_error_m": stats["max_abs_stop_error_m"],
    }


def kernel_only(runs: int) -> dict[str, float]:
    """The compiled loop alone on a prepared batch: plant steps per second per core."""
    scenario = freeze_ato(random_disturbance(paper_scenario()))
    sweep = spec(runs)
    binding = bind(resolve_controller(scenario, "qsmc"))
    values, seeds = sweep.samples()
    started = time.perf_counter()
    batch = _chunk_inputs(scenario, binding, reference_inputs(scenario), values, seeds, 0, runs)
    prepare_s = time.perf_counter() - started
    step = brake_entry_of(scenario.brake).step
    cores = os.cpu_count() or 1
    started = time.perf_counter()
    metrics = run_batch(batch, binding, step)
    kernel_s = time.perf_counter() - started
    # a Monte Carlo run ends at its stop: count the plant steps each run actually took
    steps = int(metrics[:, M_STEPS].sum())
    return {
        "prepare_s": prepare_s,
        "kernel_s": kernel_s,
        "plant_steps": steps,
        "plant_steps_simulated_if_run_to_the_end": runs * scenario.sim.n_steps,
        "cores": cores,
        "steps_per_s_per_core": steps / kernel_s / cores,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=10_000)
    parser.add_argument(
        "--scaling", action="store_true", help="also time 1,000 / 10,000 / 100,000 runs"
    )
    args = parser.parse_args()
    started = time.perf_counter()
    timed(10)  # compile (or load Numba's cache) once
    compile_s = time.perf_counter() - started
    main_run = timed(args.runs)
    # the sweep's own peak memory, before the kernel-only measure builds its batch
    peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    kernel_runs = min(args.runs, spec(args.runs).chunk)
    kernel = kernel_only(kernel_runs)
    out: dict[str, object] = {
        "benchmark": "montecarlo_speed",
        "scenario": "paper002 (QSMC, 10 ms step, 40 s simulated, sigma 1.05-1.35 s)",
        **main_run,
        "prepare_s": kernel["prepare_s"] * args.runs / kernel_runs,
        "kernel_s": kernel["kernel_s"] * args.runs / kernel_runs,
        "steps_per_s_per_core": kernel["steps_per_s_per_core"],
        "kernel_only": kernel,
        "compile_s": compile_s,
        "goal_wall_s_for_10000": 1.5,
        "goal_peak_rss_mb": 1024.0,
    }
    if args.scaling:
        out["scaling"] = [timed(n) for n in (1_000, 10_000, 100_000)]
    # ru_maxrss is in kilobytes on Linux
    out["peak_rss_mb"] = peak_rss_mb
    out["python"] = platform.python_version()
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
