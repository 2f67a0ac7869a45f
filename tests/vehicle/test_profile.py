"""Length-averaged gradient and curve resistance (railpilot.vehicle.profile).

Hand-worked cases of a 1,600 m train on a 12 per mille descent, then properties (L -> 0,
additivity, travel-direction symmetry), a cross-check against scipy's quad, and the Numba
twin == the vectorised function.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal
from scipy.integrate import quad

from railpilot.errors import ConfigError
from railpilot.units import curve_specific_resistance
from railpilot.vehicle.line import Line, Segment, step_lookup
from railpilot.vehicle.profile import (
    BACKWARD,
    FORWARD,
    elevation_table,
    length_averaged_resistance,
    mean_specific_resistance,
)

L = 1600.0  # the heavy-haul train [m]
# level up to 2 km, 12 per mille down from 2 km to 8 km, level beyond
DESCENT = Line(gradients=(Segment(2000.0, 8000.0, -12.0),))
# a busier line: overlapping grades and curves, gaps, a short steep bit
BUSY = Line(
    gradients=(
        Segment(0.0, 1500.0, 3.0),
        Segment(1500.0, 1520.0, -20.0),
        Segment(2400.0, 6000.0, -12.0),
        Segment(7000.0, 9000.0, 6.5),
    ),
    curves=(Segment(1000.0, 1800.0, 800.0), Segment(5000.0, 5400.0, 600.0)),
)


def mean(line, x, length, direction=FORWARD):
    return length_averaged_resistance(elevation_table(line, direction), x, length, direction)


# --- hand-worked cases ------------------------------------------------------------------


def test_train_straddling_a_change_of_grade():
    # head at 2,600 m: 600 m of it on -12 per mille, 1,000 m on the level behind
    # -> (-12 * 600 + 0 * 1000) / 1600 = -4.5 N/kN
    assert_allclose(mean(DESCENT, 2600.0, L), -4.5, rtol=1e-15)


def test_entering_a_grade_the_mean_ramps_linearly_over_one_train_length():
    # head x in [2000, 3600]: (x - 2000) m on the grade -> -12 (x - 2000) / 1600
    x = np.array([1500.0, 2000.0, 2400.0, 2800.0, 3200.0, 3600.0, 5000.0])
    expected = -12.0 * np.clip(x - 2000.0, 0.0, L) / L
    assert_allclose(mean(DESCENT, x, L), expected, rtol=1e-14, atol=1e-14)


def test_leaving_a_grade_the_mean_ramps_back_to_zero():
    # head x in [8000, 9600]: the tail part 9600 - x still on the grade
    x = np.array([7000.0, 8000.0, 8400.0, 9000.0, 9600.0, 12000.0])
    expected = -12.0 * np.clip(9600.0 - x, 0.0, L) / L
    assert_allclose(mean(DESCENT, x, L), expected, rtol=1e-14, atol=1e-14)


def test_train_shorter_than_a_segment_feels_the_segment_value_exactly():
    # a 400 m train wholly on the descent: exactly -12, no rounding from the subtraction
    x = np.array([2400.0, 5000.0, 8000.0])
    assert_array_equal(mean(DESCENT, x, 400.0), [-12.0, -12.0, -12.0])


def test_curve_resistance_is_averaged_over_the_length():
    # R = 800 m on [5000, 5400): 600 / 800 = 0.75 N/kN on 400 m of a train wholly on the
    # -12 descent (head at 6,000 m: [4400, 6000]) -> -12 + 0.75 * 400 / 1600 = -11.8125
    line = Line(gradients=DESCENT.gradients, curves=(Segment(5000.0, 5400.0, 800.0),))
    assert curve_specific_resistance(800.0) == 0.75
    assert_allclose(mean(line, 6000.0, L), -11.8125, rtol=1e-15)


def test_travel_towards_decreasing_position():
    # running towards -x the train occupies [x, x + L] and the descent is a climb:
    # head at 1,400 m: [1400, 3000], 1,000 m on +12 -> 12 * 1000 / 1600 = 7.5; a curve
    # R = 600 m (1 N/kN) on [2500, 2900) adds 400 / 1600 = 0.25 in either direction
    assert_allclose(mean(DESCENT, 1400.0, L, BACKWARD), 7.5, rtol=1e-15)
    curvy = Line(gradients=DESCENT.gradients, curves=(Segment(2500.0, 2900.0, 600.0),))
    assert_allclose(mean(curvy, 1400.0, L, BACKWARD), 7.75, rtol=1e-15)
    assert_allclose(mean(curvy, 3000.0, L, FORWARD), -12 * 1000 / L + 0.25, rtol=1e-15)


def test_partly_beyond_the_profile_counts_zero_there():
    # the profile ends at 8 km; level beyond it, nothing before 2 km
    assert_array_equal(mean(DESCENT, [0.0, 20000.0], L), [0.0, 0.0])
    assert_array_equal(mean(Line(), [0.0, 5.0], [L, 0.0]), [0.0, 0.0])


def test_elevation_table_is_the_elevation_in_millimetres():
    # 6 km at -12 per mille: 72 m down = -72,000 per-mille metres
    edges, cumulative, values = elevation_table(DESCENT)
    assert_array_equal(edges, [2000.0, 8000.0])
    assert_array_equal(cumulative, [0.0, -72000.0])
    assert_array_equal(values, [-12.0])
    # running the other way it is a 72 m climb
    assert_array_equal(elevation_table(DESCENT, BACKWARD).cumulative, [0.0, 72000.0])


def test_backward_table_flips_gradients_but_not_curves():
    fwd, bwd = elevation_table(BUSY, FORWARD), elevation_table(BUSY, BACKWARD)
    curves_only = elevation_table(Line(curves=BUSY.curves))
    x = np.linspace(-100.0, 9500.0, 1921)
    w_curve = step_lookup(curves_only.edges_m, curves_only.values_n_per_kn, x)
    w_fwd = step_lookup(fwd.edges_m, fwd.values_n_per_kn, x)
    w_bwd = step_lookup(bwd.edges_m, bwd.values_n_per_kn, x)
    assert_allclose(w_fwd + w_bwd, 2.0 * w_curve, atol=1e-12)


# --- the point limit --------------------------------------------------------------------


@pytest.mark.parametrize("direction", [FORWARD, BACKWARD])
def test_zero_length_is_the_point_value_everywhere_even_on_edges(direction):
    table = elevation_table(BUSY, direction)
    x = np.concatenate([table.edges_m, np.linspace(-500.0, 9500.0, 2001)])
    point = step_lookup(table.edges_m, table.values_n_per_kn, x)
    assert_array_equal(length_averaged_resistance(table, x, 0.0, direction), point)
    if direction == FORWARD:
        assert_array_equal(point, BUSY.additional_resistance(x))


@settings(max_examples=200, deadline=None)
@given(x=st.floats(-500.0, 9500.0), direction=st.sampled_from([FORWARD, BACKWARD]))
def test_short_train_tends_to_the_point_value(x, direction):
    table = elevation_table(BUSY, direction)
    eps = 1e-6
    # away from an edge (within eps of one the train spans it)
    if np.min(np.abs(table.edges_m - x)) > 2 * eps:
        point = step_lookup(table.edges_m, table.values_n_per_kn, np.asarray(x))
        assert_allclose(length_averaged_resistance(table, x, eps, direction), point, atol=1e-6)


def test_short_train_on_an_edge_feels_the_side_it_occupies():
    # head exactly at the top of the descent, L -> 0: behind it (forward) is level;
    # running backward it occupies [2000, 2000 + L]: the climb
    assert mean(DESCENT, 2000.0, 1e-9, FORWARD) == 0.0
    assert mean(DESCENT, 2000.0, 1e-9, BACKWARD) == 12.0


# --- properties -------------------------------------------------------------------------

positions = st.floats(-1000.0, 11000.0)
lengths = st.floats(0.0, 3000.0)


@settings(max_examples=200, deadline=None)
@given(x=positions, length=st.floats(1.0, 3000.0), split=st.floats(0.01, 0.99))
def test_the_integral_is_additive_over_parts_of_the_train(x, length, split):
    # L w(x, L) = L1 w(x, L1) + (L - L1) w(x - L1, L - L1)
    table = elevation_table(BUSY)
    l1 = split * length
    whole = length * length_averaged_resistance(table, x, length)
    front = l1 * length_averaged_resistance(table, x, l1)
    back = (length - l1) * length_averaged_resistance(table, x - l1, length - l1)
    assert_allclose(whole, front + back, rtol=1e-9, atol=1e-6)


@settings(max_examples=200, deadline=None)
@given(x=positions, length=lengths)
def test_backward_occupation_is_forward_occupation_shifted_by_one_length(x, length):
    # the same table, the same interval [x, x + L]: only the head's end differs
    table = elevation_table(BUSY)
    back = length_averaged_resistance(table, x, length, BACKWARD)
    if length > 0:
        fwd = length_averaged_resistance(table, x + length, length, FORWARD)
        assert_allclose(back, fwd, rtol=1e-9, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(x=positions, length=lengths)
def test_mean_lies_between_the_extreme_values_under_the_train(x, length):
    table = elevation_table(BUSY)
    w = length_averaged_resistance(table, x, length)
    lo = min(0.0, table.values_n_per_kn.min())
    hi = max(0.0, table.values_n_per_kn.max())
    assert lo - 1e-12 <= w <= hi + 1e-12


@settings(max_examples=100, deadline=None)
@given(x=positions, length=st.floats(1.0, 3000.0), direction=st.sampled_from([1.0, -1.0]))
def test_mean_matches_scipy_quad_of_the_step_profile(x, length, direction):
    table = elevation_table(BUSY, direction)
    a, b = (x - length, x) if direction > 0 else (x, x + length)
    breaks = table.edges_m[(table.edges_m > a) & (table.edges_m < b)]

    def w(s):
        return float(step_lookup(table.edges_m, table.values_n_per_kn, np.asarray(s)))

    integral, _ = quad(w, a, b, points=breaks if len(breaks) else None, limit=200)
    assert_allclose(
        length_averaged_resistance(table, x, length, direction),
        integral / length,
        rtol=1e-9,
        atol=1e-9,
    )


# --- the Numba twin ---------------------------------------------------------------------


@settings(max_examples=300, deadline=None)
@given(x=positions, length=lengths, direction=st.sampled_from([FORWARD, BACKWARD]))
def test_njit_twin_equals_vectorised(x, length, direction):
    table = elevation_table(BUSY, direction)
    scalar = mean_specific_resistance(*table, x, length, direction)
    assert scalar == length_averaged_resistance(table, x, length, direction)


def test_njit_twin_equals_vectorised_on_edges_and_off_the_profile():
    table = elevation_table(BUSY)
    x = np.concatenate([table.edges_m, table.edges_m + L, [-1e5, 1e5]])
    for direction in (FORWARD, BACKWARD):
        for length in (0.0, 20.0, L):
            vec = length_averaged_resistance(table, x, length, direction)
            scalar = [mean_specific_resistance(*table, xi, length, direction) for xi in x]
            assert_array_equal(vec, scalar)


def test_vectorised_broadcasts_positions_against_lengths():
    table = elevation_table(DESCENT)
    out = length_averaged_resistance(table, np.array([[2600.0], [3000.0]]), [0.0, 400.0, L])
    assert out.shape == (2, 3)
    assert_allclose(out[0], [-12.0, -12.0, -4.5])
    assert_allclose(out[1], [-12.0, -12.0, -12.0 * 1000.0 / L])


# --- validation -------------------------------------------------------------------------


@pytest.mark.parametrize("direction", [0.0, 2.0, 0.5])
def test_bad_direction_raises_config_error(direction):
    with pytest.raises(ConfigError) as info:
        elevation_table(DESCENT, direction)
    assert info.value.field == "direction"
    with pytest.raises(ConfigError):
        length_averaged_resistance(elevation_table(DESCENT), 0.0, L, direction)


@pytest.mark.parametrize("length", [-1.0, np.inf, np.nan])
def test_bad_length_raises_config_error(length):
    with pytest.raises(ConfigError) as info:
        mean(DESCENT, 0.0, length)
    assert info.value.field == "length_m"
