"""The dashboard over the live ground: :class:`ServerSource` (docs/dashboard.md).

:class:`ServerSource` is a :class:`~railpilot.web.source.DashboardSource` over the ground's
dispatch application on a running server (:class:`~railpilot.net.dispatch_host.DispatchHost`):

- **trains**: the core's registry (registration, last running info and its validity, link
  health, how late the last planned-curve report puts it against the plan in force: the
  registry's, which asks a line run's retimer) and the server's open connections;
- **blocks and signal aspects**: the core's block occupancy (computed every tick) and the
  dispatcher's declared restrictions;
- **TSRs**: the core's line TSRs (set from this page, the admin port or the CLI, or
  restored from the store), each with every train's delivery state read from the server's
  records (``TsrDelivery.state``);
- **target points and dispatch commands**: the records' delivery books (a train's newest
  target id is in force; a clear is no target);
- **time-distance graph**: the core's bounded history of reported head positions, and
  each train's plan in force where the ground holds its timetable (a line run's ground:
  the timetable, or the last re-timing).

The forms' requests (a TSR and its cancel, a restriction and its clear, a dispatch command)
go through ``DispatchHost.execute_now``: the same operation schema and validation as the
admin port and the CLI (ground/operations.py), and the same warning before a TSR over
trains already above its limit (ground/tsr_warning.py).

Threading: the server is not thread-safe, so the source must be used on the server's
event loop thread only; run the dashboard in the same loop (:func:`serve_dashboard`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import socket
from collections import deque
from collections.abc import Callable, Generator, Mapping
from typing import Any, Protocol

import uvicorn

from railpilot.errors import ConfigError
from railpilot.ground.dispatch import HISTORY_SAMPLES, GroundDispatch
from railpilot.ground.operations import OperationError
from railpilot.ground.registry import TrainState
from railpilot.ground.targets import is_clear, restricted_blocks
from railpilot.ground.tsr_manager import LineTsr
from railpilot.ground.tsr_warning import TsrWarning, confirm_flag
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link import TrainRecord, TsrState
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import TargetPoint, TravelDirection
from railpilot.onboard.mrsp import SpeedProfile

from . import view
from .app import DEFAULT_HOST, create_app, server_config

log = logging.getLogger("railpilot.web.ground_source")

#: Trains per slice of a snapshot built with :meth:`ServerSource.snapshot_async`.
SLICE = 100
#: The time-distance graph: how far back and ahead it shows [s].
GRAPH_PAST_S = 3600.0
GRAPH_AHEAD_S = 1200.0
#: What the dashboard answers before the ground has restored (:meth:`ServerSource.starting`).
STARTING = "ground starting: restoring from the store"
#: The delivery states in which a train enforces a TSR (it confirmed it, no cancel yet).
ENFORCED = (TsrState.ACTIVE, TsrState.PENDING_CANCEL)


class _GroundRecords(Protocol):
    """What the source reads of the ground server: its train records and its clock."""

    @property
    def records(self) -> dict[int, TrainRecord]: ...

    @property
    def clock(self) -> Callable[[], float]: ...


class DispatchApplication(Protocol):
    """What the source needs of the ground's dispatch application: a
    :class:`~railpilot.net.dispatch_host.DispatchHost` on a live server, or the demo
    ground's over the co-simulation (cosim/demo_ground.py)."""

    @property
    def line(self) -> RailLine: ...

    @property
    def server(self) -> _GroundRecords: ...

    @property
    def dispatch(self) -> GroundDispatch: ...

    @property
    def restored(self) -> bool: ...

    @property
    def tick_s(self) -> float: ...

    def sync(self) -> None: ...

    def execute_now(
        self, op: str, fields: Mapping[str, Any], actor: str, *, confirm: bool = False
    ) -> dict[str, Any]: ...


