"""A train's plan on the dashboard's time-distance graph (web/view.py ``plan_path``): the
timetable's departures and arrivals joined by straight lines, cut to the graph's window.
Checked against NumPy's interpolation of the same timetable points."""

from __future__ import annotations

import numpy as np
import pytest

from railpilot.web.view import plan_path

# stops at km 0, 10 and 25: leave at 0 s, arrive at 600 s, stand a minute, arrive at 1500 s
STOPS_M = (0.0, 10_000.0, 25_000.0)
DEPARTURES_S = (0.0, 660.0)
ARRIVALS_S = (600.0, 1500.0)
TIMES = np.array([0.0, 600.0, 660.0, 1500.0])
KMS = np.array([0.0, 10.0, 10.0, 25.0])


def test_the_whole_plan_inside_the_window_is_its_timetable_points() -> None:
    path = plan_path(STOPS_M, DEPARTURES_S, ARRIVALS_S, -100.0, 2000.0)
    assert path == [[0.0, 0.0], [600.0, 10.0], [660.0, 10.0], [1500.0, 25.0]]


def test_a_window_cuts_the_plan_where_it_crosses_the_window() -> None:
    path = plan_path(STOPS_M, DEPARTURES_S, ARRIVALS_S, 300.0, 1000.0)
    assert path == [[300.0, 5.0], [600.0, 10.0], [660.0, 10.0], [1000.0, 16.071]]


def test_a_plan_outside_the_window_draws_nothing() -> None:
    assert plan_path(STOPS_M, DEPARTURES_S, ARRIVALS_S, 1600.0, 2000.0) == []
    assert plan_path(STOPS_M, DEPARTURES_S, ARRIVALS_S, -900.0, -100.0) == []


@pytest.mark.parametrize("seed", range(20))
def test_every_point_lies_on_the_timetable_line(seed: int) -> None:
    rng = np.random.default_rng(seed)
    start = float(rng.uniform(-300.0, 1400.0))
    end = start + float(rng.uniform(1.0, 900.0))
    path = np.array(plan_path(STOPS_M, DEPARTURES_S, ARRIVALS_S, start, end))
    assert path[0, 0] == pytest.approx(max(start, 0.0), abs=0.05)
    assert path[-1, 0] == pytest.approx(min(end, 1500.0), abs=0.05)
    assert np.all(np.diff(path[:, 0]) >= 0.0)
    np.testing.assert_allclose(path[:, 1], np.interp(path[:, 0], TIMES, KMS), atol=2e-3)
