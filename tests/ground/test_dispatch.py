"""The ground dispatch core (ground/dispatch.py): link events and a dispatcher's operations
in, the commands to carry out back; no I/O, time passed in.

The synthetic block line (test_occupancy.block_line): km 0-10, signals each way at km 2,
4, 6, 8; UP blocks up-001 [0, 2], up-002 [2, 4] behind U2, up-003 [4, 6] behind U4 ...
"""

from __future__ import annotations

from pathlib import Path

import pytest

from railpilot.ground.dispatch import (
    CancelTsrOn,
    DeliverTsr,
    GroundDispatch,
    SendDispatchCommand,
    SendTargetPoint,
)
from railpilot.ground.journal import GroundJournal
from railpilot.ground.operations import OperationError, parse_operation
from railpilot.ground.store import Store
from railpilot.ground.tsr_manager import LineTsrState
from railpilot.line.model import DOWN, UP
from railpilot.link import (
    DeliveryState,
    MessageReceived,
    RunningInfo,
    TrainDeregistered,
    TrainRegistered,
    TsrState,
)
from railpilot.link.messages import (
    DeregisterReason,
    RegisterRequest,
    TargetPoint,
    TargetReason,
    TravelDirection,
)

from .test_occupancy import block_line

LINE = block_line()
T0 = 1_000_000.0
LENGTH_M = 500.0


def register(core: GroundDispatch, train_id: int, now_s: float = T0) -> list[object]:
    request = RegisterRequest(f"K{train_id}", "SS4-0001", 1, LENGTH_M)
    return list(core.on_event(train_id, TrainRegistered(train_id, request), now_s))


def report(
    core: GroundDispatch,
    train_id: int,
    km: float,
    now_s: float = T0,
    direction: TravelDirection = UP,
) -> list[object]:
    info = RunningInfo(1, f"K{train_id}", "SS4-0001", direction, 20.0, km * 1000.0)
    return list(core.on_event(train_id, MessageReceived(info, train_id, 0), now_s))


def do(core: GroundDispatch, op: str, now_s: float = T0, **fields: object):  # type: ignore[no-untyped-def]
    return core.execute(parse_operation(op, fields, line=LINE, now_s=now_s), "d1", now_s)


TSR = {"start_km": 6, "end_km": 7, "limit_kmh": 40, "valid_until_min": 60, "reason": "works"}


def test_a_tsr_goes_to_the_trains_whose_route_reaches_it_and_later_to_newcomers() -> None:
    core = GroundDispatch(LINE)
    for train, km, direction in ((1, 3.0, UP), (2, 8.5, UP), (3, 9.0, DOWN)):
        register(core, train)
        report(core, train, km, direction=direction)
    outcome = do(core, "tsr_set", **TSR)
    # 1 runs up towards km 6-7; 2 is past it (tail at 8.0); 3 runs down towards it
    assert outcome.result == {
        "session": 1,
        "trains": [1, 3],
        "valid_from_s": T0,  # from now (no valid_from_min)
        "valid_until_s": T0 + 60 * 60.0,  # valid_until_min = 60
    }
    (command,) = outcome.commands
    assert isinstance(command, DeliverTsr)
    assert command.train_ids == (1, 3)
    assert (command.tsr.start_m, command.tsr.end_m, command.tsr.set_by) == (6000.0, 7000.0, "d1")
    # a train that registers later gets it once it reports where it is
    assert register(core, 4, T0 + 10) == []
    (late,) = report(core, 4, 1.0, T0 + 10)
    assert isinstance(late, DeliverTsr) and late.train_ids == (4,)
    assert report(core, 4, 1.5, T0 + 11) == []  # once
    # named trains get it whatever the ground's view of them (no position yet)
    named = do(core, "tsr_set", **{**TSR, "start_km": 1, "end_km": 2}, trains=[9])
    assert 9 in named.result["trains"]


