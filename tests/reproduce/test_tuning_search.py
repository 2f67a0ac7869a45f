"""The baselines' parameters are what the documented tuning search picks."""

from __future__ import annotations

import math

import pytest

from railpilot.reproduce import qsmc_stop, tune_qsmc_stop, tune_smarc_ep
from railpilot.reproduce.smarc_ep import paper_scenario
from railpilot.reproduce.tuning_search import pid_params, score, search, smarc_params
from railpilot.sim.run import default_controller_params


def test_paper000_pid_defaults_are_the_grid_winner() -> None:
    best, _ = search("pid", tune_smarc_ep.PID_GRID, tune_smarc_ep.uncertainty_set())
    scenario = paper_scenario()
    assert default_controller_params(scenario, "pid") == pid_params(scenario, **best)


@pytest.mark.slow
def test_paper000_smarc_defaults_are_the_grid_winner() -> None:
    best, _ = search("smarc", tune_smarc_ep.SMARC_GRID, tune_smarc_ep.uncertainty_set())
    scenario = paper_scenario()
    assert default_controller_params(scenario, "smarc") == smarc_params(scenario, **best)


def test_paper002_pid_tuning_is_the_grid_winner() -> None:
    best, (worst_stop, _) = search("pid", tune_qsmc_stop.PID_GRID, tune_qsmc_stop.uncertainty_set())
    assert best == qsmc_stop.PID_TUNING
    assert worst_stop < 0.30


def test_a_candidate_that_brakes_beyond_the_service_limit_is_infeasible() -> None:
    # an absurdly aggressive PID (tau_c far below the delay) rings past 1 m/s^2
    scenarios = tune_smarc_ep.uncertainty_set()[:2]
    worst_stop, worst_rms = score("pid", {"tau_c_factor": 0.01, "position_factor": 1.0}, scenarios)
    assert math.isinf(worst_stop) and math.isinf(worst_rms)
