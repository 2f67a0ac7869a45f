"""Block occupancy from running info (ground/occupancy.py), by hand and by property."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.errors import ConfigError
from railpilot.ground.occupancy import (
    Occupancy,
    OccupancyConfig,
    TrainOccupancy,
    TrainReport,
    compute_occupancy,
    occupied_blocks,
)
from railpilot.line import DOWN, UP, Gradient, RailLine, Signal, SpeedLimit, load_line
from railpilot.link.messages import RunningInfo, TravelDirection
from railpilot.units import kmh_to_mps


def block_line() -> RailLine:
    """km 0-10, a signal each way at km 2, 4, 6 and 8 (sections derived from them).

    UP:   up-001 [0, 2] (entered from beyond the line, no signal), up-002 [2, 4] behind U2,
          up-003 [4, 6] U4, up-004 [6, 8] U6, up-005 [8, 10] U8.
    DOWN: down-001 [8, 10] (no signal), down-002 [6, 8] behind D8, down-003 [4, 6] D6,
          down-004 [2, 4] D4, down-005 [0, 2] D2.
    """
    signals = []
    for km in (2, 4, 6, 8):
        signals.append(Signal(f"U{km}", km * 1000.0, UP, "block"))
        signals.append(Signal(f"D{km}", km * 1000.0, DOWN, "block"))
    return RailLine(
        name="blocks",
        start_m=0.0,
        end_m=10_000.0,
        categories=("a",),
        gradients=(Gradient(0.0, 10_000.0, 0.0),),
        speed_limits=(SpeedLimit("a", 0.0, 10_000.0, kmh_to_mps(80.0)),),
        signals=tuple(signals),
    )


LINE = block_line()


@pytest.fixture(scope="module")
def heavy_haul() -> RailLine:
    return load_line("heavy-haul")


def ids(line: RailLine, head_m: float, direction: TravelDirection, length_m: float) -> list[str]:
    return [s.id for s in occupied_blocks(line, head_m, direction, length_m)]


def occupancy(*reports: TrainReport, now_s: float = 0.0, **config: Any) -> Occupancy:
    return compute_occupancy(LINE, reports, now_s, OccupancyConfig(**config))


# ---------------------------------------------------------------------------- by hand


def test_a_train_inside_one_block_occupies_only_it():
    # head km 3.5, tail km 2.5: both in up-002 [2, 4]
    assert ids(LINE, 3500.0, UP, 1000.0) == ["up-002"]


def test_a_train_straddling_a_boundary_occupies_both_going_up():
    # tail km 3.5 in up-002, head km 4.5 in up-003; rear-most first
    assert ids(LINE, 4500.0, UP, 1000.0) == ["up-002", "up-003"]


def test_a_train_straddling_a_boundary_occupies_both_going_down():
    # going down the tail is at head + length: km 6.5 in down-002 [6, 8], head km 5.5 in
    # down-003 [4, 6]
    assert ids(LINE, 5500.0, DOWN, 1000.0) == ["down-002", "down-003"]


def test_a_head_exactly_at_a_signal_is_in_the_block_it_protects_and_the_one_behind():
    assert ids(LINE, 4000.0, UP, 500.0) == ["up-002", "up-003"]
    assert ids(LINE, 4000.0, DOWN, 500.0) == ["down-003", "down-004"]
    # the head's block is the line's own answer
    assert occupied_blocks(LINE, 4000.0, UP, 500.0)[-1] == LINE.block_section_at(4000.0, UP)
    assert occupied_blocks(LINE, 4000.0, DOWN, 500.0)[-1] == LINE.block_section_at(4000.0, DOWN)


def test_a_tail_exactly_on_a_boundary_still_holds_the_block_it_is_leaving():
    # tail exactly at km 4: up-002 is released only once the tail is strictly past it
    assert ids(LINE, 4500.0, UP, 500.0) == ["up-002", "up-003"]
    assert ids(LINE, 4500.0, UP, 499.0) == ["up-003"]


def test_a_long_train_occupies_every_block_between_tail_and_head():
    # km 2.5 to 6.5
    assert ids(LINE, 6500.0, UP, 4000.0) == ["up-002", "up-003", "up-004"]


def test_a_tail_beyond_the_line_is_cut_at_the_line_end():
    occ = occupancy(TrainReport(1, 1000.0, UP, 2600.0, 0.0))
    train = occ.train(1)
    assert train.block_ids == ("up-001",)
    assert train.tail_m == 0.0


def test_a_fresh_report_gives_the_blocks_head_to_tail():
    occ = occupancy(TrainReport(1, 4500.0, UP, 1000.0, reported_s=96.0), now_s=100.0)
    train = occ.train(1)
    assert train.known
    assert train.block_ids == ("up-002", "up-003")
    assert train.head_block_id == "up-003"
    assert (train.head_m, train.tail_m) == (4500.0, 3500.0)


def test_a_report_exactly_validity_old_is_still_fresh():
    occ = occupancy(TrainReport(1, 4500.0, UP, 1000.0, 96.0), now_s=100.0, validity_s=4.0)
    assert occ.train(1).known


def test_a_stale_report_holds_the_last_blocks_and_the_next_one_ahead():
    occ = occupancy(TrainReport(1, 4500.0, UP, 1000.0, 95.0), now_s=100.0, validity_s=4.0)
    train = occ.train(1)
    assert not train.known
    assert train.block_ids == ("up-002", "up-003", "up-004")
    assert train.head_block_id == "up-003"
    assert not occ.is_free("up-004")


def test_a_stale_report_going_down_holds_the_next_block_down():
    occ = occupancy(TrainReport(1, 5500.0, DOWN, 1000.0, 0.0), now_s=100.0)
    assert occ.train(1).block_ids == ("down-002", "down-003", "down-004")


def test_stale_blocks_ahead_is_configurable():
    occ = occupancy(TrainReport(1, 4500.0, UP, 1000.0, 0.0), now_s=100.0, stale_blocks_ahead=2)
    assert occ.train(1).block_ids == ("up-002", "up-003", "up-004", "up-005")


def test_a_stale_train_at_the_end_of_the_line_holds_nothing_beyond_it():
    occ = occupancy(TrainReport(1, 9500.0, UP, 1000.0, 0.0), now_s=100.0)
    assert occ.train(1).block_ids == ("up-005",)


def test_by_block_lists_the_trains_in_each_occupied_block():
    occ = occupancy(
        TrainReport(7, 4500.0, UP, 1000.0, 0.0),
        TrainReport(3, 3900.0, UP, 300.0, 0.0),
    )
    assert dict(occ.by_block) == {"up-002": (3, 7), "up-003": (7,)}
    assert occ.occupants("up-002") == (3, 7)
    assert occ.occupants("up-004") == ()
    assert occ.is_free("up-004")
    assert occ.train_ids == (3, 7)  # sorted by id whatever the order of the reports


def test_trains_in_opposite_directions_never_share_a_block():
    # both heads at km 4.5: the up train (tail km 3.5) on the up track, the down train
    # (tail km 5.5) on the down track
    occ = occupancy(
        TrainReport(1, 4500.0, UP, 1000.0, 0.0),
        TrainReport(2, 4500.0, DOWN, 1000.0, 0.0),
    )
    assert occ.train(1).block_ids == ("up-002", "up-003")
    assert occ.train(2).block_ids == ("down-003",)
    assert all(len(trains) == 1 for trains in occ.by_block.values())


def test_heavy_haul_train_straddling_a_block_signal(heavy_haul):
    # up: U0049 at km 4.9, U0074 at km 7.45; a 2,600 m train with its head at km 9.0 has
    # its tail at km 6.4: in the block behind U0049 and the one behind U0074
    sections = occupied_blocks(heavy_haul, 9000.0, UP, 2600.0)
    assert [s.entry_signal for s in sections] == ["U0049", "U0074"]
    assert [s.id for s in sections] == ["up-004", "up-005"]


def test_heavy_haul_train_going_down(heavy_haul):
    # down: D0078 at km 7.85, D0053 at km 5.3, DH01 at km 2.75; head km 3.0, tail km 5.6
    sections = occupied_blocks(heavy_haul, 3000.0, DOWN, 2600.0)
    assert [s.entry_signal for s in sections] == ["D0078", "D0053"]
    assert [(s.start_m, s.end_m) for s in sections] == [(5300.0, 7850.0), (2750.0, 5300.0)]


def test_report_from_running_info():
    info = RunningInfo(17, "C80001", "HXD1", DOWN, 20.0, 123_456.0)
    report = TrainReport.from_running_info(4, info, 2600.0, 50.0)
    assert report == TrainReport(4, 123_456.0, DOWN, 2600.0, 50.0)


# ---------------------------------------------------------------------------- validation


def test_running_info_of_unknown_direction_cannot_be_placed():
    info = RunningInfo(17, "C80001", "HXD1", TravelDirection.UNKNOWN, 0.0, 1000.0)
    with pytest.raises(ConfigError, match=r"report\.direction = <TravelDirection.UNKNOWN"):
        TrainReport.from_running_info(4, info, 2600.0, 50.0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"train_id": -1}, "report.train_id"),
        ({"train_id": True}, "report.train_id"),
        ({"head_m": float("nan")}, "report.head_m"),
        ({"length_m": 0.0}, "report.length_m"),
        ({"length_m": 10_001.0}, "report.length_m"),
        ({"reported_s": float("inf")}, "report.reported_s"),
    ],
)
def test_a_report_names_the_bad_field(kwargs, field):
    args = {
        "train_id": 1,
        "head_m": 1000.0,
        "direction": UP,
        "length_m": 500.0,
        "reported_s": 0.0,
    } | kwargs
    with pytest.raises(ConfigError) as err:
        TrainReport(**args)
    assert err.value.field == field


def test_a_head_off_the_line_is_refused_naming_the_report():
    with pytest.raises(ConfigError) as err:
        occupancy(TrainReport(5, 10_500.0, UP, 500.0, 0.0))
    assert err.value.field == "reports[0] (train 5).head_m"
    assert "0-10000 m" in err.value.allowed


def test_two_reports_of_one_train_are_refused():
    with pytest.raises(ConfigError) as err:
        occupancy(TrainReport(5, 1000.0, UP, 500.0, 0.0), TrainReport(5, 2000.0, UP, 500.0, 0.0))
    assert err.value.field == "reports[1] (train 5).train_id"


def test_a_report_from_the_future_is_refused():
    with pytest.raises(ConfigError) as err:
        occupancy(TrainReport(5, 1000.0, UP, 500.0, 10.0), now_s=9.0)
    assert err.value.field == "reports[0] (train 5).reported_s"


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"validity_s": 0.0}, "occupancy.validity_s"),
        ({"stale_blocks_ahead": -1}, "occupancy.stale_blocks_ahead"),
        ({"stale_blocks_ahead": 1.0}, "occupancy.stale_blocks_ahead"),
    ],
)
def test_config_names_the_bad_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        OccupancyConfig(**kwargs)
    assert err.value.field == field


def test_an_occupancy_lists_each_train_once():
    train = TrainOccupancy(1, UP, 1000.0, 500.0, ("up-001",), "up-001", True, 0.0)
    with pytest.raises(ConfigError) as err:
        Occupancy("blocks", 0.0, (train, train))
    assert err.value.field == "occupancy.trains[1].train_id"


# ---------------------------------------------------------------------------- properties

directions = st.sampled_from([UP, DOWN])
positions = st.floats(0.0, 10_000.0, allow_nan=False)
lengths = st.floats(1.0, 5000.0, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(head=positions, direction=directions, length=lengths)
def test_occupied_blocks_are_a_run_from_the_tail_to_the_head(head, direction, length):
    sections = occupied_blocks(LINE, head, direction, length)
    order = LINE.block_sections_for(direction)
    first = order.index(sections[0])
    assert sections == order[first : first + len(sections)]  # contiguous, travel order
    assert sections[-1] == LINE.block_section_at(head, direction)
    sign = 1.0 if direction == UP else -1.0
    tail = min(max(head - sign * length, 0.0), 10_000.0)
    low, high = min(head, tail), max(head, tail)
    for section in sections:  # each meets the train
        assert section.start_m <= high and section.end_m >= low
    assert sections[0].start_m <= tail <= sections[0].end_m  # the tail's block is included


@settings(max_examples=200, deadline=None)
@given(head=positions, direction=directions, length=lengths, age=st.floats(0.0, 60.0))
def test_a_stale_report_never_occupies_less_than_a_fresh_one(head, direction, length, age):
    fresh = occupancy(TrainReport(1, head, direction, length, 0.0), now_s=0.0)
    later = occupancy(TrainReport(1, head, direction, length, 0.0), now_s=age)
    assert set(fresh.train(1).block_ids) <= set(later.train(1).block_ids)
    assert later.train(1).known == (age <= 4.0)


reports = st.lists(
    st.tuples(positions, directions, lengths, st.floats(0.0, 20.0)),
    min_size=1,
    max_size=8,
)


@settings(max_examples=200, deadline=None)
@given(rows=reports)
def test_a_computed_occupancy_passes_every_check_of_its_classes(rows):
    """compute_occupancy builds its results without running their checks again (the ground
    does it every second): each must still be what the checked constructors make of the
    same fields, look-ups included."""
    trains = [TrainReport(100 - i, h, d, n, 20.0 - age) for i, (h, d, n, age) in enumerate(rows)]
    computed = compute_occupancy(LINE, trains, 20.0)
    checked = Occupancy(
        computed.line_name,
        computed.now_s,
        tuple(
            TrainOccupancy(
                t.train_id,
                t.direction,
                t.head_m,
                t.tail_m,
                t.block_ids,
                t.head_block_id,
                t.known,
                t.reported_s,
            )
            for t in reversed(computed.trains)
        ),
    )
    assert computed == checked
    assert computed.trains == checked.trains  # sorted by id, as the checked one sorts
    assert [type(t.block_ids) for t in computed.trains] == [tuple] * len(rows)
    assert dict(computed.by_block) == dict(checked.by_block)
    assert list(computed.by_block) == list(checked.by_block)  # block ids in order
    for t in checked.trains:
        assert computed.train(t.train_id) == t
