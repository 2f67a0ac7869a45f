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

The trains run on the bundled heavy-haul line (:data:`LINE`): spread along its whole
length, every other one each way, each at a steady speed below the line's static limit over
the stretch it covers during the run (:func:`layout`), so the dashboard shows them where a
line would have them (two trains may still overlap: 1,000 trains of 2.6 km do not fit on
590 km of double track; it is a load test).

By default the ground is the link layer alone (frames, checks, HMAC, the train records).
With ``dispatch=True`` it also runs the dispatch core as ``railpilot ground serve`` does
(:class:`~railpilot.net.dispatch_host.DispatchHost`: registry, TSR manager, occupancy and
target points every second). With ``dashboard=True`` (which implies ``dispatch``) it also
serves the dispatcher dashboard (web/, in the server's own event loop, as ``ground serve
--http-port``), and the page is opened in Debian's headless chromium in another child
process (:mod:`railpilot.rigs.page_probe`);
the report gains a ``dashboard`` object: how often the page drew (over the steady window,
after the ramp and before the end), the longest gap between two renders, and what each
WebSocket push cost the server's loop (snapshot build + JSON encode) and weighed.

Keys are derived from the seed in memory (:func:`railpilot.link.keys.seeded_test_keys`: test
keys, never written, never used in service).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import math
import multiprocessing
import os
import random
import resource
import secrets
import statistics
import time
from dataclasses import asdict, dataclass
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError
from railpilot.gc_tuning import freeze_startup
from railpilot.ground.assembly import GroundParts
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link import (
    Event,
    GroundConfig,
    LinkConfigError,
    LinkTimers,
    MessageReceived,
    OnboardConfig,
    RunningInfo,
    TsrAcknowledged,
    TsrApplied,
    TsrSet,
)
from railpilot.link.keys import seeded_test_keys
from railpilot.net.client import OnboardClient, Trajectory
from railpilot.net.ground_app import ground_server, live_ground
from railpilot.net.timers import TickScheduler
from railpilot.units import kmh_to_mps

from .page_probe import ProbeOptions, probe_main

log = logging.getLogger("railpilot.rigs.loadtest")

GROUND_ID = 1
FIRST_TRAIN_ID = 10_001
MAX_TRAINS = 5_000
MAX_SECONDS = 600.0
TSR_SESSION = 1
HOST = "127.0.0.1"
#: The line the trains run on (and the dashboard draws).
LINE = "heavy-haul"
#: Train length [m] (a heavy-haul train).
TRAIN_LENGTH_M = 2600.0
#: Each train's speed is this share of the lowest static limit over its stretch (seeded).
SPEED_SHARE = (0.6, 0.95)


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
    #: Also run the ground's dispatch core (as ``ground serve``); ``dashboard`` implies it.
    dispatch: bool = False
    #: Also serve the dispatcher dashboard and keep it open in headless chromium.
    dashboard: bool = False
    #: With ``dashboard``: a PNG of the page (its viewport) at the end of the run.
    screenshot: str | None = None

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
        if self.screenshot is not None and not self.dashboard:
            raise LinkConfigError("screenshot", self.screenshot, "to be given with dashboard")

    @property
    def ramp(self) -> float:
        return min(2.0, self.seconds / 4) if self.ramp_s is None else self.ramp_s

    def timers(self) -> LinkTimers:
        return LinkTimers(cycle_s=self.cycle_s, max_round_trip_s=max(3.0, 3 * self.cycle_s))

    def train_ids(self) -> range:
        return range(FIRST_TRAIN_ID, FIRST_TRAIN_ID + self.trains)


