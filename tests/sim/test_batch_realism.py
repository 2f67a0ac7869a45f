"""Realism parameters sampled per run reach the kernel (a regression of the batch)."""

from __future__ import annotations

import numpy as np

from railpilot.reproduce.qsmc_stop import realistic_scenario
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim import engine
from railpilot.sim.batch import replay_scenario, run_montecarlo
from railpilot.sim.run import simulate

SPEC = MonteCarloSpec(
    runs=12,
    seed=4,
    chunk=5,
    vary=(
        Distribution("realism.adhesion", "uniform", 0.06, 0.15),
        Distribution("realism.wheel_scale_error", "uniform", -0.02, 0.02),
        Distribution("brake.delay_s", "uniform", 1.05, 1.35),
    ),
)


def test_runs_with_sampled_realism_replay_exactly() -> None:
    # before the fix every run of a chunk used the nominal realism (adhesion 0 =
    # unlimited, no wheel error), so a replayed run differed from its sweep result
    scenario = realistic_scenario()
    result = run_montecarlo(scenario, "qsmc", SPEC, progress=False)
    for run in range(SPEC.runs):
        replayed = simulate(replay_scenario(scenario, SPEC, run), "qsmc").metrics
        # bit for bit; a run that never stopped is nan in both
        assert np.array_equal([replayed["stop_error_m"]], [result.stop_errors[run]], equal_nan=True)


def test_sampled_wheel_error_shows_in_the_odometry_of_each_run() -> None:
    scenario = realistic_scenario()
    result = run_montecarlo(scenario, "pid", SPEC, progress=False)
    odometry = result.metrics[:, engine.M_ODO_ERR]
    assert len(set(odometry.round(9))) == SPEC.runs  # each run its own wheel error
