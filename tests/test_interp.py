"""railpilot/interp.py: one-point interpolation for compiled loops gives NumPy's
``np.interp`` to the bit (the simulator's and the precise-stop controller's results do not
change with it)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit
from numpy.testing import assert_array_equal

from railpilot.interp import interp_at


@njit(cache=True)
def _each(xs: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = interp_at(xs[i], xp, fp)
    return out


@njit(cache=True)
def _each_numba(xs: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:
    out = np.empty_like(xs)
    for i in range(xs.shape[0]):
        out[i] = np.interp(xs[i], xp, fp)
    return out


def _same_as_numpy(xs: np.ndarray, xp: np.ndarray, fp: np.ndarray) -> None:
    got = _each(xs, xp, fp)
    assert_array_equal(got, np.interp(xs, xp, fp))  # NaN where NumPy has NaN
    assert_array_equal(got, _each_numba(xs, xp, fp))  # and what the loops used before


def test_between_on_and_beyond_the_knots() -> None:
    xp = np.array([0.0, 1.0, 2.5, 4.0, 10.0, 10.5, 30.0])
    fp = np.array([3.0, -1.0, 2.0, 2.0, 7.5, 0.1, -4.0])
    xs = np.concatenate(
        [xp, xp + 1e-9, xp - 1e-9, np.linspace(-5.0, 35.0, 401), [np.nan, np.inf, -np.inf]]
    )
    _same_as_numpy(xs, xp, fp)


def test_repeated_knots_take_the_last_of_them() -> None:
    xp = np.array([0.0, 1.0, 1.0, 1.0, 2.0, 3.0, 3.0])
    fp = np.array([0.0, 5.0, 6.0, 7.0, 1.0, 2.0, 9.0])
    _same_as_numpy(np.linspace(-1.0, 4.0, 201), xp, fp)
    assert _each(np.array([1.0, 3.0]), xp, fp).tolist() == [7.0, 9.0]


def test_one_and_two_knots() -> None:
    xs = np.array([-1.0, 0.0, 0.5, 1.0, 2.0, np.nan])
    _same_as_numpy(xs, np.array([1.0]), np.array([4.0]))  # NumPy's fp[0] even at NaN
    _same_as_numpy(xs, np.array([0.0, 1.0]), np.array([4.0, -2.0]))


def test_infinite_values_are_interpolated_as_numpy_does() -> None:
    # an infinite slope gives NaN one way and is tried the other way (NumPy 1.17 on)
    xp = np.array([0.0, 1.0, 2.0, 3.0])
    fp = np.array([0.0, np.inf, np.inf, 1.0])
    _same_as_numpy(np.linspace(-0.5, 3.5, 81), xp, fp)


_knots = st.lists(
    st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False), min_size=1, max_size=40
)


@settings(max_examples=300, deadline=None)
@given(
    knots=_knots,
    values=st.lists(st.floats(-1e9, 1e9, allow_nan=False), min_size=40, max_size=40),
    points=st.lists(st.floats(-2e6, 2e6, allow_nan=False), min_size=1, max_size=30),
)
def test_random_tables_and_points(
    knots: list[float], values: list[float], points: list[float]
) -> None:
    xp = np.sort(np.array(knots))
    fp = np.array(values[: len(knots)])
    xs = np.concatenate([np.array(points), xp])  # the knots themselves too
    _same_as_numpy(xs, xp, fp)
