"""Precise stop (railpilot.reproduce.precise_stop): the example file is the reproduction's
heavy-haul train, and the issue's claims hold on a small Monte Carlo.

Within 2 m on the heavy-haul train and within 0.30 m on the metro,
one gain set for both; the papers' controllers with the gains they ship with for the
metro stop tens of metres off on the heavy haul. The reproduction makes these claims
over 1,000 runs; here 60 runs per case, every one of which must meet the target.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from railpilot.reproduce import precise_stop, qsmc_stop
from railpilot.scenario.loader import load_scenario_and_spec
from railpilot.sim.batch import run_montecarlo

EXAMPLES = Path(__file__).parents[2] / "examples"
RUNS = 60


@pytest.fixture(scope="module")
def heavy_haul():
    return precise_stop.heavy_haul_scenario(), precise_stop.heavy_haul_spec(RUNS)


def test_example_file_is_the_heavy_haul_scenario():
    from_file, spec = load_scenario_and_spec(EXAMPLES / "heavy_haul_stop.toml")
    code = precise_stop.heavy_haul_scenario()
    # the physics one by one (a failure names what drifted), then everything
    assert from_file.train.mass_kg == code.train.mass_kg == 10_000e3
    assert from_file.train.length_m == code.train.length_m == 1600.0
    assert (from_file.train.davis_a0, from_file.train.davis_a1, from_file.train.davis_a2) == (
        code.train.davis_a0,
        code.train.davis_a1,
        code.train.davis_a2,
    )
    assert from_file.brake == code.brake
    assert (from_file.brake.delay_s, from_file.brake.lag_s) == (4.0, 6.0)  # the issue's
    assert from_file.brake.max_decel_mps2 == code.brake.max_decel_mps2
    assert from_file.reference == code.reference
    # the braking point at 0 m (the 10 s coast runs before it): v0^2 / (2 b) from 60 km/h
    assert from_file.reference.stop_m == pytest.approx((60.0 / 3.6) ** 2 / 0.4, rel=1e-12)
    assert from_file.ato == code.ato
    assert (from_file.ato.brake_delay_s, from_file.ato.brake_lag_s) == (4.0, 6.0)  # nominal
    assert (from_file.sim.dt_s, from_file.sim.control_period_s) == (
        code.sim.dt_s,
        code.sim.control_period_s,
    )
    assert from_file.disturbance == code.disturbance
    assert from_file.realism == code.realism
    assert from_file.controller.name == code.controller.name == "pstop"
    assert from_file == code
    # and the Monte Carlo: the same distributions, seed and size
    assert spec == precise_stop.heavy_haul_spec()
    assert spec.runs == precise_stop.RUNS


@pytest.mark.slow
def test_pstop_within_2_m_on_every_heavy_haul_run(heavy_haul):
    scenario, spec = heavy_haul
    errors = run_montecarlo(scenario, "pstop", spec, progress=False).stop_errors
    assert errors.shape == (RUNS,)
    assert np.all(np.isfinite(errors))  # every run stopped
    assert np.max(np.abs(errors)) <= precise_stop.HEAVY_HAUL_TOLERANCE_M == 2.0


@pytest.mark.slow
def test_pstop_within_0_30_m_on_every_metro_run():
    spec = replace(qsmc_stop.realistic_spec(), runs=RUNS)
    result = run_montecarlo(qsmc_stop.realistic_scenario(), "pstop", spec, progress=False)
    errors = result.stop_errors
    assert np.all(np.isfinite(errors))
    assert np.max(np.abs(errors)) <= precise_stop.METRO_TOLERANCE_M == 0.30


def test_qsmc_with_its_metro_gains_overruns_the_heavy_haul(heavy_haul):
    # paper 002's gains for a 1.2 s / 0.5 s brake on a 4 s / 6 s one: the brake builds up
    # seconds after the controller asked, so it stops metres past the point, not within 2 m
    scenario, spec = heavy_haul
    shipped = precise_stop.with_metro_gains(scenario, qsmc_stop.realistic_scenario())
    assert shipped.controller.params["qsmc"]["sigma"] < 2.0  # the metro's brake model
    errors = run_montecarlo(shipped, "qsmc", spec, progress=False).stop_errors
    stopped = errors[np.isfinite(errors)]
    assert stopped.size > 0
    assert np.mean(stopped) > precise_stop.HEAVY_HAUL_TOLERANCE_M
