"""The ground dispatch application (paper 001, section 2): no I/O, time passed in.

:class:`GroundDispatch` is what the ground decides, whatever carries its messages: the
live server (net/dispatch_host.py feeds it the server's events and carries out its
commands) or a co-simulation. It holds

- the :class:`~railpilot.ground.registry.TrainRegistry` (who is there, the last running
  info, link health, timetables);
- the line's TSRs in a :class:`~railpilot.ground.tsr_manager.TsrManager` (to which trains
  each goes, late registrations, cancels, expiry);
- the target points: block occupancy from the running info and the dispatcher's declared
  restrictions (section faults, lost switch indications) through a
  :class:`~railpilot.ground.targets.TargetPointTracker`;
- dispatch command numbers, and a bounded position history per train for the
  time-distance graph.

Inputs: :meth:`on_event` (the link's events), :meth:`tick` (the clock: expiry, target
points), :meth:`execute` (a dispatcher's :mod:`~railpilot.ground.operations`). Each
returns the :data:`Command` values the transport is to carry out, in order. Delivery
state (sent, acknowledged) is the link's business and is not kept here.
"""

from __future__ import annotations

from collections import defaultdict, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from railpilot.errors import ConfigError
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link import (
    Event,
    FrameRejected,
    LinkFailed,
    Message,
    MessageReceived,
    PeriodicTimedOut,
    PlannedCurve,
    RunningInfo,
    TrainDeregistered,
    TrainRegistered,
)
from railpilot.link.messages import (
    U32_MAX,
    DispatchCommand,
    RunningTimes,
    TargetPoint,
    TargetReason,
)
from railpilot.units import km_post_to_m, m_to_km_post, mps_to_kmh

from .occupancy import (
    Occupancy,
    OccupancyConfig,
    TrainReport,
    compute_occupancy,
    line_end_m,
)
from .online_retimer import OnlineRetimer
from .operations import (
    CancelTsr,
    ClearRestriction,
    Operation,
    OperationError,
    SendDispatch,
    SendTarget,
    SetRestriction,
    SetTsr,
    Status,
    config_error_field,
)
from .registry import TrainRegistry
from .store import Snapshot
from .targets import DeclaredRestriction, TargetPointTracker, is_clear
from .tsr_manager import Cancel, Deliver, LineTsr, LineTsrState, TrainRoute, TsrManager

#: One position sample per train at most this often [s], and how many are kept (an hour).
HISTORY_INTERVAL_S = 10.0
HISTORY_SAMPLES = 360


# ---------------------------------------------------------------------------- commands


@dataclass(frozen=True)
class DeliverTsr:
    """Send ``tsr`` to each of ``train_ids`` (resent until acknowledged)."""

    tsr: LineTsr
    train_ids: tuple[int, ...]


@dataclass(frozen=True)
class CancelTsrOn:
    """Cancel TSR ``session`` on each of ``train_ids`` (resent until acknowledged)."""

    session: int
    train_ids: tuple[int, ...]
    actor: str


@dataclass(frozen=True)
class SendTargetPoint:
    """Send ``target`` to ``train_id``; its id supersedes every older one of the train."""

    train_id: int
    target: TargetPoint
    actor: str


@dataclass(frozen=True)
class SendDispatchCommand:
    train_ids: tuple[int, ...]
    command: DispatchCommand
    actor: str


@dataclass(frozen=True)
class DeliverMessage:
    """Send ``message``, of a kind the ground keeps per train (``Message.KIND``), to each
    of ``train_ids``: resent until acknowledged, also after a restart of the ground."""

    train_ids: tuple[int, ...]
    message: Message
    actor: str


@dataclass(frozen=True)
class SendRunningTimes:
    """Send ``times`` to ``train_id`` now if it is registered (unacknowledged; not kept:
    the re-timing is derived state, and a train that registers later is sent its last
    times by :meth:`GroundDispatch.on_event`)."""

    train_id: int
    times: RunningTimes


#: what the ground keeps in its store before it leaves (ground/journal.py)
KeptCommand = DeliverTsr | CancelTsrOn | SendTargetPoint | SendDispatchCommand | DeliverMessage
Command = KeptCommand | SendRunningTimes


def kept_message(command: SendTargetPoint | SendDispatchCommand | DeliverMessage) -> Message:
    """The kept message (``Message.KIND``) a command delivers."""
    if isinstance(command, SendTargetPoint):
        return command.target
    if isinstance(command, SendDispatchCommand):
        return command.command
    return command.message


