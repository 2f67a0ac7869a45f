"""Target points on the ground (ground/targets.py), by hand and by property.

The synthetic line (test_occupancy.block_line): km 0-10, signals each way at km 2, 4, 6, 8.
UP:   up-001 [0, 2], up-002 [2, 4] behind U2, up-003 [4, 6] U4, up-004 [6, 8] U6,
      up-005 [8, 10] U8.
DOWN: down-001 [8, 10], down-002 [6, 8] behind D8, down-003 [4, 6] D6, down-004 [2, 4] D4,
      down-005 [0, 2] D2.
"""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.errors import ConfigError
from railpilot.ground.occupancy import Occupancy, TrainReport, compute_occupancy
from railpilot.ground.targets import (
    DeclaredRestriction,
    Target,
    TargetPointCleared,
    TargetPointSet,
    TargetPointTracker,
    find_target,
    restricted_blocks,
)
from railpilot.line import DOWN, UP, RailLine, load_line
from railpilot.link.messages import TargetPoint, TargetReason, TravelDirection
from railpilot.onboard.mrsp import TargetStop

from .test_occupancy import block_line

LINE = block_line()
AHEAD = TargetReason.TRAIN_AHEAD
FAULT = TargetReason.SECTION_FAULT
SWITCH = TargetReason.SWITCH_INDICATION_LOST


@pytest.fixture(scope="module")
def heavy_haul() -> RailLine:
    return load_line("heavy-haul")


def train(
    train_id: int,
    head_m: float,
    direction: TravelDirection = UP,
    length_m: float = 500.0,
    reported_s: float = 0.0,
) -> TrainReport:
    return TrainReport(train_id, head_m, direction, length_m, reported_s)


def occ(*reports: TrainReport, now_s: float = 0.0, line: RailLine = LINE) -> Occupancy:
    return compute_occupancy(line, reports, now_s)


# ---------------------------------------------------------------------------- find_target


def test_the_follower_stops_at_the_signal_of_the_block_holding_the_leaders_tail():
    # leader km 6.5-7.5 (up-004); follower head km 2.5; up-003 free -> U6 at km 6
    occupancy = occ(train(1, 7500.0, length_m=1000.0), train(2, 2500.0))
    assert find_target(LINE, occupancy, 2) == Target(6000.0, AHEAD, "up-004", "U6")


def test_a_straddling_leader_holds_the_follower_at_its_rear_block():
    # leader km 5.5-6.5 over U6: its tail's block up-003 is the first red, behind U4
    occupancy = occ(train(1, 6500.0, length_m=1000.0), train(2, 2500.0))
    assert find_target(LINE, occupancy, 2) == Target(4000.0, AHEAD, "up-003", "U4")


def test_the_leader_has_no_target_from_the_train_behind_it():
    occupancy = occ(train(1, 7500.0, length_m=1000.0), train(2, 2500.0))
    assert find_target(LINE, occupancy, 1) is None


def test_trains_in_opposite_directions_do_not_hold_each_other():
    # the down train (head km 5, tail km 5.5) is right in front of the up train
    occupancy = occ(train(1, 3500.0, UP), train(2, 5000.0, DOWN))
    assert find_target(LINE, occupancy, 1) is None
    assert find_target(LINE, occupancy, 2) is None


def test_a_follower_going_down_stops_at_the_down_signal():
    # leader going down km 3.5-4.5 (down-003 [4, 6] and down-004 [2, 4]); follower at km 9.5:
    # down-002 free, down-003 holds the leader's tail -> D6 at km 6
    occupancy = occ(train(1, 3500.0, DOWN, 1000.0), train(2, 9500.0, DOWN))
    assert find_target(LINE, occupancy, 2) == Target(6000.0, AHEAD, "down-003", "D6")


def test_a_section_fault_ahead_gives_its_block_signal():
    restricted = restricted_blocks(LINE, [DeclaredRestriction.on_block("up-004", FAULT)])
    occupancy = occ(train(1, 2500.0))
    assert find_target(LINE, occupancy, 1, restricted) == Target(6000.0, FAULT, "up-004", "U6")


