"""The dashboard over the live ground server: :class:`ServerSource` (docs/dashboard.md).

:class:`ServerSource` is a :class:`~railpilot.web.source.DashboardSource` that reads a
running :class:`~railpilot.net.server.GroundServer`:

- **trains**: the server's records (registration: number, length) and the last running
  info (position, speed, direction), fed through ``server.add_listener`` into a
  :class:`~railpilot.ground.registry.TrainRegistry`, which also counts each train's
  timeouts, link failures and rejected frames; whether a connection is open is read from
  the server when a snapshot is taken (a closed connection raises no event);
- **TSRs**: the dispatcher's, kept by a :class:`~railpilot.ground.tsr_manager.TsrManager`
  over each registered train's :class:`~railpilot.ground.tsr_manager.TrainRoute` (head
  and direction from its running info, length from its registration, destination the
  line's end in its direction), with each train's delivery state read from the server's
  records (``TsrDelivery.state``);
- **target points and dispatch commands**: the records' delivery books;
- **time-distance graph**: a bounded history of reported head positions per train (one
  sample every :data:`HISTORY_INTERVAL_S`, the last :data:`HISTORY_SAMPLES`).

Setting a TSR validates the form (:func:`~railpilot.web.forms.parse_tsr_form`), asks the
manager which trains it concerns and delivers it with ``server.set_tsr``; cancelling goes
to every train it was delivered to with ``server.cancel_tsr``.

Threading: the server is not thread-safe, so the source must be used on the server's
event loop thread only; run the dashboard in the same loop (:func:`serve_dashboard`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
import time
from collections import defaultdict, deque
from collections.abc import Callable, Generator, Iterable, Mapping
from typing import Any

import uvicorn

from railpilot.errors import ConfigError
from railpilot.ground.occupancy import TrainReport, compute_occupancy
from railpilot.ground.registry import TrainRegistry, TrainState
from railpilot.ground.tsr_manager import Action, Cancel, Deliver, LineTsr, TrainRoute, TsrManager
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link import (
    Event,
    FrameRejected,
    LinkFailed,
    MessageReceived,
    PeriodicTimedOut,
    RunningInfo,
    TrainDeregistered,
    TrainRegistered,
    TsrState,
)
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import TravelDirection
from railpilot.net.server import GroundServer
from railpilot.onboard.mrsp import SpeedProfile

from . import view
from .app import DEFAULT_HOST, create_app, server_config
from .forms import TsrFormError, form_error, parse_tsr_form

log = logging.getLogger("railpilot.web.ground_source")

#: One position sample per train at most this often [s], and how many are kept (an hour).
HISTORY_INTERVAL_S = 10.0
HISTORY_SAMPLES = 360
#: The time-distance graph: how far back and ahead it shows [s] (as the fake).
GRAPH_PAST_S = 3600.0
GRAPH_AHEAD_S = 1200.0
#: The delivery states in which a train enforces a TSR (it confirmed it, no cancel yet).
ENFORCED = (TsrState.ACTIVE, TsrState.PENDING_CANCEL)


class ServerSource:
    """The live ground as the dashboard sees it (module docstring).

    Parameters
    ----------
    server
        The ground server (started or not); the source adds a listener to it.
    line
        The line the trains run on (km posts, signals, static limits).
    clock
        The ground clock [s since the epoch] (the server's own is ``time.time``).
    """

    def __init__(
        self, server: GroundServer, line: RailLine, *, clock: Callable[[], float] = time.time
    ) -> None:
        self.server = server
        self.line = line
        self._clock = clock
        timers = server.config.timers
        self._registry = TrainRegistry(validity_s=timers.cycle_s * timers.timeout_cycles)
        # The train's category is not in its registration: loaded trains (the line's
        # first category) are taken to run UP and empty ones (its last) DOWN, as the fake.
        self._category = {UP: line.categories[0], DOWN: line.categories[-1]}
        self._static: dict[TravelDirection, SpeedProfile] = {
            travel: view.static_profile(line, category, travel)
            for travel, category in self._category.items()
        }
        top_mps = max(float(line.static_limit(c, d)[1].max()) for d, c in self._category.items())
        self._tsrs = TsrManager(top_speed_mps=top_mps)
        self._history: dict[int, deque[tuple[float, float]]] = defaultdict(
            lambda: deque(maxlen=HISTORY_SAMPLES)
        )
        self._dirty: set[int] = set()  # trains whose route is to be updated
        self._update_scheduled = False
        self._version = 0
        server.add_listener(self._on_event)

    # ------------------------------------------------------------------ the link's events

    def _on_event(self, train_id: int | None, event: Event, now_s: float) -> None:
        """Every event of every connection (called by the server, on its loop)."""
        self._version += 1
        registry = self._registry
        if isinstance(event, TrainRegistered):
            registry.connected(event.train_id)
            registry.registered(event.train_id, event.request)
            self._route_changed(event.train_id)
        elif isinstance(event, TrainDeregistered):
            registry.deregistered(event.train_id)
            self._tsrs.forget(event.train_id)
        elif train_id is None:
            return
        elif isinstance(event, MessageReceived) and isinstance(event.message, RunningInfo):
            registry.running_info(train_id, event.message, now_s)
            history = self._history[train_id]
            if not history or now_s - history[-1][0] >= HISTORY_INTERVAL_S:
                history.append((now_s, event.message.position_m))
            self._route_changed(train_id)
        elif isinstance(event, PeriodicTimedOut):
            registry.timed_out(train_id)
        elif isinstance(event, LinkFailed):
            registry.link_failed(train_id)
        elif isinstance(event, FrameRejected):
            registry.rejected(train_id, event.check)

    def _route_changed(self, train_id: int) -> None:
        """Update the train's route soon: not from inside the server's event handling, since
        a delivery it causes re-enters the connection that is reporting the event."""
        self._dirty.add(train_id)
        if self._update_scheduled:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop (a unit test feeding events): at once
            self._update_routes()
            return
        self._update_scheduled = True
        loop.call_soon(self._update_routes)

    def _update_routes(self) -> None:
        self._update_scheduled = False
        dirty, self._dirty = self._dirty, set()
        now = self._clock()
        actions: list[Action] = []
        for train_id in sorted(dirty):
            route = self._route(train_id)
            if route is not None:
                actions += self._tsrs.update_route(route, now)
        actions += self._tsrs.tick(now)
        self._carry_out(actions, "ground")

    def _route(self, train_id: int) -> TrainRoute | None:
        """Where a registered train reporting its position is and goes (None: unknown)."""
        record = self.server.records.get(train_id)
        held = None if record is None else record.running_info.message
        if record is None or not record.registered or record.registration is None:
            return None
        if not isinstance(held, RunningInfo) or held.direction not in (UP, DOWN):
            return None
        destination = self.line.end_m if held.direction is UP else self.line.start_m
        try:
            return TrainRoute(
                train_id,
                held.direction,
                held.position_m,
                record.registration.train_length_m,
                destination,
            )
        except ConfigError as exc:  # a position off the km posts a route may have
            log.warning("train %s: no route: %s", train_id, exc)
            return None

    def _carry_out(self, actions: Iterable[Action], actor: str) -> None:
        """Deliver what the manager decided through the server (one call per TSR)."""
        deliver: dict[int, tuple[LineTsr, list[int]]] = {}
        cancel: dict[int, list[int]] = defaultdict(list)
        for action in actions:
            if isinstance(action, Deliver):
                deliver.setdefault(action.tsr.session, (action.tsr, []))[1].append(action.train_id)
            elif isinstance(action, Cancel):
                cancel[action.session].append(action.train_id)
            # Withdraw: nothing is sent; each train drops the TSR by its own clock.
        results: dict[int, str] = {}
        for tsr, train_ids in deliver.values():
            results |= self.server.set_tsr(
                train_ids, tsr.message, actor=tsr.set_by or actor, reason=tsr.reason
            )
        for session, train_ids in cancel.items():
            results |= self.server.cancel_tsr(train_ids, session, actor=actor)
        for train_id, outcome in sorted(results.items()):
            if outcome.startswith("error"):
                log.warning("train %s: %s", train_id, outcome)
        if results:
            self._version += 1

    # ------------------------------------------------------------------ DashboardSource

    def now_s(self) -> float:
        return float(self._clock())

    def version(self) -> int:
        return self._version

    def set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        if self._dirty:
            self._update_routes()  # every train where it last said it was
        try:
            tsr = parse_tsr_form(
                fields, line=self.line, session=self._next_session(), actor=actor, now_s=now_s
            )
            actions = self._tsrs.set(tsr, now_s)
        except TsrFormError as exc:
            return {"errors": exc.errors}
        except ConfigError as exc:  # the manager's own rules
            field_name, message = form_error(exc, {})
            return {"errors": {field_name: message}}
        self._carry_out(actions, actor)
        self._version += 1
        return {"ok": self._tsr_view(tsr)}

    def cancel_tsr(self, session: int, actor: str, now_s: float) -> dict[str, Any]:
        tsr = next((t for t in self._tsrs.tsrs() if t.session == session), None)
        if tsr is None:
            known = ", ".join(str(t.session) for t in self._tsrs.tsrs()) or "none"
            return {"errors": {"session": f"{session} is not a TSR that was set ({known})"}}
        self._carry_out(self._tsrs.cancel(session, now_s), actor)
        self._version += 1
        return {"ok": self._tsr_view(tsr)}

    def _next_session(self) -> int:
        """One above every session the manager or any train's record holds (a TSR set over
        the admin port, or restored from the store, keeps its number)."""
        used = [t.session for t in self._tsrs.tsrs()]
        used += [s for record in self.server.records.values() for s in record.tsrs]
        return max(used, default=0) + 1

    # ------------------------------------------------------------------ the snapshot

    def _sync(self, now_s: float) -> None:
        """What raises no event: open connections, and records restored from the store."""
        open_now = self.server.open_connections()
        for train_id, record in self.server.records.items():
            if record.registration is not None and train_id not in self._registry.train_ids():
                self._registry.registered(train_id, record.registration)
                if not record.registered:
                    self._registry.deregistered(train_id)
        for train_id in self._registry.train_ids():
            if train_id in open_now:
                self._registry.connected(train_id)
            else:
                self._registry.disconnected(train_id)
        self._carry_out(self._tsrs.tick(now_s), "ground")

    def snapshot(self, now_s: float) -> dict[str, Any]:
        self._sync(now_s)
        states = {s.train_id: s for s in self._registry.states(now_s)}
        reports = [
            TrainReport.from_running_info(
                s.train_id, s.running_info, s.length_m, now_s - (s.info_age_s or 0.0)
            )
            for s in states.values()
            if s.registered and s.running_info is not None and s.length_m is not None
        ]
        occupancy = compute_occupancy(self.line, reports, now_s)
        restricted: dict[str, Any] = {}  # the server holds no declared restrictions yet
        aspects = view.signal_aspects(self.line, occupancy, restricted)
        trains = [self._train_view(s, now_s) for s in states.values()]
        numbers = {t["id"]: t["number"] for t in trains}
        return {
            "now_s": now_s,
            "version": self._version,
            "line": view.line_view(self.line, aspects),
            "blocks": view.blocks_view(self.line, occupancy, restricted),
            "trains": trains,
            "tsrs": [self._tsr_view(t, numbers) for t in self._tsrs.tsrs()],
            "dispatch": [
                {
                    "command": number,
                    "train": train_id,
                    "number": numbers.get(train_id, str(train_id)),
                    "text": getattr(delivery.message, "text", ""),
                    "state": delivery.state.name,
                }
                for train_id, record in sorted(self.server.records.items())
                for number, delivery in sorted(record.dispatch_commands.items())
            ],
            "graph": self._graph(states, numbers, now_s),
            "alarms": view.alarms_view(trains),
        }

    def _train_view(self, state: TrainState, now_s: float) -> dict[str, Any]:
        info = state.running_info
        mrsp = None
        if info is not None and info.direction in (UP, DOWN):
            mrsp = view.mrsp_at(
                self._static[info.direction],
                self._applied(state, info.direction, now_s),
                info.direction,
                info.position_m,
                now_s,
            )
        return view.train_view(
            state, mrsp_mps=mrsp, deviation_s=state.deviation_s, target=self._target(state)
        )

    def _applied(
        self, state: TrainState, travel: TravelDirection, now_s: float
    ) -> list[AppliedTsr]:
        """The TSRs the train confirmed and still enforces, valid now."""
        record = self.server.records.get(state.train_id)
        if record is None:
            return []
        length = state.length_m or 0.0
        return [
            AppliedTsr.of(d.tsr, length, travel)
            for d in record.tsrs.values()
            if d.state in ENFORCED and d.tsr.valid_from_s <= now_s < d.tsr.valid_until_s
        ]

    def _target(self, state: TrainState) -> dict[str, Any] | None:
        """The train's latest target point, as ``view.target_view`` shows one."""
        record = self.server.records.get(state.train_id)
        if record is None or not record.target_points:
            return None
        target_id = max(record.target_points)
        delivery = record.target_points[target_id]
        message = delivery.message
        position = float(getattr(message, "position_m", math.nan))
        signal = next((s.id for s in self.line.signals if abs(s.position_m - position) < 1.0), None)
        reason = getattr(message, "reason", None)
        return {
            "id": target_id,
            "km": view.km(position),
            "reason": getattr(reason, "name", str(reason)),
            "signal": signal,
            "block": None,
            "state": delivery.state.name,
        }

    def _tsr_view(self, tsr: LineTsr, numbers: Mapping[int, str] | None = None) -> dict[str, Any]:
        deliveries = {
            train_id: record.tsrs[tsr.session].state
            for train_id, record in self.server.records.items()
            if tsr.session in record.tsrs and record.tsrs[tsr.session].tsr == tsr.message
        }
        if numbers is None:
            numbers = self._numbers()
        return view.tsr_view(tsr, self._tsrs.state(tsr.session), deliveries, numbers)

    def _numbers(self) -> dict[int, str]:
        return {
            train_id: record.registration.train_number
            for train_id, record in self.server.records.items()
            if record.registration is not None
        }

    def _graph(
        self, states: Mapping[int, TrainState], numbers: Mapping[int, str], now_s: float
    ) -> dict[str, Any]:
        start, end = now_s - GRAPH_PAST_S, now_s + GRAPH_AHEAD_S
        trains = []
        for train_id, state in states.items():
            info = state.running_info
            samples = [(t, x) for t, x in self._history.get(train_id, ()) if t >= start]
            if info is not None and state.info_age_s is not None:  # the latest report too
                at = now_s - state.info_age_s
                if not samples or samples[-1][0] < at:
                    samples.append((at, info.position_m))
            trains.append(
                {
                    "id": train_id,
                    "number": numbers.get(train_id, str(train_id)),
                    "direction": "unknown" if info is None else view.direction(info.direction),
                    "plan": [],  # the server holds no timetable yet
                    "actual": [[round(t), view.km(x)] for t, x in samples],
                }
            )
        return {"from_s": start, "to_s": end, "trains": trains}

    # ------------------------------------------------------------------ for tests and tools

    def delivery_state(self, session: int, train_id: int) -> TsrState | None:
        """Where the delivery of TSR ``session`` to ``train_id`` stands (None: not sent)."""
        record = self.server.records.get(train_id)
        delivery = None if record is None else record.tsrs.get(session)
        return None if delivery is None else delivery.state

    def concerned(self, session: int) -> tuple[int, ...]:
        """The trains TSR ``session`` was delivered to."""
        return self._tsrs.delivered_to(session)


