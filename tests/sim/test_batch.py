"""The Monte Carlo engine (railpilot.sim.batch): determinism, Dask, memory, statistics.

The sweeps run paper 002's stop (railpilot.reproduce.qsmc_stop.paper_scenario) with
the paper's random disturbance of -2.3 % to +2.3 % of the target acceleration: 40 s at
a 10 ms step, so 4,000 steps a run. Every run draws its own disturbance from its own
seed, so two runs never share a stop error by accident.
"""

import dataclasses
import tracemalloc
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from railpilot.errors import ConfigError
from railpilot.reproduce.qsmc_stop import paper_scenario, random_disturbance
from railpilot.scenario.model import Scenario
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim import engine
from railpilot.sim.batch import (
    MonteCarloResult,
    check_spec,
    freeze_ato,
    replay_scenario,
    run_chunk,
    run_montecarlo,
)
from railpilot.sim.run import make_controller, simulate

NOISY = random_disturbance(paper_scenario())
N_STEPS = NOISY.sim.n_steps  # 4,000

# what varies in the sweeps that are compared bit for bit: a plant parameter from a
# uniform and one from a truncated normal, and an ATO-side-invisible outside force
VARY = (
    Distribution("train.mass_t", "uniform", 270.0, 330.0),
    Distribution("initial_speed_kmh", "normal", 70.0, 73.0, mean=71.28, std=0.5),
    Distribution("disturbance.constant_kn", "uniform", -3.0, 3.0),
)
SPEC = MonteCarloSpec(runs=40, seed=11, vary=VARY, chunk=10)


def sweep(spec=SPEC, controller="qsmc", scenario=NOISY, **kwargs):
    return run_montecarlo(scenario, controller, spec, progress=False, **kwargs)


@pytest.fixture(scope="module")
def reference_sweep():
    return sweep()


# --- determinism ----------------------------------------------------------------------


def test_same_seed_gives_identical_metrics_bit_for_bit(reference_sweep):
    again = sweep()
    assert np.array_equal(reference_sweep.metrics, again.metrics, equal_nan=True)
    assert np.array_equal(reference_sweep.seeds, again.seeds)


@pytest.mark.parametrize("chunk", [1, 7, 40])
def test_chunk_size_does_not_change_any_run(reference_sweep, chunk):
    other = sweep(dataclasses.replace(SPEC, chunk=chunk))
    assert np.array_equal(reference_sweep.metrics, other.metrics, equal_nan=True)


def test_long_runs_go_in_smaller_chunks_with_the_same_numbers(reference_sweep, monkeypatch):
    from railpilot.sim import batch

    # a day at the finest step: 5 runs a chunk keep the per-step table at 5e7 values
    assert {b - a for a, b in batch._chunks(SPEC, 10_000_000)} == {5}
    assert {b - a for a, b in batch._chunks(SPEC, N_STEPS)} == {SPEC.chunk}
    # the sweep: as if a chunk of 10 of these runs were too large for memory
    monkeypatch.setattr(batch, "MAX_CHUNK_STEPS", 3 * N_STEPS)
    ran: list[tuple[int, int]] = []
    real_run_chunk = batch.run_chunk

    def recording(scenario, name, spec, start, stop):
        ran.append((start, stop))
        return real_run_chunk(scenario, name, spec, start, stop)

    monkeypatch.setattr(batch, "run_chunk", recording)
    smaller = sweep()
    assert max(stop - start for start, stop in ran) == 3
    assert sum(stop - start for start, stop in ran) == SPEC.runs
    assert np.array_equal(reference_sweep.metrics, smaller.metrics, equal_nan=True)


def test_run_chunk_alone_gives_those_rows_of_the_sweep(reference_sweep):
    # what a Dask worker executes: a pure function of (scenario, controller, spec, range)
    rows = run_chunk(NOISY, "qsmc", SPEC, 13, 21)
    assert rows.shape == (8, engine.N_METRICS)
    assert np.array_equal(rows, reference_sweep.metrics[13:21], equal_nan=True)