def test_a_lost_switch_on_a_span_of_both_tracks_holds_both_directions():
    # km 5.0-5.2 lies in up-003 [4, 6] and down-003 [4, 6]
    restricted = restricted_blocks(LINE, [DeclaredRestriction.on_span(5000.0, 5200.0, SWITCH)])
    assert restricted == {"up-003": SWITCH, "down-003": SWITCH}
    occupancy = occ(train(1, 2500.0, UP), train(2, 8500.0, DOWN))
    assert find_target(LINE, occupancy, 1, restricted) == Target(4000.0, SWITCH, "up-003", "U4")
    assert find_target(LINE, occupancy, 2, restricted) == Target(6000.0, SWITCH, "down-003", "D6")


def test_a_span_on_one_track_leaves_the_other_alone():
    restricted = restricted_blocks(
        LINE, [DeclaredRestriction.on_span(5000.0, 5200.0, SWITCH, direction=DOWN)]
    )
    assert restricted == {"down-003": SWITCH}


def test_a_span_touching_a_block_only_at_its_boundary_does_not_hold_it():
    restricted = restricted_blocks(
        LINE, [DeclaredRestriction.on_span(6000.0, 6500.0, FAULT, direction=UP)]
    )
    assert restricted == {"up-004": FAULT}


def test_a_declared_fault_outranks_a_train_ahead_in_the_same_block():
    restricted = restricted_blocks(
        LINE,
        [
            DeclaredRestriction.on_block("up-004", SWITCH),
            DeclaredRestriction.on_block("up-004", FAULT),
        ],
    )
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    assert find_target(LINE, occupancy, 2, restricted) == Target(6000.0, FAULT, "up-004", "U6")


def test_a_train_inside_a_block_with_a_train_ahead_gets_the_signal_behind_it():
    # both in up-003: the follower has passed U4 at red (or the ground lags a cycle)
    occupancy = occ(train(1, 5500.0, length_m=300.0), train(2, 4500.0, length_m=300.0))
    assert find_target(LINE, occupancy, 2) == Target(4000.0, AHEAD, "up-003", "U4")
    assert find_target(LINE, occupancy, 1) is None


def test_a_red_signal_at_or_beyond_the_horizon_is_not_a_target():
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    assert find_target(LINE, occupancy, 2, horizon_m=6000.0) is None
    assert find_target(LINE, occupancy, 2, horizon_m=6000.5) == Target(
        6000.0, AHEAD, "up-004", "U6"
    )


def test_a_stale_leader_keeps_holding_its_last_blocks():
    # the leader last reported at 0 s, the follower at 60 s: the leader may have moved on,
    # but the ground does not release its tail's block
    occupancy = occ(train(1, 7500.0, reported_s=0.0), train(2, 2500.0, reported_s=60.0), now_s=60.0)
    assert not occupancy.train(1).known
    assert find_target(LINE, occupancy, 2) == Target(6000.0, AHEAD, "up-004", "U6")


# ---------------------------------------------------------------------------- the tracker


def test_a_new_target_is_sent_once_with_a_fresh_id():
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    events = tracker.update(occupancy, now_s=0.0)
    assert events == (
        TargetPointSet(
            2, 0.0, Target(6000.0, AHEAD, "up-004", "U6"), TargetPoint(1, 6000.0, AHEAD), None
        ),
    )
    assert tracker.update(occupancy, now_s=1.0) == ()
    assert tracker.current(2) == Target(6000.0, AHEAD, "up-004", "U6")
    assert tracker.current_target_id(2) == 1
    assert tracker.next_target_id == 2


def test_when_the_leader_moves_on_the_target_moves_in_exactly_one_event():
    tracker = TargetPointTracker(LINE)
    tracker.update(occ(train(1, 7500.0), train(2, 2500.0)), now_s=0.0)
    # still in up-004: nothing changes for the follower
    assert tracker.update(occ(train(1, 7900.0), train(2, 2500.0)), now_s=1.0) == ()
    # the leader's tail is now in up-005 (behind U8)
    events = tracker.update(occ(train(1, 9500.0), train(2, 2500.0)), now_s=2.0)
    assert events == (
        TargetPointSet(
            2, 2.0, Target(8000.0, AHEAD, "up-005", "U8"), TargetPoint(2, 8000.0, AHEAD), 1
        ),
    )


