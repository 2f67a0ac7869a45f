"""The loop closed in simulation: the driver model drives the planned curve.

Measured, not tuned: the heavy-haul train from station 1 to 2 of the shipped line.
"""

import pytest

from railpilot.line import load_line
from railpilot.onboard.advice import DriverModel
from railpilot.onboard.drive import drive, heavy_haul_loaded, train_line
from railpilot.scenario.model import ATOModel, Scenario, SimSettings
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.run import simulate


@pytest.mark.slow
def test_a_driver_following_the_plan_arrives_close_to_the_planned_time() -> None:
    line = load_line("heavy-haul")
    preset = heavy_haul_loaded()
    outcome = drive(line, preset, 1, 2)
    plan = outcome.plan
    scenario = Scenario(
        name="driver",
        train=preset.train,
        line=train_line(line, preset.category, outcome.direction, outcome.departure_m),
        brake=preset.brake,
        reference=PlannedProfile(plan.s_m, plan.speed_mps),
        ato=ATOModel(reference="distance", gradient_feedforward=True),
        sim=SimSettings(dt_s=0.1, duration_s=1.6 * plan.running_time_s),
    )
    result = simulate(scenario, DriverModel(max_accel_mps2=0.07, max_decel_mps2=0.5))
    assert result.meta["stopped"]
    # measured 1.0 % late and 3.9 m past (docs/onboard.md); not a precise-stop claim
    assert abs(result.metrics["running_time_s"] / plan.running_time_s - 1.0) < 0.06
    assert abs(result.metrics["stop_error_m"]) < 50.0