def command_trains(command: Command) -> tuple[int, ...]:
    """The trains a command goes to."""
    if isinstance(command, SendTargetPoint | SendRunningTimes):
        return (command.train_id,)
    return command.train_ids


@dataclass(frozen=True)
class Outcome:
    """What an operation did: a JSON-ready ``result`` and the commands to carry out."""

    result: dict[str, Any]
    commands: tuple[Command, ...]


@dataclass(frozen=True)
class Checkpoint:
    """What a dispatcher's operation may change in the core, as it was before it
    (:meth:`GroundDispatch.checkpoint`)."""

    restrictions: dict[int, DeclaredRestriction]
    tsrs: dict[int, tuple[LineTsrState, frozenset[int]]]


# ---------------------------------------------------------------------------- the core


class GroundDispatch:
    """The ground's decisions for one line (module docstring).

    Parameters
    ----------
    line
        The fixed-block line (km posts, blocks, signals, static limits).
    validity_s
        How long a running info stays valid [s] (the link's running-info timeout).
    """

    def __init__(self, line: RailLine, *, validity_s: float = 4.0) -> None:
        if not isinstance(line, RailLine):
            raise ConfigError("line", line, "a RailLine")
        self.line = line
        self.registry = TrainRegistry(
            validity_s=validity_s, planned_arrival=self._planned_arrival_s
        )
        # a report goes stale for the occupancy when it does for the registry
        self._occupancy_config = OccupancyConfig(validity_s=validity_s)
        top_mps = max(
            float(line.static_limit(category, direction)[1].max())
            for category in line.categories
            for direction in (UP, DOWN)
        )
        self.tsrs = TsrManager(top_speed_mps=top_mps)
        self.targets = TargetPointTracker(line)
        self.restrictions: dict[int, DeclaredRestriction] = {}
        self.history: dict[int, deque[tuple[float, float]]] = defaultdict(
            lambda: deque(maxlen=HISTORY_SAMPLES)
        )
        self.occupancy: Occupancy | None = None
        #: re-timing in the loop (ground/online_retimer.py), if the ground holds the timetables
        self.retimer: OnlineRetimer | None = None
        self._next_command = 1
        #: bumped by every change a dispatcher's view should show
        self.version = 0

    # ------------------------------------------------------------------ the link

    def on_event(self, train_id: int | None, event: Event, now_s: float) -> list[Command]:
        """One event of the link (``train_id``: the connection's train, if known)."""
        self.version += 1
        registry = self.registry
        if isinstance(event, TrainRegistered):
            registry.connected(event.train_id)
            registry.registered(event.train_id, event.request)
            commands = self._route_changed(event.train_id, now_s)
            times = self.retimer.times_for(event.train_id) if self.retimer else None
            if times is not None:
                commands.append(SendRunningTimes(event.train_id, times))
            return commands
        if isinstance(event, TrainDeregistered):
            registry.deregistered(event.train_id)
            if self.retimer is not None:
                self.retimer.left(event.train_id)
            self.tsrs.forget(event.train_id)
            self.targets.forget(event.train_id)
            return []
        if train_id is None:
            return []
        if isinstance(event, MessageReceived):
            message = event.message
            if isinstance(message, RunningInfo):
                registry.running_info(train_id, message, now_s)
                history = self.history[train_id]
                if not history or now_s - history[-1][0] >= HISTORY_INTERVAL_S:
                    history.append((now_s, message.position_m))
                if self.retimer is not None:
                    self.retimer.running(train_id, message.speed_mps, now_s)
                return self._route_changed(train_id, now_s)
            if isinstance(message, PlannedCurve):
                registry.planned_curve(train_id, message, now_s)
                if self.retimer is not None:
                    self.retimer.report(train_id, message, now_s)
        elif isinstance(event, PeriodicTimedOut):
            registry.timed_out(train_id)
        elif isinstance(event, LinkFailed):
            registry.link_failed(train_id)
        elif isinstance(event, FrameRejected):
            registry.rejected(train_id, event.check)
        return []

    def connection(self, train_id: int, connected: bool) -> None:
        """Whether ``train_id`` has an open connection (a closed one raises no event)."""
        if connected:
            self.registry.connected(train_id)
        else:
            self.registry.disconnected(train_id)

    def route(self, train_id: int) -> TrainRoute | None:
        """Where a registered train that reports its position is and goes (None: unknown).

        Its destination is the line's end in its direction (the ground holds no route
        beyond its timetable, which ends there on the heavy-haul line).
        """
        report = self.registry.report(train_id)
        if report is None or report[1].direction not in (UP, DOWN):
            return None
        _, info, length_m, _ = report
        try:
            return TrainRoute(
                train_id,
                info.direction,
                info.position_m,
                length_m,
                float(line_end_m(self.line, info.direction)),
            )
        except ConfigError:  # a position off the line's km posts
            return None

    def _route_changed(self, train_id: int, now_s: float) -> list[Command]:
        route = self.route(train_id)
        if route is None:
            return []
        return self._tsr_commands(self.tsrs.update_route(route, now_s), "ground")

    # ------------------------------------------------------------------ the clock

    def tick(self, now_s: float) -> list[Command]:
        """Expire TSRs and send the target points that changed since the last tick."""
        self.tick_occupancy(now_s)
        return self.tick_targets(now_s)

    def tick_occupancy(self, now_s: float, occupancy: Occupancy | None = None) -> None:
        """The first half of :meth:`tick`: expire TSRs and take the block occupancy at
        ``now_s``: ``occupancy`` if a transport computed it elsewhere
        (:meth:`occupancy_from`), else computed here. A transport may let other work run
        before the second half."""
        self.tsrs.tick(now_s)  # Withdraw: nothing to send, each train drops it by its clock
        self.occupancy = occupancy if occupancy is not None else self.compute_occupancy(now_s)

    def tick_targets(self, now_s: float) -> list[Command]:
        """The second half of :meth:`tick`: the target points that changed, from the
        occupancy of the first half; then the running times of a re-timing, if one is due
        (ground/online_retimer.py)."""
        if self.occupancy is None:
            self.occupancy = self.compute_occupancy(now_s)
        events = self.targets.update(self.occupancy, self.restrictions.values(), now_s=now_s)
        commands: list[Command] = [SendTargetPoint(e.train_id, e.message, "ground") for e in events]
        if self.retimer is not None:
            commands += [SendRunningTimes(i, m) for i, m in self.retimer.update(now_s)]
        if commands:
            self.version += 1
        return commands

    def compute_occupancy(self, now_s: float) -> Occupancy:
        """Block occupancy at ``now_s`` [s] from every registered train's last report (a
        stale one counts conservatively: ground/occupancy.py)."""
        return self.occupancy_from(self.registry.reports(), now_s)

    def occupancy_from(
        self, reports: Iterable[tuple[int, RunningInfo, float, float]], now_s: float
    ) -> Occupancy:
        """Block occupancy at ``now_s`` [s] from ``reports``, a copy of the registry's
        (``registry.reports()``). It reads nothing else that changes, so a transport may
        run it in another thread on a copy taken in its own: the live ground does, to
        keep its tens of ms at a thousand trains off the trains' event loop."""
        line = self.line
        trains = [
            TrainReport(train_id, float(info.position_m), info.direction, length_m, received_s)
            for train_id, info, length_m, received_s in reports
            if info.direction in (UP, DOWN)
            and line.start_m <= info.position_m <= line.end_m
            and received_s <= now_s
        ]
        return compute_occupancy(line, trains, now_s, self._occupancy_config)

    def _update_targets(self, now_s: float) -> list[Command]:
        self.occupancy = self.compute_occupancy(now_s)
        return self.tick_targets(now_s)

    # ------------------------------------------------------------------ the dispatcher

    def execute(self, op: Operation, actor: str, now_s: float) -> Outcome:
        """Carry out a dispatcher's operation; a refused one raises OperationError and
        changes nothing."""
        if not isinstance(actor, str) or not actor.strip():
            raise OperationError({"actor": f"{actor!r} is not allowed: expected a name"})
        self.version += 1
        try:
            if isinstance(op, SetTsr):
                return self._set_tsr(op, actor, now_s)
            if isinstance(op, CancelTsr):
                actions = self.tsrs.cancel(op.session, now_s)
                return Outcome(
                    {
                        "session": op.session,
                        "trains": [a.train_id for a in actions if isinstance(a, Cancel)],
                    },
                    tuple(self._tsr_commands(actions, actor)),
                )
            if isinstance(op, SetRestriction):
                return self._set_restriction(op, actor, now_s)
            if isinstance(op, ClearRestriction):
                if op.restriction_id not in self.restrictions:
                    known = ", ".join(map(str, sorted(self.restrictions))) or "none"
                    raise OperationError(
                        {"id": f"{op.restriction_id} is not allowed: expected one of {known}"}
                    )
                del self.restrictions[op.restriction_id]
                return Outcome({"id": op.restriction_id}, tuple(self._update_targets(now_s)))
            if isinstance(op, SendTarget):
                commands = tuple(
                    SendTargetPoint(
                        train, TargetPoint(self.targets.take_id(), op.position_m, op.reason), actor
                    )
                    for train in op.trains
                )
                return Outcome(
                    {"targets": {str(c.train_id): c.target.target_id for c in commands}},
                    commands,
                )
            if isinstance(op, SendDispatch):
                return self._dispatch(op, actor)
            if isinstance(op, Status):
                return Outcome(self.status(now_s), ())
        except ConfigError as exc:  # a rule of the core (a session reused, ...)
            raise OperationError({config_error_field(exc): str(exc)}) from None
        raise OperationError({"op": f"{type(op).__name__} is not an operation"})

    def checkpoint(self) -> Checkpoint:
        """The declared restrictions and the line's TSRs, to :meth:`roll_back` to when an
        operation's record is refused by the store (not stored: not in force either)."""
        return Checkpoint(dict(self.restrictions), self.tsrs.checkpoint())

    def roll_back(self, checkpoint: Checkpoint) -> None:
        """Back to ``checkpoint``: what the operations since set, cancelled or declared is
        forgotten. (Target points they made the core work out were never sent; the next
        tick works them out again from the restrictions in force.)"""
        self.restrictions = dict(checkpoint.restrictions)
        self.tsrs.roll_back(checkpoint.tsrs)

    def _set_tsr(self, op: SetTsr, actor: str, now_s: float) -> Outcome:
        session = op.session if op.session is not None else self.tsrs.next_session()
        tsr = op.line_tsr(session, actor)
        actions = self.tsrs.set(tsr, now_s) + self.tsrs.deliver_also(session, op.trains)
        return Outcome(
            {
                "session": session,
                "trains": sorted({a.train_id for a in actions if isinstance(a, Deliver)}),
                # when it holds, on the ground's clock [s since the epoch]: an operation
                # given in minutes from now is pinned here
                "valid_from_s": op.valid_from_s,
                "valid_until_s": op.valid_until_s,
            },
            tuple(self._tsr_commands(actions, actor)),
        )

    def _set_restriction(self, op: SetRestriction, actor: str, now_s: float) -> Outcome:
        op.restriction.blocks(self.line)  # a span off the line is an error here, not later
        ident = op.restriction_id
        if ident is None:
            ident = max(self.restrictions, default=0) + 1
        held = self.restrictions.get(ident)
        if held is not None and held != op.restriction:
            raise OperationError(
                {"id": f"{ident} is not allowed: expected an id not used for another restriction"}
            )
        self.restrictions[ident] = op.restriction
        return Outcome({"id": ident}, tuple(self._update_targets(now_s)))

    def _dispatch(self, op: SendDispatch, actor: str) -> Outcome:
        trains = op.trains or tuple(
            s for s in self.registry.train_ids() if self._ever_registered(s)
        )
        if not trains:
            raise OperationError(
                {"trains": "'all' is not allowed: expected a train that has registered (none has)"}
            )
        number = op.command if op.command is not None else self._next_command
        if number > U32_MAX:
            raise OperationError({"command": f"{number} is not allowed: every number is used"})
        self._next_command = max(self._next_command, number + 1)
        command = DispatchCommand(number, op.text)
        return Outcome(
            {"command": number, "trains": list(trains)},
            (SendDispatchCommand(tuple(trains), command, actor),),
        )

    def _planned_arrival_s(self, train_id: int, station_id: int) -> float | None:
        """The retimer's plan in force, for the registry's deviation from plan."""
        return (
            None if self.retimer is None else self.retimer.planned_arrival_s(train_id, station_id)
        )

    def _ever_registered(self, train_id: int) -> bool:
        return self.registry.state(train_id, 0.0).train_number is not None

    # ------------------------------------------------------------------ views

    def status(self, now_s: float) -> dict[str, Any]:
        """The dispatcher's side, JSON-ready: TSRs, restrictions, targets."""
        return {
            "tsrs": [
                {
                    "session": t.session,
                    "start_km": m_to_km_post(t.start_m),
                    "end_km": m_to_km_post(t.end_m),
                    "limit_kmh": round(mps_to_kmh(t.limit_mps), 3),
                    "valid_from_s": t.valid_from_s,
                    "valid_until_s": t.valid_until_s,
                    "reason": t.reason,
                    "set_by": t.set_by,
                    "state": self.tsrs.state(t.session).value,
                    "trains": list(self.tsrs.delivered_to(t.session)),
                }
                for t in self.tsrs.tsrs()
            ],
            "restrictions": [
                {"id": ident, **restriction_view(r)}
                for ident, r in sorted(self.restrictions.items())
            ],
            "targets": {
                str(train): {
                    "target_id": self.targets.current_target_id(train),
                    "km": None if target is None else m_to_km_post(target.position_m),
                    "reason": None if target is None else target.reason.name,
                    "signal": None if target is None else target.signal_id,
                }
                for train in self.registry.train_ids()
                if (target := self.targets.current(train)) is not None
                or self.targets.current_target_id(train) is not None
            },
        }

    # ------------------------------------------------------------------ restart

    def restore(
        self, snapshot: Snapshot, now_s: float, restrictions: Mapping[int, DeclaredRestriction]
    ) -> None:
        """Take back what the store kept after a restart (nothing is sent from here: the
        link's records, restored beside this, resume each delivery where it stood).

        TSRs come back with their state (cancelled, expired by ``now_s`` or active) and
        the trains each went to; every train's newest stored target point tells the
        tracker whether it holds a target (so a clear still reaches it); command numbers
        and target ids resume above every stored one.
        """
        delivered: dict[int, list[int]] = defaultdict(list)
        for train in snapshot.trains.values():
            for session in train.tsrs:
                delivered[session].append(train.train_id)
            if train.registration is not None:
                self.registry.registered(train.train_id, train.registration)
                self.registry.deregistered(train.train_id)  # until it registers again
            if train.target_points:
                newest = max(train.target_points)
                target = train.target_points[newest][0]
                holding = not is_clear(target, self.line)
                self.targets.resume(train.train_id, newest, holding=holding)
            if train.dispatch_commands:
                self._next_command = max(self._next_command, max(train.dispatch_commands) + 1)
        for session, stored in sorted(snapshot.tsrs.items()):
            message = stored.tsr
            if stored.cancelled_at_s is not None:
                state = LineTsrState.CANCELLED
            elif message.valid_until_s <= now_s:
                state = LineTsrState.EXPIRED
            else:
                state = LineTsrState.ACTIVE
            tsr = LineTsr(
                session,
                min(message.start_m, message.end_m),
                max(message.start_m, message.end_m),
                message.limit_mps,
                message.valid_from_s,
                message.valid_until_s,
                stored.reason,
                stored.actor,
            )
            self.tsrs.restore(tsr, state, delivered.get(session, ()))
        self.restrictions.update(restrictions)

    # ------------------------------------------------------------------ internals

    def _tsr_commands(self, actions: Iterable[Deliver | Cancel | Any], actor: str) -> list[Command]:
        """One command per TSR and kind, in the manager's order."""
        deliver: dict[int, tuple[LineTsr, list[int]]] = {}
        cancel: dict[int, list[int]] = defaultdict(list)
        for action in actions:
            if isinstance(action, Deliver):
                deliver.setdefault(action.tsr.session, (action.tsr, []))[1].append(action.train_id)
            elif isinstance(action, Cancel):
                cancel[action.session].append(action.train_id)
        commands: list[Command] = [DeliverTsr(t, tuple(ids)) for t, ids in deliver.values()]
        commands += [CancelTsrOn(s, tuple(ids), actor) for s, ids in cancel.items()]
        return commands


def restriction_view(restriction: DeclaredRestriction) -> dict[str, Any]:
    """A declared restriction in the dispatcher's units."""
    track = {UP: "up", DOWN: "down", None: "both"}.get(restriction.direction, "both")
    return {
        "reason": restriction.reason.name.lower(),
        "block": restriction.block_id,
        "start_km": None if restriction.start_m is None else m_to_km_post(restriction.start_m),
        "end_km": None if restriction.end_m is None else m_to_km_post(restriction.end_m),
        "track": None if restriction.block_id is not None else track,
    }


def restriction_from_view(view: Mapping[str, Any]) -> DeclaredRestriction:
    """The inverse of :func:`restriction_view` (the audit log keeps the view)."""
    reason = TargetReason[str(view["reason"]).upper()]
    if view.get("block"):
        return DeclaredRestriction.on_block(str(view["block"]), reason)
    track = {"up": UP, "down": DOWN}.get(str(view.get("track")))
    return DeclaredRestriction.on_span(
        km_post_to_m(float(view["start_km"])),
        km_post_to_m(float(view["end_km"])),
        reason,
        track,
    )
