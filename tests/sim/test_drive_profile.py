"""Whole-run driving reference (railpilot.sim.drive_profile), against analytic values."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.sim.drive_profile import DriveProfile, drive_profile
from railpilot.sim.inputs import distance_table, feed_forward_acceleration

# from rest at 0.8 m/s^2 to 20 m/s, cruise, brake at 0.6 m/s^2; 3 km from the 100 m post
A, V, D_DEC, START, LENGTH = 0.8, 20.0, 0.6, 100.0, 3000.0
T_ACC = V / A  # 25 s
X_ACC = V**2 / (2 * A)  # 250 m
T_BRAKE = V / D_DEC  # 33.33 s
X_BRAKE = V**2 / (2 * D_DEC)  # 333.33 m
T_CRUISE = (LENGTH - X_ACC - X_BRAKE) / V  # 120.83 s


def basic(**overrides: object) -> DriveProfile:
    kwargs: dict = {
        "start_m": START,
        "stop_m": START + LENGTH,
        "cruise_mps": V,
        "accel_mps2": A,
        "decel_mps2": D_DEC,
    }
    kwargs.update(overrides)
    return drive_profile(**kwargs)


# --- from rest, no limits: trapezoid in speed ------------------------------------------------


def test_from_rest_total_duration_is_the_analytic_sum():
    assert_allclose(basic().duration_s, T_ACC + T_CRUISE + T_BRAKE, rtol=1e-12)


def test_reaches_cruise_after_v_over_a_at_v_squared_over_2a():
    x, v, a = basic().sample(np.array([T_ACC - 1e-6, T_ACC, T_ACC + 1e-6]))
    assert_allclose(x[1], START + X_ACC, rtol=1e-12)
    assert_allclose(v[1], V, rtol=1e-12)
    assert_allclose(a[[0, 2]], [A, 0.0], atol=1e-12)


def test_acceleration_phase_is_uniform_motion_from_rest():
    t = np.linspace(0.0, T_ACC, 101)
    x, v, a = basic().sample(t)
    assert_allclose(v, A * t, atol=1e-10)
    assert_allclose(x, START + A * t**2 / 2, atol=1e-9)
    assert_allclose(a[:-1], A, atol=1e-12)


def test_cruise_lasts_l_cruise_over_v_then_brakes_at_decel():
    t_brake = T_ACC + T_CRUISE
    _, v, a = basic().sample(np.array([T_ACC + 1.0, t_brake - 1e-6, t_brake + 1e-6]))
    assert_allclose(v[:2], V, rtol=1e-12)
    assert_allclose(a, [0.0, 0.0, -D_DEC], atol=1e-12)
    _, v_half, _ = basic().sample(np.array([t_brake + T_BRAKE / 2]))
    assert_allclose(v_half, V / 2, rtol=1e-10)


def test_stops_exactly_at_stop_m_and_rests_there_like_braking_curve():
    profile = basic()
    end = profile.duration_s
    x, v, a = profile.sample(np.array([end - 1e-9, end, end + 1.0, 1e6]))
    assert_allclose(x, START + LENGTH, rtol=1e-14)
    assert_allclose(v, 0.0, atol=1e-8)
    assert a[0] == pytest.approx(-D_DEC)  # the final deceleration just before the end
    assert_allclose(a[1:], 0.0)  # at rest afterwards, as BrakingCurve.sample


def test_before_t0_it_is_the_state_at_t0():
    x, v, a = basic().sample(np.array([-5.0, 0.0]))
    assert_allclose(x, START)
    assert_allclose(v, 0.0)
    assert_allclose(a, A)  # traction commanded from the first step


def test_the_grid_step_does_not_change_the_profile():
    # the kinks are knots, so any dx gives the same (exact) profile
    fine, coarse = basic(dx_m=0.5), basic(dx_m=333.3)
    assert_allclose(coarse.duration_s, fine.duration_s, rtol=1e-12)
    t = np.linspace(0.0, fine.duration_s, 777)
    for got, want in zip(coarse.sample(t), fine.sample(t), strict=True):
        assert_allclose(got, want, atol=1e-8)


def test_properties_like_a_braking_curve():
    profile = basic(v_start_mps=5.0)
    assert profile.start_m == START
    assert profile.stop_m == START + LENGTH
    assert profile.v0_mps == 5.0


# --- start: the min_speed floor and a flying start --------------------------------------------


def test_target_at_the_start_is_min_speed_from_rest():
    profile = basic(min_speed_mps=0.5)
    u = np.array([-10.0, 0.0, 0.1, 0.5**2 / (2 * A)]) + START
    assert_allclose(profile.speed_at_position(u), 0.5, rtol=1e-12)
    beyond = START + np.array([1.0, 100.0, X_ACC])
    assert_allclose(profile.speed_at_position(beyond), np.sqrt(2 * A * (beyond - START)))


def test_without_floor_the_target_at_the_start_is_zero():
    assert basic(min_speed_mps=0.0).speed_at_position(np.array([START]))[0] == 0.0


def test_flying_start_at_cruise_speed():
    profile = basic(v_start_mps=V)
    assert_allclose(profile.duration_s, (LENGTH - X_BRAKE) / V + T_BRAKE, rtol=1e-12)
    _, v, a = profile.sample(np.array([0.0, 10.0]))
    assert_allclose(v, V)
    assert_allclose(a, 0.0)


def test_flying_start_accelerates_from_v_start():
    v0 = 8.0
    profile = basic(v_start_mps=v0)
    t_acc = (V - v0) / A
    x, v, _ = profile.sample(np.array([t_acc]))
    assert_allclose(v, V, rtol=1e-12)
    assert_allclose(x, START + (V**2 - v0**2) / (2 * A), rtol=1e-12)


# --- a short line: triangle profile -----------------------------------------------------------


def test_short_line_peaks_at_sqrt_2adD_over_a_plus_d():
    dist = 400.0
    peak = np.sqrt(2 * A * D_DEC * dist / (A + D_DEC))  # 16.56 m/s < V
    profile = basic(stop_m=START + dist)
    x, v, a = profile.sample(np.array([peak / A - 1e-6, peak / A, peak / A + 1e-6]))
    assert_allclose(v[1], peak, rtol=1e-12)
    assert_allclose(x[1], START + D_DEC * dist / (A + D_DEC), rtol=1e-12)
    assert_allclose(a[[0, 2]], [A, -D_DEC], atol=1e-12)
    assert_allclose(profile.duration_s, peak / A + peak / D_DEC, rtol=1e-12)
    positions = np.linspace(START, START + dist, 4001)
    assert profile.speed_at_position(positions).max() <= peak * (1 + 1e-12)


# --- speed limits ----------------------------------------------------------------------------

# 30 m/s line, 15 m/s limit on [2000, 2500] m, 200 m train: the limit holds to 2700 m
LIM = (2000.0, 2500.0, 15.0)
TRAIN_M = 200.0


def limited(**overrides: object) -> DriveProfile:
    kwargs: dict = {
        "start_m": 0.0,
        "stop_m": 5000.0,
        "cruise_mps": 30.0,
        "accel_mps2": 1.0,
        "decel_mps2": 0.8,
        "limits": [LIM],
        "train_length_m": TRAIN_M,
        "dx_m": 7.3,
    }
    kwargs.update(overrides)
    return drive_profile(**kwargs)


def test_limit_holds_from_segment_start_to_end_plus_train_length():
    profile = limited()
    inside = np.linspace(2000.0, 2700.0, 1401)
    assert_allclose(profile.speed_at_position(inside), 15.0, rtol=1e-12)
    t = np.linspace(0.0, profile.duration_s, 20001)
    x, v, _ = profile.sample(t)
    within = (x >= 2000.0) & (x <= 2700.0)
    assert within.sum() > 100
    assert np.all(v[within] <= 15.0 * (1 + 1e-12))


def test_limit_is_entered_braking_and_left_accelerating():
    profile = limited()
    before = 2000.0 - np.array([1.0, 50.0, 400.0])
    after = 2700.0 + np.array([1.0, 50.0, 300.0])
    assert_allclose(profile.speed_at_position(before), np.sqrt(15.0**2 + 2 * 0.8 * (2000 - before)))
    assert_allclose(profile.speed_at_position(after), np.sqrt(15.0**2 + 2 * 1.0 * (after - 2700)))


def test_duration_with_a_limit_is_the_analytic_sum():
    # accel 0->30: 30 s over 450 m; brake 30->15 before 2000 m: 18.75 s over 421.875 m;
    # cruise 450 -> 1578.125 m; limit 2000 -> 2700 m; accel 15->30: 15 s over 337.5 m;
    # cruise 3037.5 -> 4437.5 m; brake 30->0: 37.5 s over 562.5 m
    expected = 30 + 1128.125 / 30 + 18.75 + 700 / 15 + 15 + 1400 / 30 + 37.5
    assert_allclose(limited().duration_s, expected, rtol=1e-12)


def test_train_length_extends_the_limit():
    short, long = limited(train_length_m=0.0), limited()
    probe = np.array([2600.0])
    assert short.speed_at_position(probe)[0] > 15.0
    assert long.speed_at_position(probe)[0] == pytest.approx(15.0)
    assert_allclose(long.duration_s - short.duration_s, 200 / 15 - 200 / 30, rtol=1e-10)


def test_overlapping_limits_the_lowest_holds():
    profile = limited(limits=[LIM, (2200.0, 2300.0, 10.0)], train_length_m=0.0)
    speeds = profile.speed_at_position(np.array([2100.0, 2180.0, 2250.0, 2320.0, 2400.0]))
    # 15 m/s far from the 10 m/s part, braking into it at 0.8, accelerating out at 1.0
    expected = [15.0, np.sqrt(10.0**2 + 2 * 0.8 * 20), 10.0, np.sqrt(10.0**2 + 2 * 1.0 * 20), 15.0]
    assert_allclose(speeds, expected, rtol=1e-12)


# --- properties over random runs --------------------------------------------------------------


@st.composite
def runs(draw: st.DrawFn) -> DriveProfile:
    accel = draw(st.floats(0.2, 1.5))
    decel = draw(st.floats(0.3, 1.2))
    cruise = draw(st.floats(5.0, 40.0))
    start = draw(st.floats(-1000.0, 1000.0))
    dist = draw(st.floats(50.0, 20_000.0))
    limits = []
    for _ in range(draw(st.integers(0, 3))):
        s = start + draw(st.floats(0.0, 0.95)) * dist
        limits.append((s, s + draw(st.floats(0.01, 0.5)) * dist, draw(st.floats(2.0, 30.0))))
    v_start = draw(st.floats(0.0, 1.0)) * min(cruise, np.sqrt(2 * decel * dist))
    try:
        return drive_profile(
            start,
            start + dist,
            cruise,
            accel,
            decel,
            limits=limits,
            v_start_mps=v_start,
            min_speed_mps=draw(st.floats(0.0, 1.0)),
            dx_m=draw(st.floats(0.5, 50.0)),
            train_length_m=draw(st.floats(0.0, 400.0)),
        )
    except ConfigError as err:  # a flying start above a limit at the start
        assume(err.field != "reference.v_start_mps")
        raise


@settings(max_examples=60, deadline=None)
@given(runs())
def test_profile_never_exceeds_any_input(profile: DriveProfile):
    x = np.linspace(profile.start_m, profile.stop_m, 20001)
    u = x - profile.start_m
    v = profile.speed_at_position(x)
    eps = 1e-9
    assert np.all(v <= profile.cruise_mps + eps)
    assert np.all(v <= np.sqrt(2 * profile.decel_mps2 * (profile.stop_m - x)) + eps)
    accel = np.sqrt(profile.v_start_mps**2 + 2 * profile.accel_mps2 * u)
    assert np.all(v <= np.maximum(accel, profile.min_speed_mps) + eps)
    for s, e, lim in profile.limits:
        held = (x >= s) & (x <= e + profile.train_length_m)
        assert np.all(v[held] <= lim + eps)


@settings(max_examples=60, deadline=None)
@given(runs())
def test_profile_is_continuous(profile: DriveProfile):
    # |d(v^2)/dx| <= 2 max(a, d), so |dv| <= sqrt(2 max(a, d) dx)
    x = np.linspace(profile.start_m, profile.stop_m, 20001)
    dv = np.abs(np.diff(profile.speed_at_position(x)))
    bound = np.sqrt(2 * max(profile.accel_mps2, profile.decel_mps2) * (x[1] - x[0]))
    assert np.all(dv <= bound * (1 + 1e-9) + 1e-12)


@settings(max_examples=60, deadline=None)
@given(runs())
def test_sample_is_consistent_with_the_speed_distance_target(profile: DriveProfile):
    t = np.linspace(0.0, profile.duration_s, 20001)
    x, v, a = profile.sample(t)
    assert np.all(np.diff(x) >= 0.0)
    assert np.all(v >= 0.0)
    assert x[0] == profile.start_m
    assert x[-1] == profile.stop_m
    target = profile.speed_at_position(x)
    # equal beyond the min_speed floor near a start from rest, below it before
    floor_m = max(profile.min_speed_mps**2 - profile.v0_mps**2, 0.0) / (2 * profile.accel_mps2)
    beyond = x - profile.start_m >= floor_m
    assert_allclose(v[beyond], target[beyond], atol=1e-7)
    assert np.all(v <= target + 1e-7)
    # distance = integral of v dt; speed change = integral of a dt (trapezoid rule). The
    # rule errs only at the kinks (at most 3 per limit + 4), each a jump of the
    # acceleration of at most a + d: by <= jump dt^2 / 8 in x, <= jump dt / 2 in v
    dt = t[1] - t[0]
    jumps = (3 * len(profile.limits) + 4) * (profile.accel_mps2 + profile.decel_mps2)
    travelled = np.sum((v[1:] + v[:-1]) / 2) * dt
    assert_allclose(travelled, profile.stop_m - profile.start_m, rtol=1e-12, atol=jumps * dt**2 / 8)
    dv = np.concatenate(([0.0], np.cumsum((a[1:] + a[:-1]) / 2) * dt))
    assert_allclose(v, profile.v0_mps + dv, atol=jumps * dt / 2 + 1e-9)


@settings(max_examples=60, deadline=None)
@given(runs())
def test_acceleration_is_v_dv_dx(profile: DriveProfile):
    # between kinks a = v dv/dx = d(v^2)/dx / 2; central differences of the target
    t = np.linspace(0.0, profile.duration_s, 501)[1:-1]
    x, _, a = profile.sample(t)
    h = 1e-4
    beyond = x - profile.start_m > profile.min_speed_mps**2 / (2 * profile.accel_mps2) + h
    v2 = profile.speed_at_position(np.stack([x - h, x + h])) ** 2
    slope = (v2[1] - v2[0]) / (4 * h)
    smooth = beyond & (np.abs(a - slope) < 1e-5)
    # at most a few samples sit within h of a kink
    assert (beyond & ~smooth).sum() <= 2 * (3 * len(profile.limits) + 4)


# --- it fits where a BrakingCurve does -----------------------------------------------------------


def test_inputs_builders_accept_a_drive_profile():
    profile = limited()
    t = np.arange(0.0, profile.duration_s + 1.0, 0.1)
    a_ff = feed_forward_acceleration(profile, t, 0.6)
    assert a_ff[0] == pytest.approx(1.0)
    end = t < profile.duration_s
    assert_allclose(a_ff[end & (t + 0.6 >= profile.duration_s)], -0.8)  # held to the stop
    table = distance_table(profile, 0.1, 0.6)
    assert np.all(np.diff(table[0]) > 0)
    assert table[0, -1] == pytest.approx(profile.stop_m)


# --- validation -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"start_m": float("nan")}, "reference.start_m"),
        ({"stop_m": START}, "reference.stop_m"),
        ({"stop_m": START - 1.0}, "reference.stop_m"),
        ({"stop_m": float("inf")}, "reference.stop_m"),
        ({"cruise_mps": 0.0}, "reference.cruise_mps"),
        ({"cruise_mps": float("inf")}, "reference.cruise_mps"),
        ({"accel_mps2": -0.5}, "reference.accel_mps2"),
        ({"decel_mps2": float("nan")}, "reference.decel_mps2"),
        ({"dx_m": 0.0}, "reference.dx_m"),
        ({"dx_m": 1e-6}, "reference.dx_m"),  # 3e9 knots
        ({"v_start_mps": -1.0}, "reference.v_start_mps"),
        ({"v_start_mps": V + 1.0}, "reference.v_start_mps"),  # above cruise
        ({"min_speed_mps": -0.1}, "reference.min_speed_mps"),
        ({"train_length_m": float("nan")}, "reference.train_length_m"),
        ({"limits": [(500.0, 400.0, 10.0)]}, "reference.limits[0]"),  # end before start
        ({"limits": [(500.0, 600.0, 0.0)]}, "reference.limits[0]"),
        ({"limits": [(500.0, 600.0, 10.0), (5.0, 6.0, 10.0)]}, "reference.limits[1]"),  # outside
        ({"limits": [(5000.0, 6000.0, 10.0)]}, "reference.limits[0]"),  # beyond the stop
        ({"limits": [(500.0, 600.0)]}, "reference.limits[0]"),
        ({"limits": [(500.0, "x", 10.0)]}, "reference.limits[0]"),
        ({"limits": [(50.0, 600.0, 10.0)], "v_start_mps": 12.0}, "reference.v_start_mps"),
    ],
)
def test_bad_inputs_name_the_field(overrides: dict, field: str):
    with pytest.raises(ConfigError) as err:
        basic(**overrides)
    assert err.value.field == field


def test_a_limit_covering_the_start_is_fine_at_or_below_it():
    profile = basic(limits=[(0.0, 600.0, 10.0)], v_start_mps=10.0)
    assert profile.speed_at_position(np.array([START, 599.0])) == pytest.approx([10.0, 10.0])


def test_profile_is_hashable_and_compares_by_its_inputs():
    assert basic() == basic()
    assert hash(basic()) == hash(basic())
    assert basic() != basic(cruise_mps=V - 1)
