"""The documented tuning of paper 000's controllers: one grid search per controller.

Both controllers get the same method and the same objective; only the grids differ
(SMARC has more free parameters). The linear part comes from SIMC
(railpilot.control.tuning) on the ATO's model of the brake; the grid then picks
SIMC's closed-loop time constant ``tau_c`` and the remaining free parameters to
minimise the worst |stop error| over an uncertainty set -- the clean case, the paper's
uncertain case, the paper case with the brake delay at 0.2 and 0.4 s and with the
mass at 90 % and 110 % -- subject to the deceleration never exceeding the maximum
service deceleration (the paper's requirement). Ties go to the lower RMS speed error.

``python -m railpilot.reproduce.tune_smarc_ep`` reruns the search and prints the
winners (a few seconds); railpilot.sim.run.default_controller_params holds them.
"""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

from railpilot.control.tuning import (
    simc_pid_integrating,
    smarc_from_simc,
    tracking_position_gain,
)
from railpilot.reproduce.smarc_ep import nominal_scenario, paper_scenario
from railpilot.scenario.model import ControllerSpec, Scenario
from railpilot.sim.run import ato_brake_model, simulate

PID_GRID: dict[str, tuple[float, ...]] = {
    "tau_c_factor": (0.5, 0.75, 1.0, 1.5, 2.0),
    "position_factor": (0.0, 0.25, 0.5, 0.75, 1.0),
}
SMARC_GRID: dict[str, tuple[float, ...]] = {
    "tau_c_factor": (0.25, 0.5, 1.0),
    "alpha": (0.0, 1.0),
    "eta": (0.02, 0.05, 0.1),
    "phi": (0.05, 0.1, 0.2),
    "gamma1": (0.0, 0.05, 0.2),
    "gamma2": (0.0, 0.05, 0.2),
}


def uncertainty_set() -> list[Scenario]:
    """The scenarios every candidate is judged on."""
    paper = paper_scenario()
    out = [nominal_scenario(), paper]
    out += [replace(paper, brake=replace(paper.brake, delay_s=d)) for d in (0.2, 0.4)]
    out += [
        replace(
            paper,
            train=replace(paper.train, mass_kg=paper.train.mass_kg * f),
            ato=replace(paper.ato, mass_kg=paper.train.mass_kg),
        )
        for f in (0.9, 1.1)
    ]
    return out


def pid_params(scenario: Scenario, tau_c_factor: float, position_factor: float) -> dict[str, Any]:
    delay, lag = ato_brake_model(scenario)
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
    delay, lag = ato_brake_model(scenario)
    return dict(
        smarc_from_simc(1.0, delay, lag, tau_c_s=tau_c_factor * (delay + lag)),
        alpha=alpha,
        eta=eta,
        phi=phi,
        gamma=(gamma1, gamma2),
        theta_bounds=((0.7, 1.5), (-0.3, 0.3)),
    )


def _candidates(grid: dict[str, tuple[float, ...]]) -> Iterator[dict[str, float]]:
    for values in itertools.product(*grid.values()):
        yield dict(zip(grid, values, strict=True))


def score(name: str, candidate: dict[str, float], scenarios: list[Scenario]) -> tuple[float, float]:
    """``(worst |stop error| [m], worst RMS speed error [m/s])``; inf if infeasible."""
    make = pid_params if name == "pid" else smarc_params
    worst_stop = 0.0
    worst_rms = 0.0
    for scenario in scenarios:
        params = make(scenario, **candidate)
        s = replace(scenario, controller=ControllerSpec(name, {name: params}))
        m = simulate(s, name).metrics
        limit = scenario.train.max_service_decel_mps2
        if math.isnan(m["stop_error_m"]) or m["max_decel_mps2"] > limit:
            return float("inf"), float("inf")
        worst_stop = max(worst_stop, abs(m["stop_error_m"]))
        worst_rms = max(worst_rms, m["rms_speed_error_mps"])
    return worst_stop, worst_rms


def search(name: str) -> tuple[dict[str, float], tuple[float, float]]:
    """The best candidate of ``name``'s grid and its score."""
    scenarios = uncertainty_set()
    grid = PID_GRID if name == "pid" else SMARC_GRID
    scored = [(score(name, c, scenarios), c) for c in _candidates(grid)]
    best_score, best = min(scored, key=lambda item: item[0])
    return best, best_score


def main() -> None:
    out = {}
    for name in ("pid", "smarc"):
        best, (stop, rms) = search(name)
        out[name] = {
            "parameters": best,
            "worst_abs_stop_error_m": stop,
            "worst_rms_speed_error_mps": rms,
        }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
