"""A deterministic in-memory ground for the dashboard: the heavy-haul line full of trains.

:class:`FakeGround` is a :class:`~railpilot.web.source.DashboardSource` for the tests and
the screenshot demo. It runs the ground's own application objects (the train registry,
block occupancy, the target point tracker, the TSR manager, the link's delivery state
machines) over trains that move by simple kinematics, so what the page shows is what the
ground would compute; only the trains and the link are made up. There is no wall clock
inside: time moves when :meth:`FakeGround.advance` is called (the test, or the demo's
loop, drives it).

What happens on the line (all from the seed, the same every run):

- ``n_trains`` trains (default 24), loaded ones going UP to Huanghua Port and empty ones
  going DOWN to Shenchi South, spread along the line, each some minutes off its plan
  (a straight line at the line's mean cruising speed);
- a train speeds up towards its cruising speed (its static limit less 5 km/h, looking
  2 km ahead), and brakes for the TSRs it has confirmed and the target point it has
  confirmed;
- the third UP train runs 5 km/h above its limits (an ``overspeed`` alarm); the fourth
  DOWN train loses its link shortly before the start (a ``link`` alarm; it stops, as an
  onboard does on link loss, and everything sent to it stays pending);
- a section fault is declared on an UP block ahead of a train five minutes before the
  start and cleared 20 minutes after it, so the train is held at a red signal by a target
  point, and the trains behind it may be too;
- one TSR (session 1, track work) is in force from before the start;
- the link's acknowledgements come back ``ack_delay_s`` after a delivery (1 to 5 s,
  depending on the train): :meth:`advance` moves each delivery through the link's own
  transition tables (``PENDING_SET`` -> ``ACTIVE`` and so on).

Run the dashboard over it (``python -m railpilot.web.fake --port 8080``): it prints the
URL and the dispatcher token and advances the fake ground in real time (``--speed``
times faster).
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import contextlib
import math
import random
import secrets
import sys
import threading
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from railpilot.errors import ConfigError
from railpilot.ground.occupancy import TrainReport, compute_occupancy
from railpilot.ground.operations import (
    OperationError,
    SendDispatch,
    SetRestriction,
    SetTsr,
    config_error_field,
    parse_operation,
)
from railpilot.ground.registry import TrainRegistry
from railpilot.ground.targets import DeclaredRestriction, TargetPointTracker, restricted_blocks
from railpilot.ground.tsr_manager import (
    Action,
    Cancel,
    Deliver,
    LineTsr,
    TrainRoute,
    TsrManager,
)
from railpilot.line.loader import load_line
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link.checks import Check
from railpilot.link.events import AppliedTsr
from railpilot.link.ground import (
    DELIVERY_TRANSITIONS,
    TSR_TRANSITIONS,
    DeliveryInput,
    DeliveryState,
    TsrInput,
    TsrState,
)
from railpilot.link.messages import RegisterRequest, RunningInfo, TargetReason, TravelDirection
from railpilot.onboard.mrsp import SpeedProfile
from railpilot.units import kmh_to_mps

from . import view

#: The fake ground clock's start: 2026-03-02 06:00:00 UTC [s since the epoch].
DEFAULT_START_S = 1_772_431_200.0
#: Simulated history before the start [s], so the time-distance graph has a past.
WARMUP_S = 1800.0
#: Longest kinematics step [s] (advance splits longer ones).
MAX_STEP_S = 1.0
#: The time-distance graph: how far back and ahead it shows [s], one sample per [s].
GRAPH_PAST_S = 3600.0
GRAPH_AHEAD_S = 1200.0
GRAPH_SAMPLE_S = 60.0
#: Cruising margin below the static limit [km/h], the overspeeding train's excess [km/h].
CRUISE_MARGIN_KMH = 5.0
OVERSPEED_KMH = 10.0
#: Acceleration and service braking of the made-up trains [m/s^2], how far they look
#: ahead for a lower limit [m] and where they stop before a target point [m].
ACCEL_MPS2 = 0.15
BRAKE_MPS2 = 0.35
LOOKAHEAD_M = 2000.0
TARGET_MARGIN_M = 150.0
#: The delivery states in which a train enforces a TSR (it confirmed it, no cancel yet).
ENFORCED = (TsrState.ACTIVE, TsrState.PENDING_CANCEL)


@dataclass
class _Train:
    """One made-up train: what it really does (the ground sees only its reports)."""

    train_id: int
    number: str
    direction: TravelDirection
    category: str
    length_m: float
    head_m: float
    destination_m: float
    plan_speed_mps: float
    plan_departure_s: float  # when the plan has it leave the line's start in its direction
    ack_delay_s: float
    excess_mps: float = 0.0  # the overspeeding train's excess over its limits
    link_fails_at_s: float | None = None
    speed_mps: float = 0.0
    link_up: bool = True
    arrived_s: float | None = None
    history: deque[tuple[float, float]] = field(default_factory=deque)

    @property
    def sign(self) -> float:
        return 1.0 if self.direction is UP else -1.0


@dataclass
class _TsrDelivery:
    """One TSR session on one train, in the link's TSR delivery states."""

    state: TsrState
    since_s: float


