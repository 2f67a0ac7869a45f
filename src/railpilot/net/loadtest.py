"""Load test: one ground server and N onboard endpoints on loopback, bounded in count and time.

The server runs in this process; the onboard endpoints run in ``client_processes`` child
processes (``spawn``), because Python runs one event loop per core and the goal machine has
two. Every train connects during a ramp (so 1,000 registrations do not arrive in the same
millisecond, as they would not after a real ground restart thanks to reconnect jitter),
sends running info every cycle (1 Hz by default) with HMAC authentication, and gets one TSR
broadcast from the ground at ``tsr_at`` of the run. At the end the children stop ticking,
report what they sent and applied, and the server waits (bounded) for frames in flight.

Latency of running info = ground receipt time (after every check, when the event reaches
the application) - the frame's timestamp, which the onboard core takes from
``time.time()`` when it encodes the frame. Both clocks are this machine's clock.

Keys are derived from the seed in memory (test keys: never written, never used in service).
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import logging
import math
import multiprocessing
import os
import resource
import statistics
import time
from dataclasses import asdict, dataclass
from multiprocessing.connection import Connection
from typing import Any

from railpilot.link import (
    Event,
    GroundConfig,
    KeyStore,
    LinkConfigError,
    LinkTimers,
    MessageReceived,
    OnboardConfig,
    RunningInfo,
    TsrAcknowledged,
    TsrApplied,
    TsrSet,
)
from railpilot.units import kmh_to_mps

from .client import OnboardClient, Trajectory
from .server import GroundServer
from .timers import TickScheduler

log = logging.getLogger("railpilot.net.loadtest")

GROUND_ID = 1
FIRST_TRAIN_ID = 10_001
MAX_TRAINS = 5_000
MAX_SECONDS = 600.0
TSR_SESSION = 1
HOST = "127.0.0.1"


@dataclass(frozen=True, slots=True)
class LoadtestOptions:
    trains: int = 100
    seconds: float = 10.0
    seed: int = 1
    #: Running info / heartbeat period [s].
    cycle_s: float = 1.0
    #: Trains connect spread over this many seconds (``None``: min(2 s, seconds / 4)).
    ramp_s: float | None = None
    #: When the TSR broadcast goes out, as a fraction of the run.
    tsr_at: float = 0.5
    client_processes: int = 1
    #: How long after the end the server waits for frames still in flight [s].
    drain_s: float = 3.0

    def __post_init__(self) -> None:
        if type(self.trains) is not int or not 1 <= self.trains <= MAX_TRAINS:
            raise LinkConfigError("trains", self.trains, f"an integer in [1, {MAX_TRAINS}]")
        if not isinstance(self.seconds, int | float) or not 1.0 <= self.seconds <= MAX_SECONDS:
            raise LinkConfigError("seconds", self.seconds, f"a number in [1, {MAX_SECONDS}]")
        if not 0.0 < self.tsr_at < 1.0:
            raise LinkConfigError("tsr_at", self.tsr_at, "a fraction in (0, 1)")
        if type(self.client_processes) is not int or not 1 <= self.client_processes <= 16:
            raise LinkConfigError("client_processes", self.client_processes, "1..16")
        LinkTimers(cycle_s=self.cycle_s, max_round_trip_s=max(3.0, 3 * self.cycle_s))

    @property
    def ramp(self) -> float:
        return min(2.0, self.seconds / 4) if self.ramp_s is None else self.ramp_s

    def timers(self) -> LinkTimers:
        return LinkTimers(cycle_s=self.cycle_s, max_round_trip_s=max(3.0, 3 * self.cycle_s))

    def train_ids(self) -> range:
        return range(FIRST_TRAIN_ID, FIRST_TRAIN_ID + self.trains)


def loadtest_keys(seed: int, train_ids: range) -> KeyStore:
    """Deterministic per-train test keys (derived from the seed, kept in memory only)."""
    keys = KeyStore()
    for train in train_ids:
        keys.add_key(
            train, 1, hashlib.sha256(f"railpilot-loadtest:{seed}:{train}".encode()).digest()
        )
    return keys


def _raise_fd_limit(need: int) -> None:
    """Each train is one socket per process; lift the soft limit up to the hard one."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < need:
        target = need if hard == resource.RLIM_INFINITY else min(need, hard)
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


# --- onboard side (child process) -----------------------------------------------------------


