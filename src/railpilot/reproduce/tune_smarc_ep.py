"""Tuning of paper 000's controllers (railpilot.reproduce.tuning_search's method).

Both controllers get the same method and objective; only the grids differ (SMARC has
more free parameters). The uncertainty set: the clean case, the paper's uncertain case,
the paper case with the brake delay at 0.2 and 0.4 s, and with the mass at 90 % and
110 %. ``python -m railpilot.reproduce.tune_smarc_ep`` reruns the search (about 5 s) and
prints the winners; railpilot.sim.run.default_controller_params holds them.
"""

from __future__ import annotations

import json
from dataclasses import replace

from railpilot.brakes.ep_blend import EPBrake
from railpilot.reproduce.smarc_ep import nominal_scenario, paper_scenario
from railpilot.reproduce.tuning_search import Grid, report
from railpilot.scenario.model import Scenario

PID_GRID: Grid = {
    "tau_c_factor": (0.5, 0.75, 1.0, 1.5, 2.0),
    "position_factor": (0.0, 0.25, 0.5, 0.75, 1.0),
}
SMARC_GRID: Grid = {
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
    assert isinstance(paper.brake, EPBrake)  # paper 000 is an EP-brake scenario
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


def main() -> None:
    scenarios = uncertainty_set()
    print(
        json.dumps(
            {
                "pid": report("pid", PID_GRID, scenarios),
                "smarc": report("smarc", SMARC_GRID, scenarios),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
