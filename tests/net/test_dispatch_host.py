"""The dispatch core on a live ground (net/dispatch_host.py): real trains on loopback TCP.

Target points follow the occupancy the trains report, a declared fault holds its signal
at red, and after a restart the ground still knows the fault and what each train holds.
Waits wake on the server's events (no sleeps as waits, no timed assertions).
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from railpilot.ground.operations import OperationError
from railpilot.ground.store import Store, StoreError
from railpilot.ground.tsr_manager import LineTsrState
from railpilot.line.loader import load_line
from railpilot.line.model import UP
from railpilot.link import DeliveryState, GroundConfig, TargetReason
from railpilot.net import GroundServer, OnboardClient, Trajectory
from railpilot.net.dispatch_host import DispatchHost
from railpilot.web.ground_source import ServerSource

from .helpers import FAST, GROUND_ID, make_keys, onboard_config, run

LINE = load_line("heavy-haul")
LEADER, FOLLOWER = 5001, 5002
LENGTH_M = 800.0
#: Both stand on the up track: the leader's tail in block up-124 [301.386, 303.923] km
#: (behind signal U3014), the follower in up-121.
POSITIONS_M = {LEADER: 303_000.0, FOLLOWER: 295_000.0}


class Ground:
    """A ground server with its dispatch host over a store, woken on every event."""

    def __init__(self, db: Path) -> None:
        self.store = Store(db)
        self.server = GroundServer(
            GroundConfig(ground_id=GROUND_ID, timers=FAST),
            make_keys(LEADER, FOLLOWER),
            store=self.store,
        )
        self.host = DispatchHost(self.server, LINE, tick_s=0.1)
        self._event = asyncio.Event()
        self.server.add_listener(lambda *_: self._event.set())

    async def start(self) -> int:
        _, port = await self.server.start()
        self.host.start()
        return port

    async def stop(self) -> None:
        self.host.stop()
        await self.server.stop(timeout_s=2.0)
        self.store.close()

    async def until(self, condition: Callable[[], bool], timeout_s: float = 15.0) -> None:
        async with asyncio.timeout(timeout_s):
            while not condition():
                self._event.clear()
                await self._event.wait()

    def acknowledged(self, train_id: int, reason: TargetReason) -> int | None:
        """The newest target id of ``train_id`` if it has ``reason`` and was acknowledged."""
        record = self.server.records.get(train_id)
        if record is None or not record.target_points:
            return None
        newest = max(record.target_points)
        delivery = record.target_points[newest]
        ok = delivery.state is DeliveryState.ACKNOWLEDGED and delivery.message.reason is reason
        return newest if ok else None


def _trains(port: int, stop: asyncio.Event) -> tuple[dict[int, OnboardClient], list[asyncio.Task]]:
    clients, tasks = {}, []
    for train_id, start_m in POSITIONS_M.items():
        config = onboard_config(train_id, length_m=LENGTH_M, loco_number="HXD1-01", driver_id=7)
        trajectory = Trajectory(start_m=start_m, speed_mps=0.0, direction=UP)
        clients[train_id] = client = OnboardClient(
            config, make_keys(LEADER, FOLLOWER), "127.0.0.1", port, trajectory=trajectory
        )
        tasks.append(asyncio.create_task(client.run(stop)))
    return clients, tasks


def test_target_points_follow_occupancy_and_faults_and_survive_a_restart(tmp_path: Path) -> None:
    async def scenario() -> None:
        db = tmp_path / "ground.db"
        ground = Ground(db)
        port = await ground.start()
        stop = asyncio.Event()
        clients, tasks = _trains(port, stop)
        try:
            # the follower is held at the signal behind the leader's tail, and says so
            await ground.until(lambda: ground.acknowledged(FOLLOWER, TargetReason.TRAIN_AHEAD))
            held = clients[FOLLOWER].endpoint.target_point
            assert held is not None and held.reason is TargetReason.TRAIN_AHEAD
            tail_m = POSITIONS_M[LEADER] - LENGTH_M
            (block,) = [b for b in LINE.block_sections_for(UP) if b.start_m <= tail_m < b.end_m]
            assert held.position_m == block.start_m  # U3014, the entry of the tail's block
            assert POSITIONS_M[FOLLOWER] < held.position_m < tail_m
            assert clients[LEADER].endpoint.target_point is None  # nothing ahead of it

            # a fault declared two blocks ahead holds the leader at that block's signal
            answer = await ground.host.execute(
                "restriction_set", {"block": "up-126", "reason": "section_fault"}, "dispatcher"
            )
            assert answer["id"] == 1 and answer["deliveries"] == {str(LEADER): "sending"}
            await ground.until(lambda: ground.acknowledged(LEADER, TargetReason.SECTION_FAULT))
            fault = clients[LEADER].endpoint.target_point
            assert fault is not None and fault.position_m == 306_459.0  # up-126's entry

            # a TSR on the follower's way ahead; the leader is past it and does not get it
            tsr = {"start_km": 299, "end_km": 300, "limit_kmh": 30, "valid_until_min": 60}
            set_ = await ground.host.execute("tsr_set", {**tsr, "reason": "works"}, "d1")
            assert set_["session"] == 1 and set_["trains"] == [FOLLOWER]
        finally:
            await ground.stop()

        # a restarted ground knows the fault and that the leader is held by it
        again = Ground(db)
        port2 = await again.start()
        assert list(again.host.dispatch.restrictions) == [1]
        # the page lists the TSR set before the restart, and can cancel it
        source = ServerSource(again.host)
        (listed,) = source.snapshot(source.now_s())["tsrs"]
        assert (listed["session"], listed["state"], listed["set_by"]) == (1, "ACTIVE", "d1")
        assert "ok" in source.cancel_tsr(1, "d2", source.now_s())
        assert source.snapshot(source.now_s())["tsrs"][0]["state"] == "CANCELLED"
        for client in clients.values():
            client.port = port2  # the trains reconnect to the new ground
        try:
            # it tells the leader again what holds it, under a fresh id
            await again.until(
                lambda: (
                    (again.acknowledged(LEADER, TargetReason.SECTION_FAULT) or 0) > fault.target_id
                )
            )
            cleared = await again.host.execute("restriction_clear", {"id": 1}, "dispatcher")
            assert cleared["deliveries"] == {str(LEADER): "sending"}
            await again.until(lambda: ground_clear(again, LEADER, fault.target_id))
            newest = clients[LEADER].endpoint.target_point
            assert newest is not None and newest.reason is TargetReason.OTHER
            assert newest.position_m == LINE.end_m  # a clear restricts nothing
            assert newest.target_id > fault.target_id  # ids resume above the stored ones
        finally:
            stop.set()
            await asyncio.gather(*tasks, return_exceptions=True)
            await again.stop()

    run(scenario())


def ground_clear(ground: Ground, train_id: int, after_id: int) -> bool:
    newest = ground.acknowledged(train_id, TargetReason.OTHER)
    return newest is not None and newest > after_id


def test_the_tick_computes_occupancy_off_the_loop_and_survives_a_failure(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """At a thousand trains the occupancy costs tens of ms: it runs in the host's worker
    thread, on a copy of the reports, and a failure there is logged without stopping the
    ground's clock."""

    async def scenario() -> None:
        server = GroundServer(GroundConfig(ground_id=GROUND_ID, timers=FAST), make_keys(LEADER))
        host = DispatchHost(server, LINE, tick_s=0.01)
        loop = asyncio.get_running_loop()
        computed_in: list[str] = []
        ticked = asyncio.Event()
        original = host.dispatch.occupancy_from

        def occupancy_from(reports, now_s):  # type: ignore[no-untyped-def]
            computed_in.append(threading.current_thread().name)
            loop.call_soon_threadsafe(ticked.set)
            if len(computed_in) == 1:
                raise RuntimeError("a bug in the occupancy")
            return original(reports, now_s)

        host.dispatch.occupancy_from = occupancy_from  # type: ignore[method-assign]
        await server.start()
        host.start()
        try:
            async with asyncio.timeout(15.0):
                while host.dispatch.occupancy is None or len(computed_in) < 3:
                    ticked.clear()
                    await ticked.wait()
        finally:
            host.stop()
            await server.stop(timeout_s=2.0)
        assert threading.current_thread().name not in computed_in
        assert all(name.startswith("occupancy") for name in computed_in)
        assert "dispatch tick failed" in caplog.text

    run(scenario())