def layout(options: LoadtestOptions, line: RailLine) -> dict[int, Trajectory]:
    """Where each train starts, which way it goes and how fast (seeded).

    Trains alternate UP and DOWN; each direction's trains are spread evenly over the line
    (a seeded jitter within each one's slot), far enough from its ends that none runs off
    during the run. Each runs at a seeded share (:data:`SPEED_SHARE`) of the lowest static
    limit over the stretch it can cover during the run, for its category: UP trains are
    taken as loaded (the line's first category) and DOWN ones as empty (its last), as the
    dashboard takes them (web/ground_source.py).
    """
    rng = random.Random(options.seed)
    ids = list(options.train_ids())
    run_s = options.ramp + options.seconds + options.drain_s + 10.0
    lo, hi = line.start_m + TRAIN_LENGTH_M, line.end_m - TRAIN_LENGTH_M
    out: dict[int, Trajectory] = {}
    for k, (travel, category) in enumerate(((UP, line.categories[0]), (DOWN, line.categories[-1]))):
        edges, limits = line.static_limit(category, travel)
        reach = float(limits.max()) * run_s  # furthest a train of this kind goes [m]
        span = max(0.0, hi - lo - reach)
        sign = 1.0 if travel is UP else -1.0
        mine = ids[k::2]
        for i, train in enumerate(mine):
            offset = (i + rng.random()) / len(mine) * span
            start = lo + offset if travel is UP else hi - offset
            a, b = sorted((start, start + sign * reach))
            covered = (edges[:-1] < b) & (edges[1:] > a)
            speed = rng.uniform(*SPEED_SHARE) * float(limits[covered].min())
            out[train] = Trajectory(start_m=start, speed_mps=speed, direction=travel)
    return out


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


def _client_main(
    options: LoadtestOptions, trajectories: dict[int, Trajectory], conn: Connection
) -> None:
    """Entry point of a client process: wait for the go, run the trains, report."""
    _raise_fd_limit(len(trajectories) + 256)
    conn.send("ready")
    port, start_at = conn.recv()
    stats = asyncio.run(_run_clients(options, trajectories, port, start_at, conn))
    conn.send(stats)
    conn.close()


async def _run_clients(
    options: LoadtestOptions,
    trajectories: dict[int, Trajectory],
    port: int,
    start_at: float,
    conn: Connection,
) -> dict[str, Any]:
    keys = seeded_test_keys(options.seed, options.train_ids())
    timers = options.timers()
    scheduler = TickScheduler()
    clients: list[OnboardClient] = []
    applied: dict[int, int] = {}
    for train, trajectory in trajectories.items():
        config = OnboardConfig(
            train_id=train,
            ground_id=GROUND_ID,
            train_number=f"K{train % 100000}",
            loco_number=f"HXD{train % 10000}",
            driver_id=train,
            train_length_m=TRAIN_LENGTH_M,
            timers=timers,
        )
        client = OnboardClient(
            config,
            keys,
            HOST,
            port,
            trajectory=trajectory,
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


def chromium() -> Path:
    """The browser ``dashboard`` needs (looked up at call time: tests point it elsewhere)."""
    from railpilot.web import browser

    return browser.CHROMIUM


def check_dashboard(options: LoadtestOptions) -> None:
    """Refuse ``dashboard`` without the browser, before anything starts."""
    if options.dashboard and not chromium().exists():
        raise ConfigError(
            "dashboard",
            True,
            f"Debian's chromium at {chromium()} to open the page in (apt-get install "
            "chromium; no browser is downloaded)",
        )


def run_loadtest(options: LoadtestOptions) -> dict[str, Any]:
    """Run the load test and return its report (one JSON-ready dict)."""
    check_dashboard(options)
    _raise_fd_limit(options.trains + 256)
    return asyncio.run(_run(options))


class _Dashboard:
    """The dashboard over the load test's ground, and the page open in the probe process."""

    def __init__(self, host: Any, options: LoadtestOptions) -> None:
        from railpilot.web.ground_source import ServerSource

        self.options = options
        self.source = ServerSource(host)
        self.http: Any = None
        self.task: asyncio.Task[None] | None = None
        self.pipe: Connection | None = None
        self.proc: Any = None
        #: What the server pushed (web.app.Push), read when the page closes.
        self.pushed: list[Any] = []

    async def start(self, ctx: Any) -> None:
        """Serve the page, then open it in chromium (in its own process)."""
        from railpilot.web.browser import CHROMIUM_FLAGS
        from railpilot.web.ground_source import serve_dashboard

        token = secrets.token_urlsafe(16)  # the page only reads: nobody needs it
        self.http, self.task = await serve_dashboard(self.source, token=token, host=HOST)
        probe = ProbeOptions(
            url=f"http://{HOST}:{self.http.port}/",
            executable=str(chromium()),
            flags=CHROMIUM_FLAGS,
            screenshot=self.options.screenshot,
        )
        parent_end, child_end = ctx.Pipe()
        self.proc = ctx.Process(target=probe_main, args=(probe, child_end), daemon=True)
        self.proc.start()
        self.pipe = parent_end

    async def wait_ready(self) -> None:
        assert self.pipe is not None
        answer = await _recv(self.pipe, self.proc, 90.0, "dashboard page")
        if "error" in answer:
            raise RuntimeError(f"the dashboard page did not open: {answer['error']}")

    async def finish(self) -> dict[str, Any]:
        """Close the page (what it drew comes back) and stop serving."""
        assert self.pipe is not None
        self.pipe.send("stop")
        result: dict[str, Any] = await _recv(self.pipe, self.proc, 60.0, "dashboard page")
        self.pushed = list(self.http.config.app.state.pushes)
        await self.stop()
        return result

    async def stop(self) -> None:
        if self.proc is not None:
            await asyncio.get_running_loop().run_in_executor(None, self.proc.join, 10.0)
            if self.proc.is_alive():
                self.proc.kill()
            self.proc = None
        if self.http is not None and self.task is not None:
            self.http.should_exit = True
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self.task, 10.0)
            self.http = None


