"""A line run live: the ground as a server and every train as its own process, over real
TCP on loopback, on a clock ``speedup`` times faster than the wall's (docs/line-run.md
"Live").

:func:`run_live` plays a line-run scenario as the co-simulation (cosim/line_run.py) does,
with real parts where the co-simulation has simulated ones:

* **the ground** is a process (cosim/live_ground.py) running what ``railpilot ground
  serve`` runs: the link's front server with its SQLite store, the dispatch application,
  the admin port and the dashboard;
* **each train** is a process (cosim/live_train.py): the same driver and simulation core
  as the co-simulation, and the onboard unit of ``railpilot onboard run``
  (:class:`~railpilot.net.client.OnboardClient`) connected to the ground over TCP;
* **the clock** is one :class:`~railpilot.net.timers.LinkClock` that every process
  computes from the same origin: the scenario's epoch at a wall time this run chooses
  once every process has said it is ready. The link's timers, its frame timestamps, TSR
  validity and the trains' physics all run on it;
* **the dispatcher** is this run, speaking to the ground's admin port (the scenario's
  operations, as typed in its file) at their times;
* **a ground restart** kills the ground process with SIGKILL and starts a new one on the
  same ports and store after the down time;
* **the trackside** (cosim/trackside.py, the KPIs' truth) is in this process: each train
  tells it over the control wire (cosim/live_wire.py) where it truly is each whole
  second, and it answers with the train's cab signal.

A process that fails tells the run over the control wire in one line, and the run stops
at once with that line, every process ended (a port that is not free names its field:
:class:`~railpilot.cosim.live_wire.PortUnavailable`). The ground holds the ports it was
given before any train starts, so a busy one stops the run within a second or two.

What differs from the co-simulation: the radio is loopback TCP with the scenario's
``[channel]`` in front of it in each train's process (cosim/live_train.py), so the link's
latencies are the channel's plus the host's, scaled by ``speedup`` (docs/line-run.md).
The KPIs are computed by the same code from the same kind of record, so the two runs of
a scenario can be compared (tests/cosim/test_live.py states the tolerance).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import secrets
import tempfile
import time
from collections.abc import Awaitable, Callable, Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from railpilot.errors import ConfigError, RailpilotError, is_finite_number
from railpilot.ground.store import open_store
from railpilot.net.admin import AdminError, admin_request
from railpilot.net.logfmt import kv
from railpilot.net.timers import LinkClock

from . import live_ground, live_train
from .channel import ChannelCounters, channel_totals
from .driver import SectionRun, Service
from .line_run import (
    RETRY_WHILE_DOWN_S,
    WATCH_S,
    LineResult,
    LiveRunInfo,
    Overspeed,
    SignalPassedAtRed,
    TrainRun,
    TsrViolation,
)
from .live_wire import (
    MAX_LINE,
    PortUnavailable,
    failure_error,
    hello_name,
    receive,
    send,
)
from .scenario import (
    MAX_SEED,
    GroundRestart,
    LineScenario,
    ScenarioEvent,
    TrainFailure,
    load_line_scenario,
)
from .trackside import CabView, Trackside, TrainSeen, TrainShape, static_overspeeds

#: the default time scale (a 9-hour day in 9 minutes)
DEFAULT_SPEEDUP = 60.0
#: the highest time scale allowed: at 200x the link's 1 s cycle is 5 ms of wall clock,
#: near what an event loop on a busy host can keep
MAX_SPEEDUP = 200.0
#: how long the processes may take to start and say they are ready [s of wall clock]
#: (imports and the simulation core's compilation: a few seconds each, on 2 cores)
READY_TIMEOUT_S = 300.0
#: how long the ground may take to come up, and the processes to report at the end [s]
ANSWER_TIMEOUT_S = 60.0
#: the clock starts this long after every process is ready [s of wall clock]
START_LEAD_S = 0.2
#: the trackside looks this long after the whole second the trains report [s]: their
#: reports are in by then
LOOK_AFTER_S = 0.5

#: how long a process that has ended may still have lines on the wire (its failure) [s]
WIRE_GRACE_S = 1.0
#: how long an ended run's processes get to exit before they are killed [s]
END_TIMEOUT_S = 5.0

#: the ports a live run listens on (:class:`LiveOptions`' fields): the ground's link,
#: dashboard and admin ports, and the run's own control wire
PORT_FIELDS = ("link_port", "http_port", "admin_port", "control_port")

#: how much nicer than the run's processes the dashboard's browser runs (os.nice)
SCREENSHOT_NICENESS = 15

log = logging.getLogger(__name__)

T = TypeVar("T")


def _lower_priority() -> None:
    """The photographer's process, and the browser it starts, yield the cores to the run.

    Niced everywhere POSIX; on Linux also scheduled only when a core is otherwise idle
    (``SCHED_IDLE``) and kept to one core, so a train or the ground always finds the
    other one. ``railpilot reproduce line-live`` on 2 cores, runs alternated: niced only,
    the link failed 9-22 times (60-70 frames rejected as late), both added 4-7 (19-33);
    without a screenshot 4 (8-12). Chromium's processes inherit all three.
    """
    if hasattr(os, "nice"):  # POSIX; elsewhere the browser runs as any process
        os.nice(SCREENSHOT_NICENESS)
    # best effort: a container may refuse either, and the picture is still worth taking
    with contextlib.suppress(OSError):
        if hasattr(os, "sched_setscheduler"):  # Linux
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    with contextlib.suppress(OSError):
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})


class LiveRunError(RailpilotError):
    """A live run that could not go on (a process that did not start or answer)."""


@dataclass
class LiveOptions:
    """How to run live (``railpilot line run``): the time scale, the seed (the scenario's
    by default), where to stop [s], the ports (each 0: a free one; :data:`PORT_FIELDS`),
    the dashboard's token, the ground's store file (default: a new one in a temporary
    directory), a screenshot of the dashboard taken at ``screenshot_at_s`` into
    ``screenshot``, and the processes' log level."""

    speedup: float = DEFAULT_SPEEDUP
    seed: int | None = None
    until_s: float | None = None
    http_port: int = 0
    link_port: int = 0
    admin_port: int = 0
    control_port: int = 0
    token: str | None = None
    store_path: str | None = None
    screenshot: Path | None = None
    screenshot_at_s: float | None = None
    #: told the dashboard's address and token once the ground is up
    on_dashboard: Callable[[str, str], None] | None = None
    #: the level of the ground's and the trains' log on stderr (at debug, a process's
    #: error comes with its traceback)
    log_level: int = logging.WARNING

    def check(self, scenario: LineScenario) -> None:
        if self.seed is not None and (
            not isinstance(self.seed, int)
            or isinstance(self.seed, bool)
            or not 0 <= self.seed <= MAX_SEED
        ):
            raise ConfigError(
                "seed", self.seed, f"None (the scenario's) or a seed in [0, {MAX_SEED}]"
            )
        if not is_finite_number(self.speedup) or not 1.0 <= self.speedup <= MAX_SPEEDUP:
            raise ConfigError("speedup", self.speedup, f"a time scale in [1, {MAX_SPEEDUP:g}]")
        if self.until_s is not None and (
            not is_finite_number(self.until_s) or not self.until_s > 0.0
        ):
            raise ConfigError("until_s", self.until_s, "a time > 0 [s]")
        given: dict[int, str] = {}
        for field in PORT_FIELDS:
            port = getattr(self, field)
            if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
                raise ConfigError(field, port, "0..65535 (0: a free one)")
            if port in given:  # the second would find the first holding it
                raise ConfigError(field, port, f"a port other than {given[port]}'s")
            if port != 0:
                given[port] = field
        if self.screenshot_at_s is not None and not (
            is_finite_number(self.screenshot_at_s)
            and 0.0 < self.screenshot_at_s < scenario.duration_s
        ):
            raise ConfigError(
                "screenshot_at_s", self.screenshot_at_s, "a time within the scenario [s]"
            )