def test_different_seed_gives_different_numbers(reference_sweep):
    other = sweep(dataclasses.replace(SPEC, seed=12))
    # every run differs, not just some: new plant values and new disturbance seeds
    assert np.all(other.stop_errors != reference_sweep.stop_errors)
    assert not np.array_equal(other.seeds, reference_sweep.seeds)


def test_every_run_has_its_own_disturbance_seed():
    # nothing varies but each run's random disturbance: the stop errors still all differ
    result = sweep(MonteCarloSpec(runs=20, seed=3, chunk=20))
    assert len(np.unique(result.seeds)) == 20
    assert len(np.unique(result.stop_errors)) == 20


@pytest.mark.parametrize("run", [0, 13, 39])
def test_replay_and_simulate_reproduce_the_run_exactly(reference_sweep, run):
    replayed = simulate(replay_scenario(NOISY, SPEC, run), "qsmc")
    # the same kernel, alone and with a recorder: the same float, not just close
    assert replayed.metrics["stop_error_m"] == reference_sweep.stop_errors[run]
    assert replayed.metrics["max_jerk_mps3"] == reference_sweep.metrics[run, engine.M_MAX_JERK]


def test_replay_carries_the_sampled_values(reference_sweep):
    run = 5
    replayed = replay_scenario(NOISY, SPEC, run)
    values = reference_sweep.values
    assert replayed.train.mass_kg == pytest.approx(values["train.mass_t"][run] * 1e3, rel=1e-12)
    assert replayed.initial_speed_mps == pytest.approx(
        values["initial_speed_kmh"][run] / 3.6, rel=1e-12
    )
    assert replayed.disturbance.constant_n == pytest.approx(
        values["disturbance.constant_kn"][run] * 1e3, rel=1e-12
    )
    assert replayed.disturbance.seed == reference_sweep.seeds[run]


DELAY_SPEC = MonteCarloSpec(
    runs=6, seed=5, chunk=6, vary=(Distribution("brake.delay_s", "uniform", 1.05, 1.35),)
)


def test_sampled_brake_delay_run_is_reproduced_with_the_nominal_ato():
    # the batch tunes the controller on the nominal plant (docs/montecarlo.md): with
    # that controller a run whose brake delay was sampled replays exactly
    result = sweep(DELAY_SPEC)
    ctrl = make_controller(freeze_ato(NOISY), "qsmc")
    for run in range(DELAY_SPEC.runs):
        replayed = simulate(replay_scenario(NOISY, DELAY_SPEC, run), ctrl)
        assert replayed.metrics["stop_error_m"] == result.stop_errors[run]


@pytest.mark.parametrize("controller", ["qsmc", "pid"])
def test_replay_and_simulate_reproduce_a_run_with_sampled_brake_delay(controller):
    result = sweep(DELAY_SPEC, controller)
    replayed = [
        simulate(replay_scenario(NOISY, DELAY_SPEC, run), controller).metrics["stop_error_m"]
        for run in range(DELAY_SPEC.runs)
    ]
    assert np.array_equal(replayed, result.stop_errors)


@pytest.mark.parametrize("run", [-1, 40])
def test_replay_rejects_a_run_outside_the_sweep(run):
    with pytest.raises(ConfigError) as info:
        replay_scenario(NOISY, SPEC, run)
    assert info.value.field == "run"


# --- the ATO side is fixed, the plant varies ------------------------------------------


def test_freeze_ato_pins_the_resistance_model_and_lead_to_the_nominal_plant():
    scenario = Scenario()  # paper 000: no ATO model given, the true values are used
    frozen = freeze_ato(scenario)
    t = scenario.train
    assert frozen.ato.davis == (t.davis_a0, t.davis_a1, t.davis_a2)
    assert frozen.ato.brake_delay_s == scenario.brake.delay_s
    assert frozen.ato.brake_lag_s == scenario.brake.air_lag_s
    assert frozen.ato.mass_kg is None  # load weighing follows the true mass