def _client_main(options: LoadtestOptions, train_ids: list[int], conn: Connection) -> None:
    """Entry point of a client process: wait for the go, run the trains, report."""
    _raise_fd_limit(len(train_ids) + 256)
    conn.send("ready")
    port, start_at = conn.recv()
    stats = asyncio.run(_run_clients(options, train_ids, port, start_at, conn))
    conn.send(stats)
    conn.close()


async def _run_clients(
    options: LoadtestOptions,
    train_ids: list[int],
    port: int,
    start_at: float,
    conn: Connection,
) -> dict[str, Any]:
    keys = loadtest_keys(options.seed, options.train_ids())
    timers = options.timers()
    scheduler = TickScheduler()
    clients: list[OnboardClient] = []
    applied: dict[int, int] = {}
    for train in train_ids:
        config = OnboardConfig(
            train_id=train,
            ground_id=GROUND_ID,
            train_number=f"K{train % 100000}",
            loco_number=f"HXD{train % 10000}",
            driver_id=train,
            train_length_m=2600.0,
            timers=timers,
        )
        client = OnboardClient(
            config,
            keys,
            HOST,
            port,
            trajectory=Trajectory(start_m=100_000.0 + (train % 50) * 2000.0, speed_mps=22.0),
            seed=options.seed * 1_000_003 + train,
            scheduler=scheduler,
            count_sent=True,
        )
        applied[train] = 0

        def on_event(event: Event, now_s: float, train: int = train) -> None:
            if isinstance(event, TsrApplied):
                applied[train] += 1

        client.add_listener(on_event)
        clients.append(client)
    stop = asyncio.Event()
    n = len(clients)

    async def start(client: OnboardClient, at: float) -> None:
        await asyncio.sleep(max(0.0, at - time.time()))
        await client.run(stop)

    tasks = [
        asyncio.create_task(start(c, start_at + options.ramp * i / max(1, n)))
        for i, c in enumerate(clients)
    ]
    end_at = start_at + options.seconds
    await asyncio.sleep(max(0.0, end_at - time.time()))
    # Freeze: no more ticks, so nothing more is sent; the sockets stay open while the
    # server drains what is in flight.
    scheduler.close()
    stats = {
        "messages_sent": sum(c.running_info_sent() for c in clients),
        "frames_sent": sum(sum(c.sent_by_type.values()) for c in clients),
        "registered": sum(1 for c in clients if c.registrations > 0),
        "connects": sum(c.connects for c in clients),
        "registrations": sum(c.registrations for c in clients),
        "tsr_applied": sum(1 for v in applied.values() if v >= 1),
        "tsr_applied_more_than_once": sum(1 for v in applied.values() if v > 1),
        "onboard_rejected": sum(sum(c.endpoint.counters.rejected.values()) for c in clients),
        "onboard_link_failures": sum(c.endpoint.counters.link_failures for c in clients),
        "ticks": scheduler.ticks,
        "cpu_s": round(_cpu_s(), 2),
    }
    conn.send(stats)
    # Keep the connections until the server has drained, then leave without ceremony.
    loop = asyncio.get_running_loop()
    with contextlib.suppress(Exception):
        await asyncio.wait_for(loop.run_in_executor(None, conn.recv), options.drain_s + 10.0)
    stop.set()
    for c in clients:
        c.drop_connection()
    for task in tasks:
        task.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    return {"done": True}


# --- ground side (this process) -------------------------------------------------------------


def run_loadtest(options: LoadtestOptions) -> dict[str, Any]:
    """Run the load test and return its report (one JSON-ready dict)."""
    _raise_fd_limit(options.trains + 256)
    return asyncio.run(_run(options))