def test_cancel_goes_where_the_tsr_went_and_an_unknown_session_names_the_field() -> None:
    core = GroundDispatch(LINE)
    register(core, 1)
    report(core, 1, 3.0)
    do(core, "tsr_set", **TSR)
    (cancel,) = do(core, "tsr_cancel", session=1).commands
    assert cancel == CancelTsrOn(1, (1,), "d1")
    assert core.tsrs.state(1) is LineTsrState.CANCELLED
    with pytest.raises(OperationError) as caught:
        do(core, "tsr_cancel", session=5)
    assert set(caught.value.errors) == {"session"}
    with pytest.raises(OperationError) as reused:  # another restriction under session 1
        do(core, "tsr_set", **{**TSR, "limit_kmh": 20}, session=1)
    assert set(reused.value.errors) == {"session"}


def test_the_follower_gets_the_signal_behind_the_leaders_tail_and_a_clear_when_it_moves_on() -> (
    None
):
    core = GroundDispatch(LINE)
    for train in (1, 2):
        register(core, train)
    report(core, 1, 5.2)  # leader: head in up-003 [4, 6], tail 4.7: holds up-003 behind U4
    report(core, 2, 1.0)  # follower in up-001
    (target,) = core.tick(T0 + 1)
    assert isinstance(target, SendTargetPoint) and target.train_id == 2
    assert (target.target.position_m, target.target.reason) == (4000.0, TargetReason.TRAIN_AHEAD)
    assert core.tick(T0 + 2) == []  # only changes are sent
    report(core, 1, 9.5, T0 + 3)  # the leader runs on into up-005: U4 and U6 clear, U8 red
    (moved,) = core.tick(T0 + 3)
    assert isinstance(moved, SendTargetPoint)
    assert moved.target.position_m == 8000.0
    assert moved.target.target_id > target.target.target_id  # the newest id is in force
    core.on_event(1, TrainDeregistered(1, DeregisterReason.LEAVING_MAIN_LINE), T0 + 4)
    (clear,) = core.tick(T0 + 4)
    assert isinstance(clear, SendTargetPoint)
    assert (clear.target.position_m, clear.target.reason) == (LINE.end_m, TargetReason.OTHER)


def test_a_declared_fault_holds_its_signal_at_red_until_cleared() -> None:
    core = GroundDispatch(LINE)
    register(core, 1)
    report(core, 1, 1.0)
    assert core.tick(T0) == []
    outcome = do(core, "restriction_set", block="up-004", reason="section_fault")
    assert outcome.result == {"id": 1}
    (target,) = outcome.commands  # at once, not at the next tick
    assert isinstance(target, SendTargetPoint)
    assert (target.target.position_m, target.target.reason) == (6000.0, TargetReason.SECTION_FAULT)
    (clear,) = do(core, "restriction_clear", id=1).commands
    assert isinstance(clear, SendTargetPoint) and clear.target.reason is TargetReason.OTHER
    with pytest.raises(OperationError):
        do(core, "restriction_clear", id=1)


def test_dispatch_commands_take_the_next_number_and_all_means_every_registered_train() -> None:
    core = GroundDispatch(LINE)
    with pytest.raises(OperationError) as none:
        do(core, "dispatch", trains="all", text="hold")
    assert set(none.value.errors) == {"trains"}
    for train in (1, 2):
        register(core, train)
    (first,) = do(core, "dispatch", trains="all", text="hold").commands
    assert isinstance(first, SendDispatchCommand)
    assert (first.train_ids, first.command.command_number) == ((1, 2), 1)
    (second,) = do(core, "dispatch", trains=[2], text="go", command=10).commands
    (third,) = do(core, "dispatch", trains=[2], text="go on").commands
    assert isinstance(second, SendDispatchCommand) and isinstance(third, SendDispatchCommand)
    assert (second.command.command_number, third.command.command_number) == (10, 11)


