"""The trackside's check of the static speed limits (cosim/trackside.py
``static_overspeeds``): the lowest limit anywhere between a train's tail and its head,
against hand-worked cases and against a brute-force lookup on the MRSP's own profile."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from tests.line.helpers import tiny

from railpilot.cosim.trackside import (
    OVERSPEED_TOLERANCE_MPS,
    TrainShape,
    static_limit_under,
    static_overspeeds,
)
from railpilot.line.loader import line_from_mapping
from railpilot.link import TravelDirection
from railpilot.onboard.mrsp import SpeedProfile

UP, DOWN = TravelDirection.UP, TravelDirection.DOWN
KMH = 1 / 3.6
LENGTH_M = 400.0


@pytest.fixture(scope="module")
def line():
    """The tiny line (km 10-13; category "a": 80 km/h, then from km 12 60 up / 40 down),
    with category "b" given a 100 m stretch at 30 km/h in its 50 km/h (km 11.5-11.6),
    shorter than the 400 m train."""
    data = tiny()
    data["speed_limits"] = [e for e in data["speed_limits"] if e["category"] == "a"] + [
        {"category": "b", "start_km": 10.0, "end_km": 11.5, "limit_kmh": 50.0},
        {"category": "b", "start_km": 11.5, "end_km": 11.6, "limit_kmh": 30.0},
        {"category": "b", "start_km": 11.6, "end_km": 13.0, "limit_kmh": 50.0},
    ]
    return line_from_mapping(data)


def _spells(line, rows, direction=UP, category="a"):
    trace = {7: np.asarray(rows, dtype=float).reshape(-1, 3)}
    return static_overspeeds(line, trace, {7: TrainShape(direction, LENGTH_M, category)})


def _limit(line, head_km, direction=UP, category="a", speed_kmh=200.0):
    """The limit the check held one look to [km/h] (a look far above every limit)."""
    (spell,) = _spells(line, [(0.0, head_km * 1000.0, speed_kmh * KMH)], direction, category)
    return spell["limit_kmh"]


def test_the_tail_keeps_the_lower_limit_until_it_has_left_it(line):
    # going up, the head past km 12 (60 km/h) and the tail behind it in the 80: 60
    assert _limit(line, 12.2) == pytest.approx(60.0)
    # the head on the boundary: the stricter side
    assert _limit(line, 12.0) == pytest.approx(60.0)
    assert _limit(line, 11.9) == pytest.approx(80.0)
    # going down from the 40 into the 80: the tail (400 m behind, at km 12.3) is in the 40
    assert _limit(line, 11.9, DOWN) == pytest.approx(40.0)
    assert _limit(line, 11.6, DOWN) == pytest.approx(40.0)  # the tail on the boundary
    assert _limit(line, 11.55, DOWN) == pytest.approx(80.0)


def test_a_slow_stretch_under_the_middle_of_the_train_counts(line):
    # head km 11.8, tail km 11.4: both ends in the 50, the 30 under the train's middle
    assert _limit(line, 11.8, category="b") == pytest.approx(30.0)
    assert _limit(line, 12.1, category="b") == pytest.approx(50.0)


def test_a_train_reaching_beyond_the_line_is_held_to_the_limit_at_its_end(line):
    # the tail 200 m before km 10, the line's start
    assert _limit(line, 10.2) == pytest.approx(80.0)
    assert _limit(line, 10.2, DOWN, speed_kmh=100.0) == pytest.approx(80.0)


def test_standing_or_within_the_tolerance_is_not_an_overspeed(line):
    limit = 60.0 * KMH
    assert _spells(line, [(0.0, 12_200.0, limit + 0.99 * OVERSPEED_TOLERANCE_MPS)]) == []
    assert _spells(line, [(0.0, 12_200.0, limit + 1.01 * OVERSPEED_TOLERANCE_MPS)]) != []
    assert _spells(line, [(0.0, 12_200.0, 0.0), (1.0, 13_500.0, 0.0)]) == []


def test_consecutive_looks_over_make_one_spell_with_its_worst_look(line):
    rows = [
        (0.0, 12_100.0, 58 * KMH),
        (1.0, 12_120.0, 61 * KMH),  # over from here
        (2.0, 12_140.0, 64 * KMH),  # the worst
        (3.0, 12_160.0, 62 * KMH),
        (4.0, 12_180.0, 59 * KMH),
        (5.0, 12_200.0, 63 * KMH),  # a second spell, one look long
    ]
    first, second = _spells(line, rows)
    assert (first["from_s"], first["to_s"], first["t_s"]) == (1.0, 3.0, 2.0)
    assert first["head_km"] == pytest.approx(12.14)
    assert first["speed_kmh"] == pytest.approx(64.0)
    assert first["excess_kmh"] == pytest.approx(4.0)
    assert (second["from_s"], second["to_s"], second["excess_kmh"]) == (5.0, 5.0, pytest.approx(3))
    assert first["train"] == second["train"] == 7


@pytest.mark.parametrize("direction", [UP, DOWN])
@pytest.mark.parametrize("category", ["a", "b"])
def test_the_limit_is_the_profiles_lowest_between_tail_and_head(line, direction, category):
    """Against the MRSP's own step function (onboard/mrsp.py: the stricter side at an
    edge) evaluated at the train's ends, every edge between them and the midpoints."""
    profile = SpeedProfile(*line.static_limit(category, direction))
    rng = np.random.default_rng(12)
    heads = np.concatenate([rng.uniform(10_000.0, 13_000.0, 400), profile.edges_m])
    sign = 1.0 if direction is UP else -1.0
    # inside the line, where the profile's ends (speed 0 beyond it) do not speak
    inner = (profile.start_m + 1e-6, profile.end_m - 1e-6)
    expected = []
    for head in heads:
        low, high = np.clip(sorted((head, head - sign * LENGTH_M)), *inner)
        edges = profile.edges_m[(profile.edges_m >= low) & (profile.edges_m <= high)]
        points = np.unique(np.concatenate([[low, high], edges]))
        points = np.concatenate([points, (points[:-1] + points[1:]) / 2])
        expected.append(profile.at(points).min())
    got = static_limit_under(line, TrainShape(direction, LENGTH_M, category), heads)
    assert_allclose(got, expected)
