"""The example scenario files are the scenarios the reproductions run."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from railpilot.reproduce import qsmc_stop, smarc_ep
from railpilot.scenario.loader import load_scenario, load_scenario_and_spec
from railpilot.sim.run import simulate

EXAMPLES = Path(__file__).parents[2] / "examples"


def test_paper000_example_is_the_reproduced_scenario() -> None:
    assert load_scenario(EXAMPLES / "paper000_smarc_ep.toml") == smarc_ep.paper_scenario()


def test_paper002_example_runs_like_the_reproduction() -> None:
    # the file rounds the tuned PID gains to 7 digits: same plant, same stops to 1e-4 m
    from_file, spec = load_scenario_and_spec(EXAMPLES / "paper002_qsmc_stop.toml")
    code = qsmc_stop.random_disturbance(qsmc_stop.paper_scenario())
    assert spec is not None and spec.runs == 1000
    assert (from_file.brake, from_file.reference, from_file.ato) == (
        code.brake,
        code.reference,
        code.ato,
    )
    for name in ("pid", "qsmc"):
        a = simulate(from_file, name).metrics["stop_error_m"]
        # the file names its own random seed; everything else is the reproduction's
        same_seed = replace(code, disturbance=from_file.disturbance)
        b = simulate(same_seed, name).metrics["stop_error_m"]
        assert abs(a - b) < 1e-4
