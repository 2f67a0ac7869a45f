"""ServerSource over a live GroundServer and onboard clients on loopback TCP (no browser).

Everything runs in one event loop, bounded by ``asyncio.timeout``; waits poll a condition
(no sleeps as waits, no timed assertions). Each runs in a thread of its own (``_run``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Callable, Coroutine
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import pytest

from net.helpers import FAST, GROUND_ID, onboard_config
from railpilot.errors import ConfigError
from railpilot.ground.online_retimer import OnlineRetimer, RetimerSettings, SectionCurve, timetabled
from railpilot.line.loader import load_line
from railpilot.line.model import UP
from railpilot.link import GroundConfig, KeyStore, PlannedCurve, TravelDirection, TsrState
from railpilot.net import GroundServer, OnboardClient, Trajectory
from railpilot.net.dispatch_host import DispatchHost
from railpilot.web.ground_source import ServerSource
from railpilot.web.source import DashboardSource

from .test_live_dashboard import CONCERNED, LENGTH_M, TRAINS


def _run(coro: Coroutine[Any, Any, None]) -> None:
    """``asyncio.run`` in a thread of its own: after a browser test, Playwright's sync API
    leaves an event loop marked running in the main thread for the rest of the session."""
    with ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, coro).result(timeout=60.0)


class _Changes:
    """Wakes a waiter on every event the ground server hands out (registrations, running
    info, acknowledgements): what the conditions below read changes only then."""

    def __init__(self, server: GroundServer) -> None:
        self._event = asyncio.Event()
        server.add_listener(lambda *_: self._event.set())

    async def until(self, condition: Callable[[], bool], timeout_s: float = 10.0) -> None:
        async with asyncio.timeout(timeout_s):
            while True:
                self._event.clear()
                if condition():
                    return
                await self._event.wait()


async def _scenario() -> None:
    keys = KeyStore()
    for i, (train_id, *_) in enumerate(TRAINS):
        keys.add_key(train_id, 1, bytes((b + i) % 256 for b in range(32)))
    server = GroundServer(GroundConfig(ground_id=GROUND_ID, timers=FAST), keys)
    changes = _Changes(server)
    host = DispatchHost(server, load_line("heavy-haul"))
    source = ServerSource(host)
    assert isinstance(source, DashboardSource)
    _, port = await server.start()
    host.start()
    stop = asyncio.Event()
    tasks = []
    try:
        for train_id, km, travel, speed in TRAINS:
            config = onboard_config(train_id, length_m=LENGTH_M, loco_number="HXD1-01", driver_id=7)
            trajectory = Trajectory(start_m=km * 1000.0, speed_mps=speed, direction=travel)
            client = OnboardClient(config, keys, "127.0.0.1", port, trajectory=trajectory)
            tasks.append(asyncio.create_task(client.run(stop)))

        def trains() -> list[dict]:
            return list(source.snapshot(source.now_s())["trains"])

        await changes.until(lambda: len(trains()) == 3 and all(t["valid"] for t in trains()))
        version = source.version()
        await changes.until(lambda: source.version() > version)  # every report bumps it
        snap = source.snapshot(source.now_s())
        json.dumps(snap, allow_nan=False)  # strict JSON
        by_id = {t["id"]: t for t in snap["trains"]}
        assert by_id[2002]["direction"] == "down" and by_id[2001]["direction"] == "up"
        assert by_id[2001]["length_km"] == LENGTH_M / 1000.0
        assert all(t["link"]["connected"] and not t["alarms"] for t in snap["trains"])
        assert snap["blocks"]  # each train occupies a block
        assert all(g["actual"] for g in snap["graph"]["trains"])
        assert all(g["plan"] == [] for g in snap["graph"]["trains"])  # no timetable here

        # a bad form: every field named, nothing sent
        answer = source.set_tsr({"start_km": "x", "limit_kmh": "fast"}, "d", source.now_s())
        assert set(answer["errors"]) >= {"start_km", "end_km", "limit_kmh", "reason"}
        assert all(not r.tsrs for r in server.records.values())

        form = {
            "start_km": 300,
            "end_km": 330,
            "limit_kmh": 40,
            "valid_until_min": 60,
            "reason": "sun kink check",
        }
        answer = source.set_tsr(form, "dispatcher", source.now_s())
        assert answer["ok"]["session"] == 1 and answer["ok"]["set_by"] == "dispatcher"
        assert source.concerned(1) == CONCERNED
        await changes.until(
            lambda: all(source.delivery_state(1, t) is TsrState.ACTIVE for t in CONCERNED)
        )
        assert source.delivery_state(1, 2003) is None  # past the TSR: not concerned
        tsr = source.snapshot(source.now_s())["tsrs"][0]
        assert [(d["train"], d["state"]) for d in tsr["deliveries"]] == [
            (2001, "ACTIVE"),
            (2002, "ACTIVE"),
        ]
        assert tsr["state"] == "ACTIVE"

        assert "session" in source.cancel_tsr(9, "dispatcher", source.now_s())["errors"]
        assert "ok" in source.cancel_tsr(1, "dispatcher", source.now_s())
        await changes.until(
            lambda: all(source.delivery_state(1, t) is TsrState.CANCELLED for t in CONCERNED)
        )
        assert source.snapshot(source.now_s())["tsrs"][0]["state"] == "CANCELLED"

        # a restriction declared and cleared from the page's form, on the core
        bad = source.set_restriction({"reason": "section_fault"}, "d", source.now_s())
        assert "block" in bad["errors"] and not host.dispatch.restrictions
        form = {"reason": "section_fault", "start_km": 300, "end_km": 301, "track": "down"}
        declared = source.set_restriction(form, "d", source.now_s())["ok"]
        assert declared["track"] == "down" and declared["blocks"]
        snap = source.snapshot(source.now_s())
        assert snap["restrictions"] == [declared]
        held = {b["id"] for b in snap["blocks"] if b["state"] == "restricted"}
        assert held == set(declared["blocks"])
        assert source.clear_restriction(declared["id"], "d", source.now_s()) == {
            "ok": {"id": declared["id"]}
        }
        assert not source.snapshot(source.now_s())["restrictions"]
        assert "id" in source.clear_restriction(declared["id"], "d", source.now_s())["errors"]

        # a dispatch command from the page's form, through the same schema as the admin port
        bad = source.send_dispatch({"trains": "K2001", "text": "hold"}, "d", source.now_s())
        assert "trains" in bad["errors"] and not source.snapshot(source.now_s())["dispatch"]
        sent = source.send_dispatch({"trains": "2001", "text": "hold"}, "d", source.now_s())
        assert sent["ok"]["trains"] == [2001]

        def command_rows() -> list[tuple[int, int, str, str]]:
            rows = source.snapshot(source.now_s())["dispatch"]
            return [(r["command"], r["train"], r["text"], r["state"]) for r in rows]

        await changes.until(
            lambda: command_rows() == [(sent["ok"]["command"], 2001, "hold", "ACKNOWLEDGED")]
        )
    finally:
        stop.set()
        async with asyncio.timeout(10.0):
            await asyncio.gather(*tasks, return_exceptions=True)
            await server.stop(timeout_s=2.0)


def test_server_source_sets_and_cancels_a_tsr_on_real_trains() -> None:
    _run(_scenario())


@dataclass
class _OneTrain:
    """A live ground (its dispatch host and dashboard source) and one onboard client."""

    host: DispatchHost
    source: ServerSource
    changes: _Changes
    client: OnboardClient | None = None


@contextlib.asynccontextmanager
async def _ground_then_one_train(
    train_id: int, start_m: float, before_the_train: Callable[[_OneTrain], None]
) -> AsyncIterator[_OneTrain]:
    """A ground on loopback; ``before_the_train`` runs once it is up, then one train
    (UP from ``start_m`` [m]) connects. Everything is stopped on the way out."""
    keys = KeyStore()
    keys.add_key(train_id, 1, bytes(range(32)))
    server = GroundServer(GroundConfig(ground_id=GROUND_ID, timers=FAST), keys)
    host = DispatchHost(server, load_line("heavy-haul"))
    ground = _OneTrain(host, ServerSource(host), _Changes(server))
    _, port = await server.start()
    host.start()
    stop = asyncio.Event()
    task = None
    try:
        before_the_train(ground)
        config = onboard_config(train_id, length_m=LENGTH_M, loco_number="HXD1-02", driver_id=7)
        trajectory = Trajectory(start_m=start_m, direction=TravelDirection.UP)
        ground.client = OnboardClient(config, keys, "127.0.0.1", port, trajectory=trajectory)
        task = asyncio.create_task(ground.client.run(stop))
        yield ground
    finally:
        stop.set()
        async with asyncio.timeout(10.0):
            if task is not None:
                await task
            await server.stop(timeout_s=2.0)


def test_a_train_reaching_a_tsr_later_gets_it() -> None:
    def tsr_before_any_train(ground: _OneTrain) -> None:
        form = {"start_km": 100, "end_km": 101, "limit_kmh": 40, "valid_until_min": 30}
        now = ground.source.now_s()
        answer = ground.source.set_tsr({**form, "reason": "before any train"}, "d", now)
        assert answer["ok"]["deliveries"] == []

    async def scenario() -> None:
        async with _ground_then_one_train(3001, 90_000.0, tsr_before_any_train) as ground:
            source = ground.source
            await ground.changes.until(lambda: source.delivery_state(1, 3001) is TsrState.ACTIVE)

    _run(scenario())


def _never_retimed(*_: object) -> SectionCurve:
    raise AssertionError("nothing is re-timed here: no train reports a planned curve")


def test_the_graph_shows_the_plan_in_force_of_a_train_the_ground_holds_a_timetable_for() -> None:
    line = load_line("heavy-haul")
    # stations 10 -> 11 -> 12: left 10 min ago, due at 11 in 30 min (beyond the graph's
    # 20 min ahead), and (a minute's stand) at 12 half an hour after that
    stops = [line.station(s).stop_m(UP) for s in (10, 11, 12)]
    departures: list[float] = []
    arrivals: list[float] = []

    def timetable(ground: _OneTrain) -> None:
        now = ground.source.now_s()
        departures[:] = [now - 600.0, now + 1860.0]
        arrivals[:] = [now + 1800.0, now + 3660.0]
        train = timetabled(2001, (10, 11, 12), stops, departures, arrivals, 60.0)
        # never off plan (a late report below must not re-time: there are no curves here)
        settings = RetimerSettings(off_plan_s=86_400.0)
        ground.host.dispatch.retimer = OnlineRetimer({2001: train}, _never_retimed, settings)

    async def scenario() -> None:
        async with _ground_then_one_train(2001, stops[0] + 5_000.0, timetable) as ground:
            source, host, changes = ground.source, ground.host, ground.changes
            client = ground.client
            assert client is not None

            def graph() -> list[dict]:
                return list(source.snapshot(source.now_s())["graph"]["trains"])

            await changes.until(lambda: len(graph()) == 1 and bool(graph()[0]["actual"]))
            snap = source.snapshot(source.now_s())
            window_end = snap["graph"]["to_s"]
            plan = snap["graph"]["trains"][0]["plan"]
            share = (window_end - departures[0]) / (arrivals[0] - departures[0])  # on 10 -> 11
            assert window_end < arrivals[0] and stops[1] - stops[0] == 30_000.0
            assert plan == [
                [round(departures[0], 1), stops[0] / 1000.0],
                [
                    round(window_end, 1),
                    pytest.approx((stops[0] + share * 30_000.0) / 1e3, abs=5e-4),
                ],
            ]
            assert snap["trains"][0]["deviation_s"] is None  # no planned curve yet

            # the train reports it needs 2 min more than the plan in force gives it to 11
            remaining = arrivals[0] + 120.0 - source.now_s()
            assert client.send(PlannedCurve(10, 11, 600.0, remaining))
            registry = host.dispatch.registry
            await changes.until(
                lambda: registry.state(2001, source.now_s()).expected_arrival_s is not None
            )
            state = registry.state(2001, source.now_s())
            expected = state.expected_arrival_s
            # the registry holds no timetable of its own: its deviation is against the
            # retimer's plan in force, the one the page shows
            assert registry.timetable(2001) is None
            assert state.deviation_s == expected - arrivals[0]
            late = source.snapshot(source.now_s())["trains"][0]["deviation_s"]
            assert late == round(expected - arrivals[0])
            assert 120 <= late <= 130  # the report's 2 min, and the moment it took to arrive

    _run(scenario())


def test_a_category_the_ground_knows_sets_the_static_limit_of_the_overspeed_alarm() -> None:
    # km 26.6-31.7 going UP: 70 km/h for loaded trains, 75-80 for empty ones; the train
    # runs at 72 km/h (Trajectory's 20 m/s)
    async def scenario() -> None:
        async with _ground_then_one_train(2001, 27_000.0, lambda _: None) as ground:
            guessed = ground.source  # no categories: UP is taken as the line's first, loaded
            known = ServerSource(ground.host, categories={2001: "freight_empty"})

            def reported() -> bool:
                trains = guessed.snapshot(guessed.now_s())["trains"]
                return bool(trains) and trains[0]["speed_kmh"] is not None

            await ground.changes.until(reported)
            now = guessed.now_s()
            (as_loaded,) = guessed.snapshot(now)["trains"]
            (as_empty,) = known.snapshot(now)["trains"]
            assert as_loaded["speed_kmh"] == as_empty["speed_kmh"] == pytest.approx(72.0)
            assert as_loaded["category"] is None and as_loaded["mrsp_kmh"] == 70.0
            assert as_loaded["alarms"] == ["overspeed"]
            assert as_empty["category"] == "freight_empty"
            assert as_empty["mrsp_kmh"] in (75.0, 80.0) and as_empty["alarms"] == []

    _run(scenario())


def test_a_category_that_is_not_the_line_s_is_refused_by_name() -> None:
    host = DispatchHost(
        GroundServer(GroundConfig(ground_id=GROUND_ID), KeyStore()), load_line("heavy-haul")
    )
    with pytest.raises(ConfigError) as refused:
        ServerSource(host, categories={2001: "freight_loaded", 2002: "metro"})
    assert refused.value.field == "categories[2002]" and refused.value.value == "metro"
    assert "freight_loaded, freight_empty" in str(refused.value)
