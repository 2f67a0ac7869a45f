"""Unit conversions (railpilot.units): round trips and hand-worked cases."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot import units


@pytest.mark.parametrize(
    ("forward", "backward", "value"),
    [
        (units.kmh_to_mps, units.mps_to_kmh, 72.0),
        (units.kn_to_n, units.n_to_kn, 380.0),
        (units.km_post_to_m, units.m_to_km_post, 20.4128),
        (units.rpm_to_rad_s, units.rad_s_to_rpm, 1500.0),
    ],
)
def test_conversion_round_trip_returns_the_input(forward, backward, value):
    assert_allclose(backward(forward(value)), value, rtol=1e-15)


def test_72_kmh_is_20_mps():
    assert units.kmh_to_mps(72.0) == pytest.approx(20.0, rel=1e-15)


def test_tonne_to_kg_of_paper000_train():
    # paper 000 Table 1: 536 t
    assert units.tonne_to_kg(536.0) == 536e3


def test_conversions_accept_arrays():
    assert_allclose(units.kmh_to_mps(np.array([0.0, 3.6, 36.0])), [0.0, 1.0, 10.0])


def test_specific_force_of_one_n_per_kn_is_weight_over_1000():
    # 1 N/kN on 536 t: 536e3 kg * 9.8 m/s^2 / 1000 = 5252.8 N
    assert units.specific_to_force_n(1.0, 536e3) == pytest.approx(5252.8, rel=1e-12)


def test_specific_force_round_trip():
    assert_allclose(
        units.force_to_specific_n_per_kn(units.specific_to_force_n(2.7, 3e5), 3e5), 2.7, rtol=1e-14
    )


def test_one_per_mille_gradient_is_one_n_per_kn():
    assert units.gradient_permille_to_specific(3.5) == 3.5


def test_curve_resistance_is_600_over_radius():
    # TB/T 1407: A = 600 -> R = 300 m gives 2 N/kN; straight track gives 0
    assert units.curve_specific_resistance(300.0) == pytest.approx(2.0)
    assert units.curve_specific_resistance(np.inf) == 0.0


def test_1500_rpm_is_50_pi_rad_s():
    assert units.rpm_to_rad_s(1500.0) == pytest.approx(50.0 * np.pi, rel=1e-15)


def test_wheel_angular_speed_matches_paper003_eq23():
    # paper 003 eq. 23: v [km/h] = 3 pi Dw n / 50 with n [rpm]; Dw = 0.84 m, n = 500 rpm
    dw, n_rpm = 0.84, 500.0
    v_mps = units.kmh_to_mps(3.0 * np.pi * dw * n_rpm / 50.0)
    assert_allclose(
        units.wheel_angular_speed_rad_s(v_mps, dw), units.rpm_to_rad_s(n_rpm), rtol=1e-14
    )


def test_wheel_speed_round_trip():
    omega = units.wheel_angular_speed_rad_s(17.3, 0.86)
    assert_allclose(units.wheel_speed_to_train_speed_mps(omega, 0.86), 17.3, rtol=1e-15)
