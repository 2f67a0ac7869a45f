"""Tuning of paper 002's PID baseline (railpilot.reproduce.tuning_search's method).

QSMC has its own analytic rule (control/tuning.qsmc_defaults). The PID gets the grid
search on paper 002's uncertainty set: the paper's stop with sigma 1.05, 1.2 and 1.35 s
and tau 0.4 and 0.6 s, each with the ±2.3 % random disturbance (one fixed seed).
``python -m railpilot.reproduce.tune_qsmc_stop`` reruns it and prints the winner, which
railpilot.reproduce.qsmc_stop.PID_TUNING holds.
"""

from __future__ import annotations

import json
from dataclasses import replace

from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.reproduce.qsmc_stop import paper_scenario, random_disturbance
from railpilot.reproduce.tuning_search import Grid, report
from railpilot.scenario.model import Scenario

PID_GRID: Grid = {
    "tau_c_factor": (0.25, 0.5, 0.75, 1.0, 1.5, 2.0),
    "position_factor": (0.0, 0.25, 0.5, 0.75, 1.0),
}


def uncertainty_set() -> list[Scenario]:
    out = [random_disturbance(paper_scenario(sigma)) for sigma in (1.05, 1.2, 1.35)]
    base = random_disturbance(paper_scenario())
    assert isinstance(base.brake, LagDelayBrake)  # paper 002's brake model
    out += [replace(base, brake=replace(base.brake, lag_s=tau)) for tau in (0.4, 0.6)]
    return out


def main() -> None:
    print(json.dumps({"pid": report("pid", PID_GRID, uncertainty_set())}, indent=2))


if __name__ == "__main__":
    main()
