"""Davis basic resistance (railpilot.vehicle.resistance), paper 000 eq. 6."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.vehicle.resistance import (
    davis_deceleration_mps2,
    davis_resistance_n,
    davis_specific_resistance,
)

# paper 000 Table 1 coefficients [N/kN], v in km/h
A0, A1, A2 = 0.42, 0.0016, 0.000132


def test_specific_resistance_at_72_kmh_by_hand():
    # 0.42 + 0.0016 * 72 + 0.000132 * 72^2 = 0.42 + 0.1152 + 0.684288 = 1.219488 N/kN
    assert davis_specific_resistance(72.0, A0, A1, A2) == pytest.approx(1.219488, rel=1e-12)


def test_specific_resistance_at_standstill_is_a0():
    assert davis_specific_resistance(0.0, A0, A1, A2) == A0


def test_resistance_force_of_536_t_at_20_mps():
    # 1.219488 N/kN * 536 t * 9.8 / 1000 kN/t -> 1.219488 * 5252.8 N
    assert_allclose(davis_resistance_n(20.0, 536e3, A0, A1, A2), 1.219488 * 5252.8, rtol=1e-12)


def test_resistance_opposes_motion_in_both_directions():
    assert_allclose(
        davis_resistance_n(-12.0, 3e5, A0, A1, A2), davis_resistance_n(12.0, 3e5, A0, A1, A2)
    )


def test_deceleration_is_force_over_effective_mass():
    mass, gamma = 536e3, 0.06
    v = np.array([0.0, 5.0, 12.5, 22.0])
    expected = davis_resistance_n(v, mass, A0, A1, A2) / (mass * (1 + gamma))
    assert_allclose(davis_deceleration_mps2(v, gamma, A0, A1, A2), expected, rtol=1e-13)


def test_deceleration_uses_paper_chi_factor():
    # paper 000 eq. 6: chi = 0.0098 / (1 + gamma); at 0 km/h w = a0
    assert davis_deceleration_mps2(0.0, 0.06, A0, A1, A2) == pytest.approx(0.0098 / 1.06 * A0)