@dataclass
class _Delivery:
    """A target point or dispatch command to one train (pending until acknowledged)."""

    state: DeliveryState
    since_s: float


class FakeGround:
    """The heavy-haul line with ``n_trains`` trains (module docstring); thread-safe.

    Parameters
    ----------
    n_trains
        How many trains (2 to 200), half of them each way.
    seed
        Everything made up (delays, lengths, which train fails) comes from it.
    line
        The line (default: the shipped heavy-haul line); its first train category runs
        UP, its last DOWN, and TSR 1 lies at km 120-126.5.
    start_s
        The ground clock [s] after the warm-up, when the page first looks.
    """

    def __init__(
        self,
        n_trains: int = 24,
        *,
        seed: int = 0,
        line: RailLine | None = None,
        start_s: float = DEFAULT_START_S,
    ) -> None:
        if type(n_trains) is not int or not 2 <= n_trains <= 200:
            raise ConfigError("n_trains", n_trains, "an integer from 2 to 200")
        self.line = line if line is not None else load_line("heavy-haul")
        self._lock = threading.RLock()
        self._rng = random.Random(seed)
        self._now = float(start_s) - WARMUP_S
        self._version = 0
        self._registry = TrainRegistry()
        self._tracker = TargetPointTracker(self.line)
        self._tsr_book: dict[tuple[int, int], _TsrDelivery] = {}  # (session, train)
        self._target_book: dict[int, tuple[int, _Delivery]] = {}  # train -> (target id, ...)
        self._commands: list[tuple[int, int, str, _Delivery]] = []  # (number, train, text, ..)
        #: declared restrictions by id: (the restriction, in force from, until) [s]
        self._restrictions: dict[int, tuple[DeclaredRestriction, float, float]] = {}
        self._static: dict[tuple[str, TravelDirection], SpeedProfile] = {}
        self._limits: dict[tuple[str, TravelDirection], tuple[list[float], list[float]]] = {}
        # Loaded trains (the line's first category) go UP, empty ones (its last) DOWN.
        self._category = {UP: self.line.categories[0], DOWN: self.line.categories[-1]}
        for travel, category in self._category.items():
            edges, values = self.line.static_limit(category, travel)
            self._limits[(category, travel)] = (edges.tolist(), values.tolist())
            self._static[(category, travel)] = view.static_profile(self.line, category, travel)
        top_mps = max(max(values) for _, values in self._limits.values())
        self._tsrs = TsrManager(top_speed_mps=top_mps)
        self._trains = self._make_trains(n_trains, float(start_s))
        for train in self._trains.values():
            self._registry.connected(train.train_id)
            self._registry.registered(
                train.train_id,
                RegisterRequest(
                    train.number, f"HXD{train.train_id}", 7000 + train.train_id, train.length_m
                ),
            )
            self._report(train)
        self._make_link_history()
        self._warm_up(float(start_s))

    # ------------------------------------------------------------------ set-up

    def _make_trains(self, n_trains: int, start_s: float) -> dict[int, _Train]:
        line, rng = self.line, self._rng
        trains: dict[int, _Train] = {}
        n_up = (n_trains + 1) // 2
        for k in range(n_trains):
            travel = UP if k < n_up else DOWN
            index = k if travel is UP else k - n_up
            count = n_up if travel is UP else n_trains - n_up
            category = self._category[travel]
            plan_mps = 0.99 * self._mean_cruise_mps(category, travel)
            length = 2650.0 if rng.random() < 0.6 else 1350.0
            # Spread the heads evenly at the start, then step back over the warm-up.
            along = (index + 0.5) / count * (line.length_m - 6000.0) + 3000.0
            along = max(along - plan_mps * WARMUP_S, length + 500.0)
            head = line.start_m + along if travel is UP else line.end_m - along
            delay_s = round(rng.uniform(-120.0, 480.0), -1)
            departure = (start_s - WARMUP_S) - along / plan_mps - delay_s
            last = line.stations[-1] if travel is UP else line.stations[0]
            train_id = 1001 + k
            trains[train_id] = _Train(
                train_id=train_id,
                number=str(76001 + 2 * index + (0 if travel is UP else 1)),
                direction=travel,
                category=category,
                length_m=length,
                head_m=head,
                destination_m=last.stop_m(travel),
                plan_speed_mps=plan_mps,
                plan_departure_s=departure,
                ack_delay_s=1.0 + (train_id * 7) % 5,
                speed_mps=self._cruise_mps(category, travel, head),
            )
        ids = sorted(trains)
        if n_up >= 3:
            trains[ids[2]].excess_mps = kmh_to_mps(OVERSPEED_KMH)
        if n_trains - n_up >= 4:
            trains[ids[n_up + 3]].link_fails_at_s = start_s - 40.0
        return trains

    def _make_link_history(self) -> None:
        """A few timeouts and rejected frames, as a real link collects them."""
        checks = (Check.CRC, Check.SEQUENCE, Check.TIMESTAMP, Check.AUTH, Check.DELAY)
        for train_id in sorted(self._trains):
            for _ in range(self._rng.choice((0, 0, 0, 1, 2))):
                self._registry.timed_out(train_id)
            for _ in range(self._rng.choice((0, 0, 1, 3))):
                self._registry.rejected(train_id, self._rng.choice(checks))

    def _mean_cruise_mps(self, category: str, travel: TravelDirection) -> float:
        """The mean cruising speed [m/s] over the whole line (the plan's speed)."""
        edges, values = self._limits[(category, travel)]
        margin = kmh_to_mps(CRUISE_MARGIN_KMH)
        time_s = sum(
            (b - a) / (v - margin) for a, b, v in zip(edges[:-1], edges[1:], values, strict=True)
        )
        return (edges[-1] - edges[0]) / time_s

    def _warm_up(self, start_s: float) -> None:
        """Run up to ``start_s``: the preset TSR, the section fault, the dispatch orders."""
        self._step_to(start_s - 1500.0, 30.0)
        session_1 = {
            "start_km": 120.0,
            "end_km": 126.5,
            "limit_kmh": 45,
            "valid_from_min": 0,
            "valid_until_min": 240,
            "reason": "track work: rail renewal",
        }
        result = self._set_tsr(session_1, "dispatcher D. Wang", self._now)
        if "ok" not in result:  # the line given has no km 120-126.5
            raise ConfigError("line", self.line.name, f"a line that takes TSR 1 ({result})")
        self._step_to(start_s - 300.0, 30.0)
        self._declare_fault(until_s=start_s + 1200.0)
        self._step_to(start_s, 10.0)

    def _declare_fault(self, until_s: float) -> None:
        """A section fault three blocks ahead of the UP train nearest the line's middle."""
        middle = 0.5 * (self.line.start_m + self.line.end_m)
        ups = [t for t in self._trains.values() if t.direction is UP and t.link_up]
        train = min(ups, key=lambda t: abs(t.head_m - middle))
        sections = self.line.block_sections_for(UP)
        here = self.line.block_section_at(train.head_m, UP)
        block = sections[min(sections.index(here) + 3, len(sections) - 1)]
        fault = DeclaredRestriction.on_block(block.id, TargetReason.SECTION_FAULT)
        self._restrictions[max(self._restrictions, default=0) + 1] = (fault, self._now, until_s)
        signal = block.entry_signal or "the line's end"
        self._send_commands(
            (train.train_id,), f"Section fault in block {block.id}: stop at signal {signal}, wait."
        )

    def _send_commands(self, train_ids: tuple[int, ...], text: str) -> int:
        """One command to each of ``train_ids`` (one number, a delivery each): its number."""
        number = max((n for n, *_ in self._commands), default=0) + 1
        for train_id in train_ids:
            pending = _Delivery(DeliveryState.PENDING, self._now)
            self._commands.append((number, train_id, text, pending))
        return number

    def _step_to(self, until_s: float, step_s: float) -> None:
        while self._now < until_s - 1e-9:
            self._step(min(step_s, until_s - self._now))

    # ------------------------------------------------------------------ the clock

    def advance(self, dt_s: float) -> None:
        """Let ``dt_s`` [s] of ground time pass (in steps of at most 1 s)."""
        if not (isinstance(dt_s, int | float) and math.isfinite(dt_s) and dt_s >= 0):
            raise ConfigError("dt_s", dt_s, "a finite time >= 0 [s]")
        with self._lock:
            self._step_to(self._now + float(dt_s), MAX_STEP_S)
            self._version += 1

    def now_s(self) -> float:
        with self._lock:
            return self._now

    def version(self) -> int:
        with self._lock:
            return self._version

    # ------------------------------------------------------------------ one step

    def _step(self, dt_s: float) -> None:
        now = self._now + dt_s
        for train in self._trains.values():
            self._move(train, dt_s, now)
        self._now = now
        for train in self._trains.values():
            if train.link_fails_at_s is not None and train.link_up and now >= train.link_fails_at_s:
                train.link_up = False
                self._registry.timed_out(train.train_id)
                self._registry.link_failed(train.train_id)
                text = "Link lost: stop, call the dispatcher by radio."
                self._send_commands((train.train_id,), text)
            if train.link_up and self._registry.state(train.train_id, now).registered:
                self._report(train)
                if train.arrived_s is not None:  # at its destination: it leaves the line
                    self._registry.deregistered(train.train_id)
                    self._tsrs.forget(train.train_id)
                    self._tracker.forget(train.train_id)
        self._acknowledge()
        self._update_tsrs()
        self._update_targets()

    def _move(self, train: _Train, dt_s: float, now_s: float) -> None:
        if train.arrived_s is not None:
            return
        wanted = 0.0 if not train.link_up else self._wanted_mps(train)
        if train.speed_mps < wanted:
            train.speed_mps = min(wanted, train.speed_mps + ACCEL_MPS2 * dt_s)
        else:
            train.speed_mps = max(wanted, train.speed_mps - BRAKE_MPS2 * dt_s)
        head = train.head_m + train.sign * train.speed_mps * dt_s
        if train.sign * (head - train.destination_m) >= 0:
            head, train.speed_mps, train.arrived_s = train.destination_m, 0.0, now_s
        train.head_m = head

    def _cruise_mps(self, category: str, travel: TravelDirection, head_m: float) -> float:
        edges, values = self._limits[(category, travel)]
        sign = 1.0 if travel is UP else -1.0
        lowest = math.inf
        for ahead in (0.0, 0.25 * LOOKAHEAD_M, 0.5 * LOOKAHEAD_M, LOOKAHEAD_M):
            x = min(max(head_m + sign * ahead, edges[0]), edges[-1])
            i = min(max(bisect.bisect_right(edges, x) - 1, 0), len(values) - 1)
            lowest = min(lowest, values[i])
        return lowest - kmh_to_mps(CRUISE_MARGIN_KMH)

    def _wanted_mps(self, train: _Train) -> float:
        wanted = self._cruise_mps(train.category, train.direction, train.head_m)
        ahead = train.head_m + train.sign * LOOKAHEAD_M
        low, high = sorted((train.head_m, ahead))
        for tsr in self._applied(train.train_id, self._now):
            if tsr.zone_start_m <= high and tsr.zone_end_m >= low:
                wanted = min(wanted, tsr.limit_mps - kmh_to_mps(2.0))
        held = self._target_book.get(train.train_id)
        target = self._tracker.current(train.train_id)
        if target is not None and held is not None and held[1].state is DeliveryState.ACKNOWLEDGED:
            distance = train.sign * (target.position_m - train.head_m) - TARGET_MARGIN_M
            wanted = min(wanted, math.sqrt(2.0 * BRAKE_MPS2 * max(distance, 0.0)))
        return max(wanted + train.excess_mps, 0.0)

    def _report(self, train: _Train) -> None:
        """The running info the train sends (every step while its link is up)."""
        info = RunningInfo(
            driver_id=7000 + train.train_id,
            train_number=train.number,
            loco_number=f"HXD{train.train_id}",
            direction=train.direction,
            speed_mps=max(train.speed_mps, 0.0),
            position_m=train.head_m,
        )
        self._registry.running_info(train.train_id, info, self._now)
        last = train.history[-1][0] if train.history else -math.inf
        if self._now - last >= GRAPH_SAMPLE_S - 1e-9 or train.arrived_s == self._now:
            train.history.append((self._now, train.head_m))
            while train.history and train.history[0][0] < self._now - GRAPH_PAST_S - 60.0:
                train.history.popleft()

    def _acknowledge(self) -> None:
        """The link's acknowledgements: each delivery to a connected train, once its
        ``ack_delay_s`` has passed, through the link's transition tables."""
        answers = {
            TsrState.PENDING_SET: TsrInput.ACK_APPLIED,
            TsrState.PENDING_CANCEL: TsrInput.CANCEL_ACK,
        }
        for (_, train_id), tsr_delivery in self._tsr_book.items():
            train = self._trains[train_id]
            answer = answers.get(tsr_delivery.state)
            if answer is not None and train.link_up and self._due(train, tsr_delivery.since_s):
                tsr_delivery.state = TSR_TRANSITIONS[(tsr_delivery.state, answer)]
                tsr_delivery.since_s = self._now
        books = [(t, d) for t, (_, d) in self._target_book.items()]
        books += [(t, d) for _, t, _, d in self._commands]
        for train_id, delivery in books:
            train = self._trains[train_id]
            if (
                delivery.state is DeliveryState.PENDING
                and train.link_up
                and self._due(train, delivery.since_s)
            ):
                delivery.state = DELIVERY_TRANSITIONS[(DeliveryState.PENDING, DeliveryInput.ACK)]
                delivery.since_s = self._now

    def _due(self, train: _Train, since_s: float) -> bool:
        return self._now - since_s >= train.ack_delay_s - 1e-9

    def _update_tsrs(self) -> None:
        for train in self._trains.values():
            state = self._registry.state(train.train_id, self._now)
            if state.running_info is None or train.arrived_s is not None:
                continue
            route = TrainRoute(
                train.train_id,
                train.direction,
                state.running_info.position_m,
                train.length_m,
                train.destination_m,
            )
            self._carry_out(self._tsrs.update_route(route, self._now))
        self._carry_out(self._tsrs.tick(self._now))

    def _carry_out(self, actions: Iterable[Action]) -> None:
        """What the TSR manager asks for, as the link's delivery book records it."""
        for action in actions:
            if isinstance(action, Deliver):
                key = (action.tsr.session, action.train_id)
                self._tsr_book[key] = _TsrDelivery(TsrState.PENDING_SET, self._now)
            elif isinstance(action, Cancel):
                delivery = self._tsr_book[(action.session, action.train_id)]
                delivery.state = TSR_TRANSITIONS[(delivery.state, TsrInput.CANCEL_REQUESTED)]
                delivery.since_s = self._now
            else:  # Withdraw: the validity ended, nothing more is sent
                for train_id in action.train_ids:
                    delivery = self._tsr_book[(action.session, train_id)]
                    delivery.state = TSR_TRANSITIONS[(delivery.state, TsrInput.VALIDITY_ENDED)]

    def _in_force(self) -> list[DeclaredRestriction]:
        return list(self._live_restrictions().values())

    def _reports(self) -> list[TrainReport]:
        reports = []
        for state in self._registry.states(self._now):
            info = state.running_info
            if state.registered and info is not None and state.length_m is not None:
                received = self._now - (state.info_age_s or 0.0)
                reports.append(
                    TrainReport.from_running_info(state.train_id, info, state.length_m, received)
                )
        return reports

    def _update_targets(self) -> None:
        occupancy = compute_occupancy(self.line, self._reports(), self._now)
        horizons = {t.train_id: self._horizon_m(t) for t in self._trains.values()}
        events = self._tracker.update(occupancy, self._in_force(), horizons, now_s=self._now)
        for event in events:
            pending = _Delivery(DeliveryState.PENDING, self._now)
            self._target_book[event.train_id] = (event.message.target_id, pending)

    def _horizon_m(self, train: _Train) -> float:
        """How far the ground looks for a red signal ahead of ``train`` [m]: the next
        station's stop point at least 2 km ahead (the trains here run through stations,
        so it is a lookout, not a stop), else its destination."""
        stops = [s.stop_m(train.direction) for s in self.line.stations]
        ahead = [x for x in stops if train.sign * (x - train.head_m) >= 2000.0]
        if not ahead:
            return train.destination_m
        return min(ahead) if train.direction is UP else max(ahead)

    def _applied(self, train_id: int, now_s: float) -> list[AppliedTsr]:
        """The TSRs ``train_id`` confirmed and still enforces (ACTIVE, not yet cancelled)."""
        train = self._trains[train_id]
        out = []
        for tsr in self._tsrs.tsrs():
            delivery = self._tsr_book.get((tsr.session, train_id))
            enforced = delivery is not None and delivery.state in ENFORCED
            if enforced and tsr.valid_from_s <= now_s < tsr.valid_until_s:
                out.append(AppliedTsr.of(tsr.message, train.length_m, train.direction))
        return out

    # ------------------------------------------------------------------ the dispatcher

    def set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        with self._lock:
            result = self._set_tsr(fields, actor, now_s)
            if "ok" in result:
                self._version += 1
            return result

    def _set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        session = max((t.session for t in self._tsrs.tsrs()), default=0) + 1
        try:
            op = parse_operation("tsr_set", fields, line=self.line, now_s=now_s)
            assert isinstance(op, SetTsr)
            tsr = op.line_tsr(op.session or session, actor)
            self._carry_out(self._tsrs.set(tsr, now_s))
        except OperationError as exc:
            return {"errors": exc.errors}
        except ConfigError as exc:  # the manager's own rules (e.g. a session reused)
            return {"errors": {config_error_field(exc): str(exc)}}
        return {"ok": self._tsr_view(tsr)}

    def cancel_tsr(self, session: int, actor: str, now_s: float) -> dict[str, Any]:
        with self._lock:
            try:
                tsr = next(t for t in self._tsrs.tsrs() if t.session == session)
            except StopIteration:
                known = ", ".join(str(t.session) for t in self._tsrs.tsrs()) or "none"
                return {"errors": {"session": f"{session} is not a TSR that was set ({known})"}}
            self._carry_out(self._tsrs.cancel(session, now_s))
            self._version += 1
            return {"ok": self._tsr_view(tsr)}

    def set_restriction(
        self, fields: Mapping[str, Any], actor: str, now_s: float
    ) -> dict[str, Any]:
        with self._lock:
            try:
                op = parse_operation("restriction_set", fields, line=self.line, now_s=now_s)
                assert isinstance(op, SetRestriction)
                op.restriction.blocks(self.line)  # a span off the line: an error here
            except OperationError as exc:
                return {"errors": exc.errors}
            except ConfigError as exc:
                return {"errors": {config_error_field(exc): str(exc)}}
            ident = op.restriction_id or max(self._restrictions, default=0) + 1
            if ident in self._restrictions:
                return {"errors": {"id": f"{ident} is not allowed: expected an unused id"}}
            self._restrictions[ident] = (op.restriction, self._now, math.inf)
            self._version += 1
            return {"ok": view.restriction_view(ident, op.restriction, self.line)}

    def clear_restriction(self, ident: int, actor: str, now_s: float) -> dict[str, Any]:
        with self._lock:
            if ident not in self._live_restrictions():
                known = ", ".join(map(str, self._live_restrictions())) or "none"
                return {"errors": {"id": f"{ident} is not allowed: expected one of {known}"}}
            restriction, start, _ = self._restrictions[ident]
            self._restrictions[ident] = (restriction, start, self._now)
            self._version += 1
            return {"ok": {"id": ident}}

    def _live_restrictions(self) -> dict[int, DeclaredRestriction]:
        """The restrictions in force now, by id."""
        return {
            i: r
            for i, (r, start, end) in sorted(self._restrictions.items())
            if start <= self._now < end
        }

    def send_dispatch(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        with self._lock:
            try:
                op = parse_operation("dispatch", fields, line=self.line, now_s=now_s)
            except OperationError as exc:
                return {"errors": exc.errors}
            assert isinstance(op, SendDispatch)
            trains = op.trains or tuple(sorted(self._trains))
            unknown = [t for t in trains if t not in self._trains]
            if unknown:
                ids = f"{min(self._trains)}-{max(self._trains)}"
                message = f"{unknown!r} is not allowed: expected ids of trains on the line ({ids})"
                return {"errors": {"trains": message}}
            number = self._send_commands(trains, op.text)
            self._version += 1
            return {"ok": {"command": number, "trains": list(trains)}}

    # ------------------------------------------------------------------ what the page sees

    def delivery_state(self, session: int, train_id: int) -> TsrState | None:
        """Where the delivery of TSR ``session`` to ``train_id`` stands (None: not sent)."""
        with self._lock:
            delivery = self._tsr_book.get((session, train_id))
            return None if delivery is None else delivery.state

    def train_ids(self) -> tuple[int, ...]:
        """The made-up trains' ids, ascending."""
        return tuple(sorted(self._trains))

    def _tsr_view(self, tsr: LineTsr) -> dict[str, Any]:
        deliveries = {t: d.state for (s, t), d in self._tsr_book.items() if s == tsr.session}
        numbers = {t: self._trains[t].number for t in deliveries}
        return view.tsr_view(tsr, self._tsrs.state(tsr.session), deliveries, numbers)

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """The page's picture at ``now_s`` [s]; a ``now_s`` before the fake's clock (asked
        just before an ``advance``) is taken as the fake's clock."""
        with self._lock:
            now_s = max(float(now_s), self._now)
            occupancy = compute_occupancy(self.line, self._reports(), now_s)
            restricted = restricted_blocks(self.line, self._in_force())
            aspects = view.signal_aspects(self.line, occupancy, restricted)
            trains = [self._train_view(t, now_s) for t in sorted(self._trains)]
            return {
                "now_s": now_s,
                "version": self._version,
                "line": view.line_view(self.line, aspects),
                "blocks": view.blocks_view(self.line, occupancy, restricted),
                "trains": trains,
                "tsrs": [self._tsr_view(t) for t in self._tsrs.tsrs()],
                "restrictions": [
                    view.restriction_view(i, r, self.line)
                    for i, r in self._live_restrictions().items()
                ],
                "dispatch": [
                    {
                        "command": number,
                        "train": train_id,
                        "number": self._trains[train_id].number,
                        "text": text,
                        "state": delivery.state.name,
                    }
                    for number, train_id, text, delivery in self._commands
                ],
                "graph": self._graph(now_s),
                "alarms": view.alarms_view(trains),
            }

    def _train_view(self, train_id: int, now_s: float) -> dict[str, Any]:
        train = self._trains[train_id]
        state = self._registry.state(train_id, now_s)
        info = state.running_info
        mrsp = None
        deviation = None
        if info is not None:
            static = self._static[(train.category, train.direction)]
            applied = self._applied(train_id, now_s)
            mrsp = view.mrsp_at(static, applied, train.direction, info.position_m, now_s)
            deviation = self._deviation_s(train, info.position_m, now_s - (state.info_age_s or 0))
        held = self._target_book.get(train_id)
        target = view.target_view(
            self._tracker.current(train_id),
            None if held is None else held[0],
            None if held is None else held[1].state,
        )
        return view.train_view(
            state, mrsp_mps=mrsp, deviation_s=deviation, target=target, category=train.category
        )

    def _plan_m(self, train: _Train, t_s: float) -> float:
        """Where the plan has ``train``'s head at ``t_s`` [s] (km-post metres)."""
        origin = self.line.start_m if train.direction is UP else self.line.end_m
        run = max(t_s - train.plan_departure_s, 0.0) * train.plan_speed_mps
        x = origin + train.sign * run
        return min(x, train.destination_m) if train.direction is UP else max(x, train.destination_m)

    def _deviation_s(self, train: _Train, head_m: float, at_s: float) -> float:
        """How late [s] (+) the train is against its plan, at the head it reported."""
        if train.arrived_s is not None and at_s >= train.arrived_s:
            origin = self.line.start_m if train.direction is UP else self.line.end_m
            planned = train.plan_departure_s + abs(train.destination_m - origin) / (
                train.plan_speed_mps
            )
            return train.arrived_s - planned
        return train.sign * (self._plan_m(train, at_s) - head_m) / train.plan_speed_mps

    def _graph(self, now_s: float) -> dict[str, Any]:
        start, end = now_s - GRAPH_PAST_S, now_s + GRAPH_AHEAD_S
        out = []
        for train_id in sorted(self._trains):
            train = self._trains[train_id]
            origin = self.line.start_m if train.direction is UP else self.line.end_m
            arrive = train.plan_departure_s + abs(train.destination_m - origin) / (
                train.plan_speed_mps
            )
            times = [t for t in (start, train.plan_departure_s, arrive, end) if start <= t <= end]
            plan = [
                [round(t), view.km(self._plan_m(train, t))]
                for t in sorted(set(times))
                if train.plan_departure_s <= t <= arrive
            ]
            actual = [[round(t), view.km(x)] for t, x in train.history if t >= start]
            out.append(
                {
                    "id": train_id,
                    "number": train.number,
                    "direction": view.direction(train.direction),
                    "plan": plan,
                    "actual": actual,
                }
            )
        return {"from_s": start, "to_s": end, "trains": out}


# ---------------------------------------------------------------------------- the demo


def main(argv: list[str] | None = None) -> int:
    """``python -m railpilot.web.fake``: serve the dashboard over a :class:`FakeGround`."""
    import uvicorn

    from .app import DEFAULT_HOST, LOCAL_HOSTS, create_app, server_config

    parser = argparse.ArgumentParser(
        prog="python -m railpilot.web.fake",
        description="Serve the dispatcher dashboard over a made-up heavy-haul line.",
    )
    parser.add_argument("--host", default=DEFAULT_HOST, help=f"address to bind [{DEFAULT_HOST}]")
    parser.add_argument("--port", type=int, default=8080, help="port (0: any free) [8080]")
    parser.add_argument("--trains", type=int, default=24, help="how many trains [24]")
    parser.add_argument("--seed", type=int, default=0, help="seed of everything made up [0]")
    parser.add_argument(
        "--speed", type=float, default=1.0, help="ground seconds per wall second [1]"
    )
    parser.add_argument("--token", default=None, help="dispatcher token [a random one]")
    args = parser.parse_args(argv)
    token = args.token or secrets.token_urlsafe(16)
    ground = FakeGround(args.trains, seed=args.seed)
    # Bound elsewhere on purpose, the page answers to any host name (the user's choice).
    hosts = LOCAL_HOSTS if args.host in LOCAL_HOSTS else None
    if hosts is None:
        print(
            f"warning: binding to {args.host}: anyone who can reach it sees the line "
            "(setting and cancelling TSRs still needs the token)",
            file=sys.stderr,
        )
    app = create_app(ground, token=token, allowed_hosts=hosts)
    server = uvicorn.Server(server_config(app, host=args.host, port=args.port))

    async def run() -> None:
        loop = asyncio.get_running_loop()
        serving = asyncio.create_task(server.serve())
        while not server.started and not serving.done():
            await asyncio.sleep(0.05)
        if server.started:
            port = server.servers[0].sockets[0].getsockname()[1]
            print(f"dashboard: http://{args.host}:{port}/", flush=True)
            print(f"dispatcher token: {token}", flush=True)
        last = loop.time()
        while not serving.done():
            await asyncio.sleep(0.5)
            now = loop.time()
            ground.advance(args.speed * (now - last))
            last = now
        await serving

    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
