"""railpilot.errors: what every check of a number starts from."""

import math

import numpy as np
import pytest

from railpilot.errors import is_finite_number


@pytest.mark.parametrize(
    "value",
    [0, -3, 10**30, 0.0, -2.5, 1e308, np.float64(4.0), 5e-324],
)
def test_finite_ints_and_floats_are_numbers(value):
    assert is_finite_number(value)


@pytest.mark.parametrize(
    "value",
    [
        math.nan,
        math.inf,
        -math.inf,
        np.float64("nan"),
        np.float64("inf"),
        True,
        False,
        "1.0",
        None,
        [1.0],
        1 + 0j,
        np.array(1.0),
    ],
)
def test_nan_inf_bools_and_non_numbers_are_not(value):
    assert not is_finite_number(value)
