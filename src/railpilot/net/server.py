"""The ground front server: an asyncio TCP server around one GroundEndpoint per connection.

Thin adapter (DESIGN habit 2): each accepted connection gets a
:class:`~railpilot.link.GroundEndpoint`; all of them share ONE ``records`` mapping
(train id -> :class:`~railpilot.link.TrainRecord`), so pending TSRs, dispatch commands and
replay protection survive reconnects. One :class:`~railpilot.net.timers.TickScheduler`
ticks every connection at its deadline.

The ground's application rules (the records, delivery or queueing, take-over of a train
that registers on a new connection, the undo of a refused request, persistence before
effect, and with a dispatch core its commands) are the
:class:`~railpilot.ground.host.GroundHost`'s; this server is its asyncio transport, as the
co-simulation (cosim/link_sim.py) is its simulated one. What the server adds:

* ``status()``: per train whether a connection is open (``connected``, also while the train
  is deregistered and only heartbeats flow) and that connection's ground endpoint state;
* a :class:`TrainView` per train: registrations, the latest running info and when it came;
* key=value logging of every registration, acknowledgement and failure, and of frame
  rejections rate-limited per connection and check (:mod:`railpilot.net.rejections`);
* graceful shutdown: stop listening, close every connection, stop the timer;
* with a :class:`~railpilot.ground.store.GroundStore` (SQLite or PostgreSQL): every
  request, delivery state change, registration and acknowledgement is committed
  *before* the frames of that step leave (persistence before effect), and
  :meth:`GroundServer.start` rebuilds the records from it, so a ground killed with SIGKILL
  resumes every pending delivery and still knows (and can cancel) every active TSR
  (docs/ground-store.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import socket
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

from railpilot.errors import ConfigError
from railpilot.ground.dispatch import Command
from railpilot.ground.host import GroundHost
from railpilot.ground.journal import (
    GroundJournal,
    audit_name,
    dispatch_request,
    target_point_request,
    tsr_cancel_request,
    tsr_set_request,
)
from railpilot.ground.store import GroundStore, Snapshot, StoreError
from railpilot.link import (
    ACKNOWLEDGEMENTS,
    DispatchCommand,
    Event,
    FrameRejected,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    LinkCounters,
    LinkFailed,
    MessageReceived,
    PeriodicTimedOut,
    RunningInfo,
    RunningTimes,
    SequenceGap,
    TargetPoint,
    TimeOffsetReport,
    TrainDeregistered,
    TrainRecord,
    TrainRegistered,
    TsrSet,
    event_name,
)
from railpilot.link.config import REPLAY_WINDOW_S
from railpilot.units import mps_to_kmh

from .logfmt import kv
from .rejections import RejectionLog
from .timers import WALL_CLOCK, LinkClock, TickScheduler

log = logging.getLogger("railpilot.net.server")

#: ``listener(train_id or None, event, now_s)``: sees every event of every connection.
EventListener = Callable[[int | None, Event, float], None]
#: ``sink(commands)``: takes the dispatch core's commands that the link's events gave
CommandSink = Callable[[list[Command]], None]

_COUNTER_FIELDS = (
    "frames_sent",
    "frames_received",
    "frames_accepted",
    "sequence_gaps",
    "frames_lost",
    "repeats",
    "reorders",
    "superseded",
    "timeouts",
    "resends",
    "link_failures",
    "bytes_discarded",
)


def counters_dict(counters: Iterable[LinkCounters]) -> dict[str, Any]:
    """Sum of endpoint counters as a JSON-ready dict (``rejected`` per check)."""
    total: dict[str, Any] = dict.fromkeys(_COUNTER_FIELDS, 0)
    rejected: Counter[str] = Counter()
    for c in counters:
        for name in _COUNTER_FIELDS:
            total[name] += getattr(c, name)
        rejected.update({check.value: n for check, n in c.rejected.items()})
    total["rejected"] = dict(sorted(rejected.items()))
    return total


@dataclass
class TrainView:
    """What the server shows about one train besides its :class:`TrainRecord`."""

    train_id: int
    registrations: int = 0
    registered_at_s: float | None = None
    peer: str = ""
    running_info: RunningInfo | None = None
    running_info_at_s: float | None = None
    running_info_count: int = 0
    acks: Counter[str] = field(default_factory=Counter)


_SERIAL = itertools.count(1)


class GroundConnection(asyncio.Protocol):
    """One accepted TCP connection: feeds the endpoint, writes its output, routes events."""

    def __init__(self, server: GroundServer) -> None:
        self.server = server
        self.serial = next(_SERIAL)  # accept order: the newest connection of a train wins
        self.endpoint = GroundEndpoint(server.config, server.keys, server.records)
        self.transport: asyncio.Transport | None = None
        self.peer = "?"
        self.scheduled_s: float | None = None
        self.rejections = RejectionLog(log)
        self._lost = False

    # --- asyncio.Protocol -------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
            # Frames are small and latency matters more than segment count.
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        peername = transport.get_extra_info("peername")
        self.peer = f"{peername[0]}:{peername[1]}" if peername else "?"
        now = self.server.clock()
        self.endpoint.connection_made(now)
        self.server._connections.add(self)
        kv(log, logging.DEBUG, "connection_accepted", peer=self.peer)
        self._after(now)

    def data_received(self, data: bytes) -> None:
        now = self.server.clock()
        self.endpoint.receive_data(data, now)
        self._after(now)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._lost:
            return
        self._lost = True
        now = self.server.clock()
        self.endpoint.connection_lost(now)
        self.server.scheduler.cancel(self)
        self.server._on_closed(self)
        self.rejections.close(train=self.endpoint.train_id, peer=self.peer)
        kv(
            log,
            logging.INFO,
            "connection_closed",
            train=self.endpoint.train_id,
            peer=self.peer,
            error=exc or "",
        )

    # --- scheduler --------------------------------------------------------------------------

    def next_deadline_s(self) -> float | None:
        deadlines = [self.endpoint.next_deadline_s(), self.rejections.next_deadline_s()]
        return min((d for d in deadlines if d is not None), default=None)

    def on_tick(self, now_s: float) -> None:
        if self._lost:
            return
        self.endpoint.tick(now_s)
        self.rejections.tick(now_s, train=self.endpoint.train_id, peer=self.peer)
        self._after(now_s, reschedule=False)

    # --- helpers ----------------------------------------------------------------------------

    @property
    def open(self) -> bool:
        return not self._lost and self.transport is not None and not self.transport.is_closing()

    def close(self, reason: str) -> None:
        if self.transport is not None and not self.transport.is_closing():
            kv(log, logging.INFO, "closing", train=self.endpoint.train_id, reason=reason)
            self.transport.close()

    def _after(self, now_s: float, *, reschedule: bool = True) -> None:
        """Write what the endpoint queued and hand its events to the server.

        With a store, what this step changed (delivery states, acknowledgements, a
        registration) is committed first; if that fails, the step's frames are dropped
        and the connection closed, so nothing leaves that the store does not hold.
        """
        data = self.endpoint.data_to_send()
        events: Iterable[Event] = self.endpoint.events()
        if self.server.store is not None:
            events = list(events)
            if not self.server._persist_step(self, events, now_s):
                data = b""
        if data and self.open:
            assert self.transport is not None
            self.transport.write(data)
        for event in events:
            self.server._handle(self, event, now_s)
        if reschedule and not self._lost:
            self.server.scheduler.schedule(self, now_s=now_s)


class GroundServer:
    """Ground front server: many trains, one endpoint per connection, shared records.

    Use ``await server.start()`` then ``await server.serve(stop_event)``, or
    ``async with server:``. Delivery methods (:meth:`set_tsr` ...) may be called at any
    time from the event loop's thread; they act at once for a connected train and wait in
    the train's record otherwise.

    ``clock`` is the link's time (epoch seconds; the host's own by default, a scaled one in
    a live line run); a ``scheduler`` given must run on it.

    ``store`` (optional) keeps requests, delivery states, registrations and an audit log
    across restarts; the server only uses it (the caller opens and closes it). Without
    one, everything lives in memory and is lost when the process ends.
    """

    def __init__(
        self,
        config: GroundConfig,
        keys: KeyStore | None = None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        scheduler: TickScheduler | None = None,
        backlog: int = 1024,
        replay_window_s: float = REPLAY_WINDOW_S,
        store: GroundStore | None = None,
        clock: LinkClock = WALL_CLOCK,
    ) -> None:
        if scheduler is not None and scheduler.clock is not clock:
            raise ConfigError("scheduler", scheduler.clock, f"a scheduler on the server's {clock}")
        self.clock = clock
        self.store = store
        #: the ground's application rules over this server's connections
        self.ground_host: GroundHost[GroundConnection] = GroundHost(
            config,
            _ServerTransport(),
            journal=GroundJournal(store) if store is not None else None,
            note=lambda level, event, fields: kv(log, level, event, **fields),
        )
        #: where the dispatch core's commands go (net/dispatch_host.py sets it)
        self.command_sink: CommandSink | None = None
        self.replay_window_s = replay_window_s
        self.keys: KeyStore | None = keys
        self.host = host
        self.port = port
        self.backlog = backlog
        self.scheduler = scheduler if scheduler is not None else TickScheduler(clock=clock)
        self.views: dict[int, TrainView] = {}
        self._connections: set[GroundConnection] = set()
        self._closed_counters = LinkCounters()
        self._listeners: list[EventListener] = []
        self._server: asyncio.Server | None = None
        self.started_at_s: float | None = None
        #: what :meth:`start` took back from the store (GroundJournal.restore's summary)
        self.restored: dict[str, int] = {}

    # --- lifecycle ----------------------------------------------------------------------------

    async def start(self) -> tuple[str, int]:
        """Start listening; returns the bound ``(host, port)`` (port 0 = ephemeral)."""
        loop = asyncio.get_running_loop()
        # Nothing sent before this process started can be genuine: frames timestamped
        # earlier (less an allowance for the trains' clock offset and transit) are replays
        # of recordings made before a restart (protocol.md 5.2).
        if self.config.not_before_s == 0.0:
            self.config = replace(self.config, not_before_s=self.clock() - self.replay_window_s)
        # Bind first (a busy port or a foreign address fails before the store is touched),
        # answer only once the records are restored: no train may register against
        # records not yet restored.
        self._server = await loop.create_server(
            lambda: GroundConnection(self),
            self.host,
            self.port,
            backlog=self.backlog,
            start_serving=False,
        )
        try:
            if self.store is not None:
                self._restore(self.store.load())
            await self._server.start_serving()
        except BaseException:
            self._server.close()
            self._server = None
            raise
        sockname = self._server.sockets[0].getsockname()
        self.port = int(sockname[1])
        self.started_at_s = self.clock()
        kv(
            log,
            logging.INFO,
            "listening",
            host=self.host,
            port=self.port,
            ground_id=self.config.ground_id,
            auth=self.config.require_auth,
        )
        return self.host, self.port

    async def serve(self, stop: asyncio.Event) -> None:
        """Serve until ``stop`` is set, then shut down gracefully."""
        if self._server is None:
            await self.start()
        await stop.wait()
        await self.stop()

    async def stop(self, timeout_s: float = 5.0) -> None:
        """Stop listening, close every connection (flushing what is queued), stop the timer."""
        if self._server is not None:
            self._server.close()
        for conn in list(self._connections):
            conn.close("server shutdown")
        deadline = time.monotonic() + timeout_s
        while self._connections and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        for conn in list(self._connections):  # peers that would not let go
            if conn.transport is not None:
                conn.transport.abort()
        if self._server is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._server.wait_closed(), timeout=timeout_s)
            self._server = None
        self.scheduler.close()
        kv(log, logging.INFO, "stopped", trains=len(self.records))

    @property
    def config(self) -> GroundConfig:
        """The ground endpoints' configuration (its ``not_before_s`` set at start)."""
        return self.ground_host.config

    @config.setter
    def config(self, config: GroundConfig) -> None:
        self.ground_host.config = config

    @property
    def journal(self) -> GroundJournal | None:
        """What the ground commits to ``store`` before anything leaves, and restores."""
        return self.ground_host.journal

    @property
    def records(self) -> dict[int, TrainRecord]:
        """Train id -> its record, shared by every connection's endpoint."""
        return self.ground_host.records

    @property
    def live(self) -> dict[int, GroundConnection]:
        """Registered train id -> its current connection."""
        return self.ground_host.live

    async def __aenter__(self) -> GroundServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def add_listener(self, listener: EventListener) -> None:
        """Call ``listener(train_id, event, now_s)`` for every endpoint event."""
        self._listeners.append(listener)

    # --- deliveries (application API) ---------------------------------------------------------

    def known_trains(self) -> list[int]:
        """Trains that have registered at least once (the targets of ``all``)."""
        return sorted(t for t, r in self.records.items() if r.registration is not None)

    async def paced(
        self,
        deliver: Callable[[Iterable[int], Any], dict[int, str]],
        train_ids: Iterable[int],
        item: Any,
        *,
        batch: int = 50,
    ) -> dict[int, str]:
        """Run a delivery method over many trains in batches, yielding to the loop between.

        A broadcast to a thousand trains is a thousand encodes and writes; done in one go
        it holds up every incoming frame for tens of milliseconds. Batches keep the
        receive path flowing (``await server.paced(server.set_tsr, ids, tsr)``).
        """
        ids = list(train_ids)
        results: dict[int, str] = {}
        for start in range(0, len(ids), batch):
            results.update(deliver(ids[start : start + batch], item))
            await asyncio.sleep(0)
        return results

    # ``actor`` (who asked) and ``reason`` go to the store's audit log and TSR table only.

    def set_tsr(
        self, train_ids: Iterable[int], tsr: TsrSet, *, actor: str = "api", reason: str = ""
    ) -> dict[int, str]:
        """Set a TSR on each train; resent until acknowledged (also across reconnects)."""

        def apply(target: Any, now: float) -> None:
            if isinstance(target, GroundEndpoint):
                target.set_tsr(tsr, now)
            else:
                target.add_tsr(tsr)

        return self.ground_host.deliver_each(
            train_ids, tsr_set_request(tsr, actor, reason), apply, self.clock()
        )

    def cancel_tsr(
        self, train_ids: Iterable[int], session: int, *, actor: str = "api"
    ) -> dict[int, str]:
        """Cancel a TSR session on each train; resent until acknowledged."""

        def apply(target: Any, now: float) -> None:
            if isinstance(target, GroundEndpoint):
                target.cancel_tsr(session, now)
            else:
                target.cancel_tsr(session)

        return self.ground_host.deliver_each(
            train_ids, tsr_cancel_request(session, actor), apply, self.clock()
        )

    def send_target_point(
        self, train_ids: Iterable[int], target: TargetPoint, *, actor: str = "api"
    ) -> dict[int, str]:
        def apply(dest: Any, now: float) -> None:
            if isinstance(dest, GroundEndpoint):
                dest.send_target_point(target, now)
            else:
                dest.add_target_point(target)

        return self.ground_host.deliver_each(
            train_ids, target_point_request(target, actor), apply, self.clock()
        )

    def send_dispatch_command(
        self, train_ids: Iterable[int], command: DispatchCommand, *, actor: str = "api"
    ) -> dict[int, str]:
        def apply(dest: Any, now: float) -> None:
            if isinstance(dest, GroundEndpoint):
                dest.send_dispatch_command(command, now)
            else:
                dest.add_dispatch_command(command)

        return self.ground_host.deliver_each(
            train_ids, dispatch_request(command, actor), apply, self.clock()
        )

    def send_running_times(self, train_ids: Iterable[int], times: RunningTimes) -> dict[int, str]:
        """Send running times now to each train registered on an open connection. They are
        unacknowledged and not kept: a train not connected is not sent them (the dispatch
        core sends its last ones when it registers)."""
        return self.ground_host.send_running_times(train_ids, times, self.clock())

    # --- status -------------------------------------------------------------------------------

    def counters(self) -> dict[str, Any]:
        """Counters summed over every connection so far (closed and open)."""
        return counters_dict(
            [self._closed_counters] + [c.endpoint.counters for c in self._connections]
        )

    def open_connections(self) -> dict[int, GroundConnection]:
        """Train id -> its open connection, whatever the registration state.

        A connection belongs to a train from its first accepted frame on. The registered
        connection wins; otherwise the newest (an old one is about to be closed).
        """
        found: dict[int, GroundConnection] = {}
        for conn in sorted(self._connections, key=lambda c: c.serial):
            train_id = conn.endpoint.train_id
            if train_id is not None and conn.open:
                found[train_id] = conn
        for train_id, conn in self.live.items():
            if conn.open and conn.endpoint.train_id == train_id:
                found[train_id] = conn
        return found

    def status(self) -> dict[str, Any]:
        """JSON-ready snapshot: per train link, registration, running info and deliveries."""
        now = self.clock()
        trains = []
        connections = self.open_connections()
        for train_id in sorted(self.records):
            record = self.records[train_id]
            view = self.views.get(train_id, TrainView(train_id))
            conn = connections.get(train_id)
            info = view.running_info
            reg = record.registration
            trains.append(
                {
                    "train_id": train_id,
                    # The TCP connection is open (also while deregistered: heartbeats flow).
                    "connected": conn is not None,
                    # Ground endpoint state of that connection (protocol.md 8.2), None if none.
                    "state": None if conn is None else conn.endpoint.state.name,
                    "registered": record.registered,
                    "registrations": view.registrations,
                    "peer": view.peer,
                    "train_number": reg.train_number if reg else None,
                    "loco_number": reg.loco_number if reg else None,
                    "train_length_m": reg.train_length_m if reg else None,
                    "running_info": None
                    if info is None
                    else {
                        "position_km": round(info.position_m / 1000.0, 5),
                        "speed_kmh": round(mps_to_kmh(info.speed_mps), 2),
                        "direction": info.direction.name,
                        "age_s": round(now - (view.running_info_at_s or now), 3),
                        # a dispatcher must not take a position for live when the train
                        # is no longer managed or no longer connected, whatever its age
                        "valid": record.running_info.valid
                        and conn is not None
                        and record.registered,
                        "timed_out": not record.running_info.valid,
                        "count": view.running_info_count,
                    },
                    "time_offset_s": record.time_offset_s,
                    "tsrs": {str(s): d.state.name for s, d in sorted(record.tsrs.items())},
                    "target_points": {
                        str(i): d.state.name for i, d in sorted(record.target_points.items())
                    },
                    "dispatch_commands": {
                        str(i): d.state.name for i, d in sorted(record.dispatch_commands.items())
                    },
                }
            )
        return {
            "host": self.host,
            "port": self.port,
            "ground_id": self.config.ground_id,
            # where requests and delivery states are kept (None: in memory only)
            "store": None if self.store is None else self.store.path,
            "uptime_s": round(now - (self.started_at_s or now), 3),
            "connections": len(self._connections),
            "registered": sum(1 for t in trains if t["registered"]),
            "trains": trains,
            "counters": self.counters(),
        }

    # --- store --------------------------------------------------------------------------------

    def _restore(self, snapshot: Snapshot) -> None:
        """Rebuild the train records from the store (:meth:`GroundJournal.restore`)."""
        assert self.journal is not None
        summary = self.ground_host.restore(snapshot, self.clock())
        self.restored = summary
        kv(log, logging.INFO, "restored", store=self.journal.store.path, **summary)

    def _persist_step(self, conn: GroundConnection, events: list[Event], now_s: float) -> bool:
        """Commit what one step of a connection changed; False (and the connection closed)
        when the store could not take it."""
        assert self.journal is not None
        try:
            self.journal.commit_step(conn.endpoint.record, events, now_s)
        except StoreError as exc:
            kv(log, logging.ERROR, "store_failed", train=conn.endpoint.train_id, error=exc)
            # This step's changes are not on disk: its frames must not leave. The train
            # reconnects, and the next step writes what is still missing.
            conn.close("store write failed")
            return False
        return True

    # --- internals ----------------------------------------------------------------------------

    def _view(self, train_id: int) -> TrainView:
        view = self.views.get(train_id)
        if view is None:
            view = self.views[train_id] = TrainView(train_id)
        return view

    def _on_closed(self, conn: GroundConnection) -> None:
        self._connections.discard(conn)
        self.ground_host.closed(conn, conn.endpoint.train_id)
        # Keep the totals of finished connections without keeping the connections.
        closed = self._closed_counters
        for name in _COUNTER_FIELDS:
            setattr(closed, name, getattr(closed, name) + getattr(conn.endpoint.counters, name))
        closed.rejected.update(conn.endpoint.counters.rejected)

    def _handle(self, conn: GroundConnection, event: Event, now_s: float) -> None:
        train_id = conn.endpoint.train_id
        # the ground's rules first (take-over, the live map, the dispatch core)
        commands = self.ground_host.on_event(conn, event, now_s)
        if isinstance(event, MessageReceived):
            message = event.message
            if isinstance(message, RunningInfo) and train_id is not None:
                view = self._view(train_id)
                view.running_info = message
                view.running_info_at_s = now_s
                view.running_info_count += 1
            elif isinstance(message, TimeOffsetReport):
                kv(log, logging.DEBUG, "time_offset", train=train_id, offset_s=message.offset_s)
        elif isinstance(event, TrainRegistered):
            view = self._view(event.train_id)
            view.registrations += 1
            view.registered_at_s = now_s
            view.peer = conn.peer
            kv(
                log,
                logging.INFO,
                "registered",
                train=event.train_id,
                train_number=event.request.train_number,
                loco=event.request.loco_number,
                length_m=event.request.train_length_m,
                peer=conn.peer,
            )
        elif isinstance(event, TrainDeregistered):
            kv(log, logging.INFO, "deregistered", train=event.train_id, reason=event.reason.name)
        elif isinstance(event, ACKNOWLEDGEMENTS):
            self._view(event.train_id).acks[event_name(event)] += 1
            fields = {k: getattr(event, k) for k in event.__dataclass_fields__}
            fields = {k: getattr(v, "name", v) for k, v in fields.items()}
            kv(log, logging.INFO, audit_name(event), **fields)
        elif isinstance(event, FrameRejected):
            conn.rejections.record(event, now_s, train=train_id, peer=conn.peer)
        elif isinstance(event, SequenceGap):
            kv(log, logging.WARNING, "sequence_gap", train=train_id, lost=event.lost)
        elif isinstance(event, PeriodicTimedOut):
            kv(
                log,
                logging.WARNING,
                "timeout",
                train=train_id,
                message=event.message_type.name,
                missed_cycles=event.missed_cycles,
            )
        elif isinstance(event, LinkFailed):
            kv(log, logging.WARNING, "link_failed", train=train_id, reason=event.reason)
            conn.close(f"link failed: {event.reason}")
        for listener in self._listeners:
            listener(train_id, event, now_s)
        if commands and self.command_sink is not None:
            self.command_sink(commands)


class _ServerTransport:
    """How the ground host writes out and closes the server's connections."""

    def flush(self, conn: GroundConnection, now_s: float) -> None:
        conn._after(now_s)

    def close(self, conn: GroundConnection, reason: str) -> None:
        conn.close(reason)