# --- check_spec -----------------------------------------------------------------------


def test_check_spec_rejects_a_key_that_does_not_apply_to_the_brake():
    # brake.lag_s is the lag-delay brake's tau; paper 000's EP brake has no such field
    spec = MonteCarloSpec(runs=4, vary=(Distribution("brake.lag_s", "uniform", 0.4, 0.6),))
    with pytest.raises(ConfigError) as info:
        check_spec(Scenario(), spec)
    assert info.value.field == "montecarlo.vary.brake.lag_s"
    assert "EPBrake" in info.value.allowed


def test_check_spec_accepts_the_same_key_on_a_lag_delay_brake():
    spec = MonteCarloSpec(runs=4, vary=(Distribution("brake.lag_s", "uniform", 0.4, 0.6),))
    check_spec(NOISY, spec)  # no error


def test_run_montecarlo_refuses_a_bad_spec_before_running():
    spec = MonteCarloSpec(runs=4, vary=(Distribution("brake.air_lag_s", "uniform", 0.5, 0.7),))
    with pytest.raises(ConfigError, match=r"montecarlo\.vary\.brake\.air_lag_s"):
        sweep(spec)


# --- Dask -----------------------------------------------------------------------------


@pytest.mark.slow
def test_dask_local_cluster_gives_the_local_numbers_bit_for_bit(reference_sweep):
    distributed = pytest.importorskip("dask.distributed")
    # worker processes: the scenario and spec really are pickled to another interpreter
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        pool = ThreadPoolExecutor(1)
        try:
            future = pool.submit(sweep, scheduler=cluster.scheduler_address)
            remote = future.result(timeout=120)  # bounded: a hung cluster fails the test
        finally:
            pool.shutdown(wait=False, cancel_futures=True)
    assert np.array_equal(remote.metrics, reference_sweep.metrics, equal_nan=True)
    assert np.array_equal(remote.seeds, reference_sweep.seeds)


# --- memory stays flat ----------------------------------------------------------------


def test_result_keeps_only_scalars_per_run(reference_sweep):
    result = reference_sweep
    assert result.metrics.shape == (SPEC.runs, engine.N_METRICS)
    arrays = [v for v in vars(result).values() if isinstance(v, np.ndarray)]
    arrays += list(result.values.values())
    total = sum(a.nbytes for a in arrays)
    # 15 metrics + 1 seed + 1 value per varied parameter, 8 bytes each, per run
    assert total == SPEC.runs * 8 * (engine.N_METRICS + 1 + len(VARY))
    # one recorded channel of every run would already be 4,000 / 19 times as much
    assert total < SPEC.runs * N_STEPS * 8 / 100


def test_peak_memory_does_not_grow_with_the_run_count():
    spec_small = MonteCarloSpec(runs=40, seed=1, chunk=20)
    spec_large = dataclasses.replace(spec_small, runs=400)
    sweep(spec_small)  # compile and warm everything first

    def peak(spec):
        tracemalloc.start()
        try:
            sweep(spec)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    small, large = peak(spec_small), peak(spec_large)
    # keeping even one 4,000-step series per extra run would add 360 x 32 kB = 11.5 MB;
    # the metrics of 360 more runs are 43 kB
    one_series_per_extra_run = (spec_large.runs - spec_small.runs) * N_STEPS * 8
    assert large - small < one_series_per_extra_run / 20


# --- statistics -----------------------------------------------------------------------


def synthetic(stop_errors, jerks=None, seeds=None):
    n = len(stop_errors)
    metrics = np.zeros((n, engine.N_METRICS))
    metrics[:, engine.M_STOP_ERR] = stop_errors
    metrics[:, engine.M_MAX_JERK] = np.arange(n) * 0.01 if jerks is None else jerks
    seeds = np.arange(1000, 1000 + n) if seeds is None else seeds
    return MonteCarloResult("synthetic", "qsmc", MonteCarloSpec(runs=n), metrics, seeds)


