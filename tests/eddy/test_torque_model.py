"""Analytic torque model (paper 003 eq. 15-24) against hand calculations and limits."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.eddy.torque_model import (
    MU0_H_PER_M,
    EddyBrakeParams,
    current_for_torque_a,
    eddy_torque_at_speed_nm,
    eddy_torque_nm,
    gap_flux_density_t,
    peak_torque_angular_speed_rad_s,
    sector_factors,
    skin_depth_m,
)
from railpilot.errors import ConfigError
from railpilot.units import kmh_to_mps, wheel_angular_speed_rad_s

P = EddyBrakeParams()


def test_sector_factors_match_the_integrals():
    # k2 = int_0^dr r/(r+a) dr, k1 = int_0^dr r^2/(r+a) dr with a = pi rc (eq. 20-21)
    k1, k2 = sector_factors(0.13, 0.29)
    a, dr = np.pi * 0.21, 0.08
    r = np.linspace(0.0, dr, 200_001)
    assert_allclose(k2, np.trapezoid(r / (r + a), r), rtol=1e-8)
    assert_allclose(k1, np.trapezoid(r**2 / (r + a), r), rtol=1e-8)


def test_torque_by_hand_at_one_point():
    # hand calculation of eq. 15 and 19 with the default parameters at 300 A, 100 rad/s
    k1, k2 = sector_factors(0.13, 0.29)
    rc, ni, wn = 0.21, 12 * 300.0, 4 * 100.0
    reaction = np.pi * 0.30 * rc * k2 * np.sqrt(MU0_H_PER_M * wn / (2.5e-7 * 100.0))
    b = MU0_H_PER_M * ni / (0.004 + reaction)
    m = 16 * 2 * np.sqrt(2) * np.pi**2 / 9 * k1 * rc**2 * b**2 * 4**1.5 * np.sqrt(100.0)
    m /= np.sqrt(2.5e-7 * MU0_H_PER_M * 100.0)
    assert_allclose(gap_flux_density_t(300.0, 100.0, P), b, rtol=1e-12)
    assert_allclose(eddy_torque_nm(300.0, 100.0, P), m, rtol=1e-12)


def test_torque_is_quadratic_in_current_and_zero_at_standstill():
    w = np.array([5.0, 50.0, 150.0])
    assert_allclose(eddy_torque_nm(200.0, w, P), 4 * eddy_torque_nm(100.0, w, P), rtol=1e-12)
    assert eddy_torque_nm(300.0, 0.0, P) == 0.0


def test_limits_sqrt_low_speed_and_inverse_sqrt_high_speed():
    # M ~ w^(1/2) for w -> 0 and M ~ w^(-1/2) for w -> inf
    lo = eddy_torque_nm(100.0, np.array([1e-6, 4e-6]), P)
    hi = eddy_torque_nm(100.0, np.array([1e9, 4e9]), P)
    assert_allclose(lo[1] / lo[0], 2.0, rtol=1e-3)
    assert_allclose(hi[1] / hi[0], 0.5, rtol=1e-3)


def test_rises_then_falls_with_a_peak_where_the_reaction_halves_the_flux():
    w_star = peak_torque_angular_speed_rad_s(P)
    w = np.linspace(0.2 * w_star, 3 * w_star, 2001)
    m = eddy_torque_nm(300.0, w, P)
    assert_allclose(w[np.argmax(m)], w_star, rtol=2e-3)
    assert_allclose(gap_flux_density_t(300.0, w_star, P), gap_flux_density_t(300.0, 0.0, P) / 2)


def test_parameter_set_meets_the_design_points():
    limit = 425.0
    at16 = eddy_torque_at_speed_nm(limit, kmh_to_mps(16.0), P)
    at200 = eddy_torque_at_speed_nm(limit, kmh_to_mps(200.0), P)
    assert 3400 < at16 < 3600  # 3500 N m held down to about 16 km/h
    assert at200 > 4500 * 1.03  # 4500 N m reachable from 200 km/h with margin
    peak_kmh = 3.6 * peak_torque_angular_speed_rad_s(P) * P.wheel_diameter_m / 2
    assert 100 < peak_kmh < 160


def test_dimensionless_scaling_of_the_denominator():
    # eq. 19's two denominator terms are both lengths: doubling gap and reaction length
    # (via ke and rho/mu_r unchanged) must scale B by exactly 1/2
    p2 = EddyBrakeParams(air_gap_m=2 * P.air_gap_m, eddy_flux_factor=2 * P.eddy_flux_factor)
    assert_allclose(gap_flux_density_t(300.0, 80.0, p2), gap_flux_density_t(300.0, 80.0, P) / 2)


def test_skin_depth_and_inverse_current():
    assert_allclose(
        skin_depth_m(2.5e-7, 100.0, 400.0), np.sqrt(2 * 2.5e-7 / (MU0_H_PER_M * 100 * 400))
    )
    v = kmh_to_mps(120.0)
    i = current_for_torque_a(3500.0, v, P)
    assert_allclose(eddy_torque_at_speed_nm(i, v, P), 3500.0, rtol=1e-12)
    assert_allclose(
        wheel_angular_speed_rad_s(kmh_to_mps(3 * np.pi * 0.845 * 1000 / 50), 0.845),
        np.pi * 1000 / 30,
    )  # eq. 22-23 at n = 1000 rpm


def test_bad_parameters_raise_config_error():
    with pytest.raises(ConfigError, match=r"brake.air_gap_m"):
        EddyBrakeParams(air_gap_m=0.0)
    with pytest.raises(ConfigError, match=r"brake.r_outer_m"):
        EddyBrakeParams(r_inner_m=0.3, r_outer_m=0.2)
