"""Trains and the ground over the simulated radio, in simulated time (docs/cosim.md).

:class:`LinkSim` runs the live system's protocol and application code with another
transport. Each train has an :class:`~railpilot.link.OnboardEndpoint`, kept across
reconnects as ``net/client.py`` keeps it. The ground has one
:class:`~railpilot.link.GroundEndpoint` per connection, all sharing one ``records``
mapping as ``net/server.py`` does, and the dispatch core
(:class:`~railpilot.ground.dispatch.GroundDispatch`) as ``net/dispatch_host.py`` runs it.
Frames cross a :class:`~railpilot.cosim.channel.RadioChannel` per train.

It is a discrete-event simulation. The queue holds packet arrivals, each endpoint's next
deadline (``next_deadline_s``), the dispatch core's tick every ``tick_s`` and the trains'
reconnect attempts. Nothing waits on a wall clock, so a day runs as fast as the events
can be processed, and the same seed gives the same run, event for event.

Connections. A connection is opened when the train's radio is up where it stands. When
either end gives up on the link (``LinkFailed``: a timeout, or too many rejected frames
in a row), the connection is closed at both ends at that instant, as the live adapters
close their sockets. Packets still in flight on it are dropped. The onboard tries again
after its own back-off (``reconnect_delay_s``, with jitter from a seeded generator).
A train that registers on a new connection takes its deliveries over from the old one.

The ground's store. With a :class:`~railpilot.ground.store.GroundStore`, the ground keeps
its TSRs, deliveries, acknowledgements and audit log there as the live ground does (the
same :class:`~railpilot.ground.journal.GroundJournal`): each step's changes are committed
before its frames leave, each dispatcher's request before it is carried out.
:meth:`LinkSim.restart_ground` then kills the ground as ``kill -9`` would (every
connection drops, nothing more is written, everything in memory is gone) and starts it
again later from the store alone.

Trains. A train is anything that says where it is (:class:`Mover`): here a constant-speed
:class:`~railpilot.net.client.Trajectory`, as the load test uses. It hears every
onboard event (``on_event``), so a driving model can obey what the link brings.
"""

from __future__ import annotations

import heapq
import itertools
import random
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from railpilot.errors import ConfigError, is_finite_number
from railpilot.ground.dispatch import (
    CancelTsrOn,
    Command,
    DeliverTsr,
    GroundDispatch,
    KeptCommand,
    Outcome,
    SendRunningTimes,
    SendTargetPoint,
    command_trains,
)
from railpilot.ground.journal import GroundJournal, command_request, declared_restrictions
from railpilot.ground.operations import Operation
from railpilot.ground.retimer import OnlineRetimer
from railpilot.ground.store import GroundStore
from railpilot.line.model import RailLine
from railpilot.link import (
    Deregistered,
    DeregisterReason,
    Event,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    LinkFailed,
    OnboardConfig,
    OnboardEndpoint,
    OnboardState,
    PlannedCurve,
    Registered,
    RunningInfo,
    TrainDeregistered,
    TrainRecord,
    TrainRegistered,
    TsrApplied,
)
from railpilot.link.config import REPLAY_WINDOW_S
from railpilot.net.client import Mover, Trajectory
from railpilot.net.server import counters_dict

from .channel import ChannelModel, RadioChannel, channel_totals

#: The dispatch core's tick [s], as on the live ground (net/dispatch_host.py TICK_S).
TICK_S = 1.0


@dataclass
class SimTrain:
    """One train of a :class:`LinkSim`: its onboard configuration, how it moves, and when
    its onboard unit comes up [s after the start of the run]."""

    config: OnboardConfig
    mover: Mover
    start_s: float = 0.0
    #: every onboard event, with the simulated time [s since the epoch]
    on_event: Callable[[Event, float], None] | None = None
    #: the onboard's planned-curve report due at a time [s since the start of the run]
    #: (None: none due), asked for at each onboard tick while registered
    report: Callable[[float], PlannedCurve | None] | None = None


@dataclass
class _Connection:
    serial: int
    train_id: int
    ground: GroundEndpoint
    open: bool = True


