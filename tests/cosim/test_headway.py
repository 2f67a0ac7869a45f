"""Headway conflicts of a line run's timetable (cosim/headway.py): found from the timetable
alone, physically sound, and in agreement with what the co-simulation's signals do."""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.cosim.driver import Service, shared_route
from railpilot.cosim.headway import (
    SHIFT_STEP_S,
    headway_conflicts,
    occupations,
    shift_until_clear,
    shifted,
)
from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import LineScenario, line_scenario_from_mapping, load_line_scenario
from railpilot.errors import ConfigError

EXAMPLES = Path(__file__).parents[2] / "examples"


@functools.cache
def _short_day() -> LineScenario:
    return load_line_scenario(EXAMPLES / "line_short_day.toml")


def _departing(service: Service, at_s: float) -> Service:
    """``service`` shifted in time to leave its origin at ``at_s`` [s]."""
    by = at_s - service.stops[0].departure_s
    stops = tuple(
        dataclasses.replace(s, arrival_s=s.arrival_s + by, departure_s=s.departure_s + by)
        for s in service.stops
    )
    return dataclasses.replace(service, stops=stops)


def _pair(scenario: LineScenario, spacing_s: float) -> tuple[Service, Service]:
    """The short day's first two loaded trains, the second ``spacing_s`` after the first."""
    first, second = [s for s in scenario.services if s.kind == "heavy-haul-loaded"][:2]
    start = first.stops[0].departure_s
    return first, _departing(second, start + spacing_s)


@settings(max_examples=40, deadline=None)
@given(spacing_min=st.floats(0.0, 40.0), closer_min=st.floats(0.0, 40.0))
def test_a_conflict_stays_a_conflict_when_the_trains_come_closer(
    spacing_min: float, closer_min: float
) -> None:
    """Two trains of one route: if they conflict at some spacing, they do at every
    smaller one; at no spacing do they conflict on the other track."""
    short_day = _short_day()
    closer = min(spacing_min, closer_min)
    far = headway_conflicts(_pair(short_day, 60.0 * spacing_min), short_day.line, 5.0)
    near = headway_conflicts(_pair(short_day, 60.0 * closer), short_day.line, 5.0)
    if far:
        assert near
    assert all(c.first.block.direction.name == "UP" for c in far + near)


def test_a_train_holds_its_block_sections_one_after_the_other_no_faster_than_its_top_speed() -> (
    None
):
    """In the order a train enters them, its block sections are neighbours along the
    track and each is entered before the one behind is clear (the train straddles their
    boundary); none it runs wholly through is clear sooner than the section's length and
    the train's at the train's highest limit."""
    short_day = _short_day()
    for service in short_day.services:
        first, second = service.stops[0].station, service.stops[1].station
        route = shared_route(short_day.line, service.kind, first, second, 5.0)
        top_mps = float(np.max(route.static.speeds_mps[np.isfinite(route.static.speeds_mps)]))
        length = route.preset.train.length_m
        held = sorted(occupations(service, short_day.line, 5.0), key=lambda o: o.start_s)
        assert len(held) > 2, service.train_id
        for before, after in itertools.pairwise(held):
            a, b = before.block, after.block
            assert a.end_m == b.start_m or b.end_m == a.start_m, (a.id, b.id)
            assert before.start_s <= after.start_s <= before.end_s
        for one in held[1:-1]:  # wholly run through: not the origin's, not the destination's
            span = one.block.end_m - one.block.start_m
            assert one.end_s - one.start_s >= (span + length) / top_mps


@pytest.mark.parametrize(
    ("spacing_min", "conflict"), [(6.0, True), (6.5, True), (7.0, False), (8.0, False)]
)
def test_the_co_simulation_holds_the_follower_exactly_when_the_check_finds_a_conflict(
    spacing_min: float, conflict: bool
) -> None:
    """The live example's two loaded trains, without its events, at four spacings: where
    the check finds a conflict (the follower would need a block section the leader still
    holds), the co-simulation's signals hold the follower (it leaves late, or stops at a
    red signal); where it finds none, the follower leaves on time and runs on."""
    scenario = load_line_scenario(EXAMPLES / "line_live_short.toml")
    leader, follower = [s for s in scenario.services if s.kind == "heavy-haul-loaded"][:2]
    follower = _departing(follower, leader.stops[0].departure_s + 60.0 * spacing_min)
    found = headway_conflicts((leader, follower), scenario.line, scenario.margin_kmh)
    assert bool(found) is conflict
    result = run_line(
        scenario.with_(services=(leader, follower), events=()),
        until_s=follower.stops[0].departure_s + 300.0,
    )

    # how long after its departure a train of the kind is 1 m on, with nothing ahead of it:
    # the leader's own start
    def moving_after_s(service: Service) -> float:
        t, head = result.trace[service.train_id][:, 0], result.trace[service.train_id][:, 1]
        return float(t[np.argmax(np.abs(head - head[0]) > 1.0)]) - service.stops[0].departure_s

    late_s = moving_after_s(follower) - moving_after_s(leader)
    held = late_s > 2.0 or result.drivers[follower.train_id].red_signal_stops > 0
    assert held is conflict


def _times(service: Service) -> list[float | None]:
    """A service's stop times [s] in order (None where a stop has none: NaN is not equal
    to itself)."""
    return [
        t if math.isfinite(t) else None
        for stop in service.stops
        for t in (stop.arrival_s, stop.departure_s)
    ]


@settings(max_examples=15, deadline=None)
@given(spacing_min=st.floats(0.0, 12.0))
def test_a_shift_clears_every_conflict_moving_only_later_trains_by_whole_steps(
    spacing_min: float,
) -> None:
    """Two trains of one route at any spacing: shifted, none shares a block section with
    the other; the first keeps its times, the second is moved later (never earlier) by a
    whole number of 10 s steps, and not at all where there was no conflict."""
    short_day = _short_day()
    pair = _pair(short_day, 60.0 * spacing_min)
    had = headway_conflicts(pair, short_day.line, 5.0)
    out, moved = shift_until_clear(pair, short_day.line, 5.0, latest_s=24 * 3600.0)
    assert headway_conflicts(out, short_day.line, 5.0) == []
    assert _times(out[0]) == _times(pair[0])
    by = moved.get(pair[1].train_id, 0.0)
    assert (by > 0.0) is bool(had)
    assert by % SHIFT_STEP_S == 0.0
    assert _times(out[1]) == _times(shifted(pair[1], by))


def test_a_file_may_ask_for_the_shift_and_a_run_too_short_for_it_is_refused() -> None:
    """``conflicts = "shift"``: the short day's loaded trains a minute apart load, moved
    later (the KPI object lists by how much); in a run too short to hold them it is an
    error naming the key."""
    data = tomllib.loads((EXAMPLES / "line_short_day.toml").read_text())
    data["services"][0]["every_min"] = 1.0
    scenario = line_scenario_from_mapping({**data, "conflicts": "shift"})
    assert set(scenario.shifted_s) == {102, 103}
    assert headway_conflicts(scenario.services, scenario.line, scenario.margin_kmh) == []
    with pytest.raises(ConfigError) as refused:
        line_scenario_from_mapping({**data, "conflicts": "shift", "duration_h": 0.2})
    assert refused.value.field == "conflicts" and "after the run's end" in str(refused.value)