class ServerSource:
    """The live ground as the dashboard sees it (module docstring).

    Parameters
    ----------
    host
        The dispatch application on the ground server (net/dispatch_host.py): the page
        shows what its core decided and the server's delivery books; the form's requests
        go through it, as the admin port's do.
    clock
        The ground clock [s since the epoch]; the server's own by default.
    categories
        Each train's speed-limit category (one of the line's) by train id, where the ground
        knows it from elsewhere (a line run's ground: its scenario), since a registration
        does not carry it. The page shows it, and the overspeed alarm takes that
        category's static limit. A train not in it is taken as the line's first category
        running UP and its last running DOWN (loaded trains up, empty ones down, as the
        demo), and shows no category.

    Raises
    ------
    ConfigError
        A category that is not one of the line's.
    """

    def __init__(
        self,
        host: DispatchApplication,
        *,
        clock: Callable[[], float] | None = None,
        categories: Mapping[int, str] | None = None,
    ) -> None:
        line = host.line
        categories = dict(categories or {})
        for train_id, category in categories.items():
            if category not in line.categories:
                raise ConfigError(
                    f"categories[{train_id}]", category, f"one of {', '.join(line.categories)}"
                )
        self.host = host
        self.server = host.server
        self.dispatch = host.dispatch
        self.line = line
        self._clock = host.server.clock if clock is None else clock
        self._categories = categories
        self._guessed = {UP: line.categories[0], DOWN: line.categories[-1]}
        #: each train's history as the page shows it, and the last sample converted [s]
        self._shown: dict[int, deque[list[float]]] = {}
        self._shown_until: dict[int, float] = {}
        #: static limits as MRSP inputs by (category, travel), made when first asked for
        self._static: dict[tuple[str, TravelDirection], SpeedProfile] = {}

    # ------------------------------------------------------------------ DashboardSource

    def starting(self) -> str | None:
        """Why the page cannot be answered yet, or None: until the dispatch core has
        restored from the store (``DispatchHost.start``), it holds none of the ground's
        TSRs, restrictions or trains, and an empty line would look like the truth."""
        return None if self.host.restored else STARTING

    def now_s(self) -> float:
        return float(self._clock())

    def version(self) -> int:
        return self.dispatch.version

    def set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        """Set a TSR from the form's fields; one that would catch trains above its limit
        answers ``{"errors": {"confirm": ...}, "warning": {...}}`` and is sent only when
        the form comes back with ``confirm: true`` (ground/tsr_warning.py)."""
        fields = dict(fields)
        try:
            confirm = confirm_flag(fields, "tsr_set")
            fields.pop("confirm", None)
            result = self.host.execute_now("tsr_set", fields, actor, confirm=confirm)
        except TsrWarning as exc:
            return {"errors": exc.errors, "warning": exc.view()}
        except OperationError as exc:
            return {"errors": exc.errors}
        tsr = next(t for t in self.dispatch.tsrs.tsrs() if t.session == result["session"])
        return {"ok": self._tsr_view(tsr)}

    def cancel_tsr(self, session: int, actor: str, now_s: float) -> dict[str, Any]:
        tsr = next((t for t in self.dispatch.tsrs.tsrs() if t.session == session), None)
        if tsr is None:
            known = ", ".join(str(t.session) for t in self.dispatch.tsrs.tsrs()) or "none"
            return {"errors": {"session": f"{session} is not a TSR that was set ({known})"}}
        try:
            self.host.execute_now("tsr_cancel", {"session": session}, actor)
        except OperationError as exc:
            return {"errors": exc.errors}
        return {"ok": self._tsr_view(tsr)}

    def set_restriction(
        self, fields: Mapping[str, Any], actor: str, now_s: float
    ) -> dict[str, Any]:
        try:
            result = self.host.execute_now("restriction_set", fields, actor)
        except OperationError as exc:
            return {"errors": exc.errors}
        ident = result["id"]
        return {"ok": view.restriction_view(ident, self.dispatch.restrictions[ident], self.line)}

    def clear_restriction(self, ident: int, actor: str, now_s: float) -> dict[str, Any]:
        try:
            self.host.execute_now("restriction_clear", {"id": ident}, actor)
        except OperationError as exc:
            return {"errors": exc.errors}
        return {"ok": {"id": ident}}

    def send_dispatch(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        try:
            result = self.host.execute_now("dispatch", fields, actor)
        except OperationError as exc:
            return {"errors": exc.errors}
        return {"ok": {"command": result["command"], "trains": result["trains"]}}

    # ------------------------------------------------------------------ the snapshot

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """The whole picture at ``now_s`` (DashboardSource), built in one go."""
        build = self._build(now_s)
        while (snap := next(build)) is None:
            pass
        return snap

    async def snapshot_async(self, now_s: float) -> dict[str, Any]:
        """:meth:`snapshot`, yielding to the event loop every :data:`SLICE` trains: at a
        thousand trains a snapshot costs tens of ms, and the trains' frames, which share
        this loop, wait for one slice instead of the whole."""
        build = self._build(now_s)
        while (snap := next(build)) is None:
            await asyncio.sleep(0)
        return snap

    def _build(self, now_s: float) -> Generator[dict[str, Any] | None, None, None]:
        """Yields None where a caller may let the loop run, then the snapshot."""
        self.host.sync()
        registry = self.dispatch.registry
        states = {s.train_id: s for s in registry.states(now_s)}
        # The last tick's rather than a new one per push: it is what the target points
        # were computed from, and it costs tens of ms at 1000 trains. A tick's lands a
        # little after the tick (its worker thread), so two ticks' age is allowed.
        occupancy = self.dispatch.occupancy
        if occupancy is None or now_s - occupancy.now_s > 2 * self.host.tick_s:
            occupancy = self.dispatch.compute_occupancy(now_s)
        restricted = restricted_blocks(self.line, self.dispatch.restrictions.values())
        aspects = view.signal_aspects(self.line, occupancy, restricted)
        yield None
        trains: list[dict[str, Any]] = []
        for k, state in enumerate(states.values(), 1):
            trains.append(self._train_view(state, now_s))
            if k % SLICE == 0:
                yield None
        numbers = {t["id"]: t["number"] for t in trains}
        graph = yield from self._graph(states, numbers, now_s)
        yield {
            "now_s": now_s,
            "version": self.dispatch.version,
            "line": view.line_view(self.line, aspects),
            "blocks": view.blocks_view(self.line, occupancy, restricted),
            "trains": trains,
            "tsrs": [self._tsr_view(t, numbers) for t in self.dispatch.tsrs.tsrs()],
            "restrictions": [
                view.restriction_view(ident, r, self.line)
                for ident, r in sorted(self.dispatch.restrictions.items())
            ],
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
            "graph": graph,
            "alarms": view.alarms_view(trains),
        }

    def _train_view(self, state: TrainState, now_s: float) -> dict[str, Any]:
        info = state.running_info
        category = self._categories.get(state.train_id)
        mrsp = None
        if info is not None and info.direction in (UP, DOWN):
            mrsp = view.mrsp_at(
                self._static_limit(category or self._guessed[info.direction], info.direction),
                self._applied(state, info.direction, now_s),
                info.direction,
                info.position_m,
                now_s,
            )
        return view.train_view(
            state,
            mrsp_mps=mrsp,
            deviation_s=state.deviation_s,
            target=self._target(state),
            category=category,
        )

    def _static_limit(self, category: str, travel: TravelDirection) -> SpeedProfile:
        key = (category, travel)
        if key not in self._static:
            self._static[key] = view.static_profile(self.line, category, travel)
        return self._static[key]

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
        """The train's target point in force (its newest id), as ``view.target_view``
        shows one; a clear is no target."""
        record = self.server.records.get(state.train_id)
        if record is None or not record.target_points:
            return None
        target_id = max(record.target_points)
        delivery = record.target_points[target_id]
        message = delivery.message
        if not isinstance(message, TargetPoint) or is_clear(message, self.line):
            return None
        # the block only when the ground computed this target (not one sent by hand)
        targets = self.dispatch.targets
        computed = targets.current(state.train_id)
        ours = computed is not None and targets.current_target_id(state.train_id) == target_id
        info = state.running_info
        travel = info.direction if info is not None and info.direction in (UP, DOWN) else UP
        return {
            "id": target_id,
            "km": view.km(message.position_m),
            "reason": message.reason.name,
            "signal": self.line.signal_near(message.position_m, travel),
            "block": computed.block_id if ours and computed is not None else None,
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
        return view.tsr_view(tsr, self.dispatch.tsrs.state(tsr.session), deliveries, numbers)

    def _numbers(self) -> dict[int, str]:
        return {
            train_id: record.registration.train_number
            for train_id, record in self.server.records.items()
            if record.registration is not None
        }

    def _graph(
        self, states: Mapping[int, TrainState], numbers: Mapping[int, str], now_s: float
    ) -> Generator[None, None, dict[str, Any]]:
        start, end = now_s - GRAPH_PAST_S, now_s + GRAPH_AHEAD_S
        trains = []
        for k, (train_id, state) in enumerate(states.items(), 1):
            info = state.running_info
            actual = [p for p in self._actual(train_id) if p[0] >= start]
            if info is not None and state.info_age_s is not None:  # the latest report too
                at = now_s - state.info_age_s
                if not actual or actual[-1][0] < round(at):
                    actual.append([round(at), view.km(info.position_m)])
            trains.append(
                {
                    "id": train_id,
                    "number": numbers.get(train_id, str(train_id)),
                    "direction": "unknown" if info is None else view.direction(info.direction),
                    "plan": self._plan(train_id, start, end),
                    "actual": actual,
                }
            )
            if k % SLICE == 0:
                yield
        return {"from_s": start, "to_s": end, "trains": trains}

    def _plan(self, train_id: int, start_s: float, end_s: float) -> list[list[float]]:
        """The train's plan in force (its timetable, or the ground's last re-timing of it)
        over the graph's window; none when the ground holds no timetable for it."""
        retimer = self.dispatch.retimer
        if retimer is None or train_id not in retimer.trains:
            return []
        return view.plan_path(
            retimer.trains[train_id].stops_m,
            retimer.planned_departures(train_id),
            retimer.planned_arrivals(train_id),
            start_s,
            end_s,
        )

    def _actual(self, train_id: int) -> deque[list[float]]:
        """The train's history in the page's units, each sample converted once (the core
        keeps up to an hour of samples per train, in time order)."""
        shown = self._shown.get(train_id)
        if shown is None:
            shown = self._shown[train_id] = deque(maxlen=HISTORY_SAMPLES)
        last = self._shown_until.get(train_id, -math.inf)
        new: list[tuple[float, float]] = []
        for t, x in reversed(self.dispatch.history.get(train_id, ())):
            if t <= last:
                break
            new.append((t, x))
        for t, x in reversed(new):
            shown.append([round(t), view.km(x)])
        if new:
            self._shown_until[train_id] = new[0][0]
        return shown

    # ------------------------------------------------------------------ for tests and tools

    def delivery_state(self, session: int, train_id: int) -> TsrState | None:
        """Where the delivery of TSR ``session`` to ``train_id`` stands (None: not sent)."""
        record = self.server.records.get(train_id)
        delivery = None if record is None else record.tsrs.get(session)
        return None if delivery is None else delivery.state

    def concerned(self, session: int) -> tuple[int, ...]:
        """The trains TSR ``session`` was delivered to."""
        return self.dispatch.tsrs.delivered_to(session)


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
