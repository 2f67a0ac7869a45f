"""The ground's train registry: live state, its validity, link health, deviation from plan."""

from __future__ import annotations

import pytest

from railpilot.errors import ConfigError
from railpilot.ground.registry import (
    TimetableStop,
    TrainRegistry,
    TrainTimetable,
    with_departure,
)
from railpilot.link.checks import Check
from railpilot.link.messages import PlannedCurve, RegisterRequest, RunningInfo, TravelDirection

REQUEST = RegisterRequest("K101", "HXD10001", 7, 1600.0)


def info(position_m: float = 30_000.0) -> RunningInfo:
    return RunningInfo(7, "K101", "HXD10001", TravelDirection.UP, 19.0, position_m)


def timetable() -> TrainTimetable:
    # depart station 1 at 1,000 s; 1,490 s to station 2, 120 s dwell; 2,350 s to station 3
    return TrainTimetable.from_running_times(5, (1, 2, 3), (1490.0, 2350.0), 1000.0, 120.0)


def test_timetable_from_running_times() -> None:
    t = timetable()
    assert [(s.station_id, s.arrival_s, s.departure_s) for s in t.stops] == [
        (1, 1000.0, 1000.0),
        (2, 2490.0, 2610.0),
        (3, 4960.0, 4960.0),
    ]
    assert t.section_running_times_s() == (1490.0, 2350.0)
    assert with_departure(t, 1300.0).planned_arrival_s(3) == 5260.0


def test_running_info_is_valid_for_the_validity_window_only() -> None:
    registry = TrainRegistry(validity_s=4.0)
    registry.registered(5, REQUEST)
    registry.running_info(5, info(), 100.0)
    fresh = registry.state(5, 104.0)
    assert fresh.registered and fresh.train_number == "K101" and fresh.length_m == 1600.0
    assert fresh.info_age_s == pytest.approx(4.0) and fresh.info_valid
    stale = registry.state(5, 104.1)
    assert not stale.info_valid
    assert stale.running_info == info()  # kept, marked invalid


def test_link_health_counts_by_check() -> None:
    registry = TrainRegistry()
    registry.connected(5)
    registry.rejected(5, Check.CRC)
    registry.rejected(5, Check.CRC)
    registry.rejected(5, Check.AUTH)
    registry.timed_out(5)
    registry.link_failed(5)
    health = registry.state(5, 0.0).health
    assert not health.connected  # a failed link closes the connection
    assert (health.timeouts, health.failures) == (1, 1)
    assert health.rejections == (("auth", 1), ("crc", 2))


def test_deviation_from_the_planned_curve_report() -> None:
    registry = TrainRegistry(off_plan_s=60.0)
    registry.set_timetable(timetable())
    # at 2,000 s the train reports 600 s still to run to station 2: expected at 2,600 s,
    # planned at 2,490 s: 110 s late, off plan
    registry.planned_curve(5, PlannedCurve(1, 2, 1000.0, 600.0), 2000.0)
    state = registry.state(5, 2000.0)
    assert state.expected_arrival_s == pytest.approx(2600.0)
    assert state.deviation_s == pytest.approx(110.0)
    assert [s.train_id for s in registry.off_plan(2000.0)] == [5]
    # 100 s later, without a new report, the same arrival is expected
    assert registry.state(5, 2100.0).expected_arrival_s == pytest.approx(2600.0)
    # a report 30 s late is on plan
    registry.planned_curve(5, PlannedCurve(1, 2, 1100.0, 420.0), 2100.0)
    assert registry.state(5, 2100.0).deviation_s == pytest.approx(30.0)
    assert registry.off_plan(2100.0) == ()


def test_without_a_timetable_there_is_no_deviation() -> None:
    registry = TrainRegistry()
    registry.planned_curve(5, PlannedCurve(1, 2, 10.0, 600.0), 0.0)
    state = registry.state(5, 0.0)
    assert state.expected_arrival_s == 600.0 and state.deviation_s is None


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: TrainRegistry(validity_s=0.0), "validity_s"),
        (lambda: TrainRegistry().state(9, 0.0), "train_id"),
        (lambda: TrainRegistry().running_info(-1, info(), 0.0), "train_id"),
        (lambda: TrainRegistry().running_info(1, info(), float("nan")), "now_s"),
        (lambda: TimetableStop(1, 10.0, 5.0), "stop.departure_s"),
        (
            lambda: TrainTimetable(1, (TimetableStop(1, 0.0, 10.0), TimetableStop(2, 5.0, 5.0))),
            "timetable.stops[1].arrival_s",
        ),
        (lambda: TrainTimetable.from_running_times(1, (1, 2), (1.0, 2.0), 0.0), "running_times_s"),
        (lambda: timetable().planned_arrival_s(9), "station_id"),
    ],
)
def test_bad_input_names_the_field(make, field) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ConfigError) as exc:
        make()
    assert exc.value.field == field


def test_a_plan_held_elsewhere_gives_the_deviation_of_a_train_without_a_timetable() -> None:
    planned = {(7, 3): 1_000.0}
    registry = TrainRegistry(planned_arrival=lambda train, station: planned.get((train, station)))
    registry.planned_curve(7, PlannedCurve(2, 3, 100.0, 200.0), 900.0)
    state = registry.state(7, 900.0)
    assert (state.expected_arrival_s, state.deviation_s) == (1_100.0, 100.0)
    assert [s.train_id for s in registry.off_plan(900.0)] == [7]
    # a station the plan does not have: no deviation
    registry.planned_curve(7, PlannedCurve(3, 4, 0.0, 50.0), 950.0)
    assert registry.state(7, 950.0).deviation_s is None
    # the train's own timetable comes first
    registry.set_timetable(TrainTimetable.from_running_times(7, [3, 4], [100.0], 900.0))
    assert registry.state(7, 950.0).deviation_s == 0.0
