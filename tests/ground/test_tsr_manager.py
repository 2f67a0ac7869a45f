"""Line TSRs on the ground: to whom each goes, cancels, late registrations, expiry."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from railpilot.errors import ConfigError
from railpilot.ground.tsr_manager import (
    Cancel,
    Deliver,
    LineTsr,
    LineTsrState,
    TrainRoute,
    TsrManager,
    Withdraw,
)
from railpilot.line.model import DOWN, UP

TOP = 25.0  # line top speed [m/s] (90 km/h)


def tsr(session: int = 7, start: float = 50_000.0, end: float = 52_000.0, until: float = 1e6):
    return LineTsr(session, start, end, 12.5, 0.0, until, reason="track works", set_by="d1")


def up(train: int, head: float, dest: float = 100_000.0, length: float = 1600.0):
    return TrainRoute(train, UP, head, length, dest)


def down(train: int, head: float, dest: float = 0.0, length: float = 1600.0):
    return TrainRoute(train, DOWN, head, length, dest)


def test_a_tsr_goes_to_the_trains_whose_route_reaches_it() -> None:
    manager = TsrManager(TOP)
    manager.update_route(up(1, 10_000.0), 0.0)  # approaching: concerned
    manager.update_route(up(2, 60_000.0), 0.0)  # past it (tail at 58.4 km): not
    manager.update_route(up(3, 51_000.0), 0.0)  # in it: concerned
    manager.update_route(down(4, 80_000.0), 0.0)  # down the line towards it: concerned
    manager.update_route(up(5, 10_000.0, dest=40_000.0), 0.0)  # ends before it: not
    actions = manager.set(tsr(), 100.0)
    assert actions == [Deliver(t, tsr()) for t in (1, 3, 4)]
    assert manager.delivered_to(7) == (1, 3, 4)


def test_a_train_whose_tail_is_still_in_the_zone_gets_it() -> None:
    # head 1 m past the zone's end, the 1,600 m train still in it
    manager = TsrManager(TOP)
    manager.update_route(up(1, 52_001.0), 0.0)
    assert manager.set(tsr(), 0.0) == [Deliver(1, tsr())]


def test_a_train_that_cannot_reach_it_before_it_expires_is_spared() -> None:
    # 40 km away at 25 m/s is 1,600 s: a TSR valid for 1,000 s more does not concern it,
    # one valid for 2,000 s does
    manager = TsrManager(TOP)
    manager.update_route(up(1, 10_000.0), 0.0)
    assert manager.set(tsr(7, until=1_000.0), 0.0) == []
    assert manager.set(tsr(8, until=2_000.0), 0.0) == [Deliver(1, tsr(8, until=2_000.0))]


def test_a_train_registering_later_gets_every_tsr_that_concerns_it() -> None:
    manager = TsrManager(TOP)
    manager.set(tsr(7), 0.0)
    manager.set(tsr(8, 20_000.0, 21_000.0), 0.0)
    manager.set(tsr(9, 5_000.0, 6_000.0), 0.0)  # behind the train: not
    actions = manager.update_route(up(1, 10_000.0), 50.0)
    assert [a.tsr.session for a in actions if isinstance(a, Deliver)] == [7, 8]
    # the train's next position report changes nothing already delivered
    assert manager.update_route(up(1, 12_000.0), 60.0) == []


def test_cancel_goes_where_the_tsr_went_and_only_once() -> None:
    manager = TsrManager(TOP)
    for train in (1, 2):
        manager.update_route(up(train, 10_000.0 * train), 0.0)
    manager.set(tsr(), 0.0)
    assert manager.cancel(7, 10.0) == [Cancel(1, 7), Cancel(2, 7)]
    assert manager.state(7) is LineTsrState.CANCELLED
    assert manager.cancel(7, 11.0) == []
    # a cancelled TSR is not delivered to a train that registers afterwards
    assert manager.update_route(up(3, 1_000.0), 12.0) == []


def test_rolling_back_forgets_what_was_set_cancelled_or_sent_since_the_checkpoint() -> None:
    manager = TsrManager(TOP)
    manager.update_route(up(1, 10_000.0), 0.0)
    manager.set(tsr(7), 0.0)
    checkpoint = manager.checkpoint()
    manager.set(tsr(8, start=60_000.0, end=61_000.0), 1.0)
    manager.deliver_also(7, [2])
    manager.cancel(7, 2.0)
    manager.roll_back(checkpoint)
    assert [t.session for t in manager.tsrs()] == [7]
    assert (manager.state(7), manager.delivered_to(7)) == (LineTsrState.ACTIVE, (1,))
    assert manager.next_session() == 8
    # and it goes on as if nothing had happened: train 2 still gets it when it asks
    assert manager.deliver_also(7, [2]) == [Deliver(2, tsr(7))]


def test_expiry_withdraws_it_everywhere_and_stops_late_deliveries() -> None:
    manager = TsrManager(TOP)
    manager.update_route(up(1, 45_000.0), 0.0)
    manager.set(tsr(until=500.0), 0.0)
    assert manager.tick(499.9) == []
    assert manager.tick(500.0) == [Withdraw(7, (1,))]
    assert manager.state(7) is LineTsrState.EXPIRED
    assert manager.tick(600.0) == []
    assert manager.update_route(up(2, 45_000.0), 600.0) == []
    assert manager.cancel(7, 600.0) == []


def test_setting_the_same_tsr_twice_is_idempotent_a_reused_session_is_an_error() -> None:
    manager = TsrManager(TOP)
    manager.update_route(up(1, 10_000.0), 0.0)
    assert len(manager.set(tsr(), 0.0)) == 1
    assert manager.set(tsr(), 1.0) == []
    with pytest.raises(ConfigError, match=r"tsr\.session"):
        manager.set(tsr(7, 60_000.0, 61_000.0), 2.0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"session": 0}, "tsr.session"),
        ({"start_m": 52_000.0}, "tsr.end_m"),
        ({"limit_mps": 0.0}, "tsr.limit_mps"),
        ({"valid_until_s": -1.0}, "tsr.valid_until_s"),
        ({"start_m": float("nan")}, "tsr.start_m"),
    ],
)
def test_bad_tsrs_name_the_field(kwargs, field) -> None:  # type: ignore[no-untyped-def]
    values = dict(
        session=7,
        start_m=50_000.0,
        end_m=52_000.0,
        limit_mps=12.5,
        valid_from_s=0.0,
        valid_until_s=100.0,
    )
    values.update(kwargs)
    with pytest.raises(ConfigError) as info:
        LineTsr(**values)  # type: ignore[arg-type]
    assert info.value.field == field


def test_unknown_sessions_and_expired_tsrs_are_refused_clearly() -> None:
    manager = TsrManager(TOP)
    with pytest.raises(ConfigError, match="session"):
        manager.cancel(3, 0.0)
    with pytest.raises(ConfigError, match=r"tsr\.valid_until_s"):
        manager.set(tsr(until=10.0), 20.0)


@given(
    head=st.floats(0.0, 100_000.0),
    dest=st.floats(0.0, 100_000.0),
    length=st.floats(0.0, 3_000.0),
    start=st.floats(0.0, 99_000.0),
    span=st.floats(10.0, 5_000.0),
)
def test_concerned_means_overlapping_the_rest_of_the_route(head, dest, length, start, span) -> None:  # type: ignore[no-untyped-def]
    # with a validity that never ends, "concerns" is exactly the overlap of the zone with
    # [tail, destination] (up) computed here independently
    manager = TsrManager(TOP)
    restriction = LineTsr(1, start, start + span, 10.0, 0.0, 1e12)
    route = TrainRoute(1, UP, head, length, dest)
    tail = head - length
    low, high = min(tail, dest), dest
    assert manager.concerns(restriction, route, 0.0) == (low < start + span and start < high)
