"""Trains and the ground over the simulated radio, in simulated time (docs/cosim.md).

:class:`LinkSim` runs the live system's protocol and application code with another
transport. Each train has an :class:`~railpilot.link.OnboardEndpoint`, kept across
reconnects as ``net/client.py`` keeps it. The ground has one
:class:`~railpilot.link.GroundEndpoint` per connection, and the same
:class:`~railpilot.ground.host.GroundHost` as the live server (the train records they
share, delivery or queueing, take-over, the dispatch core): this module is its transport
in simulated time. Frames cross a :class:`~railpilot.cosim.channel.RadioChannel` per
train.

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

import itertools
import random
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from railpilot.deadlines import DeadlineHeap, run_until
from railpilot.errors import ConfigError, is_finite_number
from railpilot.ground.assembly import GroundParts
from railpilot.ground.dispatch import Command, GroundDispatch, Outcome
from railpilot.ground.host import GroundHost
from railpilot.ground.journal import GroundJournal, declared_restrictions
from railpilot.ground.online_retimer import OnlineRetimer
from railpilot.ground.operations import Operation
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
    TrainRecord,
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
    endpoint: GroundEndpoint
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
        What the radio does to packets (its outages in seconds from ``start_s``): one
        model for every train, or each train's by its id.
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
        Makes the ground's re-timing in the loop (ground/online_retimer.py), for the first
        ground and for each restarted one (None: no re-timing).

    :meth:`over` builds one from a :class:`~railpilot.ground.assembly.GroundParts`
    instead (the ground's line, configuration, keys, store and retimer in one place).
    """

    def __init__(
        self,
        line: RailLine,
        trains: Sequence[SimTrain],
        channel: ChannelModel | Mapping[int, ChannelModel],
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
        parts = GroundParts(
            GroundConfig(ground_id=ground_id, timers=trains[0].config.timers),
            line,
            keys,
            store,
            retimer,
        )
        self._start(parts, trains, channel, seed=seed, start_s=start_s, tick_s=tick_s)

    @classmethod
    def over(
        cls,
        parts: GroundParts,
        trains: Sequence[SimTrain],
        channel: ChannelModel | Mapping[int, ChannelModel],
        *,
        seed: int = 0,
        start_s: float = 1_800_000_000.0,
        tick_s: float = TICK_S,
    ) -> LinkSim:
        """The trains and the ground made of ``parts`` (which must have a line and the
        trains' keys), over ``channel`` (the other parameters as the class's)."""
        if parts.line is None:
            raise ConfigError("parts.line", None, "the line the simulated ground dispatches")
        if parts.keys is None:
            raise ConfigError("parts.keys", None, "the trains' keys (every frame is signed)")
        sim = cls.__new__(cls)
        sim._start(parts, trains, channel, seed=seed, start_s=start_s, tick_s=tick_s)
        return sim

    def _start(
        self,
        parts: GroundParts,
        trains: Sequence[SimTrain],
        channel: ChannelModel | Mapping[int, ChannelModel],
        *,
        seed: int,
        start_s: float,
        tick_s: float,
    ) -> None:
        """Set up the run over the ground made of ``parts`` (both constructors)."""
        assert parts.line is not None and parts.keys is not None  # over() checks them
        if not trains:
            raise ConfigError("trains", [], "at least one train")
        ids = [t.config.train_id for t in trains]
        duplicates = sorted({i for i in ids if ids.count(i) > 1})
        if duplicates:
            raise ConfigError("trains", duplicates, "unique train ids")
        if not is_finite_number(start_s) or start_s <= 0:
            raise ConfigError("start_s", start_s, "a time > 0 [s since the epoch]")
        keys = parts.keys
        self.line = parts.line
        self.start_s = float(start_s)
        self.now_s = self.start_s
        self.keys = keys
        self.tick_s = tick_s
        #: what the ground is made of (each ground process is built from it)
        self.parts = parts
        #: the ground's application rules; this simulation is their transport
        self.host: GroundHost[_Connection] = self.parts.new_host(self)
        #: whether the ground is running (:meth:`restart_ground`)
        self.ground_up = True
        #: each restart: when the ground went down and came up [s since the start of the
        #: run], and what it restored (GroundJournal.restore's summary)
        self.restarts: list[dict[str, Any]] = []
        self.trains = {t.config.train_id: t for t in trains}
        self.onboard = {i: OnboardEndpoint(t.config, keys) for i, t in self.trains.items()}
        models = channel if isinstance(channel, Mapping) else dict.fromkeys(self.trains, channel)
        missing = sorted(set(self.trains) - set(models))
        if missing:
            raise ConfigError("channel", missing, "a channel model for every train")
        self.channels = {i: RadioChannel(models[i], seed, i, self.start_s) for i in self.trains}
        self._jitter = {i: random.Random(f"railpilot-reconnect:{seed}:{i}") for i in self.trains}
        self.stats = {i: TrainLinkStats() for i in self.trains}
        #: train id -> (position, speed) of its onboard's running info (:meth:`_refresh`)
        self._seen: dict[int, tuple[float, float]] = {}
        self._connections: dict[int, _Connection] = {}  # serial -> connection, open or not
        #: train id -> the serial of the onboard's open connection
        self._onboard_serial: dict[int, int] = {}
        self._serials = itertools.count(1)
        #: the events to come, (kind, item) by time; driven in virtual time (run_until)
        self._queue: DeadlineHeap[tuple[str, Any]] = DeadlineHeap()
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
        run_until(self._queue, end, self._handle)
        self.now_s = max(self.now_s, end)

    def _handle(self, at_s: float, event: tuple[str, Any]) -> None:
        """One event of the queue, at its time."""
        self.now_s = at_s
        kind, item = event
        handler = self._handlers.get(kind)
        if handler is None:
            # each kind's method looked up once (millions of events in a day)
            handler = self._handlers[kind] = getattr(self, f"_on_{kind}")
        handler(item)

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
        # everything the process held in memory (the store, and its writer, outlive it)
        self.host = self.parts.new_host(self, config=self.host.config, journal=self.journal)
        self._push(self.now_s + down_s, "ground_start", None)

    def operate(self, operation: Operation, actor: str) -> Outcome:
        """A dispatcher's operation, now, as ``DispatchHost`` carries it out: the core
        decides, what it changed on the line goes to the store, then its deliveries leave.
        Raises :class:`~railpilot.ground.operations.OperationError` (nothing done)."""
        outcome = self.host.operate(operation, actor, self.now_s)
        self.execute(outcome.commands)
        return outcome

    def execute(self, commands: Iterable[Command]) -> dict[int, str]:
        """Carry out the dispatch core's commands now; the outcome per train (a request
        a train's record refuses is reported there, not raised)."""
        return self.host.carry_out(commands, self.now_s)

    # ------------------------------------------------------------------ the ground host

    @property
    def records(self) -> dict[int, TrainRecord]:
        """The ground's train records (train id -> record)."""
        return self.host.records

    @property
    def live(self) -> dict[int, _Connection]:
        """Registered train id -> its open connection."""
        return self.host.live

    @property
    def dispatch(self) -> GroundDispatch:
        """The ground's dispatch core."""
        assert self.host.dispatch is not None  # _new_host gives it one
        return self.host.dispatch

    @property
    def journal(self) -> GroundJournal | None:
        """The ground's writer to its store (None: no store)."""
        return self.host.journal

    @property
    def ground_config(self) -> GroundConfig:
        """The ground endpoints' configuration."""
        return self.host.config

    def flush(self, conn: _Connection, now_s: float) -> None:
        """The host's transport: what ``conn``'s endpoint queued leaves now."""
        self._after_ground(conn)

    def close(self, conn: _Connection, reason: str) -> None:
        """The host's transport: close ``conn`` at both ends (module docstring)."""
        self._close(conn)

    # ------------------------------------------------------------------ what a train is doing

    def position(self, train_id: int, now_s: float | None = None) -> tuple[float, float]:
        """``(position_m, speed_mps)`` of ``train_id`` at ``now_s`` (default: now)."""
        train = self.trains[train_id]
        at = self.now_s if now_s is None else now_s
        return train.mover.state(at - self.start_s - train.start_s)

    def link_report(self) -> dict[str, Any]:
        """The link statistics of the run: frames, losses, resends, timeouts, rejections
        by check (ground and onboard), and the channel's counts."""
        ground = counters_dict(c.endpoint.counters for c in self._connections.values())
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
        self._queue.push(at_s, (kind, item))

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
        self.host.config = replace(self.host.config, not_before_s=not_before_s)
        snapshot = store.load()
        summary = self.host.restore(snapshot, self.now_s)
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
            GroundEndpoint(self.host.config, self.keys, self.host.records),
        )
        self._connections[conn.serial] = conn
        self._onboard_serial[train_id] = conn.serial
        conn.endpoint.connection_made(self.now_s)
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
            conn.endpoint.tick(self.now_s)
            self._after_ground(conn)

    def _on_to_ground(self, item: tuple[int, bytes]) -> None:
        serial, data = item
        conn = self._connections[serial]
        if conn.open:
            conn.endpoint.receive_data(data, self.now_s)
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
            self.host.sync(t for t, c in self.live.items() if c.open)
            self.execute(self.dispatch.tick(self.now_s))
        self._push(self.now_s + self.tick_s, "dispatch_tick", None)

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
        ground = conn.endpoint
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
            failed |= isinstance(event, LinkFailed)
            commands += self.host.on_event(conn, event, self.now_s)
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
        conn.endpoint.connection_lost(self.now_s)
        self._deadline.pop(("ground", conn.serial), None)
        self.host.closed(conn, conn.train_id)
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


__all__ = ["LinkSim", "Mover", "SimTrain", "TrainLinkStats", "Trajectory"]