def run_live(path: str | Path, options: LiveOptions | None = None) -> LineResult:
    """Run the line-run file ``path`` live (module docstring) and return what the
    co-simulation returns for it (its ``kpis()``)."""
    options = options or LiveOptions()
    scenario = load_line_scenario(path)
    options.check(scenario)
    with tempfile.TemporaryDirectory(prefix="railpilot-live-") as scratch:
        store = options.store_path or str(Path(scratch) / "ground.db")
        run = _LiveRun(scenario, str(path), options, store)
        return asyncio.run(run.main())


class _LiveRun:
    def __init__(
        self, scenario: LineScenario, path: str, options: LiveOptions, store_path: str
    ) -> None:
        self.scenario = scenario
        self.path = path
        self.options = options
        self.seed = scenario.seed if options.seed is None else options.seed
        self.store_path = store_path
        self.token = options.token or secrets.token_urlsafe(16)
        #: what each process's hello on the control wire must carry (cosim/live_wire.py)
        self.secret = secrets.token_urlsafe(32)
        end = scenario.duration_s
        self.end_s = end if options.until_s is None else min(options.until_s, end)
        self.services = {s.train_id: s for s in scenario.services}
        self.context = multiprocessing.get_context("spawn")
        self.trackside = Trackside(
            scenario.line,
            {i: _train_shape(s) for i, s in self.services.items()},
        )
        self.clock: LinkClock | None = None
        self.ground: Any = None  # the ground's process
        self.ground_up = False
        #: the ground's ports: as given, then (once it is up) as bound, for a restart
        self.ports = {f: getattr(options, f) for f in ("link_port", "http_port", "admin_port")}
        self.trains: dict[int, Any] = {}  # train id -> its process
        self.writers: dict[int | str, asyncio.StreamWriter] = {}
        self.hello: dict[int | str, asyncio.Future[None]] = {}
        self.ground_messages: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.seen: dict[int, dict[str, Any]] = {}
        self.results: dict[int, dict[str, Any]] = {}
        self.reported: dict[int, asyncio.Future[None]] = {}
        self.events: list[dict[str, Any]] = []
        self.restarts: list[dict[str, Any]] = []
        self.screenshot: dict[str, Any] | None = None
        #: the (last) ground process's re-timings (a killed ground's go with it)
        self.retiming: list[dict[str, Any]] = []
        #: the first failure a process told, and the run's way to hear of it at once
        self.failure: RailpilotError | None = None
        self.failed = asyncio.Event()
        #: every connection on the control wire, and the processes whose wire has closed
        self.connections: set[asyncio.StreamWriter] = set()
        self.readers: set[asyncio.Task[Any]] = set()
        self.closed: set[int | str] = set()
        #: when the run first saw a process ended (wall clock, monotonic) [s]
        self.ended_at: dict[int | str, float] = {}

    # ------------------------------------------------------------------ the run

    async def main(self) -> LineResult:
        loop = asyncio.get_running_loop()
        self.hello = {"ground": loop.create_future()}
        self.hello |= {i: loop.create_future() for i in self.services}
        self.reported = {i: loop.create_future() for i in self.services}
        control = await self._listen_control()
        tasks: list[asyncio.Task[None]] = []
        ended = False
        try:
            self._start_ground(None)
            # the ground holds its ports before a train starts: a busy one ends the run
            # before the trains' start-up (most of a run's first minute)
            await self._ready(["ground"], READY_TIMEOUT_S)
            await self._ground_says("held", READY_TIMEOUT_S)
            for train_id in self.services:
                args = live_train.TrainArgs(
                    self.control_port,
                    self.path,
                    self.seed,
                    train_id,
                    self.secret,
                    self.options.log_level,
                )
                process = self.context.Process(
                    target=live_train.run, args=(args,), name=f"train {train_id}", daemon=True
                )
                process.start()
                self.trains[train_id] = process
            await self._ready(list(self.hello), READY_TIMEOUT_S)
            kv(log, logging.INFO, "live_ready", trains=len(self.trains))
            self.clock = LinkClock(
                self.options.speedup, self.scenario.epoch_s, time.time() + START_LEAD_S
            )
            await self._send("ground", self._start_message())
            up = await self._ground_up(ANSWER_TIMEOUT_S)
            self.ports = {k: up[k] for k in ("link_port", "http_port", "admin_port")}
            kv(log, logging.INFO, "ground_up", **self.ports)
            url = f"http://127.0.0.1:{self.ports['http_port']}/"
            if self.options.on_dashboard is not None:
                self.options.on_dashboard(url, self.token)
            for train_id in self.services:
                await self._send(train_id, self._start_message())
            wall_started = time.perf_counter()
            tasks = [asyncio.create_task(self._event(e)) for e in self.scenario.events]
            tasks.append(asyncio.create_task(self._watch()))
            shot = None
            if self.options.screenshot is not None and self.options.screenshot_at_s is not None:
                shot = asyncio.create_task(self._screenshot(url))
            await self._unless_failed(self._sleep_until(self.end_s))
            wall = time.perf_counter() - wall_started
            for task in tasks:
                task.cancel()
            for outcome in await asyncio.gather(*tasks, return_exceptions=True):
                if isinstance(outcome, Exception):  # an event that failed (not cancelled)
                    raise outcome
            if shot is not None:
                # not cancelled with the rest: on a busy machine the browser may still be
                # drawing when the run ends (the ground and its page are still up), and
                # a cancelled photograph left the report without one, or its reason.
                # dashboard_screenshot bounds its own waits
                await shot
            for train_id in self.services:
                await self._send(train_id, {"op": "stop"})
            await self._ready(list(self.reported), ANSWER_TIMEOUT_S, self.reported)
            ground_counters = await self._stop_ground()
            ended = True
        finally:
            for task in tasks:
                task.cancel()
            control.close()
            # a run that failed does not wait for its processes: each is ended at once
            self._end_processes(at_once=not ended)
            await self._close_wire()
        return self._result(wall, ground_counters)

    async def _listen_control(self) -> asyncio.Server:
        """Listen for the processes' control wire (on ``control_port``, 0: a free one)."""
        port = self.options.control_port
        try:
            control = await asyncio.start_server(self._accept, "127.0.0.1", port, limit=MAX_LINE)
        except OSError as exc:
            raise PortUnavailable.bind_failed("control_port", port, exc) from None
        self.control_port = int(control.sockets[0].getsockname()[1])
        return control

    async def _close_wire(self) -> None:
        """Close every connection of the control wire and let their readers end (a reader
        left to asyncio.run's cancellation prints a traceback on Python 3.11)."""
        for writer in self.connections:
            writer.close()
        readers = [t for t in self.readers if not t.done()]
        if readers:
            await asyncio.wait(readers, timeout=END_TIMEOUT_S)

    async def _unless_failed(self, awaitable: Awaitable[T]) -> T:
        """``awaitable``'s result, unless a process fails first: then its failure."""
        task = asyncio.ensure_future(awaitable)
        failed = asyncio.ensure_future(self.failed.wait())
        try:
            await asyncio.wait({task, failed}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            failed.cancel()
            if not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await task
        self._raise_failure()
        return task.result()

    def _raise_failure(self) -> None:
        if self.failure is not None:
            raise self.failure

    def _fail(self, error: RailpilotError) -> None:
        """A process's failure: the first one stops the run (the others follow from it)."""
        if self.failure is None:
            self.failure = error
        self.failed.set()

    def _start_message(self) -> dict[str, Any]:
        assert self.clock is not None
        return {
            "op": "start",
            "speedup": self.clock.speedup,
            "wall_origin_s": self.clock.wall_origin_s,
            "link_port": self.ports["link_port"],
        }

    def _start_ground(self, start_at_s: float | None) -> None:
        args = live_ground.GroundArgs(
            self.control_port,
            self.path,
            self.seed,
            self.store_path,
            self.token,
            self.secret,
            start_at_s=start_at_s,
            log_level=self.options.log_level,
            **self.ports,
        )
        self.ground = self.context.Process(
            target=live_ground.run, args=(args,), name="ground", daemon=True
        )
        self.ground.start()

    async def _ready(
        self,
        names: list[int | str],
        timeout_s: float,
        futures: Mapping[Any, asyncio.Future[None]] | None = None,
    ) -> None:
        """Wait for every process in ``names`` to say hello (or to report); a process that
        failed, or has ended, or the timeout, stops the run with its name and why."""
        futures = self.hello if futures is None else futures
        deadline = time.monotonic() + timeout_s
        while not all(futures[n].done() for n in names):
            self._raise_failure()
            for name in names:
                if not futures[name].done():
                    self._check_alive(name)
            if time.monotonic() > deadline:
                late = [str(n) for n in names if not futures[n].done()]
                raise LiveRunError(f"no answer within {timeout_s:g} s from: {', '.join(late)}")
            await asyncio.wait([futures[n] for n in names if not futures[n].done()], timeout=0.1)
        self._raise_failure()

    def _check_alive(self, name: int | str) -> None:
        """Stop the run if the process ``name`` has ended: once its wire has closed (what
        it said last, its failure, has been read by then), or a moment after."""
        process = self.ground if name == "ground" else self.trains[int(name)]
        if process.exitcode is None:
            return
        now = time.monotonic()
        seen = self.ended_at.setdefault(name, now)
        if name in self.closed or name not in self.writers or now - seen > WIRE_GRACE_S:
            self._raise_failure()
            raise LiveRunError(f"the {process.name} process ended (exit code {process.exitcode})")

    async def _ground_says(self, op: str, timeout_s: float) -> dict[str, Any]:
        """The ground's next message ``op`` (any other before it is passed over); its
        failure, its end or the timeout stops the run."""
        deadline = time.monotonic() + timeout_s
        while True:
            try:  # what it said before it ended first (its counters, at the end)
                message = self.ground_messages.get_nowait()
            except asyncio.QueueEmpty:
                self._raise_failure()
                self._check_alive("ground")
                if time.monotonic() > deadline:
                    raise LiveRunError(
                        f"the ground did not answer ({op}) within {timeout_s:g} s"
                    ) from None
                try:
                    async with asyncio.timeout(0.1):
                        message = await self.ground_messages.get()
                except TimeoutError:
                    continue
            if message["op"] == op:
                return message

    async def _ground_up(self, timeout_s: float) -> dict[str, Any]:
        message = await self._ground_says("up", timeout_s)
        self.ground_up = True
        return message

    async def _stop_ground(self) -> dict[str, Any]:
        await self._send("ground", {"op": "stop"})
        message = await self._ground_says("counters", ANSWER_TIMEOUT_S)
        counters: dict[str, Any] = message["counters"]
        self.retiming = message["retiming"]
        await asyncio.to_thread(self.ground.join, ANSWER_TIMEOUT_S)
        return counters

    def _end_processes(self, at_once: bool) -> None:
        """Wait for the processes to end (at the end of a run: they are ending), or, when
        ``at_once`` (a run that failed), end them (SIGTERM: no traceback)."""
        processes = [p for p in [self.ground, *self.trains.values()] if p is not None]
        processes = [p for p in processes if p.pid is not None]  # not those never started
        if at_once:
            for process in processes:
                if process.is_alive():
                    process.terminate()
        for process in processes:
            process.join(timeout=END_TIMEOUT_S)
            if process.is_alive():
                process.kill()
                process.join()

    # ------------------------------------------------------------------ the wire

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.connections.add(writer)
        reading = asyncio.current_task()
        if reading is not None:
            self.readers.add(reading)
        try:
            hello = await receive(reader)
        except ValueError:  # not JSON, or not an object: not one of ours
            hello = None
        name = hello_name(hello, self.secret, self.services)
        if name is None:
            writer.close()
            return
        self.writers[name] = writer
        self.closed.discard(name)
        if not self.hello[name].done():
            self.hello[name].set_result(None)
        elif name == "ground":
            # a restarted ground: it starts (on the same clock) when its down time is over
            await self._send("ground", self._start_message())
        while (message := await receive(reader)) is not None:
            if message["op"] == "failed":
                what = "ground" if name == "ground" else f"train {name}"
                self._fail(failure_error(what, message))
            elif name == "ground":
                self.ground_messages.put_nowait(message)
            elif message["op"] == "seen":
                self.seen[int(name)] = message
            elif message["op"] == "result":
                self.results[int(name)] = message
                if not self.reported[int(name)].done():
                    self.reported[int(name)].set_result(None)
        if self.writers.get(name) is writer:  # not a restarted ground's predecessor
            self.closed.add(name)

    async def _send(self, name: int | str, message: dict[str, Any]) -> None:
        writer = self.writers.get(name)
        if writer is None or writer.is_closing():
            return
        with contextlib.suppress(ConnectionError):
            await send(writer, message)

    # ------------------------------------------------------------------ time

    def _now_t(self) -> float:
        assert self.clock is not None
        return self.clock() - self.scenario.epoch_s

    async def _sleep_until(self, t: float) -> None:
        assert self.clock is not None
        await asyncio.sleep(max(self.clock.wall_s(t - self._now_t()), 0.0))

    # ------------------------------------------------------------------ the trackside

    async def _watch(self) -> None:
        """Once a second: the trains' last reports to the trackside, the cab views back."""
        shown: dict[int, CabView] = {}
        t = WATCH_S
        while True:
            await self._sleep_until(t + LOOK_AFTER_S)
            seen = {
                i: TrainSeen(m["head_m"], m["speed_mps"], m["next_stop_m"])
                for i, m in self.seen.items()
                if not m["finished"]
            }
            views = self.trackside.look(t, self.scenario.epoch_s + t, seen)
            for train_id, view in views.items():
                # a train acts on a change of its cab signal only: the rest is not sent
                if shown.get(train_id) != view:
                    shown[train_id] = view
                    await self._send(
                        train_id, {"op": "cab", "red_m": view.red_signal_m, "sight_m": view.sight_m}
                    )
            t += WATCH_S

    # ------------------------------------------------------------------ the scenario

    async def _event(self, event: ScenarioEvent) -> None:
        try:
            await self._play(event)
        except RailpilotError as exc:  # the run stops now, not when the day is over
            self._fail(exc)
            raise

    async def _play(self, event: ScenarioEvent) -> None:
        await self._sleep_until(event.at_s)
        action = event.action
        entry: dict[str, Any] = {"t_s": self._now_t(), "event": event.label}
        if isinstance(action, TrainFailure):
            await self._send(action.train_id, {"op": "fail", "stand_s": action.stand_s})
            entry["train"] = action.train_id
        elif isinstance(action, GroundRestart):
            await self._restart_ground(action.down_s)
            entry["down_s"] = action.down_s
        else:
            entry["result"] = result = await self._operate(event)
            assert self.clock is not None
            tsr = self.trackside.dispatched(action, result, self.clock(), self.scenario.epoch_s)
            if tsr is not None:
                entry["tsr"] = tsr
        self.events.append(entry)

    async def _restart_ground(self, down_s: float) -> None:
        """Kill the ground (SIGKILL) and start a new process that opens the same store on
        the same ports ``down_s`` later."""
        down_at = self._now_t()
        self.ground_up = False
        self.ground.kill()
        await asyncio.to_thread(self.ground.join)
        self.writers.pop("ground", None)
        self.restarts.append({"down_at_s": down_at})
        kv(log, logging.INFO, "ground_killed", t_s=down_at, down_s=down_s)
        self._start_ground(down_at + down_s)
        assert self.clock is not None
        up = await self._ground_up(ANSWER_TIMEOUT_S + self.clock.wall_s(down_s))
        kv(log, logging.INFO, "ground_restarted", t_s=up["at_s"], **up["restored"])
        self.restarts[-1] |= {"up_at_s": up["at_s"], "restored": up["restored"]}

    async def _operate(self, event: ScenarioEvent) -> dict[str, Any]:
        """The dispatcher's operation through the ground's admin port; while the ground is
        down it is tried again ``RETRY_WHILE_DOWN_S`` later."""
        request = {"op": event.label, **event.fields, "actor": "scenario"}
        if event.label == "tsr_set":  # the scenario's intent: sent whatever trains it catches
            request["confirm"] = True
        while True:
            if self.ground_up:
                try:
                    response = await admin_request(request, port=self.ports["admin_port"])
                    break
                except (OSError, TimeoutError, AdminError):
                    pass  # killed under the request: asked again when it is back
            await self._sleep_until(self._now_t() + RETRY_WHILE_DOWN_S)
        if not response.get("ok"):
            raise LiveRunError(f"the ground refused {event.label} at {event.at_s:g} s: {response}")
        result: dict[str, Any] = response["result"]
        return result

    async def _screenshot(self, url: str) -> None:
        assert self.options.screenshot is not None and self.options.screenshot_at_s is not None
        await self._sleep_until(self.options.screenshot_at_s)
        from railpilot.web.browser import dashboard_screenshot

        trains = len([m for m in self.seen.values() if not m["finished"]])
        # the browser in a process of its own, below the run's priority: while chromium
        # started and rendered, the trains' one-second steps took 60-220 ms of wall clock
        # on two cores (4-13 s of the run's at 60x), late enough to fail their links
        # (docs/line-run.md, "Live")
        photographer = ProcessPoolExecutor(1, mp_context=self.context, initializer=_lower_priority)
        try:
            self.screenshot = await asyncio.wrap_future(
                photographer.submit(dashboard_screenshot, url, self.options.screenshot, trains)
            )
        except Exception as exc:  # the browser's trouble is reported, the run goes on
            self.screenshot = {"screenshot": None, "skipped": f"the screenshot failed: {exc}"}
        finally:
            await asyncio.to_thread(photographer.shutdown)
        self.screenshot["t_s"] = self.options.screenshot_at_s

    # ------------------------------------------------------------------ what it gives

    def _result(self, wall_s: float, ground_counters: dict[str, Any]) -> LineResult:
        drivers = {
            i: TrainRun(
                self.services[i],
                [SectionRun(**s) for s in r["sections"]],
                bool(r["finished"]),
                int(r["red_signal_stops"]),
                int(r["running_times_received"]),
                {(int(a), int(b)): float(t) for a, b, t in r["running_times"]},
            )
            for i, r in sorted(self.results.items())
        }
        results = self.results.values()
        link = {
            "ground": ground_counters,
            "onboard": _sum_counts([r["onboard"] for r in results]),
            "channel": channel_totals(ChannelCounters(**r["channel"]) for r in results),
            "connects": sum(r["connects"] for r in results),
            "link_failures": sum(r["link_failures"] for r in results),
        }
        store = open_store(self.store_path)
        try:
            audit_log, snapshot = store.audit_log(), store.load()
        finally:
            store.close()
        traces = self.trackside.traces()
        result = LineResult(
            self.scenario,
            self.seed,
            "advised",
            drivers,
            traces,
            [TsrViolation(**seen) for seen in self.trackside.tsr_violations],
            [SignalPassedAtRed(**seen) for seen in self.trackside.passed_at_red],
            [
                Overspeed(**spell)
                for spell in static_overspeeds(self.scenario.line, traces, self.trackside.trains)
            ],
            link,
            {i: {int(k): v for k, v in r["tsr_applied"].items()} for i, r in self.results.items()},
            wall_s,
            sorted(self.events, key=lambda e: e["t_s"]),
            self.restarts,
            audit_log,
            snapshot,
            {i: list(r["active_tsrs"]) for i, r in self.results.items()},
            self.end_s,
            live=LiveRunInfo(self.options.speedup, self.screenshot),
            retiming=self.retiming,
        )
        return result


def _train_shape(service: Service) -> TrainShape:
    from railpilot.onboard.drive import train_preset

    preset = train_preset(service.kind)
    return TrainShape(service.direction, float(preset.train.length_m), preset.category)


def _sum_counts(dicts: list[dict[str, Any]]) -> dict[str, Any]:
    """Counter dicts summed key by key (nested ones too: ``rejected`` per check)."""
    total: dict[str, Any] = {}
    for d in dicts:
        for key, value in d.items():
            if isinstance(value, dict):
                total[key] = _sum_counts([total.get(key, {}), value])
            else:
                total[key] = total.get(key, 0) + value
    return total


__all__ = ["DEFAULT_SPEEDUP", "LiveOptions", "LiveRunError", "run_live"]