@dataclass
class TrainLinkStats:
    """What happened on one train's link during the run."""

    connects: int = 0
    connect_attempts: int = 0
    registrations: int = 0
    link_failures: int = 0
    tsr_applied: Counter[int] = field(default_factory=Counter)  # session -> times applied

    def as_dict(self) -> dict[str, Any]:
        return {
            "connects": self.connects,
            "connect_attempts": self.connect_attempts,
            "registrations": self.registrations,
            "link_failures": self.link_failures,
            "tsr_applied": {str(k): v for k, v in sorted(self.tsr_applied.items())},
        }


class LinkSim:
    """The trains' onboard endpoints, the ground's endpoints and dispatch core, and the
    radio between them, in simulated time (module docstring).

    Parameters
    ----------
    line
        The line the ground dispatches (block occupancy, target points, TSR routes).
    trains
        The trains; ids must be unique and have keys in ``keys``.
    channel
        What the radio does to packets (its outages in seconds from ``start_s``).
    keys
        The per-train keys (HMAC-SHA256 on every frame, as on the live link).
    seed
        Seeds every channel (per train) and the reconnect jitter.
    start_s
        The simulated clock at the start of the run [s since the epoch]: frame timestamps
        and TSR validity are epoch times, as on the live link.
    ground_id
        The ground's link id.
    store
        The ground's store (module docstring); None: the ground keeps everything in
        memory, and cannot be restarted.
    retimer
        Makes the ground's re-timing in the loop (ground/retimer.py), for the first
        ground and for each restarted one (None: no re-timing).
    """

    def __init__(
        self,
        line: RailLine,
        trains: Sequence[SimTrain],
        channel: ChannelModel,
        keys: KeyStore,
        *,
        seed: int = 0,
        start_s: float = 1_800_000_000.0,
        ground_id: int = 1,
        tick_s: float = TICK_S,
        store: GroundStore | None = None,
        retimer: Callable[[], OnlineRetimer] | None = None,
    ) -> None:
        if not trains:
            raise ConfigError("trains", [], "at least one train")
        ids = [t.config.train_id for t in trains]
        duplicates = sorted({i for i in ids if ids.count(i) > 1})
        if duplicates:
            raise ConfigError("trains", duplicates, "unique train ids")
        if not is_finite_number(start_s) or start_s <= 0:
            raise ConfigError("start_s", start_s, "a time > 0 [s since the epoch]")
        timers = trains[0].config.timers
        self.line = line
        self.start_s = float(start_s)
        self.now_s = self.start_s
        self.keys = keys
        self.tick_s = tick_s
        self.ground_config = GroundConfig(ground_id=ground_id, timers=timers)
        self.records: dict[int, TrainRecord] = {}
        self._retimer = retimer
        self.dispatch = self._new_dispatch()
        self.journal = GroundJournal(store) if store is not None else None
        #: whether the ground is running (:meth:`restart_ground`)
        self.ground_up = True
        #: each restart: when the ground went down and came up [s since the start of the
        #: run], and what it restored (GroundJournal.restore's summary)
        self.restarts: list[dict[str, Any]] = []
        self.trains = {t.config.train_id: t for t in trains}
        self.onboard = {i: OnboardEndpoint(t.config, keys) for i, t in self.trains.items()}
        self.channels = {i: RadioChannel(channel, seed, i, self.start_s) for i in self.trains}
        self._jitter = {i: random.Random(f"railpilot-reconnect:{seed}:{i}") for i in self.trains}
        self.stats = {i: TrainLinkStats() for i in self.trains}
        #: train id -> (position, speed) of its onboard's running info (:meth:`_refresh`)
        self._seen: dict[int, tuple[float, float]] = {}
        self.live: dict[int, _Connection] = {}  # train id -> its open connection
        self._connections: dict[int, _Connection] = {}  # serial -> connection, open or not
        #: train id -> the serial of the onboard's open connection
        self._onboard_serial: dict[int, int] = {}
        self._serials = itertools.count(1)
        self._queue: list[tuple[float, int, str, Any]] = []
        self._order = itertools.count()  # ties keep the order they were queued in
        self._deadline: dict[tuple[str, int], float] = {}
        self._handlers: dict[str, Callable[[Any], None]] = {}  # event kind -> its method
        #: trains leaving the line (:meth:`retire`), until their deregistration is through
        self.retiring: set[int] = set()
        #: trains that have left the line: they never connect again
        self.retired: set[int] = set()
        for train_id, train in self.trains.items():
            self._push(self.start_s + train.start_s, "connect", train_id)
        self._push(self.start_s + tick_s, "dispatch_tick", None)

    # ------------------------------------------------------------------ running

    def run_until(self, t_s: float) -> None:
        """Process every event up to ``t_s`` seconds after the start of the run."""
        end = self.start_s + t_s
        queue = self._queue
        handlers = self._handlers
        while queue and queue[0][0] <= end:
            at, _, kind, item = heapq.heappop(queue)
            self.now_s = at
            handler = handlers.get(kind)
            if handler is None:
                # each kind's method looked up once (millions of events in a day)
                handler = handlers[kind] = getattr(self, f"_on_{kind}")
            handler(item)
        self.now_s = max(self.now_s, end)

    def call_at(self, t_s: float, action: Callable[[], None]) -> None:
        """Run ``action`` at ``t_s`` seconds after the start of the run, in its turn among
        the events (a scenario's TSR, a failure, the trackside's signals)."""
        self._push(self.start_s + t_s, "call", action)

    def retire(self, train_id: int) -> None:
        """The train leaves the line: it deregisters (leaving the main line) now if it is
        registered, else as soon as it has registered again, and once the ground has
        confirmed that, it never connects again.

        A train that just left without deregistering would stay on the ground as a train
        that stopped reporting, where it was last seen: a conservative ground keeps its
        block occupied and holds the train behind it at a red signal for ever.
        """
        self.retiring.add(train_id)
        self._leave(train_id)

    def _leave(self, train_id: int) -> None:
        serial = self._serial_of(train_id)
        if self.onboard[train_id].state is OnboardState.REGISTERED and serial is not None:
            self.onboard[train_id].deregister(DeregisterReason.LEAVING_MAIN_LINE, self.now_s)
            self._after_onboard(train_id, serial)

    def restart_ground(self, down_s: float) -> None:
        """Kill the ground now, as ``kill -9`` would, and start it again ``down_s`` seconds
        later from its store alone (module docstring).

        The killed process writes nothing more; the operating system closes its sockets,
        so every train sees its connection drop at once and tries again after its
        back-off; frames in flight are lost. Until it is up again no connection is
        accepted and the dispatch core does not tick.
        """
        if self.journal is None:
            raise ConfigError("store", None, "a ground store (without one, a restart loses all)")
        if not is_finite_number(down_s) or down_s < 0:
            raise ConfigError("down_s", down_s, "a time >= 0 [s]")
        if not self.ground_up:
            raise ConfigError("restart_ground", self.now_s - self.start_s, "a running ground")
        self.ground_up = False
        for conn in list(self._connections.values()):
            self._close(conn)
        self.restarts.append({"down_at_s": self.now_s - self.start_s})
        # everything the process held in memory
        self.records = {}
        self.live.clear()
        self.dispatch = self._new_dispatch()
        self._push(self.now_s + down_s, "ground_start", None)

    def operate(self, operation: Operation, actor: str) -> Outcome:
        """A dispatcher's operation, now, as ``DispatchHost`` carries it out: the core
        decides, what it changed on the line goes to the store, then its deliveries leave.
        Raises :class:`~railpilot.ground.operations.OperationError` (nothing done)."""
        outcome = self.dispatch.execute(operation, actor, self.now_s)
        if self.journal is not None:
            self.journal.record_operation(operation, outcome.result, actor, self.now_s)
        self.execute(outcome.commands)
        return outcome

    def execute(self, commands: Iterable[Command]) -> None:
        """Carry out the dispatch core's commands now (as ``DispatchHost`` does)."""
        for command in commands:
            for train_id in command_trains(command):
                self._deliver(train_id, command)

    # ------------------------------------------------------------------ what a train is doing

    def position(self, train_id: int, now_s: float | None = None) -> tuple[float, float]:
        """``(position_m, speed_mps)`` of ``train_id`` at ``now_s`` (default: now)."""
        train = self.trains[train_id]
        at = self.now_s if now_s is None else now_s
        return train.mover.state(at - self.start_s - train.start_s)

    def link_report(self) -> dict[str, Any]:
        """The link statistics of the run: frames, losses, resends, timeouts, rejections
        by check (ground and onboard), and the channel's counts."""
        ground = counters_dict(c.ground.counters for c in self._connections.values())
        onboard = counters_dict([e.counters for e in self.onboard.values()])
        return {
            "ground": ground,
            "onboard": onboard,
            "channel": channel_totals(c.counters for c in self.channels.values()),
            "connects": sum(s.connects for s in self.stats.values()),
            "link_failures": sum(s.link_failures for s in self.stats.values()),
        }

    # ------------------------------------------------------------------ the queue

    def _push(self, at_s: float, kind: str, item: Any) -> None:
        heapq.heappush(self._queue, (at_s, next(self._order), kind, item))

    def _schedule(self, side: str, ident: int, deadline: float | None) -> None:
        """Keep one live deadline per endpoint; older entries are skipped when popped."""
        key = (side, ident)
        if deadline is None:
            self._deadline.pop(key, None)
            return
        deadline = max(deadline, self.now_s)
        if self._deadline.get(key) == deadline:
            return
        self._deadline[key] = deadline
        self._push(deadline, f"{side}_tick", (ident, deadline))

    def _due(self, side: str, ident: int, deadline: float) -> bool:
        if self._deadline.get((side, ident)) != deadline:
            return False
        del self._deadline[(side, ident)]
        return True

    # ------------------------------------------------------------------ events

    def _on_call(self, action: Callable[[], None]) -> None:
        action()

    def _on_ground_start(self, _: None) -> None:
        """The restarted ground rebuilds its records and its dispatch core from the store,
        as ``GroundServer.start`` and ``DispatchHost.start`` do."""
        assert self.journal is not None  # restart_ground needs it
        store = self.journal.store
        not_before_s = self.now_s - REPLAY_WINDOW_S  # frames older than this are replays
        self.ground_config = replace(self.ground_config, not_before_s=not_before_s)
        snapshot = store.load()
        self.records, summary = self.journal.restore(snapshot, not_before_s, self.now_s)
        self.dispatch.restore(snapshot, self.now_s, declared_restrictions(store.audit_log()))
        self.ground_up = True
        self.restarts[-1] |= {"up_at_s": self.now_s - self.start_s, "restored": summary}

    def _on_connect(self, train_id: int) -> None:
        if train_id in self.retired:
            return
        stats = self.stats[train_id]
        stats.connect_attempts += 1
        onboard = self.onboard[train_id]
        position, _ = self.position(train_id)
        if not self.ground_up or not self.channels[train_id].up(self.now_s, position):
            delay = onboard.reconnect_delay_s(self._jitter[train_id].random())
            self._push(self.now_s + delay, "connect", train_id)
            return
        stats.connects += 1
        conn = _Connection(
            next(self._serials),
            train_id,
            GroundEndpoint(self.ground_config, self.keys, self.records),
        )
        self._connections[conn.serial] = conn
        self._onboard_serial[train_id] = conn.serial
        conn.ground.connection_made(self.now_s)
        self._after_ground(conn)
        self._refresh(train_id)
        onboard.connection_made(self.now_s)
        self._after_onboard(train_id, conn.serial)

    def _on_onboard_tick(self, item: tuple[int, float]) -> None:
        train_id, deadline = item
        if self._due("onboard", train_id, deadline):
            self._refresh(train_id)
            onboard = self.onboard[train_id]
            report = self.trains[train_id].report
            if report is not None and onboard.state is OnboardState.REGISTERED:
                message = report(self.now_s - self.start_s)
                if message is not None:
                    onboard.send(message, self.now_s)
            onboard.tick(self.now_s)
            self._after_onboard(train_id, self._serial_of(train_id))

    def _on_ground_tick(self, item: tuple[int, float]) -> None:
        serial, deadline = item
        conn = self._connections[serial]
        if self._due("ground", serial, deadline) and conn.open:
            conn.ground.tick(self.now_s)
            self._after_ground(conn)

    def _on_to_ground(self, item: tuple[int, bytes]) -> None:
        serial, data = item
        conn = self._connections[serial]
        if conn.open:
            conn.ground.receive_data(data, self.now_s)
            self._after_ground(conn)

    def _on_to_train(self, item: tuple[int, bytes]) -> None:
        serial, data = item
        conn = self._connections[serial]
        if conn.open:
            self._refresh(conn.train_id)
            self.onboard[conn.train_id].receive_data(data, self.now_s)
            self._after_onboard(conn.train_id, serial)

    def _on_dispatch_tick(self, _: None) -> None:
        if self.ground_up:
            open_now = {t for t, c in self.live.items() if c.open}
            for train_id in self.dispatch.registry.train_ids():
                self.dispatch.connection(train_id, train_id in open_now)
            self.execute(self.dispatch.tick(self.now_s))
        self._push(self.now_s + self.tick_s, "dispatch_tick", None)

    def _new_dispatch(self) -> GroundDispatch:
        timers = self.ground_config.timers
        dispatch = GroundDispatch(self.line, validity_s=timers.cycle_s * timers.timeout_cycles)
        if self._retimer is not None:
            dispatch.retimer = self._retimer()
        return dispatch

    # ------------------------------------------------------------------ the two ends

    def _serial_of(self, train_id: int) -> int | None:
        """The serial of the onboard's open connection (at most one: its newest)."""
        return self._onboard_serial.get(train_id)

    def _refresh(self, train_id: int) -> None:
        """The onboard's running info from where its train is now."""
        train = self.trains[train_id]
        seen = self.position(train_id)
        if self._seen.get(train_id) == seen:
            # the same as last time (the odometry changes once a control cycle; this is
            # asked at every frame and tick): the onboard holds that running info already
            return
        self._seen[train_id] = seen
        position, speed = seen
        c = train.config
        self.onboard[train_id].update_running_info(
            RunningInfo(
                c.driver_id, c.train_number, c.loco_number, train.mover.direction, speed, position
            )
        )

    def _after_onboard(self, train_id: int, serial: int | None) -> None:
        onboard = self.onboard[train_id]
        data = onboard.data_to_send()
        if data and serial is not None:
            self._send("up", train_id, serial, data)
        failed = left = registered = False
        listener = self.trains[train_id].on_event
        for event in onboard.events():
            self._count_onboard(train_id, event)
            if listener is not None:
                listener(event, self.now_s)
            failed |= isinstance(event, LinkFailed)
            left |= isinstance(event, Deregistered)
            registered |= isinstance(event, Registered)
        if left and train_id in self.retiring:
            self.retired.add(train_id)  # the ground knows it has gone: it is off the line
        if (failed or left) and serial is not None:
            self._close(self._connections[serial], failure=failed)
        elif registered and train_id in self.retiring:
            self._leave(train_id)  # back on the radio only to say it has left
            return
        self._schedule("onboard", train_id, onboard.next_deadline_s())

    def _after_ground(self, conn: _Connection) -> None:
        ground = conn.ground
        data = ground.data_to_send()
        events = list(ground.events())
        if self.journal is not None:
            # persistence before effect, as on the live ground (a failing store stops the
            # run: in a simulation it is a bug, not a fault to ride out)
            self.journal.commit_step(ground.record, events, self.now_s)
        if data and conn.open:
            self._send("down", conn.train_id, conn.serial, data)
        failed = False
        commands: list[Command] = []
        for event in events:
            train_id = ground.train_id
            if isinstance(event, TrainRegistered):
                old = self.live.get(event.train_id)
                if old is not None and old is not conn:
                    self._close(old)
                self.live[event.train_id] = conn
            elif isinstance(event, TrainDeregistered) and self.live.get(event.train_id) is conn:
                del self.live[event.train_id]
            failed |= isinstance(event, LinkFailed)
            commands += self.dispatch.on_event(train_id, event, self.now_s)
        if failed:
            self._close(conn)
        else:
            self._schedule("ground", conn.serial, ground.next_deadline_s())
        if commands:
            self.execute(commands)

    def _send(self, direction: str, train_id: int, serial: int, data: bytes) -> None:
        position, _ = self.position(train_id)
        arrival = self.channels[train_id].transmit(direction, self.now_s, position)
        if arrival is not None:
            self._push(arrival, "to_ground" if direction == "up" else "to_train", (serial, data))

    def _close(self, conn: _Connection, *, failure: bool = True) -> None:
        """Close a connection at both ends (module docstring) and plan the reconnect
        (``failure=False``: a train that left the line, closed and not counted)."""
        if not conn.open:
            return
        conn.open = False
        conn.ground.connection_lost(self.now_s)
        self._deadline.pop(("ground", conn.serial), None)
        if self.live.get(conn.train_id) is conn:
            del self.live[conn.train_id]
        if self._onboard_serial.get(conn.train_id) != conn.serial:
            return  # an older connection the onboard had already left
        del self._onboard_serial[conn.train_id]
        onboard = self.onboard[conn.train_id]
        if onboard.state is not OnboardState.DISCONNECTED:
            onboard.connection_lost(self.now_s)
        self.stats[conn.train_id].link_failures += int(failure)
        for event in onboard.events():
            self._count_onboard(conn.train_id, event)
        if conn.train_id in self.retired:
            return
        delay = onboard.reconnect_delay_s(self._jitter[conn.train_id].random())
        self._push(self.now_s + delay, "connect", conn.train_id)

    def _count_onboard(self, train_id: int, event: Event) -> None:
        stats = self.stats[train_id]
        if isinstance(event, TsrApplied):
            stats.tsr_applied[event.tsr.session] += 1
        elif isinstance(event, Registered):
            stats.registrations += 1

    def _deliver(self, train_id: int, command: Command) -> None:
        """On the train's live connection, else into its record for the next
        registration (as ``GroundServer._deliver``); running times only on a live
        registered connection, and not kept (ground/dispatch.py ``SendRunningTimes``)."""
        if isinstance(command, SendRunningTimes):
            live = self.live.get(train_id)
            if live is not None and live.open and live.ground.holds_registration:
                live.ground.send(command.times, self.now_s)
                self._after_ground(live)
            return
        self._deliver_kept(train_id, command)

    def _deliver_kept(self, train_id: int, command: KeptCommand) -> None:
        def apply(dest: GroundEndpoint | TrainRecord, now_s: float) -> None:
            _apply(dest, command, now_s)

        record = self.records.get(train_id)
        if self.journal is not None:
            self.journal.commit_request(
                record, train_id, command_request(command), apply, self.now_s
            )
        conn = self.live.get(train_id)
        if conn is not None and conn.open and conn.ground.train_id == train_id:
            apply(conn.ground, self.now_s)
            self._after_ground(conn)
            return
        if record is None:
            record = self.records[train_id] = TrainRecord(train_id)
            record.history.not_before_us = round(self.ground_config.not_before_s * 1e6)
        apply(record, self.now_s)


def _apply(dest: GroundEndpoint | TrainRecord, command: KeptCommand, now_s: float) -> None:
    """Carry out ``command`` on a train's live endpoint (sent now) or on its record (sent
    on its next registration), as ``GroundServer``'s delivery methods do."""
    if isinstance(dest, GroundEndpoint):
        if isinstance(command, DeliverTsr):
            dest.set_tsr(command.tsr.message, now_s)
        elif isinstance(command, CancelTsrOn):
            dest.cancel_tsr(command.session, now_s)
        elif isinstance(command, SendTargetPoint):
            dest.send_target_point(command.target, now_s)
        else:
            dest.send_dispatch_command(command.command, now_s)
    elif isinstance(command, DeliverTsr):
        dest.add_tsr(command.tsr.message)
    elif isinstance(command, CancelTsrOn):
        dest.cancel_tsr(command.session)
    elif isinstance(command, SendTargetPoint):
        dest.add_target_point(command.target)
    else:
        dest.add_dispatch_command(command.command)


__all__ = ["LinkSim", "Mover", "SimTrain", "TrainLinkStats", "Trajectory"]