def test_when_the_path_is_free_to_the_horizon_the_target_clears_in_exactly_one_event():
    tracker = TargetPointTracker(LINE)
    horizons = {2: 7000.0}  # the follower's next stop, km 7
    assert len(tracker.update(occ(train(1, 7500.0), train(2, 2500.0)), (), horizons, now_s=0.0))
    # the leader's tail passes U8 at km 8: nothing red before the stop
    moved = occ(train(1, 9500.0), train(2, 2500.0))
    events = tracker.update(moved, (), horizons, now_s=5.0)
    # the clear: a fresh id at the end of the line going up, reason OTHER
    assert events == (TargetPointCleared(2, 5.0, TargetPoint(2, 10_000.0, TargetReason.OTHER), 1),)
    assert tracker.current(2) is None
    assert tracker.current_target_id(2) == 2
    assert tracker.update(moved, (), horizons, now_s=6.0) == ()


def test_a_clear_going_down_points_at_the_line_start():
    tracker = TargetPointTracker(LINE)
    tracker.update(occ(train(1, 3500.0, DOWN), train(2, 9500.0, DOWN)), now_s=0.0)
    events = tracker.update(occ(train(2, 9500.0, DOWN)), now_s=1.0)
    assert events == (TargetPointCleared(2, 1.0, TargetPoint(2, 0.0, TargetReason.OTHER), 1),)


def test_a_train_clear_from_the_start_gets_no_event():
    tracker = TargetPointTracker(LINE)
    assert tracker.update(occ(train(1, 2500.0)), now_s=0.0) == ()
    assert tracker.current_target_id(1) is None


def test_a_fault_declared_and_lifted_gives_a_set_then_a_clear():
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 2500.0))
    fault = DeclaredRestriction.on_block("up-004", FAULT)
    (set_event,) = tracker.update(occupancy, {fault}, now_s=0.0)
    assert isinstance(set_event, TargetPointSet)
    assert set_event.message == TargetPoint(1, 6000.0, FAULT)
    assert tracker.update(occupancy, {fault}, now_s=1.0) == ()
    (clear_event,) = tracker.update(occupancy, set(), now_s=2.0)
    assert isinstance(clear_event, TargetPointCleared)
    assert clear_event.replaces == 1


def test_a_leader_leaving_a_faulted_block_changes_nothing_for_the_follower():
    tracker = TargetPointTracker(LINE)
    fault = {DeclaredRestriction.on_block("up-004", FAULT)}
    first = tracker.update(occ(train(1, 7500.0), train(2, 2500.0)), fault, now_s=0.0)
    assert [(e.train_id, e.message) for e in first] == [
        (1, TargetPoint(1, 6000.0, FAULT)),  # the leader is inside the faulted block
        (2, TargetPoint(2, 6000.0, FAULT)),
    ]
    later = tracker.update(occ(train(1, 9500.0), train(2, 2500.0)), fault, now_s=1.0)
    assert [e.train_id for e in later] == [1]  # only the leader, now out of it, is cleared
    assert isinstance(later[0], TargetPointCleared)


def test_a_train_inside_a_faulted_block_gets_the_signal_behind_it():
    restricted = restricted_blocks(LINE, [DeclaredRestriction.on_block("up-004", FAULT)])
    occupancy = occ(train(1, 7500.0))
    assert find_target(LINE, occupancy, 1, restricted) == Target(6000.0, FAULT, "up-004", "U6")