def test_after_a_restart_tsrs_target_ids_and_command_numbers_come_back(tmp_path: Path) -> None:
    core = GroundDispatch(LINE)
    register(core, 1)
    report(core, 1, 3.0)
    (deliver,) = do(core, "tsr_set", **TSR).commands
    assert isinstance(deliver, DeliverTsr)
    with Store(tmp_path / "g.db") as store:
        store.record_tsr(deliver.tsr.message, actor="d1", reason="works", at_s=T0)
        store.record_tsr_state(1, 1, TsrState.ACTIVE, at_s=T0)
        held = TargetPoint(41, 4000.0, TargetReason.TRAIN_AHEAD)
        store.record_delivery(1, held, DeliveryState.ACKNOWLEDGED, at_s=T0)
        snapshot = store.load()
    again = GroundDispatch(LINE)
    again.restore(snapshot, T0 + 5, {})
    (tsr,) = again.tsrs.tsrs()
    assert (tsr.session, tsr.reason, tsr.set_by) == (1, "works", "d1")
    assert again.tsrs.state(1) is LineTsrState.ACTIVE
    assert again.tsrs.delivered_to(1) == (1,)
    assert again.tsrs.next_session() == 2
    # train 1 was held by target 41; when it reports with a free path it gets a clear,
    # under an id above every stored one
    register(again, 1, T0 + 6)
    report(again, 1, 3.0, T0 + 6)
    (clear,) = again.tick(T0 + 6)
    assert isinstance(clear, SendTargetPoint)
    assert clear.target.target_id == 42 and clear.target.reason is TargetReason.OTHER
    # an expired TSR comes back expired
    late = GroundDispatch(LINE)
    late.restore(snapshot, T0 + 7200, {})
    assert late.tsrs.state(1) is LineTsrState.EXPIRED


def test_status_shows_each_tsr_with_its_range_limit_expiry_and_trains() -> None:
    core = GroundDispatch(LINE)
    register(core, 1)
    report(core, 1, 3.0)
    do(core, "tsr_set", **TSR)
    do(core, "restriction_set", start_km=6.5, end_km=7.5, track="down", reason="section_fault")
    status = core.status(T0)
    (tsr,) = status["tsrs"]
    assert tsr == {
        "session": 1,
        "start_km": 6.0,
        "end_km": 7.0,
        "limit_kmh": 40.0,
        "valid_from_s": T0,
        "valid_until_s": T0 + 3600.0,
        "reason": "works",
        "set_by": "d1",
        "state": "active",
        "trains": [1],
    }
    (restriction,) = status["restrictions"]
    assert (restriction["track"], restriction["block"]) == ("down", None)


def test_a_tsr_no_train_has_yet_and_its_cancel_survive_a_restart() -> None:
    # The journal records the dispatcher's TSR when it is set, not only when it leaves for
    # a train: one set before any train is concerned would otherwise vanish on a restart.
    core = GroundDispatch(LINE)
    with Store(":memory:") as store:
        journal = GroundJournal(store)
        for fields in (TSR, {**TSR, "start_km": 8, "end_km": 9}):
            op = parse_operation("tsr_set", fields, line=LINE, now_s=T0)
            outcome = core.execute(op, "d1", T0)
            assert outcome.commands == ()  # no train to send it to
            journal.record_operation(op, outcome.result, "d1", T0)
        cancel = parse_operation("tsr_cancel", {"session": 2}, line=LINE, now_s=T0 + 1)
        journal.record_operation(cancel, core.execute(cancel, "d1", T0 + 1).result, "d1", T0 + 1)
        snapshot = store.load()
    again = GroundDispatch(LINE)
    again.restore(snapshot, T0 + 5, {})
    assert again.tsrs.state(1) is LineTsrState.ACTIVE
    assert again.tsrs.state(2) is LineTsrState.CANCELLED
    (tsr,) = [t for t in again.tsrs.tsrs() if t.session == 1]
    assert (tsr.start_m, tsr.end_m, tsr.reason, tsr.set_by) == (6000.0, 7000.0, "works", "d1")
    # a train that registers after the restart, short of the TSR, gets it
    register(again, 1, T0 + 6)
    (deliver,) = report(again, 1, 3.0, T0 + 6)
    assert isinstance(deliver, DeliverTsr) and deliver.train_ids == (1,)
    assert deliver.tsr.session == 1
