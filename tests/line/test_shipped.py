"""The shipped lines: they load, and they carry the facts docs/line-data.md claims."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.line import DIRECTIONS, DOWN, UP, RailLine, load_line
from railpilot.line.data import make_heavy_haul
from railpilot.units import km_post_to_m, mps_to_kmh

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def heavy() -> RailLine:
    return load_line("heavy-haul")


@pytest.fixture(scope="module")
def metro() -> RailLine:
    return load_line("metro")


def test_load_by_name_and_by_path(heavy):
    path = Path(make_heavy_haul.__file__).with_name("heavy_haul.toml")
    assert load_line(path) == heavy
    assert load_line(str(path)).name == "heavy-haul"


def test_the_committed_file_is_the_generators_output():
    path = Path(make_heavy_haul.__file__).with_name("heavy_haul.toml")
    assert path.read_text(encoding="utf-8") == make_heavy_haul.render()


# ---------------------------------------------------------------- heavy haul


def test_heavy_haul_length_stations_and_loops(heavy):
    assert heavy.start_m == 0.0
    assert heavy.length_m == km_post_to_m(590.0)
    assert 15 <= len(heavy.stations) <= 20
    assert {s.loop_length_m for s in heavy.stations} == {1700.0}
    assert heavy.stations[0].name == "Shenchi South"
    assert heavy.stations[-1].name == "Huanghua Port"


def test_heavy_haul_descends_from_1533_m_to_below_200_m_within_240_km(heavy):
    assert heavy.elevation_at(0.0) == pytest.approx(1533.0)
    assert heavy.elevation_at(km_post_to_m(240.0)) < 200.0
    xibaipo = next(s for s in heavy.stations if s.name == "Xibaipo")
    assert xibaipo.centre_m <= km_post_to_m(240.0)
    assert heavy.elevation_at(xibaipo.centre_m) < 200.0
    # a descent all the way: every km of the first 240 is at or below the one before it
    km = km_post_to_m(np.arange(0.0, 241.0))
    assert np.all(np.diff(heavy.elevation_at(km)) <= 1e-9 + 4.0)  # humps of at most 4 m
    assert 0.0 < heavy.elevation_at(heavy.end_m) < 50.0  # near sea level at the port


def test_heavy_haul_ruling_grade_and_12_per_mille_descents(heavy):
    edges, up = heavy.gradient_profile(UP)
    assert up.max() == 4.0  # loaded trains (UP) climb at most the 4 per mille ruling grade
    assert up.min() == -12.0
    _, down = heavy.gradient_profile(DOWN)
    assert down.max() == 12.0  # empty trains climb the 12 per mille
    lengths = np.diff(edges)[up == -12.0]
    assert lengths.max() >= km_post_to_m(30.0)  # a long unbroken 12 per mille descent
    assert lengths.sum() >= km_post_to_m(60.0)


def test_station_loops_are_level(heavy):
    for station in heavy.stations:
        x = np.linspace(station.loop_start_m + 1.0, station.loop_end_m - 1.0, 11)
        assert np.all(heavy.gradient_at(x, UP) == 0.0), station.name


def test_heavy_haul_limits(heavy):
    for category in ("freight_loaded", "freight_empty"):
        for direction in DIRECTIONS:
            _, limits = heavy.static_limit(category, direction)
            assert mps_to_kmh(limits.max()) == pytest.approx(80.0)
            assert mps_to_kmh(limits.min()) == pytest.approx(45.0)  # the yards
    # loaded trains going down the 12 per mille (UP) are held to 70 km/h; empties are not
    x = km_post_to_m(40.0)
    assert mps_to_kmh(heavy.limit_at("freight_loaded", UP, x)) == pytest.approx(70.0)
    assert mps_to_kmh(heavy.limit_at("freight_loaded", DOWN, x)) > 70.0
    # sharp curves are slower than line speed
    sharp = [c for c in heavy.curves if c.radius_m < 450.0]
    assert sharp
    for curve in sharp:
        mid = 0.5 * (curve.start_m + curve.end_m)
        assert mps_to_kmh(heavy.limit_at("freight_empty", DOWN, mid)) == pytest.approx(65.0)


def test_heavy_haul_fixed_block(heavy):
    assert 300 <= len(heavy.signals) <= 700
    for direction in DIRECTIONS:
        sections = heavy.block_sections_for(direction)
        lengths = np.array([s.end_m - s.start_m for s in sections])
        assert lengths.max() <= 3000.0
        assert np.median(lengths) >= 2000.0
        kinds = {s.kind for s in heavy.signals_for(direction)}
        assert kinds == {"home", "exit", "block"}
    for station in heavy.stations:
        assert station.loop_start_m < station.stop_m(UP) < station.loop_end_m


# ---------------------------------------------------------------- metro


def test_metro_line(metro):
    assert metro.categories == ("metro",)
    centres = np.array([s.centre_m for s in metro.stations])
    assert np.all((np.diff(centres) >= 1000.0) & (np.diff(centres) <= 1500.0))
    _, limits = metro.static_limit("metro", UP)
    assert mps_to_kmh(limits.max()) == pytest.approx(80.0)
    _, gradients = metro.gradient_profile(UP)
    assert np.abs(gradients).max() == 30.0
    for station in metro.stations:
        x = np.linspace(station.loop_start_m + 1.0, station.loop_end_m - 1.0, 5)
        assert np.all(metro.gradient_at(x) == 0.0), station.name


def test_metro_stop_matches_paper_000s_braking_run(metro):
    from railpilot.scenario.loader import load_scenario

    scenario = load_scenario(EXAMPLES / "paper000_smarc_ep.toml")
    station = metro.station(6)
    assert_allclose(station.stop_m(UP), scenario.reference.stop_m, atol=1.0)
    # the run from km 19.96 to the stop is on level track, as the paper's is
    x = np.linspace(scenario.reference.start_m, station.stop_m(UP), 50)
    assert np.all(metro.gradient_at(x, UP) == 0.0)


# ---------------------------------------------------------------- both


@pytest.mark.parametrize("name", ["heavy-haul", "metro"])
def test_block_sections_tile_the_line_per_direction(name):
    line = load_line(name)
    for direction in DIRECTIONS:
        sections = sorted(line.block_sections_for(direction), key=lambda s: s.start_m)
        assert sections[0].start_m == line.start_m
        assert sections[-1].end_m == line.end_m
        for a, b in itertools.pairwise(sections):
            assert a.end_m == b.start_m
        signals = {s.id: s for s in line.signals_for(direction)}
        for section in line.block_sections_for(direction)[1:]:
            assert section.entry_signal is not None
            assert signals[section.entry_signal].position_m == section.entry_m


@pytest.mark.parametrize("name", ["heavy-haul", "metro"])
@pytest.mark.parametrize("direction", DIRECTIONS)
def test_vehicle_line_round_trip(name, direction):
    line = load_line(name)
    category = line.categories[0]
    vehicle = line.to_vehicle_line(category, direction)
    rng = np.random.default_rng(3)
    x = rng.uniform(line.start_m, line.end_m, 500)
    s = line.distance_along(x, direction)
    assert_allclose(vehicle.speed_limit(s), line.limit_at(category, direction, x))
    grade_only = type(vehicle)(gradients=vehicle.gradients)
    assert_allclose(grade_only.additional_resistance(s), line.gradient_at(x, direction))
    rise = line.elevation_at(line.end_m) - line.elevation_at(line.start_m)
    total = sum((g.end_m - g.start_m) * g.value for g in vehicle.gradients) / 1000.0
    assert_allclose(total, rise if direction == UP else -rise, atol=1e-6)
    assert len(vehicle.stations) == len(line.stations)
    assert all(a.stop_m <= b.stop_m for a, b in itertools.pairwise(vehicle.stations))


def test_a_line_hashes_as_its_fields_and_afresh_when_unpickled():
    # the hash is kept (a line keys the caches of its routes and controllers), but it is
    # the hash of its fields, equal lines hash alike, and a pickled line does not carry it
    # (string hashes differ between processes)
    import dataclasses
    import pickle

    line = load_line("heavy-haul")
    fields = tuple(getattr(line, f.name) for f in dataclasses.fields(line))
    assert hash(line) == hash(fields)
    again = load_line("heavy-haul")
    assert again == line and hash(again) == hash(line)
    assert "_hash" not in pickle.loads(pickle.dumps(line)).__dict__
    assert hash(pickle.loads(pickle.dumps(line))) == hash(line)
    shorter = dataclasses.replace(line, description="another")
    assert shorter != line and hash(shorter) != hash(line)


def test_an_equal_line_is_loaded_as_the_first_instance(heavy, monkeypatch):
    # caches keyed by a line find the same instance at once, where an equal copy is
    # compared item by item on every lookup: every load of an equal line gives the first
    from railpilot.line import loader

    monkeypatch.setattr(loader, "_INTERNED", dict(loader._INTERNED))  # restored after
    path = Path(make_heavy_haul.__file__).with_name("heavy_haul.toml")
    assert load_line("heavy-haul") is heavy
    assert load_line(path) is heavy
    copy = loader.read_line(path)
    assert copy == heavy and copy is not heavy  # what interning saves the caches from
    text = path.read_text(encoding="utf-8")
    renamed = loader.parse_line(text.replace('name = "heavy-haul"', 'name = "b"', 1))
    assert loader.interned(renamed) is renamed
    # the table keeps the latest few lines, not every line ever loaded
    variants = [
        loader.parse_line(text.replace('name = "heavy-haul"', f'name = "v{i}"', 1))
        for i in range(loader._INTERNED_MAX)
    ]
    for variant in variants:
        assert loader.interned(variant) is variant
    assert len(loader._INTERNED) == loader._INTERNED_MAX
    assert loader.interned(copy) is copy  # heavy, the oldest, has gone