def test_a_reason_change_at_the_same_signal_is_resent():
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    tracker.update(occupancy, now_s=0.0)
    fault = {DeclaredRestriction.on_block("up-003", FAULT)}
    (event,) = tracker.update(occupancy, fault, now_s=1.0)
    assert isinstance(event, TargetPointSet)
    assert event.message == TargetPoint(2, 4000.0, FAULT)
    # and from TRAIN_AHEAD to a fault at the very same signal
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 7500.0, length_m=300.0), train(2, 2500.0))
    tracker.update(occupancy, now_s=0.0)
    fault = {DeclaredRestriction.on_span(6000.0, 7000.0, FAULT, direction=UP)}
    events = tracker.update(occupancy, fault, now_s=1.0)
    assert [(e.train_id, e.message) for e in events] == [
        (1, TargetPoint(2, 6000.0, FAULT)),
        (2, TargetPoint(3, 6000.0, FAULT)),
    ]


def test_events_come_in_train_id_order_with_consecutive_ids():
    tracker = TargetPointTracker(LINE, first_target_id=100)
    fault = {DeclaredRestriction.on_block("up-005", FAULT)}
    occupancy = occ(train(7, 1500.0), train(3, 5500.0), train(5, 3500.0))
    events = tracker.update(occupancy, fault, now_s=0.0)
    assert [(e.train_id, e.message.target_id) for e in events] == [(3, 100), (5, 101), (7, 102)]
    assert tracker.next_target_id == 103


def test_a_train_missing_from_an_update_keeps_its_state_and_gets_nothing():
    tracker = TargetPointTracker(LINE)
    tracker.update(occ(train(1, 7500.0), train(2, 2500.0)), now_s=0.0)
    assert tracker.update(occ(train(1, 7500.0)), now_s=1.0) == ()
    # back with the same target: nothing to send
    assert tracker.update(occ(train(1, 7500.0), train(2, 2500.0)), now_s=2.0) == ()


def test_a_forgotten_train_is_told_afresh():
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    tracker.update(occupancy, now_s=0.0)
    tracker.forget(2)
    (event,) = tracker.update(occupancy, now_s=1.0)
    assert isinstance(event, TargetPointSet)
    assert (event.message.target_id, event.replaces) == (2, None)


def test_the_onboard_stop_from_the_ground_target_lies_behind_the_leaders_tail():
    tracker = TargetPointTracker(LINE)
    occupancy = occ(train(1, 7500.0), train(2, 2500.0))
    (event,) = tracker.update(occupancy, now_s=0.0)
    stop = TargetStop.from_target_point(event.message, 300.0, UP)
    assert stop.position_m == 5700.0
    assert stop.position_m < occupancy.train(1).tail_m


# ---------------------------------------------------------------------------- heavy haul


def test_heavy_haul_follower_held_then_released_as_the_leader_runs_on(heavy_haul):
    tracker = TargetPointTracker(heavy_haul)

    def step(leader_head_m: float, now_s: float) -> tuple[object, ...]:
        occupancy = occ(
            train(1, leader_head_m, length_m=1600.0),
            train(2, 3000.0, length_m=2600.0),
            line=heavy_haul,
            now_s=now_s,
        )
        # the follower's next stop: Ningwu West, km 24.82, 30 m before exit signal UX02
        return tracker.update(occupancy, (), {2: 24_820.0}, now_s=now_s)

    # leader km 6.4-8.0: its tail is behind U0049 (km 4.9)
    (first,) = step(8000.0, 0.0)
    assert isinstance(first, TargetPointSet)
    assert first.target == Target(4900.0, AHEAD, "up-004", "U0049")
    # leader km 10.4-12.0: its tail passed U0100 (km 10.0)
    (moved,) = step(12_000.0, 60.0)
    assert isinstance(moved, TargetPointSet)
    assert moved.target == Target(10_000.0, AHEAD, "up-006", "U0100")
    # the leader stands at Ningwu West's stop, km 23.22-24.82: held at the home signal UH02
    (home,) = step(24_820.0, 600.0)
    assert isinstance(home, TargetPointSet)
    assert home.target == Target(22_750.0, AHEAD, "up-011", "UH02")
    # the leader's tail (km 25.4) is past the exit signal UX02 (km 24.85), which it holds at
    # red; but that is beyond the follower's stop: clear, at the end of the line going up
    (cleared,) = step(27_000.0, 900.0)
    assert cleared == TargetPointCleared(2, 900.0, TargetPoint(4, 590_000.0, TargetReason.OTHER), 3)
    assert step(27_100.0, 901.0) == ()