async def _run(options: LoadtestOptions) -> dict[str, Any]:
    ids = list(options.train_ids())
    keys = loadtest_keys(options.seed, options.train_ids())
    server = GroundServer(
        GroundConfig(ground_id=GROUND_ID, timers=options.timers()),
        keys,
        host=HOST,
        port=0,
        backlog=min(4096, options.trains + 64),
    )
    latencies_ms: list[float] = []
    received = 0
    acknowledged: set[int] = set()

    def listener(train_id: int | None, event: Event, now_s: float) -> None:
        nonlocal received
        if isinstance(event, MessageReceived) and isinstance(event.message, RunningInfo):
            received += 1
            latencies_ms.append((now_s - event.timestamp_us / 1e6) * 1000.0)
        elif isinstance(event, TsrAcknowledged):
            acknowledged.add(event.train_id)

    server.add_listener(listener)
    _, port = await server.start()
    cpu0 = _cpu_s()

    ctx = multiprocessing.get_context("spawn")
    shares = [ids[i :: options.client_processes] for i in range(options.client_processes)]
    pipes: list[Connection] = []
    procs = []
    for share in shares:
        parent_end, child_end = ctx.Pipe()
        proc = ctx.Process(target=_client_main, args=(options, share, child_end), daemon=True)
        proc.start()
        pipes.append(parent_end)
        procs.append(proc)
    try:
        for p, proc in zip(pipes, procs, strict=True):
            await _recv(p, proc, 60.0)  # "ready"
        start_at = time.time() + 0.3
        for p in pipes:
            p.send((port, start_at))

        # The TSR broadcast: every train, connected or not (offline ones get it on
        # registration, from their record).
        await asyncio.sleep(max(0.0, start_at + options.seconds * options.tsr_at - time.time()))
        now = time.time()
        tsr = TsrSet(TSR_SESSION, 120_000.0, 121_500.0, kmh_to_mps(45.0), now, now + 3600.0)
        t_broadcast = time.perf_counter()
        results = await server.paced(server.set_tsr, ids, tsr)
        broadcast_ms = (time.perf_counter() - t_broadcast) * 1000.0
        tsr_sent = sum(1 for r in results.values() if not r.startswith("error"))

        client_stats = []
        for p, proc in zip(pipes, procs, strict=True):
            client_stats.append(await _recv(p, proc, options.seconds + 60.0))
        sent = sum(s["messages_sent"] for s in client_stats)
        # Frames still in flight when the clients froze: wait for them, bounded.
        drain_until = time.time() + options.drain_s
        while (received < sent or len(acknowledged) < tsr_sent) and time.time() < drain_until:
            await asyncio.sleep(0.05)
        counters = server.counters()
        cpu_server = _cpu_s() - cpu0
        for p in pipes:
            p.send("bye")
    finally:
        for p, proc in zip(pipes, procs, strict=True):
            with contextlib.suppress(Exception):
                await _recv(p, proc, 15.0)
        for proc in procs:
            proc.join(timeout=10.0)
            if proc.is_alive():
                proc.kill()
        await server.stop(timeout_s=2.0)

    def total(key: str) -> int:
        return int(sum(s[key] for s in client_stats))

    lat = sorted(latencies_ms)
    report: dict[str, Any] = {
        "trains": options.trains,
        "seconds": options.seconds,
        "messages_sent": sent,
        "messages_received": received,
        "lost": sent - received,
        "p50_latency_ms": _pct(lat, 50),
        "p90_latency_ms": _pct(lat, 90),
        "p99_latency_ms": _pct(lat, 99),
        "max_latency_ms": round(lat[-1], 3) if lat else None,
        "mean_latency_ms": round(statistics.fmean(lat), 3) if lat else None,
        "tsr_sent": tsr_sent,
        "tsr_acknowledged": len(acknowledged),
        "tsr_applied_on_trains": total("tsr_applied"),
        "tsr_applied_more_than_once": total("tsr_applied_more_than_once"),
        "tsr_broadcast_ms": round(broadcast_ms, 1),
        "registered": total("registered"),
        "connects": total("connects"),
        "ground_frames_received": counters["frames_received"],
        "ground_frames_accepted": counters["frames_accepted"],
        "ground_rejected": counters["rejected"],
        "ground_frames_lost": counters["frames_lost"],
        "ground_superseded": counters["superseded"],
        "link_failures": counters["link_failures"] + total("onboard_link_failures"),
        "onboard_rejected": total("onboard_rejected"),
        "server_cpu_s": round(cpu_server, 2),
        "clients_cpu_s": round(sum(s["cpu_s"] for s in client_stats), 2),
        "client_processes": options.client_processes,
        "cpus": os.cpu_count(),
        "auth": "HMAC-SHA256",
        "options": asdict(options),
    }
    return report


async def _recv(pipe: Connection, proc: Any, timeout_s: float) -> Any:
    """Receive from a child without blocking the loop; fail fast if the child died."""
    deadline = time.monotonic() + timeout_s
    while not pipe.poll():
        if not proc.is_alive():
            raise RuntimeError(f"load-test client process exited with code {proc.exitcode}")
        if time.monotonic() > deadline:
            raise TimeoutError(f"load-test client process silent for {timeout_s:.0f} s")
        await asyncio.sleep(0.02)
    return pipe.recv()


def _pct(sorted_values: list[float], q: float) -> float | None:
    """Nearest-rank percentile of an already sorted list (None when empty)."""
    if not sorted_values:
        return None
    rank = max(1, math.ceil(q / 100.0 * len(sorted_values)))
    return round(sorted_values[min(rank, len(sorted_values)) - 1], 3)
