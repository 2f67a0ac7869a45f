"""A Monte Carlo chunk built at once (sim/inputs.batch_inputs) is exactly the chunk built
run by run (each run's own scenario through sim/inputs.run_inputs, stacked): every array
of every part, bit for bit, for every parameter a sweep can vary.
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from railpilot.brakes.lag_delay import LagDelay, exact_params
from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import bind
from railpilot.reproduce.qsmc_stop import paper_scenario, random_disturbance, realistic_scenario
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim import engine
from railpilot.sim.batch import _chunk_inputs, _chunk_inputs_per_run, freeze_ato, run_batch
from railpilot.sim.inputs import batch_inputs, reference_inputs
from railpilot.sim.run import resolve_controller

LAG_DELAY_VARY = (
    Distribution("train.mass_t", "uniform", 270.0, 330.0),
    Distribution("train.davis_scale", "uniform", 0.8, 1.2),
    Distribution("brake.delay_s", "uniform", 1.05, 1.35),
    Distribution("brake.lag_s", "uniform", 0.0, 0.6),
    Distribution("brake.gain", "uniform", 0.9, 1.1),
    Distribution("disturbance.constant_kn", "uniform", -3.0, 3.0),
    Distribution("initial_speed_kmh", "normal", 70.0, 73.0, mean=71.28, std=0.5),
    Distribution("realism.wheel_scale_error", "uniform", -0.01, 0.01),
    Distribution("realism.adhesion", "uniform", 0.1, 0.2),
)


def _both(scenario, vary, runs=30, controller="qsmc", start=3, stop=27):
    nominal = freeze_ato(scenario)
    binding = bind(resolve_controller(nominal, controller))
    values, seeds = MonteCarloSpec(runs=runs, seed=5, vary=vary).samples()
    reference = reference_inputs(nominal)
    per_run = _chunk_inputs_per_run(nominal, binding, reference, values, seeds, start, stop)
    at_once = _chunk_inputs(nominal, binding, reference, values, seeds, start, stop)
    return per_run, at_once, binding, nominal


def _assert_same(per_run, at_once):
    for part_a, part_b in zip(per_run, at_once, strict=True):
        if isinstance(part_a, tuple):
            for a, b in zip(part_a, part_b, strict=True):
                assert_array_equal(np.asarray(a), np.asarray(b))
                if isinstance(a, np.ndarray):
                    assert a.dtype == b.dtype and b.flags.c_contiguous
        else:
            assert part_a == part_b


def test_a_chunk_of_one_run():
    per_run, at_once, _, _ = _both(realistic_scenario(), LAG_DELAY_VARY, start=29, stop=30)
    _assert_same(per_run, at_once)


@pytest.mark.parametrize("key", [d.key for d in LAG_DELAY_VARY] + ["all"])
def test_lag_delay_chunk_at_once_is_the_chunk_run_by_run(key):
    vary = LAG_DELAY_VARY if key == "all" else tuple(d for d in LAG_DELAY_VARY if d.key == key)
    per_run, at_once, _, _ = _both(realistic_scenario(), vary)
    _assert_same(per_run, at_once)


def test_paper_sweep_at_once_gives_the_same_metrics():
    per_run, at_once, binding, nominal = _both(
        random_disturbance(paper_scenario()), LAG_DELAY_VARY[2:3], runs=12, start=0, stop=12
    )
    _assert_same(per_run, at_once)
    step = brake_entry_of(nominal.brake).step
    assert_array_equal(run_batch(per_run, binding, step), run_batch(at_once, binding, step))


def test_nothing_varied_and_speed_noise():
    # no sampled parameter: only the seeds (disturbance and speed noise) differ per run
    scenario = realistic_scenario()
    per_run, at_once, _, _ = _both(scenario, ())
    _assert_same(per_run, at_once)
    assert at_once.realism.speed_noise.shape[0] == 24 or scenario.realism.speed_noise_std_mps == 0


def test_a_brake_without_pack_many_is_built_run_by_run():
    # the EP brake's packing depends on the sampled mass and its delay is rounded to
    # whole steps: batch_inputs declines, and the chunk is still the per-run one
    from railpilot.scenario.loader import load_scenario_and_spec

    scenario, spec = load_scenario_and_spec("examples/paper000_montecarlo.toml")
    nominal = freeze_ato(scenario)
    binding = bind(resolve_controller(nominal, "smarc"))
    values, seeds = spec.samples()
    assert batch_inputs(nominal, binding, values, seeds) is None
    per_run, at_once, _, _ = _both(scenario, spec.vary, controller="smarc")
    _assert_same(per_run, at_once)


def test_exact_params_vectorised_equals_one_by_one():
    rng = np.random.default_rng(3)
    lag = np.concatenate([[0.0, 0.5], rng.uniform(0.0, 2.0, 200)])
    delay = np.concatenate([[0.0, 1.2], rng.uniform(0.01, 3.0, 200)])
    rows = exact_params(lag, delay, 0.01)
    for i in range(lag.shape[0]):
        assert_array_equal(rows[i], LagDelay(lag[i], delay[i], 0.01).params)


def test_a_monte_carlo_run_stops_at_the_stop_and_counts_its_steps():
    per_run, _, binding, nominal = _both(
        random_disturbance(paper_scenario()), (), runs=4, start=0, stop=4
    )
    metrics = run_batch(per_run, binding, brake_entry_of(nominal.brake).step)
    steps = metrics[:, engine.M_STEPS]
    stop_t = metrics[:, engine.M_STOP_T]
    dt = nominal.sim.dt_s
    # every run stopped inside the step it ended with
    assert np.all(steps < nominal.sim.n_steps)
    assert np.all(((steps - 1) * dt <= stop_t) & (stop_t <= steps * dt))