def test_an_operation_the_store_refuses_is_not_in_force(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Persistence before effect: a TSR set, or cancelled, that the store did not keep must
    # not stay set, or cancelled, in the dispatch core either (the ground would otherwise
    # hold a TSR a restart forgets, and number the next one past it).
    ground = Ground(tmp_path / "ground.db")
    journal = ground.server.journal
    assert journal is not None
    keep = journal.record_operation

    def refuse(*_: object) -> None:
        raise StoreError("disk full")

    tsr = {
        "start_km": 300,
        "end_km": 302,
        "limit_kmh": 45,
        "valid_until_min": 60,
        "reason": "works",
    }
    monkeypatch.setattr(journal, "record_operation", refuse)
    with pytest.raises(OperationError, match="the store refused it: disk full"):
        ground.host.execute_now("tsr_set", tsr, "d1")
    assert ground.host.dispatch.tsrs.tsrs() == ()

    monkeypatch.setattr(journal, "record_operation", keep)
    assert ground.host.execute_now("tsr_set", tsr, "d1")["session"] == 1

    monkeypatch.setattr(journal, "record_operation", refuse)
    with pytest.raises(OperationError, match="the store refused it"):
        ground.host.execute_now("tsr_cancel", {"session": 1}, "d1")
    assert ground.host.dispatch.tsrs.state(1) is LineTsrState.ACTIVE

    monkeypatch.setattr(journal, "record_operation", keep)
    ground.host.execute_now("tsr_cancel", {"session": 1}, "d1")
    assert ground.host.dispatch.tsrs.state(1) is LineTsrState.CANCELLED
    stored = ground.store.load().tsrs
    assert list(stored) == [1] and stored[1].cancelled_at_s is not None
    ground.store.close()