# |stop error| = 0, 0.01, ..., 1.00 m with alternating signs (101 runs): the linear
# interpolated percentiles of |error| are exactly p / 100 m
MAGNITUDES = np.arange(101) / 100.0
SIGNED = MAGNITUDES * np.where(np.arange(101) % 2 == 0, 1.0, -1.0)


def test_stats_percentiles_of_abs_stop_error():
    stats = synthetic(SIGNED).stats()
    assert stats["p50_abs_stop_error_m"] == pytest.approx(0.50, abs=1e-12)
    assert stats["p95_abs_stop_error_m"] == pytest.approx(0.95, abs=1e-12)
    assert stats["p99_abs_stop_error_m"] == pytest.approx(0.99, abs=1e-12)
    assert stats["max_abs_stop_error_m"] == 1.0


def test_stats_mean_and_std_are_of_the_signed_error():
    stats = synthetic(SIGNED).stats()
    # even k positive, odd k negative: sum = (0 + 2 + ... + 100 - 1 - 3 - ... - 99) / 100
    assert stats["mean_stop_error_m"] == pytest.approx(0.50 / 101, abs=1e-12)
    mean = 0.50 / 101
    std = np.sqrt(np.sum(MAGNITUDES**2) / 101 - mean**2)  # population std
    assert stats["std_stop_error_m"] == pytest.approx(std, rel=1e-12)


def test_stats_share_within_tolerance_counts_the_boundary_in():
    stats = synthetic(SIGNED).stats()
    assert stats["share_within_0_30_m"] == pytest.approx(31 / 101)  # 0.00 .. 0.30
    wider = synthetic(SIGNED).stats(tolerance_m=0.5)
    assert wider["share_within_0_50_m"] == pytest.approx(51 / 101)


def test_stats_worst_run_and_its_seed():
    errors = np.array([0.1, -0.2, 0.05, -0.7, 0.3])
    seeds = np.array([11, 22, 33, 44, 55])
    stats = synthetic(errors, seeds=seeds).stats()
    assert stats["worst_run"] == 3
    assert stats["worst_run_seed"] == 44
    assert stats["worst_run_metrics"]["stop_error_m"] == -0.7
    assert stats["runs"] == 5
    assert stats["not_stopped"] == 0


def test_stats_jerk_columns():
    jerks = np.array([0.5, 2.0, 1.0, 0.25])
    stats = synthetic(np.zeros(4), jerks=jerks).stats()
    assert stats["max_jerk_mps3"] == 2.0
    assert stats["p99_max_jerk_mps3"] == pytest.approx(np.percentile(jerks, 99))


def test_runs_that_never_stopped_are_counted_and_make_max_none():
    errors = np.array([0.1, np.nan, -0.2, 0.4, np.nan])
    stats = synthetic(errors).stats()
    assert stats["runs"] == 5
    assert stats["not_stopped"] == 2
    assert stats["max_abs_stop_error_m"] is None
    # the others are of the runs that stopped
    assert stats["mean_stop_error_m"] == pytest.approx(0.1, abs=1e-12)
    assert stats["p50_abs_stop_error_m"] == pytest.approx(0.2)
    # a run that never stopped is not within tolerance, and it is the worst run
    assert stats["share_within_0_30_m"] == pytest.approx(2 / 5)
    assert stats["worst_run"] in (1, 4)


def test_no_run_stopped_gives_none_not_nan():
    stats = synthetic(np.full(3, np.nan)).stats()
    assert stats["not_stopped"] == 3
    for key in ("mean_stop_error_m", "std_stop_error_m", "p99_abs_stop_error_m"):
        assert stats[key] is None
    assert stats["share_within_0_30_m"] == 0.0
