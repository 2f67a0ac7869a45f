"""Queries of a RailLine and its adapter to the simulation core's Line, by hand."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from railpilot.errors import LineError
from railpilot.line import DOWN, UP, RailLine, parse_line
from railpilot.link.messages import TravelDirection
from railpilot.units import kmh_to_mps
from railpilot.vehicle.line import Line, Segment, StopPoint
from railpilot.vehicle.profile import elevation_table

from .helpers import dumps, tiny


@pytest.fixture
def line() -> RailLine:
    return parse_line(dumps(tiny()))


def _segments(segments: tuple[Segment, ...]) -> np.ndarray:
    return np.array([(s.start_m, s.end_m, s.value) for s in segments])


def test_to_vehicle_line_going_up(line):
    # train coordinate s = km post - 10 km
    vehicle = line.to_vehicle_line("a", UP)
    assert isinstance(vehicle, Line)
    assert_allclose(_segments(vehicle.gradients), [[0, 1000, 5.0], [1000, 3000, -2.0]])
    assert_allclose(_segments(vehicle.curves), [[1500, 2000, 500.0]])
    assert_allclose(
        _segments(vehicle.speed_limits),
        [[0, 2000, kmh_to_mps(80.0)], [2000, 3000, kmh_to_mps(60.0)]],
    )
    assert vehicle.stations == (StopPoint("S", pytest.approx(2650.0)),)


def test_to_vehicle_line_going_down(line):
    # train coordinate s = 13 km - km post; gradients negated, order reversed
    vehicle = line.to_vehicle_line("a", DOWN)
    assert_allclose(_segments(vehicle.gradients), [[0, 2000, 2.0], [2000, 3000, -5.0]])
    assert_allclose(_segments(vehicle.curves), [[1000, 1500, 500.0]])
    assert_allclose(
        _segments(vehicle.speed_limits),
        [[0, 1000, kmh_to_mps(40.0)], [1000, 3000, kmh_to_mps(80.0)]],
    )
    assert vehicle.stations == (StopPoint("S", pytest.approx(650.0)),)


def test_distance_along_and_back(line):
    x = np.array([10_000.0, 11_250.0, 13_000.0])
    assert_allclose(line.distance_along(x, UP), [0.0, 1250.0, 3000.0])
    assert_allclose(line.distance_along(x, DOWN), [3000.0, 1750.0, 0.0])
    for d in (UP, DOWN):
        assert_allclose(line.position_at(line.distance_along(x, d), d), x)


def test_gradient_at_a_boundary_depends_on_the_direction(line):
    # km 11.000: going up the train has entered the -2 section [11, 13); going down it has
    # entered (10, 11], the +5 section, which it runs down at -5
    assert line.gradient_at(11_000.0, UP) == -2.0
    assert line.gradient_at(11_000.0, DOWN) == -5.0
    assert_array_equal(line.gradient_at([10_000.0, 10_999.0, 13_000.0], UP), [5.0, 5.0, -2.0])
    assert_array_equal(line.gradient_at([10_000.0, 11_001.0, 13_000.0], DOWN), [-5.0, 2.0, 2.0])


def test_elevation_profile_integrates_the_gradients(line):
    edges, elevation = line.elevation_profile()
    assert_allclose(edges, [10_000.0, 11_000.0, 13_000.0])
    assert_allclose(elevation, [100.0, 105.0, 101.0])  # +5 m over 1 km, -4 m over 2 km
    assert_allclose(line.elevation_at([10_500.0, 12_000.0]), [102.5, 103.0])


def test_elevation_agrees_with_the_simulation_cores_integral(line):
    # vehicle/profile.py integrates the train's line; gradients alone: cumulative/1000 = rise
    for direction, rise in ((UP, 1.0), (DOWN, -1.0)):
        vehicle = line.to_vehicle_line("a", direction)
        table = elevation_table(Line(gradients=vehicle.gradients))
        assert_allclose(table.cumulative[-1] / 1000.0, rise * (101.0 - 100.0))


def test_static_limit_step_function(line):
    edges, limits = line.static_limit("a", UP)
    assert_allclose(edges, [10_000.0, 12_000.0, 13_000.0])
    assert_allclose(limits, kmh_to_mps(np.array([80.0, 60.0])))
    edges, limits = line.static_limit("a", DOWN)
    assert_allclose(limits, kmh_to_mps(np.array([80.0, 40.0])))
    edges, limits = line.static_limit("b", DOWN)
    assert_allclose(edges, [10_000.0, 13_000.0])
    assert_allclose(
        line.limit_at("a", DOWN, [12_000.0, 12_000.001]), kmh_to_mps(np.array([80.0, 40.0]))
    )


def test_unknown_category_and_direction(line):
    with pytest.raises(LineError, match="one of the line's categories: a, b"):
        line.static_limit("c", UP)
    with pytest.raises(LineError, match=r"TravelDirection\.UP or TravelDirection\.DOWN"):
        line.static_limit("a", TravelDirection.UNKNOWN)


def test_positions_outside_the_line_are_an_error(line):
    with pytest.raises(LineError, match=r"position_m = 9000\.0"):
        line.gradient_at([10_000.0, 9_000.0])
    with pytest.raises(LineError, match="position_m"):
        line.block_section_at(13_500.0, UP)


def test_block_sections_derived_from_the_signals(line):
    up = line.block_sections_for(UP)
    assert [(s.start_m, s.end_m, s.entry_signal) for s in up] == [
        (10_000.0, 10_500.0, None),
        (10_500.0, 12_000.0, "U1"),
        (12_000.0, 12_700.0, "U2"),
        (12_700.0, 13_000.0, "U3"),
    ]
    down = line.block_sections_for(DOWN)  # in travel order: from km 13 downwards
    assert [(s.start_m, s.end_m, s.entry_signal) for s in down] == [
        (12_900.0, 13_000.0, None),
        (12_300.0, 12_900.0, "D3"),
        (11_000.0, 12_300.0, "D2"),
        (10_000.0, 11_000.0, "D1"),
    ]
    assert [s.id for s in down] == ["down-001", "down-002", "down-003", "down-004"]


def test_a_train_at_a_signal_is_in_the_section_it_protects(line):
    assert line.block_section_at(12_000.0, UP).entry_signal == "U2"
    assert line.block_section_at(11_999.0, UP).entry_signal == "U1"
    assert line.block_section_at(12_300.0, DOWN).entry_signal == "D2"
    assert line.block_section_at(12_301.0, DOWN).entry_signal == "D3"


def test_signals_ahead(line):
    assert [s.id for s in line.signals_ahead(10_500.0, UP)] == ["U2", "U3"]
    assert [s.id for s in line.signals_ahead(10_499.0, UP)] == ["U1", "U2", "U3"]
    assert [s.id for s in line.signals_ahead(12_300.0, DOWN)] == ["D1"]
    assert [s.id for s in line.signals_ahead(13_000.0, DOWN)] == ["D3", "D2", "D1"]


def test_station_lookup_and_stop_points(line):
    station = line.station(1)
    assert (station.loop_start_m, station.loop_end_m) == (12_300.0, 12_700.0)
    assert station.stop_m(UP) == pytest.approx(12_650.0)
    assert station.stop_m(DOWN) == pytest.approx(12_350.0)
    with pytest.raises(LineError, match="station_id = 7"):
        line.station(7)


def test_curve_radius_lookup(line):
    assert_array_equal(line.curve_radius_at([11_000.0, 11_700.0]), [np.inf, 500.0])


def test_stop_points_default_to_the_station_centre():
    data = tiny()
    del data["stations"][0]["stop_up_km"]
    del data["stations"][0]["stop_down_km"]
    station = parse_line(dumps(data)).stations[0]
    assert station.stop_up_m == station.stop_down_m == 12_500.0