# ---------------------------------------------------------------------------- validation


def test_a_restriction_on_an_unknown_block_is_refused():
    with pytest.raises(ConfigError) as err:
        restricted_blocks(LINE, [DeclaredRestriction.on_block("up-999", FAULT)])
    assert err.value.field == "restriction.block_id"
    assert "line 'blocks'" in err.value.allowed


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: DeclaredRestriction.on_block("up-001", AHEAD), "restriction.reason"),
        (lambda: DeclaredRestriction.on_block("", FAULT), "restriction.block_id"),
        (lambda: DeclaredRestriction.on_span(5000.0, 5000.0, FAULT), "restriction.end_m"),
        (lambda: DeclaredRestriction.on_span(-1.0, 5000.0, FAULT), "restriction.start_m"),
        (
            lambda: DeclaredRestriction(FAULT, block_id="up-001", direction=UP),
            "restriction.start_m",
        ),
        (
            lambda: DeclaredRestriction.on_span(1.0, 2.0, FAULT, TravelDirection.UNKNOWN),
            "restriction.direction",
        ),
    ],
)
def test_a_restriction_names_the_bad_field(make, field):
    with pytest.raises(ConfigError) as err:
        make()
    assert err.value.field == field


def test_a_span_off_the_line_is_refused():
    with pytest.raises(ConfigError) as err:
        restricted_blocks(LINE, [DeclaredRestriction.on_span(9000.0, 11_000.0, FAULT)])
    assert err.value.field == "restriction.start_m"


def test_a_horizon_off_the_line_is_refused():
    tracker = TargetPointTracker(LINE)
    with pytest.raises(ConfigError) as err:
        tracker.update(occ(train(1, 2500.0)), (), {1: 12_000.0}, now_s=0.0)
    assert err.value.field == "horizons[1]"


def test_time_may_not_run_backwards():
    tracker = TargetPointTracker(LINE)
    tracker.update(occ(train(1, 2500.0)), now_s=10.0)
    with pytest.raises(ConfigError) as err:
        tracker.update(occ(train(1, 2500.0)), now_s=9.0)
    assert err.value.field == "now_s"


def test_an_occupancy_of_another_line_is_refused(heavy_haul):
    tracker = TargetPointTracker(LINE)
    with pytest.raises(ConfigError) as err:
        tracker.update(occ(train(1, 2500.0), line=heavy_haul), now_s=0.0)
    assert err.value.field == "occupancy.line_name"


def test_target_ids_are_bounded_by_the_wire():
    tracker = TargetPointTracker(LINE, first_target_id=0xFFFF_FFFF)
    fault = DeclaredRestriction.on_block("up-004", FAULT)
    tracker.update(occ(train(1, 2500.0)), {fault}, now_s=0.0)
    with pytest.raises(ConfigError) as err:
        tracker.update(occ(train(1, 2500.0)), set(), now_s=1.0)
    assert err.value.field == "target_id"


def test_a_failed_update_leaves_the_tracker_as_it_was():
    # two trains want an event but only one id is left: neither event is taken
    tracker = TargetPointTracker(LINE, first_target_id=0xFFFF_FFFF)
    fault = {DeclaredRestriction.on_block("up-004", FAULT)}
    occupancy = occ(train(1, 2500.0), train(2, 4500.0))
    with pytest.raises(ConfigError):
        tracker.update(occupancy, fault, now_s=0.0)
    assert tracker.current(1) is None
    assert tracker.next_target_id == 0xFFFF_FFFF
    (event, *_) = TargetPointTracker(LINE, first_target_id=0xFFFF_FFFF).update(
        occ(train(1, 2500.0)), fault, now_s=0.0
    )
    assert event.message.target_id == 0xFFFF_FFFF


# ---------------------------------------------------------------------------- properties

directions = st.sampled_from([UP, DOWN])


