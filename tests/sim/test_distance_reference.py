"""The ATO's distance-to-go reference (``[ato] reference = "distance"``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from railpilot.errors import ScenarioError
from railpilot.reproduce.smarc_ep import paper_scenario
from railpilot.scenario import scenario_from_mapping
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.batch import freeze_ato, replay_scenario, run_montecarlo
from railpilot.sim.run import distance_table, simulate


def _distance(scenario):  # type: ignore[no-untyped-def]
    return replace(scenario, ato=replace(scenario.ato, reference="distance"))


@pytest.mark.parametrize("controller", ["pid", "smarc"])
def test_a_train_that_starts_slow_still_stops_at_the_point(controller: str) -> None:
    # 4 m/s below the curve at the start: a braking-only ATO cannot catch up with a
    # time-based reference, but on distance to go the curve simply waits for the train
    slow = replace(paper_scenario(), initial_speed_mps=16.0)
    assert abs(simulate(_distance(slow), controller).metrics["stop_error_m"]) < 0.05


def test_the_time_based_pid_overshoots_the_same_slow_start() -> None:
    slow = replace(paper_scenario(), initial_speed_mps=16.0)
    assert simulate(slow, "pid").metrics["stop_error_m"] > 1.0


def test_distance_table_is_the_curve_by_position() -> None:
    curve = paper_scenario().reference
    table = distance_table(curve, 0.01, 0.95)
    assert np.all(np.diff(table[0]) > 0)
    assert table[0][-1] == pytest.approx(curve.stop_m)
    probe = np.linspace(table[0][0], table[0][-1], 50)
    np.testing.assert_allclose(
        np.interp(probe, table[0], table[1]), curve.speed_at_position(probe), atol=1e-3
    )


def test_the_recorded_reference_follows_the_measured_position() -> None:
    result = simulate(_distance(paper_scenario()), "smarc")
    moving = result["speed_mps"] > 0
    np.testing.assert_allclose(
        result["ref_position_m"][moving][::20], result["odometer_m"][moving][::20], atol=1e-9
    )


def test_freeze_ato_keeps_the_reference_mode_and_replay_is_exact() -> None:
    scenario = _distance(paper_scenario())
    assert freeze_ato(scenario).ato.reference == "distance"
    spec = MonteCarloSpec(
        runs=6, seed=3, chunk=4, vary=(Distribution("train.mass_t", "uniform", 490.0, 580.0),)
    )
    result = run_montecarlo(scenario, "pid", spec, progress=False)
    for run in range(spec.runs):
        replayed = simulate(replay_scenario(scenario, spec, run), "pid").metrics
        assert replayed["stop_error_m"] == result.stop_errors[run]


def test_loader_reads_and_checks_the_reference_mode() -> None:
    loaded = scenario_from_mapping({"name": "t", "ato": {"reference": "distance"}})
    assert loaded.ato.reference == "distance"
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({"name": "t", "ato": {"reference": "position"}})
    assert info.value.field == "ato.reference"
