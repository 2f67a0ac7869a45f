"""Shoe friction (railpilot.brakes.friction), paper 000 eq. 3 and 5."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.brakes.friction import friction_ratio, shoe_friction


def test_friction_at_standstill_is_beta1_plus_beta3():
    # mu(0) = 0.138 + 0.221 = 0.359
    assert shoe_friction(0.0) == pytest.approx(0.359, rel=1e-14)


def test_friction_ratio_at_standstill():
    # g(0) = 0.359 / 0.221 = 1.6244...
    assert friction_ratio(0.0) == pytest.approx(0.359 / 0.221, rel=1e-14)


def test_friction_ratio_at_6_kmh_matches_docstring_value():
    # g(6) = (0.138 exp(-0.168 * 6) + 0.221) / 0.221 = 1.2284...
    assert friction_ratio(6.0) == pytest.approx(1.0 + 0.138 * np.exp(-1.008) / 0.221, rel=1e-14)


def test_friction_ratio_tends_to_one_at_speed():
    assert friction_ratio(200.0) == pytest.approx(1.0, abs=1e-12)


def test_friction_ratio_decreases_with_speed():
    g = friction_ratio(np.linspace(0.0, 100.0, 101))
    assert np.all(np.diff(g) < 0)


def test_friction_is_even_in_speed():
    assert_allclose(shoe_friction(-20.0), shoe_friction(20.0))
