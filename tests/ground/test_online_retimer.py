"""Re-timing in the loop (railpilot.ground.online_retimer).

A small line (stations 1 to 4, three sections of 1000 s planned, 800 s at the fastest), a
train every 10 minutes each way, synthetic energy curves: what the retimer hears (planned
curve reports), when it re-times, whom it re-times, and what it sends, checked against the
timetable and the LP's own rules worked out here (never slower than the timetable, never
faster than the fastest run, the headway behind a train that is not re-timed).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from railpilot.errors import ConfigError
from railpilot.ground.dispatch import GroundDispatch, SendRunningTimes
from railpilot.ground.online_retimer import (
    OnlineRetimer,
    RetimerSettings,
    SectionCurve,
    TimetabledTrain,
    timetabled,
)
from railpilot.ground.running_time_lp import EnergyCurve
from railpilot.line import load_line
from railpilot.link import MessageReceived, TrainRegistered
from railpilot.link.messages import (
    PlannedCurve,
    RegisterRequest,
    RunningInfo,
    RunningTimes,
    TravelDirection,
)

PLANNED_S = 1000.0
FASTEST_S = 800.0
DWELL_S = 120.0  # planned
MIN_DWELL_S = 60.0
HEADWAY_S = 300.0
T0 = 10_000.0
STOPS_M = (0.0, 30_000.0, 60_000.0, 90_000.0)
CURVE = SectionCurve(
    FASTEST_S, EnergyCurve((FASTEST_S, 900.0, PLANNED_S, 1200.0), (60.0, 45.0, 36.0, 30.0))
)


def train(train_id: int, first_departure_s: float, up: bool = True) -> TimetabledTrain:
    stations = (1, 2, 3, 4) if up else (4, 3, 2, 1)
    stops = STOPS_M if up else STOPS_M[::-1]
    dep = [first_departure_s + j * (PLANNED_S + DWELL_S) for j in range(3)]
    return timetabled(train_id, stations, stops, dep, [d + PLANNED_S for d in dep], MIN_DWELL_S)


def retimer(*trains: TimetabledTrain, **settings: float) -> OnlineRetimer:
    asked: list[tuple[int, int, int]] = []

    def curves(train_id: int, a: int, b: int) -> SectionCurve:
        asked.append((train_id, a, b))
        return CURVE

    made = OnlineRetimer(
        {t.train_id: t for t in trains},
        curves,
        RetimerSettings(headway_s=HEADWAY_S, **settings),
    )
    made.asked = asked  # type: ignore[attr-defined]
    return made


def report(r: OnlineRetimer, train_id: int, now_s: float, section: int, late_s: float) -> None:
    """A report from ``train_id`` running ``section`` (0-based) ``late_s`` behind its plan
    (its planned time run so far, the rest late)."""
    t = r.trains[train_id]
    elapsed = now_s - t.departures_s[section]
    remaining = t.arrivals_s[section] + late_s - now_s
    r.report(
        train_id,
        PlannedCurve(t.stations[section], t.stations[section + 1], elapsed, remaining),
        now_s,
    )


def three_up() -> OnlineRetimer:
    return retimer(train(1, T0), train(2, T0 + 600.0), train(3, T0 + 1200.0))


def times_of(message: RunningTimes) -> dict[tuple[int, int], float]:
    return {(t.from_station_id, t.to_station_id): t.running_time_s for t in message.times}


def test_trains_on_plan_are_not_retimed() -> None:
    r = three_up()
    now = T0 + 1300.0
    for i, section in ((1, 1), (2, 0), (3, 0)):
        report(r, i, now, section, late_s=30.0)  # within off_plan_s = 120 s
    assert r.update(now) == []
    assert r.update(now + 400.0) == []
    assert r.log == []


def test_a_late_train_and_those_behind_it_are_retimed_and_the_one_ahead_is_not() -> None:
    r = three_up()
    start = T0 + 1100.0
    r.update(start)  # the ground comes up: it waits every_s for the reports
    now = start + 300.0
    report(r, 1, now, 1, late_s=0.0)  # ahead, on time
    report(r, 2, now, 0, late_s=600.0)  # ten minutes late
    report(r, 3, now, 0, late_s=0.0)  # behind, just departed, on time
    assert r.off_plan(now) == [2]
    sent = dict(r.update(now))
    assert set(sent) == {2, 3}
    (entry,) = r.log
    assert entry["trigger"] == 2
    assert entry["trains"] == [2, 3]
    assert entry["status"] == "optimal"
    # the late train recovers: each remaining section no slower than the timetable, no
    # faster than the fastest run, and faster in total
    late = times_of(sent[2])
    assert set(late) == {(2, 3), (3, 4)}
    assert all(FASTEST_S - 1e-6 <= v <= PLANNED_S + 1e-6 for v in late.values())
    assert sum(late.values()) < 2 * PLANNED_S - 60.0
    assert entry["lateness_s"] < entry["lateness_fixed_s"]
    # and is planned ahead of its old plan in force
    assert r.planned_arrivals(2)[2] < r.trains[2].arrivals_s[2] + 600.0
    # the one behind is held by the headway behind the late one, not sped past it
    behind = r.planned_arrivals(3)
    assert np.all(behind[1:] >= r.planned_arrivals(2)[1:] + HEADWAY_S - 1e-6)
    assert r.times_for(2) == sent[2]
    # nobody is sent a time slower than the timetable's, even where a dwell's margin
    # would let the LP save energy on it
    for message in sent.values():
        assert all(FASTEST_S - 1e-6 <= v <= PLANNED_S + 1e-6 for v in times_of(message).values())


def test_no_retiming_in_the_first_every_s_nor_more_often() -> None:
    r = three_up()
    now = T0 + 900.0
    report(r, 1, now, 0, late_s=600.0)
    assert r.update(now) == []  # just started
    assert r.update(now + 299.0) == []
    assert r.update(now + 300.0) != []
    report(r, 1, now + 400.0, 0, late_s=1200.0)  # later still: off the new plan
    assert r.update(now + 400.0) == []  # too soon after the last
    assert r.update(now + 600.0) != []
    assert len(r.log) == 2


def test_a_restarted_ground_re_times_once_every_train_on_the_line_has_reported() -> None:
    # the ground comes back at T0 + 1300: trains 1 and 2 are on the line, train 3 (due
    # away at T0 + 1200) too; 2 is ten minutes late
    r = three_up()
    start = T0 + 1300.0
    assert r.update(start) == []
    report(r, 2, start + 20.0, 0, late_s=600.0)
    report(r, 1, start + 30.0, 1, late_s=0.0)
    assert r.update(start + 30.0) == []  # train 3 not heard of yet
    report(r, 3, start + 50.0, 0, late_s=0.0)
    sent = dict(r.update(start + 50.0))  # all three heard: no need to wait every_s
    assert set(sent) == {2, 3}
    assert r.log[-1]["t_s"] == start + 50.0


def test_trains_not_yet_away_or_long_due_at_their_destination_are_not_waited_for() -> None:
    r = three_up()
    start = T0 + 700.0  # train 3 leaves at T0 + 1200: not waited for
    r.update(start)
    report(r, 1, start + 10.0, 0, late_s=0.0)
    report(r, 2, start + 20.0, 0, late_s=600.0)
    assert dict(r.update(start + 20.0)).keys() == {2, 3}
    # train 1 was due at its destination long ago and never said so (its link down)
    later = three_up()
    t1 = later.trains[1]
    late_start = t1.arrivals_s[-1] + later.settings.off_plan_s + 1.0
    later.update(late_start)
    report(later, 2, late_start + 10.0, 2, late_s=0.0)
    report(later, 3, late_start + 10.0, 1, late_s=100.0)
    assert later._heard_from_all(late_start + 10.0)
    # while one it does wait for keeps it waiting, up to every_s
    waiting = three_up()
    waiting.update(start)
    report(waiting, 2, start + 20.0, 0, late_s=600.0)
    assert waiting.update(start + 20.0) == []
    assert waiting.update(start + waiting.settings.every_s - 1.0) == []
    assert waiting.update(start + waiting.settings.every_s) != []


def test_a_train_on_its_last_section_does_not_trigger_but_bounds_the_one_behind() -> None:
    r = retimer(train(1, T0), train(2, T0 + 600.0))
    r.update(T0)
    now = T0 + 2 * (PLANNED_S + DWELL_S) + 100.0  # train 1 on its last section
    report(r, 1, now, 2, late_s=900.0)
    assert r.off_plan(now) == []
    report(r, 2, now, 1, late_s=300.0)  # 2 late on its middle section
    sent = dict(r.update(now))
    assert set(sent) == {2}
    assert r.log[-1]["trains"] == [2]
    # train 1 arrives at 4 at its report's time: train 2 not before that plus the headway
    arrival_1 = r.trains[1].arrivals_s[2] + 900.0
    assert r.planned_arrivals(2)[2] >= arrival_1 + HEADWAY_S - 1e-6


def test_the_other_direction_is_retimed_on_its_own() -> None:
    r = retimer(train(1, T0), train(2, T0 + 600.0), train(11, T0, up=False))
    r.update(T0)
    now = T0 + 500.0
    report(r, 11, now, 0, late_s=600.0)
    report(r, 1, now, 0, late_s=0.0)
    report(r, 2, now - 400.0 + 600.0, 0, late_s=0.0)
    sent = dict(r.update(now + 300.0))
    assert set(sent) == {11}


def test_a_train_not_heard_of_long_after_its_departure_is_left_out() -> None:
    r = three_up()
    r.update(T0)
    now = T0 + 1500.0
    report(r, 1, now, 1, late_s=0.0)
    report(r, 2, now, 0, late_s=600.0)
    # train 3 was due away at T0 + 1200, 300 s ago (= every_s): still counted as at its
    # origin; 1 s later it is not known
    sent = dict(r.update(now + 1.0))
    assert 3 not in sent and 3 not in r.log[-1]["trains"]


def test_a_train_at_its_destination_is_done() -> None:
    r = retimer(train(1, T0))
    t = r.trains[1]
    r.report(1, PlannedCurve(3, 4, PLANNED_S + 700.0, 0.0), t.arrivals_s[2] + 700.0)
    r.update(T0)
    assert r.off_plan(t.arrivals_s[2] + 2000.0) == []


def test_a_report_off_the_timetable_is_ignored() -> None:
    r = three_up()
    r.report(1, PlannedCurve(1, 3, 10.0, 10.0), T0 + 10.0)  # not a section of it
    r.report(99, PlannedCurve(1, 2, 10.0, 10.0), T0 + 10.0)  # not a train of it
    assert r.off_plan(T0 + 5000.0) == []


def test_the_dispatch_core_sends_a_registering_train_its_last_times() -> None:
    dispatch = GroundDispatch(load_line("heavy-haul"))
    r = three_up()
    dispatch.retimer = r
    r.update(T0)
    now = T0 + 900.0
    report(r, 1, now, 0, late_s=600.0)
    commands = dispatch.tick(now)
    sent = [c for c in commands if isinstance(c, SendRunningTimes)]
    assert {c.train_id for c in sent} == {1, 2, 3}
    request = RegisterRequest("K1", "HXD10001", 1, 1600.0)
    again = dispatch.on_event(1, TrainRegistered(1, request), now + 5.0)
    (resent,) = [c for c in again if isinstance(c, SendRunningTimes)]
    assert resent.times == r.times_for(1)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("headway_s", -1.0),
        ("energy_weight_s_per_kwh", math.nan),
        ("off_plan_s", 0.0),
        ("every_s", "5"),
    ],
)
def test_bad_settings_name_the_field(field: str, value: object) -> None:
    with pytest.raises(ConfigError) as error:
        RetimerSettings(**{field: value})  # type: ignore[arg-type]
    assert error.value.field == f"retiming.{field}"


def test_a_bad_timetable_names_the_train() -> None:
    with pytest.raises(ConfigError, match="timetable of train 7"):
        timetabled(7, (1, 2), (0.0, 1.0), (10.0,), (5.0,), 60.0)


def test_a_train_running_early_is_not_slowed_below_its_timetable() -> None:
    # early by 200 s: it waits for its departures (never early) and runs its timetable;
    # the dwell's 60 s margin would let an LP free to run slower save energy with it
    r = retimer(train(1, T0))
    r.update(T0)
    now = T0 + 500.0
    report(r, 1, now, 0, late_s=-200.0)
    (sent,) = dict(r.update(now)).values()
    assert times_of(sent) == pytest.approx({(2, 3): PLANNED_S, (3, 4): PLANNED_S}, abs=1e-6)


def arrived(r: OnlineRetimer, train_id: int, now_s: float, section: int) -> None:
    """``train_id``'s report at ``now_s``: it has run ``section`` (0-based) in its planned
    time and stands at its end."""
    t = r.trains[train_id]
    r.report(
        train_id,
        PlannedCurve(t.stations[section], t.stations[section + 1], PLANNED_S, 0.0),
        now_s,
    )


def test_a_train_standing_its_dwell_says_so_each_minute_and_stays_on_plan() -> None:
    # on time at station 2 (T0 + 1000), due out at T0 + 1120: the reports it repeats while
    # it stands do not move its arrival (that of the first), so it is not late, even with
    # a threshold shorter than its dwell
    r = retimer(train(1, T0), off_plan_s=60.0)
    r.update(T0)
    for now in (T0 + 1000.0, T0 + 1060.0, T0 + 1119.0):
        arrived(r, 1, now, 0)
        assert r.off_plan(now) == []
    assert r.update(T0 + 1119.0) == []


def test_a_train_held_at_a_station_past_its_departure_is_retimed_from_now() -> None:
    # on time in at station 2, due out at T0 + 1120, still there 200 s later (a failure):
    # its arrival was on plan, its departure is not
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    now = T0 + 1120.0 + 200.0
    assert r.off_plan(now - 100.0) == []  # within off_plan_s of its departure
    assert r.off_plan(now) == [1]
    sent = dict(r.update(now))
    times = times_of(sent[1])
    assert set(times) == {(2, 3), (3, 4)}
    # it leaves no earlier than now: the 200 s it is late are made up by the next dwell's
    # margin (60 s) and the two sections left (140 s), and it is due on time again
    assert sum(times.values()) <= 2 * PLANNED_S - (200.0 - (DWELL_S - MIN_DWELL_S)) + 1e-6
    assert r.planned_arrivals(1)[2] <= r.trains[1].arrivals_s[2] + 1e-6
    assert all(FASTEST_S - 1e-6 <= v <= PLANNED_S + 1e-6 for v in times.values())
    # on the new plan while it stands no longer than the re-timing expected ...
    assert r.off_plan(now + 100.0) == []
    # ... and off it again once it has stood off_plan_s longer
    assert r.off_plan(now + 121.0) == [1]


def test_a_train_seen_leaving_on_time_is_not_held_though_its_report_was_lost() -> None:
    # on time in at station 2, due out at T0 + 1120, leaves on time; the report of its new
    # section is lost, but its running info shows it moving: it is not held at the station
    # (the case before: test_a_train_held_at_a_station_past_its_departure_is_retimed_from_now)
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    r.running(1, 0.0, T0 + 1119.0)  # standing: nothing new
    r.running(1, 0.3, T0 + 1121.0)
    now = T0 + 1120.0 + 200.0
    assert r.off_plan(now) == []
    assert r.update(now) == []
    # it runs section 2-3 in the plan's time from T0 + 1121, due at T0 + 2121; off plan
    # once it has not arrived off_plan_s after the plan's arrival, T0 + 2120
    assert r.off_plan(T0 + 2120.0 + 120.0 - 1e-6) == []
    assert r.off_plan(T0 + 2120.0 + 120.0 + 1e-3) == [1]


def test_without_the_running_info_the_same_train_looks_held() -> None:
    # the control for the test above: the same reports, no running info
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    assert r.off_plan(T0 + 1120.0 + 200.0) == [1]


def test_a_train_seen_leaving_late_is_retimed_for_what_it_has_left() -> None:
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    left = T0 + 1120.0 + 150.0  # 150 s late out of station 2
    r.running(1, 0.0, left - 1.0)
    r.running(1, 0.3, left)
    assert r.off_plan(left) == [1]
    sent = dict(r.update(left))
    times = times_of(sent[1])
    # the section it runs is committed (planned from its departure); the one left, 3-4,
    # makes up what the next dwell's margin (60 s) does not
    assert set(times) == {(3, 4)}
    assert times[(3, 4)] == pytest.approx(PLANNED_S - (150.0 - (DWELL_S - MIN_DWELL_S)), abs=1e-6)
    assert r.planned_arrivals(1)[1] == pytest.approx(left + PLANNED_S)


def test_a_report_of_a_section_it_has_been_seen_to_leave_is_stale() -> None:
    # the minute's repeat of its arrival at station 2, delayed past the running info that
    # shows it moving on, does not put it back at the station
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    r.running(1, 0.0, T0 + 1001.0)
    r.running(1, 0.3, T0 + 1121.0)
    r.report(1, PlannedCurve(1, 2, PLANNED_S, 0.0), T0 + 1122.0)
    assert r.off_plan(T0 + 1120.0 + 200.0) == []
    # its own report of the new section is taken (30 s late on it)
    r.report(1, PlannedCurve(2, 3, 200.0, PLANNED_S - 200.0 + 30.0), T0 + 1321.0)
    assert r.off_plan(T0 + 1321.0) == []
    assert r.off_plan(T0 + 1121.0 + PLANNED_S + 30.0 + 121.0) == [1]


def test_a_train_moving_at_its_destination_or_before_its_first_report_is_not_moved_on() -> None:
    r = retimer(train(1, T0))
    r.running(1, 5.0, T0 + 10.0)  # not heard of yet: nothing to move on
    assert r.off_plan(T0 + 10.0) == []
    arrived(r, 1, T0 + 3 * PLANNED_S + 2 * DWELL_S, 2)  # at station 4, its destination
    r.running(1, 0.0, T0 + 3990.0)
    r.running(1, 0.3, T0 + 4000.0)
    assert r.off_plan(T0 + 5000.0) == []


def test_the_dispatch_core_tells_the_retimer_of_running_info() -> None:
    dispatch = GroundDispatch(load_line("heavy-haul"))
    r = retimer(train(1, T0))
    dispatch.retimer = r
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    for now, speed in ((T0 + 1119.0, 0.0), (T0 + 1121.0, 0.3)):
        info = RunningInfo(7, "K1", "HXD10001", TravelDirection.UP, speed, 30_001.0)
        dispatch.on_event(1, MessageReceived(info, 1, 0), now)
    assert r.off_plan(T0 + 1120.0 + 200.0) == []


def test_an_arrival_heard_late_is_dated_by_the_departure_and_the_time_run() -> None:
    # on time at station 2 (T0 + 1000); the report that says so is heard only at
    # T0 + 1130 (the onboard reports again a minute after its last, or that one was lost)
    r = retimer(train(1, T0))
    r.update(T0)
    report(r, 1, T0 + 900.0, 0, late_s=0.0)  # departed T0, due T0 + 1000
    arrived(r, 1, T0 + 1130.0, 0)  # run in PLANNED_S: arrived at T0 + 1000
    assert r.off_plan(T0 + 1130.0) == []
    # its departure is due at T0 + 1120: held once it is still there 120 s after
    assert r.off_plan(T0 + 1240.0 - 1e-6) == []
    assert r.off_plan(T0 + 1240.0 + 1e-3) == [1]


def test_an_arrival_heard_at_once_keeps_the_report_time() -> None:
    # the departure as the ground knows it is never earlier than the truth (heard 10 s
    # after it here): the report's own time, earlier, dates the arrival
    r = retimer(train(1, T0), off_plan_s=5.0)
    r.update(T0)
    r.report(1, PlannedCurve(1, 2, 890.0, 100.0), T0 + 900.0)  # departed T0 + 10 to it
    arrived(r, 1, T0 + 1000.0, 0)
    assert r.off_plan(T0 + 1000.0) == []


def test_a_train_still_rolling_to_its_stop_has_not_left() -> None:
    # the report of the arrival goes when the plan has no time left, the train still
    # rolling at a few cm/s (seen on the 9-hour day): moving then is not leaving; at rest
    # and then moving is
    r = retimer(train(1, T0))
    r.update(T0)
    arrived(r, 1, T0 + 1000.0, 0)
    r.running(1, 0.08, T0 + 1000.0)
    assert r.off_plan(T0 + 1120.0 + 200.0) == [1]  # held, as without running info
    r.running(1, 0.0, T0 + 1003.0)
    r.running(1, 0.3, T0 + 1121.0)
    assert r.off_plan(T0 + 1120.0 + 200.0) == []
