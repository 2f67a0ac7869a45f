"""Property: the step-function queries agree with a brute-force walk over the entries.

The brute force reads the raw entries as the module docstring of railpilot.line.model
states the convention: going UP a position on a boundary belongs to the section starting
there, ``[start, end)``; going DOWN to ``(start, end]``; at the line's own ends, to the end
section.
"""

from __future__ import annotations

from collections.abc import Iterable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.line import DIRECTIONS, DOWN, UP, RailLine, load_line
from railpilot.link.messages import TravelDirection

LINES = {name: load_line(name) for name in ("heavy-haul", "metro")}


def _inside(x: float, start: float, end: float, direction: TravelDirection) -> bool:
    if direction == UP:
        return start <= x < end
    return start < x <= end


def _brute(
    line: RailLine,
    spans: Iterable[tuple[float, float, float]],
    x: float,
    direction: TravelDirection,
) -> float:
    spans = list(spans)
    for start, end, value in spans:
        if _inside(x, start, end, direction):
            return value
    # only the line's two ends are outside every half-open span
    assert x in (line.start_m, line.end_m)
    return spans[-1][2] if x == line.end_m else spans[0][2]


def _edges(line: RailLine) -> list[float]:
    points = {line.start_m, line.end_m}
    for g in line.gradients:
        points |= {g.start_m, g.end_m}
    for e in line.speed_limits:
        points |= {e.start_m, e.end_m}
    for s in line.signals:
        points.add(s.position_m)
    return sorted(points)


@st.composite
def positions(draw: st.DrawFn) -> tuple[str, float, TravelDirection, str]:
    name = draw(st.sampled_from(sorted(LINES)))
    line = LINES[name]
    x = draw(
        st.one_of(
            st.floats(line.start_m, line.end_m, allow_nan=False),
            st.sampled_from(_edges(line)),  # boundaries, where conventions matter
        )
    )
    direction = draw(st.sampled_from(DIRECTIONS))
    category = draw(st.sampled_from(line.categories))
    return name, x, direction, category


@settings(max_examples=400, deadline=None)
@given(positions())
def test_gradient_at_agrees_with_brute_force(case):
    name, x, direction, _ = case
    line = LINES[name]
    sign = 1.0 if direction == UP else -1.0
    expected = _brute(
        line, ((g.start_m, g.end_m, sign * g.permille) for g in line.gradients), x, direction
    )
    assert line.gradient_at(x, direction) == expected


@settings(max_examples=400, deadline=None)
@given(positions())
def test_static_limit_agrees_with_brute_force(case):
    name, x, direction, category = case
    line = LINES[name]
    spans = sorted(
        (e.start_m, e.end_m, e.limit_mps)
        for e in line.speed_limits
        if e.category == category and e.applies_to(direction)
    )
    assert line.limit_at(category, direction, x) == _brute(line, spans, x, direction)


@settings(max_examples=400, deadline=None)
@given(positions())
def test_block_section_and_signals_ahead_agree_with_brute_force(case):
    name, x, direction, _ = case
    line = LINES[name]
    section = line.block_section_at(x, direction)
    spans = sorted(
        (s.start_m, s.end_m, float(i))
        for i, s in enumerate(line.block_sections)
        if s.direction == direction
    )
    assert line.block_sections[int(_brute(line, spans, x, direction))] == section
    # the next signal ahead, if any, is where the train leaves this section
    ahead = line.signals_ahead(x, direction)
    brute = [
        s
        for s in line.signals
        if s.direction == direction and (s.position_m > x if direction == UP else s.position_m < x)
    ]
    assert sorted(ahead, key=lambda s: s.position_m) == sorted(brute, key=lambda s: s.position_m)
    if ahead:
        assert ahead[0].position_m == pytest.approx(section.exit_m)


@settings(max_examples=200, deadline=None)
@given(positions())
def test_vehicle_line_agrees_at_every_position(case):
    name, x, direction, category = case
    line = LINES[name]
    vehicle = line.to_vehicle_line(category, direction)
    s = float(line.distance_along(x, direction))
    if s < line.length_m:  # the vehicle Line's segments are [s0, s1): its end is outside
        assert vehicle.speed_limit(s) == line.limit_at(category, direction, x)


@settings(max_examples=400, deadline=None)
@given(positions(), st.floats(0.0, 20_000.0))
def test_block_sections_between_and_indices_agree_with_brute_force(case, length_m):
    """The bisection the ground's occupancy runs on, against a scan of every section."""
    name, x, direction, _ = case
    line = LINES[name]
    low, high = max(x - length_m, line.start_m), x
    travel = line.block_sections_for(direction)
    brute = tuple(s for s in travel if s.start_m <= high and s.end_m >= low)
    assert line.block_sections_between(low, high, direction) == brute
    assert all(line.block_index(s.id, direction) == k for k, s in enumerate(travel))
    other = DOWN if direction == UP else UP
    assert line.block_index(travel[0].id, other) is None


@settings(max_examples=400, deadline=None)
@given(positions())
def test_signal_near_agrees_with_brute_force(case):
    name, x, direction, _ = case
    line = LINES[name]
    for signal in line.signals_for(direction)[:50]:
        assert line.signal_near(signal.position_m + 0.5, direction) == signal.id
    near = [s.id for s in line.signals if s.direction == direction and abs(s.position_m - x) <= 1.0]
    assert line.signal_near(x, direction) == (near[0] if near else None)
