"""Target point safety distance (railpilot.onboard.target_point).

Each term's effect on its own, against the formula worked by hand (docs/onboard.md).
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.onboard.target_point import (
    SafetyDistanceParameters,
    gradient_deceleration_mps2,
    safety_distance_m,
    target_stop_point_m,
)

#: every term off: the distance is 0 at any speed
NONE = SafetyDistanceParameters(
    fixed_margin_m=0.0,
    comm_delay_s=0.0,
    driver_reaction_s=0.0,
    speed_margin_mps=0.0,
    brake_guarantee=1.0,
)
V = np.array([0.0, 5.0, 12.5, 22.2])
A = 0.5


def test_with_every_term_off_the_distance_is_zero():
    assert_allclose(safety_distance_m(V, A, 0.0, NONE), 0.0, atol=1e-12)


def test_fixed_margin_adds_itself():
    p = SafetyDistanceParameters(**{**NONE.__dict__, "fixed_margin_m": 75.0})
    assert_allclose(safety_distance_m(V, A, 0.0, p), 75.0)


@pytest.mark.parametrize("name", ["comm_delay_s", "driver_reaction_s"])
def test_each_delay_adds_speed_times_delay(name):
    p = SafetyDistanceParameters(**{**NONE.__dict__, name: 2.5})
    assert_allclose(safety_distance_m(V, A, 0.0, p), V * 2.5)


def test_speed_margin_adds_the_extra_braking_distance_of_the_faster_train():
    p = SafetyDistanceParameters(**{**NONE.__dict__, "speed_margin_mps": 1.0})
    # by hand: ((v + 1)^2 - v^2) / (2 a) = (2 v + 1) / (2 a)
    assert_allclose(safety_distance_m(V, A, 0.0, p), (2 * V + 1.0) / (2 * A))


def test_brake_guarantee_adds_the_braking_distance_lost_to_a_weaker_brake():
    p = SafetyDistanceParameters(**{**NONE.__dict__, "brake_guarantee": 0.8})
    # by hand: v^2 / (2 0.8 a) - v^2 / (2 a) = v^2 / (2 a) (1 / 0.8 - 1)
    assert_allclose(safety_distance_m(V, A, 0.0, p), V**2 / (2 * A) * 0.25)


def test_a_descent_lengthens_and_an_ascent_shortens_the_distance():
    p = SafetyDistanceParameters()
    level = safety_distance_m(V[1:], A, 0.0, p)
    down = safety_distance_m(V[1:], A, -12.0, p)
    up = safety_distance_m(V[1:], A, 4.0, p)
    assert np.all(down > level) and np.all(up < level)
    # by hand on 12 per mille down: a = 0.5 - 9.8 * 12 / 1000 / 1.06 = 0.38906 m/s^2
    a = 0.5 - 9.8 * 12 / 1000 / 1.06
    assert_allclose(gradient_deceleration_mps2(A, -12.0), a, rtol=1e-12)
    v = V[1:]
    expected = 50.0 + v * 5.0 + (v + 0.6) ** 2 / (2 * 0.85 * a) - v**2 / (2 * a)
    assert_allclose(down, expected, rtol=1e-12)


def test_the_default_distance_at_80_kmh_on_the_level():
    # 22.22 m/s: 50 + 22.22 * 5 + (22.82^2 / 0.85 - 22.22^2) / 1.0
    v = 80 / 3.6
    expected = 50.0 + v * 5.0 + (v + 0.6) ** 2 / (2 * 0.85 * 0.5) - v**2 / (2 * 0.5)
    assert_allclose(safety_distance_m(v, 0.5), expected, rtol=1e-12)


def test_the_stop_point_is_on_the_approach_side_in_both_directions():
    d = float(safety_distance_m(15.0, A))
    assert target_stop_point_m(10_000.0, +1, 15.0, A) == pytest.approx(10_000.0 - d)
    assert target_stop_point_m(10_000.0, -1, 15.0, A) == pytest.approx(10_000.0 + d)


def test_a_gradient_the_brake_cannot_stop_on_is_an_error():
    with pytest.raises(ConfigError) as err:
        safety_distance_m(10.0, 0.05, -12.0)
    assert err.value.field == "gradient_permille"


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"fixed_margin_m": -1.0}, "safety.fixed_margin_m"),
        ({"comm_delay_s": math.nan}, "safety.comm_delay_s"),
        ({"driver_reaction_s": True}, "safety.driver_reaction_s"),
        ({"speed_margin_mps": math.inf}, "safety.speed_margin_mps"),
        ({"brake_guarantee": 0.0}, "safety.brake_guarantee"),
        ({"brake_guarantee": 1.2}, "safety.brake_guarantee"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        SafetyDistanceParameters(**kwargs)
    assert err.value.field == field


def test_bad_speed_or_deceleration_name_the_field():
    with pytest.raises(ConfigError) as err:
        safety_distance_m(-1.0, A)
    assert err.value.field == "speed_mps"
    with pytest.raises(ConfigError) as err:
        safety_distance_m(10.0, 0.0)
    assert err.value.field == "brake_decel_mps2"
