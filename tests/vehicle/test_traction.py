"""Traction and electric-brake envelopes, energy chain (railpilot.vehicle.traction).

The envelopes alone (regions, continuity, published HXD1 points, Numba twin == NumPy), then
the envelope driving a train against Davis resistance, checked against the closed forms of
tests/vehicle/analytic.py through scipy's solve_ivp.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.integrate import solve_ivp

from railpilot.errors import ConfigError
from railpilot.units import kmh_to_mps, kn_to_n, specific_to_force_n, tonne_to_kg
from railpilot.vehicle.resistance import davis_resistance_n
from railpilot.vehicle.traction import (
    HXD1_MAX_REGEN_FORCE_N,
    HXD1_MAX_TRACTIVE_FORCE_N,
    HXD1_POWER_W,
    HXD1_REGEN_FADE_BELOW_MPS,
    REGEN_EFFICIENCY,
    TRACTION_EFFICIENCY,
    Locomotive,
    RegenEnvelope,
    TractionEnvelope,
    hxd1_locomotive,
    regen_force_envelope_n,
    regen_force_max,
    regenerated_energy_returned_j,
    traction_energy_drawn_j,
    traction_force_envelope_n,
    traction_force_max,
)
from railpilot.vehicle.train import ElectricBrakeCurve

from .analytic import (
    distance_at_time_analytic,
    quadratic_motion_coefficients,
    speed_at_time_analytic,
    terminal_speed,
    time_to_speed_analytic,
    time_to_speed_constant_power,
)

HXD1 = hxd1_locomotive()
F0, P = HXD1_MAX_TRACTIVE_FORCE_N, HXD1_POWER_W
V_BASE = P / F0  # 12.63 m/s = 45.47 km/h

# --- traction envelope ------------------------------------------------------------------


def test_constant_force_up_to_the_base_speed():
    # starting effort at standstill and everywhere below P / F0
    v = np.array([0.0, 1.0, 5.0, 12.0, V_BASE * (1 - 1e-12)])
    assert_array_equal(HXD1.traction.max_force(v), np.full(v.shape, F0))


def test_constant_power_above_the_base_speed():
    # F v = P exactly, 45.5 .. 120 km/h
    v = np.array([V_BASE * 1.001, 15.0, 20.0, kmh_to_mps(80.0), kmh_to_mps(120.0)])
    assert_allclose(HXD1.traction.max_force(v) * v, P, rtol=1e-15)


def test_envelope_is_continuous_at_the_base_speed():
    below, at, above = HXD1.traction.max_force(V_BASE * np.array([1 - 1e-9, 1.0, 1 + 1e-9]))
    assert at == pytest.approx(F0, rel=1e-15)
    assert_allclose([below, above], F0, rtol=2e-9)


def test_base_speed_property():
    # 9.6 MW / 760 kN = 12.63 m/s = 45.47 km/h
    assert HXD1.traction.base_speed_mps == pytest.approx(9.6e6 / 760e3)


@pytest.mark.parametrize(
    ("speed_kmh", "published_kn"),
    [
        (70.0, 494.0),  # continuous rating at 70 km/h (class's Wikipedia infobox)
        (65.0, 532.0),  # the "about 532 kN continuous": 9.6 MW at 65 km/h
    ],
)
def test_hxd1_traction_meets_published_continuous_ratings(speed_kmh, published_kn):
    # published figures are rounded to 1 kN: 9.6e6 / 19.444 = 493.7 kN, / 18.056 = 531.7 kN
    force = HXD1.traction.max_force(kmh_to_mps(speed_kmh))
    assert_allclose(force, kn_to_n(published_kn), rtol=1e-3)


def test_traction_is_cut_above_the_maximum_speed():
    v = kmh_to_mps(np.array([119.9, 120.0, 120.1, 150.0]))
    assert_allclose(HXD1.traction.max_force(v), [P / v[0], P / v[1], 0.0, 0.0], rtol=1e-15)


def test_envelopes_ignore_the_sign_of_the_speed():
    v = np.array([3.0, 14.0, 30.0])
    assert_array_equal(HXD1.traction.max_force(-v), HXD1.traction.max_force(v))
    assert_array_equal(HXD1.regen.max_force(-v), HXD1.regen.max_force(v))


# --- regenerative brake envelope --------------------------------------------------------


@pytest.mark.parametrize(
    ("speed_kmh", "published_kn"),
    [
        (75.0, 461.0),  # published: 461 kN continuous up to 75 km/h ...
        (120.0, 288.0),  # ... falling to 288 kN at 120 km/h (9.6 MW)
    ],
)
def test_hxd1_regen_meets_published_brake_ratings(speed_kmh, published_kn):
    assert_allclose(HXD1.regen.max_force(kmh_to_mps(speed_kmh)), kn_to_n(published_kn), rtol=1e-3)


def test_regen_constant_force_then_constant_power():
    fe, pe = HXD1_MAX_REGEN_FORCE_N, HXD1.regen.max_power_w
    v = np.array([5.0, 15.0, 20.0, 25.0, 30.0])  # all above the 10 km/h fade
    expected = np.where(v < pe / fe, fe, pe / v)
    assert_allclose(HXD1.regen.max_force(v), expected, rtol=1e-15)


def test_regen_fades_linearly_to_zero_at_standstill():
    vf = HXD1_REGEN_FADE_BELOW_MPS
    v = vf * np.array([0.0, 0.1, 0.5, 0.9, 1.0 - 1e-12])
    # below v_fade: F_E0 * v / v_fade (the fade is far below the base speed)
    assert_allclose(HXD1.regen.max_force(v), HXD1_MAX_REGEN_FORCE_N * v / vf, rtol=1e-15)


def test_regen_is_continuous_at_the_fade_speed():
    vf = HXD1_REGEN_FADE_BELOW_MPS
    below, at = HXD1.regen.max_force([vf * (1 - 1e-9), vf])
    assert at == HXD1_MAX_REGEN_FORCE_N
    assert below == pytest.approx(HXD1_MAX_REGEN_FORCE_N, rel=2e-9)


def test_fade_in_the_constant_power_region_multiplies_the_power_limit():
    # a fade speed above the base speed: F = (P / v) * (v / v_fade) = P / v_fade
    env = RegenEnvelope(max_force_n=100e3, max_power_w=1e6, fade_below_mps=20.0)
    v = np.array([12.0, 15.0, 19.0])
    assert_allclose(env.max_force(v), 1e6 / 20.0, rtol=1e-15)


def test_regen_without_fade_equals_the_existing_electric_brake_curve():
    # cross-check against vehicle.train.ElectricBrakeCurve (no fade, same law)
    curve = ElectricBrakeCurve(max_force_n=461e3, max_power_w=9.6e6)
    env = RegenEnvelope(max_force_n=461e3, max_power_w=9.6e6, fade_below_mps=0.0)
    v = np.linspace(0.0, 40.0, 81)
    assert_allclose(env.max_force(v), curve.max_force(v), rtol=1e-15)


# --- Numba twins == vectorised ----------------------------------------------------------

speeds = st.floats(-60.0, 60.0, allow_nan=False)
forces = st.floats(1e3, 2e6)
powers = st.floats(1e4, 2e7)


@settings(max_examples=300, deadline=None)
@given(
    v=speeds,
    f0=forces,
    p=powers,
    vmax=st.one_of(st.just(math.inf), st.floats(1.0, 60.0)),
)
def test_traction_njit_twin_equals_vectorised(v, f0, p, vmax):
    assert traction_force_max(v, f0, p, vmax) == traction_force_envelope_n(v, f0, p, vmax)


@settings(max_examples=300, deadline=None)
@given(v=speeds, f0=forces, p=powers, fade=st.one_of(st.just(0.0), st.floats(0.1, 40.0)))
def test_regen_njit_twin_equals_vectorised(v, f0, p, fade):
    assert regen_force_max(v, f0, p, fade) == regen_force_envelope_n(v, f0, p, fade)


def test_twins_agree_on_the_hxd1_grid():
    v = np.linspace(-40.0, 40.0, 801)
    t, r = HXD1.traction, HXD1.regen
    scalar_t = [traction_force_max(x, t.max_force_n, t.max_power_w, t.speed_limit_mps) for x in v]
    scalar_r = [regen_force_max(x, r.max_force_n, r.max_power_w, r.fade_below_mps) for x in v]
    assert_array_equal(t.max_force(v), scalar_t)
    assert_array_equal(r.max_force(v), scalar_r)


def test_traction_default_has_no_speed_limit():
    assert traction_force_max(100.0, F0, P) == P / 100.0


@settings(max_examples=200, deadline=None)
@given(v1=st.floats(0.0, 60.0), dv=st.floats(0.0, 10.0), f0=forces, p=powers)
def test_traction_envelope_never_rises_with_speed_and_respects_both_limits(v1, dv, f0, p):
    f1, f2 = traction_force_envelope_n([v1, v1 + dv], f0, p)
    assert f2 <= f1 <= f0
    assert f1 * v1 <= p * (1 + 1e-12)


# --- validation -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: TractionEnvelope(0.0, 1e6), "locomotive.traction.max_force_n"),
        (lambda: TractionEnvelope(1e5, -1.0), "locomotive.traction.max_power_w"),
        (lambda: TractionEnvelope(1e5, 1e6, math.nan), "locomotive.traction.max_speed_mps"),
        (lambda: RegenEnvelope(-1.0, 1e6), "locomotive.regen.max_force_n"),
        (lambda: RegenEnvelope(1e5, math.inf), "locomotive.regen.max_power_w"),
        (lambda: RegenEnvelope(1e5, 1e6, -2.0), "locomotive.regen.fade_below_mps"),
        (
            lambda: Locomotive("x", 0.0, 20.0, HXD1.traction, HXD1.regen),
            "locomotive.mass_kg",
        ),
        (
            lambda: Locomotive("x", 1e5, 20.0, HXD1.traction, HXD1.regen, 1.2),
            "locomotive.traction_efficiency",
        ),
        (
            lambda: Locomotive("x", 1e5, 20.0, HXD1.traction, HXD1.regen, 0.9, 0.0),
            "locomotive.regen_efficiency",
        ),
    ],
)
def test_bad_parameter_raises_config_error_naming_it(make, field):
    with pytest.raises(ConfigError) as info:
        make()
    assert info.value.field == field


def test_hxd1_factory_numbers():
    assert (HXD1.name, HXD1.mass_kg, HXD1.length_m) == ("HXD1", tonne_to_kg(200.0), 35.222)
    assert HXD1.traction.max_speed_mps == pytest.approx(120.0 / 3.6)
    assert (HXD1.traction_efficiency, HXD1.regen_efficiency) == (0.85, 0.80)


# --- energy accounting ------------------------------------------------------------------


def test_traction_energy_drawn_is_wheel_energy_over_efficiency():
    # 1 GJ at the wheel at 0.85 -> 1.176 GJ from the catenary
    assert_allclose(traction_energy_drawn_j(1e9), 1e9 / 0.85, rtol=1e-15)
    assert_allclose(traction_energy_drawn_j([0.0, 2e9], 0.5), [0.0, 4e9])


def test_regenerated_energy_returned_is_efficiency_times_wheel_energy():
    assert_allclose(regenerated_energy_returned_j(1e9), 0.8e9, rtol=1e-15)
    assert_allclose(regenerated_energy_returned_j([0.0, 2e9], 1.0), [0.0, 2e9])


def test_a_regen_and_redrive_round_trip_loses_energy():
    # brake 1 GJ into the line, then spend what came back on traction: 0.80 * 0.85 of it
    back = regenerated_energy_returned_j(1e9)
    assert_allclose(back * TRACTION_EFFICIENCY, 1e9 * REGEN_EFFICIENCY * TRACTION_EFFICIENCY)


@pytest.mark.parametrize("efficiency", [0.0, -0.1, 1.01, math.nan])
def test_energy_helpers_reject_bad_efficiency(efficiency):
    with pytest.raises(ConfigError):
        traction_energy_drawn_j(1.0, efficiency)
    with pytest.raises(ConfigError):
        regenerated_energy_returned_j(1.0, efficiency)


def test_energy_helpers_reject_negative_energy():
    with pytest.raises(ConfigError) as info:
        traction_energy_drawn_j([1.0, -1.0])
    assert info.value.field == "wheel_energy_j"


# --- the envelope driving a train: solve_ivp against closed forms ------------------------

MASS = tonne_to_kg(10_000.0)  # the heavy-haul train, locomotive included
GAMMA = 0.06
M_EFF = MASS * (1 + GAMMA)
# Davis coefficients [N/kN], v in km/h, of the order of the Chinese rules' loaded
# roller-bearing freight wagon (0.92 + 0.0048 v + 0.000125 v^2)
A0, A1, A2 = 0.92, 0.0048, 0.000125


def _accelerate(envelope, v0, v1, extra_n_per_kn=0.0, davis=(A0, A1, A2)):
    """solve_ivp of m_eff dv/dt = F(v) - R(v) - grade from v0 until v = v1 (y = [x, v]).

    ``davis=None``: no running resistance.
    """
    grade_n = specific_to_force_n(extra_n_per_kn, MASS)

    def rhs(t, y):
        v = y[1]
        resist = 0.0 if davis is None else davis_resistance_n(v, MASS, *davis)
        return [v, (float(envelope.max_force(v)) - resist - grade_n) / M_EFF]

    def reached(t, y):
        return y[1] - v1

    reached.terminal = True
    return solve_ivp(
        rhs,
        (0.0, 1e5),
        [0.0, v0],
        method="DOP853",
        rtol=1e-11,
        atol=1e-12,
        events=reached,
        dense_output=True,
    )


@pytest.mark.parametrize(
    ("envelope", "v0_kmh", "v1_kmh", "grade"),
    [
        # HXD1 from standstill to 40 km/h on the level: below its 45.5 km/h base speed,
        # so 760 kN throughout
        (HXD1.traction, 0.0, 40.0, 0.0),
        # 10 -> 45 km/h up a 4 per mille grade, still on the constant-force part
        (HXD1.traction, 10.0, 45.0, 4.0),
        # a 300 kN constant-force drive (power unbounded) to 95 % of its terminal speed,
        # where the quadratic term matters most
        (TractionEnvelope(300e3, 1e12), 0.0, None, 0.0),
    ],
)
def test_time_to_speed_under_constant_force_matches_closed_form(envelope, v0_kmh, v1_kmh, grade):
    coeffs = quadratic_motion_coefficients(
        envelope.max_force_n, MASS, M_EFF, A0, A1, A2, extra_specific_n_per_kn=grade
    )
    v0 = kmh_to_mps(v0_kmh)
    v1 = 0.95 * terminal_speed(*coeffs) if v1_kmh is None else kmh_to_mps(v1_kmh)
    sol = _accelerate(envelope, v0, v1, grade)
    t_num = sol.t_events[0][0]
    assert_allclose(t_num, time_to_speed_analytic(v1, *coeffs, v0=v0), rtol=1e-8)


def test_speed_and_distance_histories_match_closed_form():
    # HXD1 from standstill on the level, 0..200 s (reaches about 39 km/h: constant force)
    coeffs = quadratic_motion_coefficients(F0, MASS, M_EFF, A0, A1, A2)
    sol = _accelerate(HXD1.traction, 0.0, kmh_to_mps(45.0))
    t = np.linspace(0.0, 200.0, 21)
    x_num, v_num = sol.sol(t)
    v_ref = [speed_at_time_analytic(ti, *coeffs) for ti in t]
    x_ref = [distance_at_time_analytic(ti, *coeffs) for ti in t]
    assert_allclose(v_num, v_ref, rtol=1e-9, atol=1e-9)
    assert_allclose(x_num, x_ref, rtol=1e-9, atol=1e-8)


def test_constant_power_acceleration_without_resistance():
    # 60 -> 80 km/h is all above the base speed: t = m_eff (v1^2 - v0^2) / (2 P)
    v0, v1 = kmh_to_mps(60.0), kmh_to_mps(80.0)
    sol = _accelerate(HXD1.traction, v0, v1, davis=None)
    expected = time_to_speed_constant_power(v0, v1, P, M_EFF)
    assert_allclose(sol.t_events[0][0], expected, rtol=1e-8)


def test_acceleration_through_both_regions_without_resistance():
    # 0 -> 80 km/h: m_eff v_b / F0 on constant force, then the constant-power formula
    v1 = kmh_to_mps(80.0)
    sol = _accelerate(HXD1.traction, 0.0, v1, davis=None)
    expected = M_EFF * V_BASE / F0 + time_to_speed_constant_power(V_BASE, v1, P, M_EFF)
    assert_allclose(sol.t_events[0][0], expected, rtol=1e-7)


# --- the closed forms themselves --------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(frac=st.floats(0.0, 0.999), force_kn=st.floats(150.0, 900.0))
def test_speed_at_time_inverts_time_to_speed(frac, force_kn):
    coeffs = quadratic_motion_coefficients(kn_to_n(force_kn), MASS, M_EFF, A0, A1, A2)
    v1 = frac * terminal_speed(*coeffs)
    t1 = time_to_speed_analytic(v1, *coeffs)
    assert speed_at_time_analytic(t1, *coeffs) == pytest.approx(v1, rel=1e-9, abs=1e-9)


def test_closed_form_reduces_to_linear_and_constant_cases():
    # C -> 0: the artanh form tends to ln((A - B v0)/(A - B v1)) / B; B, C -> 0: v / A
    a, b = 0.05, 1e-3
    linear = time_to_speed_analytic(20.0, a, b, 0.0)
    assert linear == pytest.approx(math.log(a / (a - b * 20.0)) / b, rel=1e-15)
    assert time_to_speed_analytic(20.0, a, b, 1e-12) == pytest.approx(linear, rel=1e-6)
    assert time_to_speed_analytic(20.0, a, 0.0, 0.0) == pytest.approx(20.0 / a)


def test_closed_form_rejects_speeds_beyond_terminal():
    coeffs = quadratic_motion_coefficients(F0, MASS, M_EFF, A0, A1, A2)
    with pytest.raises(ValueError):
        time_to_speed_analytic(terminal_speed(*coeffs), *coeffs)