# ---------------------------------------------------------------------------- serving


class DashboardServer(uvicorn.Server):
    """uvicorn's server in the ground's event loop: it leaves the process's signals to the
    ground (which stops it), and says when it has started (or failed to)."""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self.ready = asyncio.Event()

    @contextlib.contextmanager
    def capture_signals(self) -> Generator[None, None, None]:
        yield

    async def startup(self, sockets: Any = None) -> None:
        try:
            await super().startup(sockets)
        finally:
            self.ready.set()

    @property
    def port(self) -> int:
        """The bound port (after ``ready``)."""
        return int(self.servers[0].sockets[0].getsockname()[1])


async def serve_dashboard(
    source: ServerSource,
    *,
    token: str,
    host: str = DEFAULT_HOST,
    port: int = 0,
    actor: str = "dispatcher",
) -> tuple[DashboardServer, asyncio.Task[None]]:
    """Start the dashboard over ``source`` in the running loop (the server's) on ``host``
    (a loopback address: the app answers only to 127.0.0.1 and localhost) and ``port``
    (0: any free one). Returns the uvicorn server (``.port``: the bound port) and its task;
    stop it with ``server.should_exit = True`` and await the task.

    The socket is bound here, so a port in use is a :class:`ConfigError` naming
    ``http_port`` (uvicorn would exit the process).
    """
    app = create_app(source, token=token, actor=actor)
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(128)
        sock.setblocking(False)
    except OSError as exc:
        sock.close()
        raise ConfigError("http_port", port, f"a port free on {host} ({exc.strerror})") from None
    dashboard = DashboardServer(server_config(app, host=host, port=port))
    task = asyncio.create_task(dashboard.serve(sockets=[sock]), name="dashboard")
    ready = asyncio.ensure_future(dashboard.ready.wait())
    await asyncio.wait({task, ready}, return_when=asyncio.FIRST_COMPLETED)
    ready.cancel()
    if not dashboard.started:
        sock.close()
        with contextlib.suppress(BaseException):
            await task
        raise ConfigError("http_port", port, f"a dashboard that starts on {host} (see the log)")
    return dashboard, task