@settings(max_examples=300, deadline=None)
@given(
    direction=directions,
    leader_head=st.floats(3000.0, 587_000.0),
    leader_length=st.floats(100.0, 4000.0),
    gap=st.floats(1.0, 30_000.0),
    follower_length=st.floats(100.0, 4000.0),
)
def test_a_followers_target_is_never_beyond_the_leaders_tail(
    heavy_haul, direction, leader_head, leader_length, gap, follower_length
):
    sign = 1.0 if direction == UP else -1.0
    if direction == DOWN:
        leader_head = 590_000.0 - leader_head
    leader_tail = leader_head - sign * leader_length
    follower_head = leader_tail - sign * gap
    if not 0.0 <= follower_head <= 590_000.0 or not 0.0 <= leader_tail <= 590_000.0:
        return
    occupancy = occ(
        train(1, leader_head, direction, leader_length),
        train(2, follower_head, direction, follower_length),
        line=heavy_haul,
    )
    target = find_target(heavy_haul, occupancy, 2)
    assert target is not None  # the leader is on the line ahead: something is red
    assert sign * (leader_tail - target.position_m) >= 0.0
    # and it is the first red: every block between is free
    sections = heavy_haul.block_sections_for(direction)
    ids = [s.id for s in sections]
    start = ids.index(occupancy.train(2).head_block_id)
    end = ids.index(target.block_id)
    assert all(occupancy.is_free(i) for i in ids[start + 1 : end])


trains = st.lists(
    st.tuples(st.floats(0.0, 10_000.0), directions, st.floats(50.0, 3000.0)),
    min_size=1,
    max_size=6,
)
block_ids = st.sampled_from([s.id for s in LINE.block_sections])
restrictions = st.frozensets(
    st.builds(DeclaredRestriction.on_block, block_ids, st.sampled_from([FAULT, SWITCH])),
    max_size=3,
)


def _occupancy(spec: list[tuple[float, TravelDirection, float]]) -> Occupancy:
    return occ(*(train(i, head, d, length) for i, (head, d, length) in enumerate(spec)))


@settings(max_examples=300, deadline=None)
@given(spec=trains, held=restrictions)
def test_updating_twice_with_the_same_inputs_emits_nothing_the_second_time(spec, held):
    tracker = TargetPointTracker(LINE)
    occupancy = _occupancy(spec)
    first = tracker.update(occupancy, held, now_s=0.0)
    assert tracker.update(occupancy, held, now_s=1.0) == ()
    # the first update: only sets (nothing was sent before), ascending trains, ids 1, 2, ...
    assert all(isinstance(e, TargetPointSet) for e in first)
    assert [e.train_id for e in first] == sorted({e.train_id for e in first})
    assert [e.message.target_id for e in first] == list(range(1, len(first) + 1))


@settings(max_examples=200, deadline=None)
@given(ups=trains, downs=trains, held=restrictions)
def test_trains_going_down_never_change_a_target_going_up(ups, downs, held):
    up_spec = [(head, UP, length) for head, _, length in ups]
    down_spec = [(head, DOWN, length) for head, _, length in downs]
    alone = _occupancy(up_spec)
    mixed = _occupancy(up_spec + down_spec)
    restricted = restricted_blocks(LINE, held)
    for train_id in alone.train_ids:
        assert find_target(LINE, alone, train_id, restricted) == find_target(
            LINE, mixed, train_id, restricted
        )


@settings(max_examples=200, deadline=None)
@given(before=trains, after=trains, held=restrictions)
def test_the_tracker_holds_exactly_the_targets_it_sent(before, after, held):
    # whatever happens in between, after an update the tracker's view of each train is
    # find_target's answer, and one more update with the same inputs sends nothing
    tracker = TargetPointTracker(LINE)
    tracker.update(_occupancy(before), now_s=0.0)
    occupancy = _occupancy(after)
    events = tracker.update(occupancy, held, now_s=1.0)
    restricted = restricted_blocks(LINE, held)
    for train_id in occupancy.train_ids:
        assert tracker.current(train_id) == find_target(LINE, occupancy, train_id, restricted)
    assert len({e.train_id for e in events}) == len(events)  # at most one event per train
    assert tracker.update(occupancy, held, now_s=2.0) == ()
