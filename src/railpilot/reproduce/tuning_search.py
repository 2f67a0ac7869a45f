"""The documented tuning method for baselines: SIMC, then a grid over an uncertainty set.

The linear part of a controller comes from SIMC (railpilot.control.tuning) on the ATO's
model of the brake; a grid search then picks SIMC's closed-loop time constant ``tau_c``
and the remaining free parameters: the candidate with the smallest worst |stop error|
over a set of scenarios (the uncertainty the controller must live with), among those
whose deceleration never exceeds the maximum service deceleration. Ties go to the lower
worst RMS speed error. Each paper's module (tune_smarc_ep, tune_qsmc_stop) names its
uncertainty set and grids and prints the winners.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

from railpilot.control.tuning import (
    simc_pid_integrating,
    smarc_from_simc,
    tracking_position_gain,
)
from railpilot.scenario.model import ControllerSpec, Scenario
from railpilot.sim.run import simulate, tuning_model

Grid = dict[str, tuple[float, ...]]
ParamMaker = Callable[..., dict[str, Any]]


def pid_params(scenario: Scenario, tau_c_factor: float, position_factor: float) -> dict[str, Any]:
    """Tracking PID: SIMC PID with ``tau_c = factor * theta``, position loop by rule."""
    delay, lag = tuning_model(scenario)
    tau_c = tau_c_factor * delay
    return dict(
        simc_pid_integrating(1.0, delay, lag, tau_c_s=tau_c),
        anti_windup="backcalc",
        position_gain=tracking_position_gain(delay, lag, tau_c, position_factor),
    )


def smarc_params(
    scenario: Scenario,
    tau_c_factor: float,
    alpha: float,
    eta: float,
    phi: float,
    gamma1: float,
    gamma2: float,
) -> dict[str, Any]:
    """SMARC: SIMC PI rule for ``c, ks`` with ``tau_c = factor * theta_eff``, the rest given."""
    delay, lag = tuning_model(scenario)
    return dict(
        smarc_from_simc(1.0, delay, lag, tau_c_s=tau_c_factor * (delay + lag)),
        alpha=alpha,
        eta=eta,
        phi=phi,
        gamma=(gamma1, gamma2),
        theta_bounds=((0.7, 1.5), (-0.3, 0.3)),
    )


MAKERS: dict[str, ParamMaker] = {"pid": pid_params, "smarc": smarc_params}


def candidates(grid: Grid) -> Iterator[dict[str, float]]:
    for values in itertools.product(*grid.values()):
        yield dict(zip(grid, values, strict=True))


def score(name: str, candidate: dict[str, float], scenarios: list[Scenario]) -> tuple[float, float]:
    """``(worst |stop error| [m], worst RMS speed error [m/s])``; inf if infeasible."""
    worst_stop = 0.0
    worst_rms = 0.0
    for scenario in scenarios:
        params = MAKERS[name](scenario, **candidate)
        s = replace(scenario, controller=ControllerSpec(name, {name: params}))
        m = simulate(s, name).metrics
        limit = scenario.train.max_service_decel_mps2
        if math.isnan(m["stop_error_m"]) or m["max_decel_mps2"] > limit:
            return math.inf, math.inf
        worst_stop = max(worst_stop, abs(m["stop_error_m"]))
        worst_rms = max(worst_rms, m["rms_speed_error_mps"])
    return worst_stop, worst_rms


def search(
    name: str, grid: Grid, scenarios: list[Scenario]
) -> tuple[dict[str, float], tuple[float, float]]:
    """The best candidate of ``grid`` for controller ``name`` and its score."""
    scored = [(score(name, c, scenarios), c) for c in candidates(grid)]
    best_score, best = min(scored, key=lambda item: item[0])
    return best, best_score


def report(name: str, grid: Grid, scenarios: list[Scenario]) -> dict[str, Any]:
    best, (stop, rms) = search(name, grid, scenarios)
    return {"parameters": best, "worst_abs_stop_error_m": stop, "worst_rms_speed_error_mps": rms}