async def _run(options: LoadtestOptions) -> dict[str, Any]:
    from railpilot.line.loader import load_line

    ids = list(options.train_ids())
    keys = seeded_test_keys(options.seed, options.train_ids())
    line = load_line(LINE)
    trajectories = layout(options, line)
    parts = GroundParts(GroundConfig(ground_id=GROUND_ID, timers=options.timers()), line, keys)
    backlog = min(4096, options.trains + 64)
    host = None
    if options.dispatch or options.dashboard:
        host = live_ground(parts, host=HOST, port=0, backlog=backlog)
        server = host.server
    else:
        server = ground_server(parts, host=HOST, port=0, backlog=backlog)
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
    if host is not None:
        host.start()
    ctx = multiprocessing.get_context("spawn")
    dashboard = None
    if options.dashboard:
        dashboard = _Dashboard(host, options)
        await dashboard.start(ctx)
    freeze_startup()  # as `ground serve` does, once started (railpilot/gc_tuning.py)

    shares = [ids[i :: options.client_processes] for i in range(options.client_processes)]
    pipes: list[Connection] = []
    procs = []
    for share in shares:
        parent_end, child_end = ctx.Pipe()
        mine = {train: trajectories[train] for train in share}
        proc = ctx.Process(target=_client_main, args=(options, mine, child_end), daemon=True)
        proc.start()
        pipes.append(parent_end)
        procs.append(proc)
    page: dict[str, Any] | None = None
    try:
        for p, proc in zip(pipes, procs, strict=True):
            await _recv(p, proc, 60.0)  # "ready"
        if dashboard is not None:
            await dashboard.wait_ready()  # the page has drawn its first snapshot
        cpu0 = _cpu_s()
        start_at = time.time() + 0.3
        loop_offset = asyncio.get_running_loop().time() - time.time()
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
        target_points = sum(len(r.target_points) for r in server.records.values())
        cpu_server = _cpu_s() - cpu0
        wall_server = time.time() - start_at
        if dashboard is not None:
            page = await dashboard.finish()
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
        if dashboard is not None:
            await dashboard.stop()
        if host is not None:
            host.stop()
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
        "target_points_sent": target_points,
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
        "server_cpu_pct": round(100.0 * cpu_server / wall_server, 1),
        "clients_cpu_s": round(sum(s["cpu_s"] for s in client_stats), 2),
        "client_processes": options.client_processes,
        "dispatch": host is not None,
        "cpus": os.cpu_count(),
        "auth": "HMAC-SHA256",
        "options": asdict(options),
    }
    if dashboard is not None and page is not None:
        window = (start_at + options.ramp, start_at + options.seconds)
        pushes = [p for p in dashboard.pushed if window[0] <= p.at_s - loop_offset <= window[1]]
        report["dashboard"] = dashboard_report(page, pushes, window)
    return report


