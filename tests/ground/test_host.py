"""The ground host alone (ground/host.py): its rules over a recording transport, no bytes.

A connection here is an endpoint that never met a train, so every delivery waits in a
record; the take-over and the live map are driven with the link's own events.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from railpilot.ground.assembly import GroundParts
from railpilot.ground.dispatch import CancelTsrOn, SendDispatchCommand, SendRunningTimes
from railpilot.ground.host import GroundHost
from railpilot.ground.operations import OperationError, parse_operation
from railpilot.ground.store import StoreError
from railpilot.line.loader import load_line
from railpilot.link import (
    DeregisterReason,
    DispatchCommand,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    RegisterRequest,
    RunningTimes,
    TrainDeregistered,
    TrainRegistered,
)

NOW_S = 1_800_000_000.0
CONFIG = GroundConfig(ground_id=1, not_before_s=NOW_S - 60.0)
REQUEST = RegisterRequest("K1", "HXD1-01", 7, 1300.0)


@dataclass
class Conn:
    endpoint: GroundEndpoint
    open: bool = True


@dataclass
class Wire:
    """A transport that records what the host asks of it."""

    flushed: list[Conn] = field(default_factory=list)
    closed: list[tuple[Conn, str]] = field(default_factory=list)

    def flush(self, conn: Conn, now_s: float) -> None:
        self.flushed.append(conn)

    def close(self, conn: Conn, reason: str) -> None:
        conn.open = False
        self.closed.append((conn, reason))


def _host(parts: GroundParts | None = None) -> tuple[GroundHost[Conn], Wire]:
    wire = Wire()
    host = (parts or GroundParts(CONFIG)).new_host(wire)
    return host, wire


def _conn(host: GroundHost[Conn]) -> Conn:
    return Conn(GroundEndpoint(host.config, KeyStore(), host.records))


def test_a_delivery_to_a_train_not_connected_waits_in_a_record_behind_the_replay_floor() -> None:
    host, wire = _host()
    command = SendDispatchCommand((11,), DispatchCommand(1, "hold"), "d1")
    assert host.carry_out([command], NOW_S) == {11: "queued until the train registers"}
    record = host.records[11]
    assert list(record.dispatch_commands) == [1]
    assert record.history.not_before_us == round(CONFIG.not_before_s * 1e6)
    assert wire.flushed == []


def test_a_refused_request_leaves_no_record_and_the_other_trains_still_get_it() -> None:
    host, _ = _host()
    host.carry_out([SendDispatchCommand((12,), DispatchCommand(1, "hold"), "d1")], NOW_S)
    # the same number again for train 12 is refused by its record; train 13 is new
    again = host.carry_out([SendDispatchCommand((12, 13), DispatchCommand(1, "go"), "d1")], NOW_S)
    assert again[12].startswith("error:") and again[13] == "queued until the train registers"
    # a cancel of a session never sent to a train it has never heard of: no train invented
    cancel = host.carry_out([CancelTsrOn(5, (14,), "d1")], NOW_S)
    assert cancel[14].startswith("error:")
    assert sorted(host.records) == [12, 13]


def test_running_times_go_only_to_a_live_registered_train_and_are_not_kept() -> None:
    host, _ = _host()
    times = RunningTimes(())
    assert host.carry_out([SendRunningTimes(15, times)], NOW_S) == {
        15: "not sent: the train is not registered"
    }
    assert host.records == {}


def test_a_train_registering_on_a_new_connection_takes_over_and_the_old_one_is_closed() -> None:
    host, wire = _host()
    old, new = _conn(host), _conn(host)
    host.on_event(old, TrainRegistered(21, REQUEST), NOW_S)
    assert host.live[21] is old
    host.on_event(new, TrainRegistered(21, REQUEST), NOW_S + 1.0)
    assert host.live[21] is new
    assert wire.closed == [(old, "train registered on a new connection")]
    # the old connection's close and deregistration no longer touch the train's live one
    host.closed(old, 21)
    host.on_event(old, TrainDeregistered(21, DeregisterReason.LEAVING_MAIN_LINE), NOW_S + 2.0)
    assert host.live[21] is new
    host.on_event(new, TrainDeregistered(21, DeregisterReason.LEAVING_MAIN_LINE), NOW_S + 3.0)
    assert 21 not in host.live


def test_an_operation_the_store_refuses_is_rolled_back() -> None:
    line = load_line("heavy-haul")

    class RefusingJournal:
        def record_operation(self, *args: object) -> None:
            raise StoreError("database or disk is full")

    wire = Wire()
    journal: Any = RefusingJournal()  # refuses every write, as a full disk does
    host = GroundParts(CONFIG, line).new_host(wire, journal=journal)
    fields = {"start_km": 300, "end_km": 302, "limit_kmh": 40, "valid_until_min": 60}
    op = parse_operation("tsr_set", {**fields, "reason": "works"}, line=line, now_s=NOW_S)
    with pytest.raises(OperationError, match="the store refused it"):
        host.operate(op, "d1", NOW_S)
    assert host.dispatch is not None and host.dispatch.tsrs.tsrs() == ()
