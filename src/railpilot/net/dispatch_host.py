"""The ground dispatch application on the live server: :class:`DispatchHost`.

A thin adapter (DESIGN habit 2) that gives a :class:`~railpilot.net.server.GroundServer`'s
:class:`~railpilot.ground.host.GroundHost` a :class:`~railpilot.ground.dispatch.GroundDispatch`
and drives it in wall-clock time:

- every event of every connection goes to the core (the host's ``on_event``);
- the core's clock ticks every :data:`TICK_S` (TSR expiry, target points from occupancy);
- the commands the core returns are carried out by the host (which commits to the store
  before any frame leaves), never from inside the server's own event handling: a delivery
  re-enters the connection that is reporting the event;
- a dispatcher's request (admin port, HTTP, CLI: one schema, ground/operations.py) is
  parsed once, carried out by the core, and its deliveries sent in batches so a broadcast
  to a thousand trains does not hold up the receive path; a TSR that would catch trains
  already above its limit is refused with the list of them until the request confirms it
  (ground/tsr_warning.py);
- at start, after the server has restored its records, the core takes back the TSRs,
  target-point ids, command numbers and declared restrictions from the store.

Declared restrictions live in the store's audit log (``restriction_set`` and
``restriction_clear`` entries, written before their target points leave) and are replayed
from it at start.

Threading: everything runs on the server's event loop thread, except each tick's block
occupancy: a pure function of a copy of the trains' last reports, computed in a worker
thread (:meth:`DispatchHost._on_tick`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from railpilot.ground.dispatch import Command, GroundDispatch, Outcome, command_trains
from railpilot.ground.host import refuse_keyless
from railpilot.ground.journal import declared_restrictions
from railpilot.ground.occupancy import Occupancy
from railpilot.ground.operations import Status, parse_operation
from railpilot.ground.tsr_warning import refuse_unconfirmed
from railpilot.line.model import RailLine

from .logfmt import kv
from .server import GroundServer
from .timers import LinkClock

log = logging.getLogger("railpilot.net.dispatch_host")

#: How often the core's clock ticks [s] (target points follow occupancy this fast).
TICK_S = 1.0
#: Deliveries per batch when an operation reaches many trains.
BATCH = 50


class DispatchHost:
    """The dispatch core on a live server (module docstring).

    ``clock``: the ground clock [s since the epoch], the server's own by default (its
    ticks come every ``tick_s`` seconds of it). ``dispatch``: the core, if it was built
    elsewhere (:meth:`~railpilot.ground.assembly.GroundParts.new_dispatch`, with the
    ground's retimer); by default a new one for ``line``.
    """

    def __init__(
        self,
        server: GroundServer,
        line: RailLine,
        *,
        clock: LinkClock | None = None,
        tick_s: float = TICK_S,
        dispatch: GroundDispatch | None = None,
    ) -> None:
        timers = server.config.timers
        self.server = server
        self.line = line
        if dispatch is None:
            dispatch = GroundDispatch(line, validity_s=timers.cycle_s * timers.timeout_cycles)
        self.dispatch = dispatch
        self.host = server.ground_host
        self.host.dispatch = self.dispatch
        self._clock = server.clock if clock is None else clock
        self.tick_s = tick_s
        self._queued: list[Command] = []
        self._flush_scheduled = False
        self._ticker: asyncio.TimerHandle | None = None
        self._started = False
        #: True once :meth:`start` has restored the core from the store (and stays so):
        #: before, the core holds none of the ground's TSRs, restrictions or trains, and
        #: what it would show (the dashboard) is not the ground's state
        self.restored = False
        self._tasks: set[asyncio.Task[dict[int, str]]] = set()
        #: computes each tick's block occupancy, one at a time (:meth:`_on_tick`)
        self._worker: ThreadPoolExecutor | None = None
        server.command_sink = self._on_commands

    # ------------------------------------------------------------------ lifecycle

    def start(self) -> None:
        """Restore from the store and start ticking (call after ``server.start()``, on
        its loop)."""
        if self._started:
            return
        self._started = True
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="occupancy")
        store = self.server.store
        if store is not None:
            restrictions = declared_restrictions(store.audit_log())
            self.dispatch.restore(store.load(), self._clock(), restrictions)
            kv(
                log,
                logging.INFO,
                "dispatch_restored",
                tsrs=len(self.dispatch.tsrs.tsrs()),
                restrictions=len(restrictions),
            )
        self.restored = True
        self._schedule_tick()

    def stop(self) -> None:
        """Stop ticking. Target points still waiting for their batch are dropped: they are
        not in the store, so a restarted ground resumes from what the trains were sent and
        sends each what holds then."""
        if self._ticker is not None:
            self._ticker.cancel()
            self._ticker = None
        if self._worker is not None:
            self._worker.shutdown(wait=False, cancel_futures=True)
            self._worker = None
        for task in self._tasks:
            task.cancel()
        self._started = False

    def _schedule_tick(self) -> None:
        loop = asyncio.get_running_loop()
        self._ticker = loop.call_later(self._clock.wall_s(self.tick_s), self._on_tick)

    def _on_tick(self) -> None:
        # The block occupancy, a pure function of a copy of the trains' last reports, is
        # computed in a worker thread: at a thousand trains it costs 15-40 ms, which on
        # the loop every train's frame would wait for. The GIL passes back to the loop
        # every few ms (sys.getswitchinterval). Then, on the loop, TSR expiry and the
        # target points, sent in batches (docs/scaling.md).
        loop = asyncio.get_running_loop()
        now = self._clock()
        try:
            self.sync()
            reports = self.dispatch.registry.reports()
        except Exception:  # a bug here must not stop the clock of a running ground
            log.exception("dispatch tick failed")
        else:
            assert self._worker is not None  # ticks run only between start() and stop()
            future = loop.run_in_executor(self._worker, self.dispatch.occupancy_from, reports, now)
            future.add_done_callback(lambda f: self._tick_targets(now, f))
        if self._started:
            self._schedule_tick()

    def _tick_targets(self, now_s: float, occupancy: asyncio.Future[Occupancy]) -> None:
        if occupancy.cancelled() or not self._started:
            return
        try:
            self.dispatch.tick_occupancy(now_s, occupancy.result())
            commands = self.dispatch.tick_targets(now_s)
        except Exception:
            log.exception("dispatch tick failed")
            return
        if len(commands) <= BATCH:
            self._carry_out(commands)
        else:  # a burst (every train at start-up): in batches, yielding between them
            task = asyncio.get_running_loop().create_task(self._carry_out_paced(tuple(commands)))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)

    def sync(self) -> None:
        """What raises no event: which trains have an open connection."""
        self.host.sync(self.server.open_connections())

    # ------------------------------------------------------------------ the link

    def _on_commands(self, commands: list[Command]) -> None:
        self._queued += commands
        if self._flush_scheduled:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop (a test feeding events by hand): at once
            self._flush()
            return
        self._flush_scheduled = True
        loop.call_soon(self._flush)

    def _flush(self) -> None:
        self._flush_scheduled = False
        commands, self._queued = self._queued, []
        self._carry_out(commands)

    # ------------------------------------------------------------------ the dispatcher

    async def execute(
        self, op: object, fields: Mapping[str, Any], actor: str, *, confirm: bool = False
    ) -> dict[str, Any]:
        """Parse and carry out one operation; returns the result, with per-train delivery
        outcomes under ``deliveries`` (sent in batches, yielding to the loop between).
        Raises :class:`OperationError` (nothing done); a TSR that would catch trains above
        its limit raises :class:`~railpilot.ground.tsr_warning.TsrWarning` unless
        ``confirm``."""
        decided = self._decide(op, fields, actor, confirm)
        if isinstance(decided, dict):
            return decided
        deliveries = await self._carry_out_paced(decided.commands)
        return self._answer(op, actor, decided, deliveries)

    def execute_now(
        self, op: object, fields: Mapping[str, Any], actor: str, *, confirm: bool = False
    ) -> dict[str, Any]:
        """:meth:`execute` with every delivery made at once (a dispatcher's form: a TSR
        goes to the trains it concerns, a few dozen at most on one line)."""
        decided = self._decide(op, fields, actor, confirm)
        if isinstance(decided, dict):
            return decided
        return self._answer(op, actor, decided, self._carry_out(list(decided.commands)))

    def _decide(
        self, op: object, fields: Mapping[str, Any], actor: str, confirm: bool
    ) -> Outcome | dict[str, Any]:
        """The core's outcome of the operation (its record in the store made), or the
        status for ``status``."""
        now = self._clock()
        operation = parse_operation(op, fields, line=self.line, now_s=now)
        self._check_keys(operation)
        if isinstance(operation, Status):
            self.sync()
            return {**self.server.status(), "dispatch": self.dispatch.status(now)}
        self._flush()  # every train where it last said it was
        refuse_unconfirmed(
            operation,
            self.dispatch.registry.reports(),
            now,
            validity_s=self.dispatch.registry.validity_s,
            confirm=confirm,
        )
        return self.host.operate(operation, actor, now)

    @staticmethod
    def _answer(
        op: object, actor: str, outcome: Outcome, deliveries: Mapping[int, str]
    ) -> dict[str, Any]:
        kv(log, logging.INFO, "operation", op=op, actor=actor, trains=len(deliveries))
        return {**outcome.result, "deliveries": {str(t): r for t, r in sorted(deliveries.items())}}

    def _check_keys(self, operation: object) -> None:
        keys = self.server.keys
        if self.server.config.require_auth and keys is not None:
            refuse_keyless(operation, keys, "in the server's key file ")

    # ------------------------------------------------------------------ carrying out

    def _send(self, command: Command, train_ids: list[int]) -> dict[int, str]:
        """Carry out one command for ``train_ids`` through the host, now."""
        return self.host.carry_out_for(command, train_ids, self.server.clock())

    def _carry_out(self, commands: list[Command]) -> dict[int, str]:
        results: dict[int, str] = {}
        for command in commands:
            results |= self._send(command, list(command_trains(command)))
        self._log_errors(results)
        return results

    async def _carry_out_paced(self, commands: tuple[Command, ...]) -> dict[int, str]:
        results: dict[int, str] = {}
        for command in commands:
            ids = command_trains(command)
            for start in range(0, len(ids), BATCH):
                results |= self._send(command, list(ids[start : start + BATCH]))
                await asyncio.sleep(0)
        self._log_errors(results)
        return results

    @staticmethod
    def _log_errors(results: Mapping[int, str]) -> None:
        for train_id, outcome in sorted(results.items()):
            if outcome.startswith("error"):
                kv(log, logging.WARNING, "delivery_refused", train=train_id, error=outcome)