def dashboard_report(
    page: dict[str, Any], pushes: list[Any], window: tuple[float, float]
) -> dict[str, Any]:
    """The ``dashboard`` object of the report, from what the page drew (``page``: the probe's
    answer) and what the server pushed during the steady ``window`` (wall clock [s])."""
    if "error" in page:
        return {"error": page["error"], "errors": page.get("errors", [])}
    w0, w1 = window
    at_s = sorted(t / 1000.0 for t in page["render_at_ms"])
    inside = [t for t in at_s if w0 <= t <= w1]
    before = [t for t in at_s if t < w0]
    marks = before[-1:] + inside + [w1]  # the gap still open at the end counts too
    gaps = [b - a for a, b in itertools.pairwise(marks)]
    in_window = [i for i, t in enumerate(page["render_at_ms"]) if w0 <= t / 1000.0 <= w1]
    render_ms = sorted(page["render_ms"][i] for i in in_window)
    paint_ms = sorted(p for i in in_window if (p := page["paint_ms"][i]) is not None)
    build = sorted(p.build_s * 1000.0 for p in pushes)
    encode = sorted(p.encode_s * 1000.0 for p in pushes)
    total = sorted((p.build_s + p.encode_s) * 1000.0 for p in pushes)
    sizes = [p.size_bytes for p in pushes]
    return {
        "renders": page["renders"],
        "window_s": round(w1 - w0, 2),
        "renders_in_window": len(inside),
        "updates_per_s": round(len(inside) / (w1 - w0), 2) if w1 > w0 else None,
        "max_gap_s": round(max(gaps), 3) if before or inside else None,
        "render_ms_p50": _pct(render_ms, 50),
        "render_ms_max": _pct(render_ms, 100),
        "paint_ms_p50": _pct(paint_ms, 50),
        "paint_ms_max": _pct(paint_ms, 100),
        "pushes_in_window": len(pushes),
        "snapshot_ms_p50": _pct(total, 50),
        "snapshot_ms_p99": _pct(total, 99),
        "snapshot_ms_max": _pct(total, 100),
        "snapshot_build_ms_p50": _pct(build, 50),
        "snapshot_encode_ms_p50": _pct(encode, 50),
        "snapshot_bytes": max(sizes) if sizes else None,
        "trains_drawn": page["trains_shown"],
        "train_rows": page["rows"],
        "status": page["status"],
        "errors": page["errors"],
        "screenshot": page["screenshot"],
    }


async def _recv(
    pipe: Connection, proc: Any, timeout_s: float, what: str = "load-test client"
) -> Any:
    """Receive from a child without blocking the loop; fail fast if the child died."""
    deadline = time.monotonic() + timeout_s
    while not pipe.poll():
        if not proc.is_alive():
            raise RuntimeError(f"{what} process exited with code {proc.exitcode}")
        if time.monotonic() > deadline:
            raise TimeoutError(f"{what} process silent for {timeout_s:.0f} s")
        await asyncio.sleep(0.02)
    return pipe.recv()


def _pct(sorted_values: list[float], q: float) -> float | None:
    """Nearest-rank percentile of an already sorted list (None when empty)."""
    if not sorted_values:
        return None
    rank = max(1, math.ceil(q / 100.0 * len(sorted_values)))
    return round(sorted_values[min(rank, len(sorted_values)) - 1], 3)
