"""Shared pieces of the network tests: keys, short timers, a server with trains on loopback.

Every test runs its coroutine under :func:`run`, which bounds it with ``asyncio.timeout``;
waits inside use :func:`until` (poll a condition, bounded). Nothing here asserts on time.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable, Coroutine
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from typing import Any, TypeVar

from railpilot.link import (
    Event,
    GroundConfig,
    KeyStore,
    LinkTimers,
    MessageReceived,
    OnboardConfig,
    RunningInfo,
    TsrSet,
)
from railpilot.net import FaultProxy, GroundServer, OnboardClient, ProxyOptions, Trajectory
from railpilot.net.proxy import PacketRadio

T = TypeVar("T")
GROUND_ID = 1
TRAIN_ID = 1001
KEY = bytes(range(32))
SPEED_MPS = 15.0
LENGTH_M = 800.0

#: Short timers so a test sees many cycles in little time.
FAST = LinkTimers(
    cycle_s=0.1,
    timeout_cycles=5,
    resend_interval_s=0.2,
    max_round_trip_s=0.5,
    reconnect_initial_s=0.05,
    reconnect_max_s=0.5,
)


def run(coro: Coroutine[Any, Any, T], timeout_s: float = 20.0) -> T:
    """Run ``coro`` with a hard bound; a hang fails the test instead of blocking the suite."""

    async def bounded() -> T:
        async with asyncio.timeout(timeout_s):
            return await coro

    return asyncio.run(bounded())


async def until(condition: Callable[[], bool], timeout_s: float = 8.0) -> None:
    """Wait (polling every 10 ms) until ``condition()``; TimeoutError after ``timeout_s``."""
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.01)


def make_keys(*train_ids: int) -> KeyStore:
    keys = KeyStore()
    for i, train in enumerate(train_ids or (TRAIN_ID,)):
        keys.add_key(train, 1, bytes((b + i) % 256 for b in KEY))
    return keys


def tsr(session: int, start_m: float = 5_000.0, end_m: float = 6_000.0) -> TsrSet:
    now = time.time()
    return TsrSet(session, start_m, end_m, 40 / 3.6, now, now + 600.0)


def onboard_config(
    train_id: int,
    *,
    timers: LinkTimers = FAST,
    length_m: float = LENGTH_M,
    loco_number: str = "SS4-0123",
    driver_id: int = 42,
) -> OnboardConfig:
    """A test train's onboard configuration (train number ``K<id>``, this ground)."""
    return OnboardConfig(
        train_id=train_id,
        ground_id=GROUND_ID,
        train_number=f"K{train_id}",
        loco_number=loco_number,
        driver_id=driver_id,
        train_length_m=length_m,
        timers=timers,
    )


@dataclass
class Rig:
    """A ground server, optionally a proxy, and trains, with everything they reported."""

    server: GroundServer
    keys: KeyStore
    timers: LinkTimers
    port: int
    proxy: FaultProxy | None = None
    clients: list[OnboardClient] = field(default_factory=list)
    ground_events: list[tuple[int | None, Event]] = field(default_factory=list)
    onboard_events: dict[int, list[Event]] = field(default_factory=dict)
    tasks: list[asyncio.Task[None]] = field(default_factory=list)
    stop: asyncio.Event = field(default_factory=asyncio.Event)

    def add_train(self, train_id: int = TRAIN_ID, *, start: bool = True) -> OnboardClient:
        config = onboard_config(train_id, timers=self.timers)
        client = OnboardClient(
            config,
            self.keys,
            "127.0.0.1",
            self.port,
            trajectory=Trajectory(start_m=4_000.0, speed_mps=SPEED_MPS),
            seed=train_id,
        )
        events = self.onboard_events.setdefault(train_id, [])
        client.add_listener(lambda event, now: events.append(event))
        self.clients.append(client)
        if start:
            self.start(client)
        return client

    def start(self, client: OnboardClient) -> None:
        self.tasks.append(asyncio.create_task(client.run(self.stop)))

    def ground_of(self, kind: type) -> list[Any]:
        return [e for _, e in self.ground_events if isinstance(e, kind)]

    def onboard_of(self, train_id: int, kind: type) -> list[Any]:
        return [e for e in self.onboard_events.get(train_id, []) if isinstance(e, kind)]

    def running_infos(self) -> list[MessageReceived]:
        return [e for e in self.ground_of(MessageReceived) if isinstance(e.message, RunningInfo)]


@asynccontextmanager
async def rig(
    *train_ids: int,
    proxy: ProxyOptions | None = None,
    timers: LinkTimers = FAST,
    start: bool = True,
    radio: PacketRadio | None = None,
) -> AsyncIterator[Rig]:
    """Server (+ proxy, with its options or its radio) on ephemeral loopback ports and
    trains connected to it."""
    ids = train_ids or (TRAIN_ID,)
    keys = make_keys(*ids)
    server = GroundServer(GroundConfig(ground_id=GROUND_ID, timers=timers), keys)
    _, port = await server.start()
    fault = None
    if proxy is not None or radio is not None:
        fault = FaultProxy("127.0.0.1", port, proxy, radio=radio)
        _, port = await fault.start()
    r = Rig(server, keys, timers, port, fault)
    server.add_listener(lambda train, event, now: r.ground_events.append((train, event)))
    for train in ids:
        r.add_train(train, start=start)
    try:
        yield r
    finally:
        r.stop.set()
        async with asyncio.timeout(5.0):
            await asyncio.gather(*r.tasks, return_exceptions=True)
        if fault is not None:
            await fault.stop()
        await server.stop(timeout_s=2.0)
