"""The ATO's traction clamp follows the drive's envelope, and its gradient feed-forward can
look ahead (``ato.preview_s``): the heavy-haul run of docs/heavy-haul-vehicle.md.

Open-loop 'controllers' (a constant command) make the ATO's own additions visible in the
recorded command: the clamp, and the resistance feed-forward the ATO adds to every command.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.scenario.model import ATOModel
from railpilot.sim.run import simulate
from railpilot.vehicle.line import Line, Segment
from sim.test_driving import Constant, drive_scenario


def test_traction_command_is_clamped_to_the_envelope_at_the_measured_speed() -> None:
    # full traction asked: the ATO commands min(F0, P / v) / m_eff, not F0 / m_eff, so a
    # controller's anti-windup sees the saturation the drive has
    s = drive_scenario(duration_s=400.0)
    s = replace(s, sim=replace(s.sim, dt_s=0.1, control_period_s=0.1))
    result = simulate(s, Constant(10.0))
    traction = s.brake.locomotive.traction
    m_eff = s.train.effective_mass_kg
    v = result["speed_mps"]
    expected = traction.max_force(v) / m_eff
    assert v.max() > 1.5 * traction.base_speed_mps  # well into the constant-power range
    assert_allclose(result["command_mps2"], expected, rtol=1e-12)


def descent_scenario(preview_s: float):  # type: ignore[no-untyped-def]
    line = Line(gradients=(Segment(6_000.0, 12_000.0, -12.0),))
    s = drive_scenario(line, duration_s=800.0)
    s = replace(
        s, sim=replace(s.sim, dt_s=0.1, control_period_s=0.1), train=replace(s.train, length_m=10.0)
    )
    return replace(s, ato=replace(s.ato, gradient_feedforward=True, preview_s=preview_s))


def first_braking_position(preview_s: float) -> tuple[float, float]:
    # a controller that asks a small constant acceleration: the ATO adds its resistance
    # feed-forward, which turns the command to braking where the ATO expects the descent
    result = simulate(descent_scenario(preview_s), Constant(0.03))
    assert result["position_m"][-1] > 6_000.0
    k = int(np.argmax(result["command_mps2"] < 0.0))
    return float(result["position_m"][k]), float(result["speed_mps"][k])


def test_without_preview_the_feedforward_brakes_where_the_descent_begins() -> None:
    x, _ = first_braking_position(0.0)
    # within the (10 m) train's length, over which the averaged grade turns, and a step
    assert x == pytest.approx(6_000.0, abs=12.0)


def test_preview_brakes_that_many_seconds_of_travel_ahead_of_the_descent() -> None:
    x, v = first_braking_position(30.0)
    assert x == pytest.approx(6_000.0 - 30.0 * v, abs=12.0)
    assert x < 6_000.0 - 400.0  # (about 14 m/s there: 425 m ahead)


def test_preview_zero_is_the_default_and_changes_nothing() -> None:
    base = simulate(descent_scenario(0.0), Constant(0.03))
    s = descent_scenario(0.0)
    default = replace(s, ato=ATOModel(**{**s.ato.__dict__, "preview_s": ATOModel().preview_s}))
    again = simulate(default, Constant(0.03))
    assert ATOModel().preview_s == 0.0
    assert np.array_equal(base["command_mps2"], again["command_mps2"])


@pytest.mark.parametrize("value", [-1.0, float("nan"), 601.0, True])
def test_bad_preview_names_the_field(value) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError) as err:
        ATOModel(preview_s=value)
    assert err.value.field == "ato.preview_s"
