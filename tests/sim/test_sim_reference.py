"""Target braking curves (railpilot.sim.reference)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.sim.reference import constant_deceleration, smooth_stop

# paper 000 style curve: 72 km/h, 0.5 m/s^2, jerk 0.5, final 0.3 m/s^2 from 2 m/s
SMOOTH = {
    "v0_mps": 20.0,
    "decel_mps2": 0.5,
    "jerk_mps3": 0.5,
    "final_decel_mps2": 0.3,
    "final_phase_speed_mps": 2.0,
}


def test_constant_deceleration_stop_point_is_v0_squared_over_2a():
    # 19.8 m/s at 0.65 m/s^2: 19.8^2 / 1.3 = 301.5692... m
    curve = constant_deceleration(19.8, 0.65, start_m=1000.0)
    assert_allclose(curve.stop_m, 1000.0 + 19.8**2 / 1.3, rtol=1e-14)
    assert curve.stop_m == pytest.approx(1301.569, abs=1e-3)


def test_constant_deceleration_duration_is_v0_over_a():
    assert_allclose(constant_deceleration(19.8, 0.65).duration_s, 19.8 / 0.65, rtol=1e-14)


def test_constant_deceleration_sample_is_uniform_motion():
    curve = constant_deceleration(19.8, 0.65)
    t = np.linspace(0.0, 30.0, 61)
    x, v, a = curve.sample(t)
    assert_allclose(v, 19.8 - 0.65 * t, atol=1e-12)
    assert_allclose(x, 19.8 * t - 0.65 * t**2 / 2, atol=1e-9)
    assert_allclose(a, -0.65)


def test_curve_rests_at_stop_point_after_its_end():
    curve = constant_deceleration(19.8, 0.65)
    x, v, a = curve.sample(np.array([31.0, 100.0]))
    assert_allclose(x, curve.stop_m)
    assert_allclose(v, 0.0)
    assert_allclose(a, 0.0)


def phase_boundaries(curve):
    return np.cumsum(curve.durations_s)[:-1]


@pytest.mark.parametrize("ease_out", [False, True])
def test_smooth_stop_is_continuous_at_phase_boundaries(ease_out):
    curve = smooth_stop(**SMOOTH, ease_out=ease_out)
    eps = 1e-9
    for tb in phase_boundaries(curve):
        before = np.array(curve.sample(np.array([tb - eps])))
        after = np.array(curve.sample(np.array([tb + eps])))
        assert_allclose(after, before, atol=1e-7)


@pytest.mark.parametrize("ease_out", [False, True])
def test_smooth_stop_speed_reaches_zero_exactly_at_duration(ease_out):
    curve = smooth_stop(**SMOOTH, ease_out=ease_out)
    _, v_end, _ = curve.sample(np.array([curve.duration_s - 1e-12]))
    assert v_end[0] == pytest.approx(0.0, abs=1e-9)
    _, v_before, _ = curve.sample(np.array([curve.duration_s - 0.1]))
    assert v_before[0] > 0.0


def test_smooth_stop_ease_out_ends_with_zero_deceleration():
    curve = smooth_stop(**SMOOTH, ease_out=True)
    _, _, a_end = curve.sample(np.array([curve.duration_s - 1e-9]))
    assert a_end[0] == pytest.approx(0.0, abs=1e-6)


def test_smooth_stop_never_decelerates_beyond_decel_nor_jerks_beyond_jerk():
    curve = smooth_stop(**SMOOTH, ease_out=True)
    t = np.linspace(0.0, curve.duration_s, 20001)
    _, v, a = curve.sample(t)
    assert a.min() >= -0.5 - 1e-12
    assert a.min() == pytest.approx(-0.5)
    assert np.max(np.abs(np.diff(a) / np.diff(t))) <= 0.5 + 1e-9
    assert np.all(np.diff(v) <= 1e-12)


def test_smooth_stop_stop_point_matches_integrated_speed():
    # independent check of the knot algebra: trapezoid integral of v(t)
    curve = smooth_stop(**SMOOTH, start_m=500.0)
    t = np.linspace(0.0, curve.duration_s, 200001)
    _, v, _ = curve.sample(t)
    assert_allclose(500.0 + np.trapezoid(v, t), curve.stop_m, rtol=1e-9)


def test_smooth_stop_coast_keeps_the_braking_point():
    # with a 2 s coast the curve starts 2 v0 earlier and reaches start_m at t = 2 s
    curve = smooth_stop(**SMOOTH, start_m=1000.0, coast_s=2.0)
    x, v, a = curve.sample(np.array([0.0, 2.0]))
    assert_allclose(x, [1000.0 - 40.0, 1000.0])
    assert_allclose(v, [20.0, 20.0])
    assert_allclose(a, [0.0, 0.0])
    assert_allclose(curve.stop_m, smooth_stop(**SMOOTH, start_m=1000.0).stop_m, rtol=1e-14)


def test_speed_at_position_is_monotone_and_ends_at_zero():
    curve = smooth_stop(**SMOOTH, start_m=100.0)
    pos = np.linspace(0.0, curve.stop_m + 50.0, 3000)
    v = curve.speed_at_position(pos)
    assert np.all(np.diff(v) <= 1e-12)
    assert v[0] == 20.0
    assert v[-1] == 0.0


def test_speed_at_position_of_constant_curve_is_sqrt_law():
    # v(x) = sqrt(v0^2 - 2 a x) on a constant-deceleration curve
    curve = constant_deceleration(19.8, 0.65)
    pos = np.linspace(0.0, 290.0, 50)
    assert_allclose(curve.speed_at_position(pos), np.sqrt(19.8**2 - 1.3 * pos), rtol=2e-3)


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: constant_deceleration(0.0, 0.65), "reference.v0"),
        (lambda: constant_deceleration(19.8, -0.1), "reference.decel"),
        (lambda: smooth_stop(**{**SMOOTH, "jerk_mps3": np.nan}), "reference.jerk"),
        (lambda: smooth_stop(**{**SMOOTH, "final_decel_mps2": 0.8}), "reference.final_decel"),
        # ramps alone lose 0.25 + 0.16 m/s before the 2 m/s final phase: 2.2 m/s is too slow
        (lambda: smooth_stop(**{**SMOOTH, "v0_mps": 2.2}), "reference.v0"),
        (lambda: smooth_stop(**SMOOTH, coast_s=-1.0), "reference.coast_s"),
        (
            lambda: smooth_stop(**{**SMOOTH, "final_phase_speed_mps": 0.05}, ease_out=True),
            "reference.final_phase_speed",
        ),
    ],
)
def test_bad_input_raises_config_error_naming_it(build, field):
    with pytest.raises(ConfigError) as info:
        build()
    assert info.value.field == field
