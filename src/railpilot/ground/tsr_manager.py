"""Temporary speed restrictions on the ground (paper 001, section 2.5): no I/O, time passed in.

The dispatcher sets a TSR once for the line (km range, limit, validity window, reason).
The ground works out which trains it concerns and delivers it to each:

- a train **concerns** a TSR when the rest of its route (from its tail to its destination,
  in its direction) overlaps the restriction, and it can reach the restriction before the
  restriction expires (at the line's top speed, the earliest it could);
- a train that registers later, or whose route is given later, gets every active TSR that
  concerns it;
- a cancel goes to every train the TSR was delivered to;
- a TSR whose validity has ended is withdrawn everywhere: the manager marks it expired
  and tells the transport, which stops resending (the onboard drops it by its own clock,
  since the ``TsrSet`` carries its validity).

The manager decides *what* to deliver to *whom*. The link endpoints deliver and resend
until acknowledged, and the store persists both (ground/store.py). Every method returns
the actions to carry out, in a deterministic order (by session, then train id).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum

from railpilot.errors import ConfigError, is_finite_number
from railpilot.line.model import UP
from railpilot.link.messages import MAX_POSITION_M, U32_MAX, TravelDirection, TsrSet


class LineTsrState(Enum):
    ACTIVE = "active"  # set, not yet expired nor cancelled
    CANCELLED = "cancelled"
    EXPIRED = "expired"


@dataclass(frozen=True)
class LineTsr:
    """A TSR as the dispatcher set it for the line.

    ``start_m < end_m`` [m] km posts (both tracks), ``limit_mps`` [m/s], validity
    ``[valid_from_s, valid_until_s)`` [s, ground clock], ``reason`` and ``set_by`` (the
    dispatcher) for the audit log.
    """

    session: int
    start_m: float
    end_m: float
    limit_mps: float
    valid_from_s: float
    valid_until_s: float
    reason: str = ""
    set_by: str = ""

    def __post_init__(self) -> None:
        if type(self.session) is not int or not 1 <= self.session <= U32_MAX:
            raise ConfigError("tsr.session", self.session, f"an integer in [1, {U32_MAX}]")
        for name in ("start_m", "end_m"):
            value = getattr(self, name)
            if not is_finite_number(value) or not 0.0 <= value <= MAX_POSITION_M:
                raise ConfigError(f"tsr.{name}", value, "a km post [m] on the line")
        if not self.start_m < self.end_m:
            raise ConfigError("tsr.end_m", self.end_m, f"a km post above start_m = {self.start_m}")
        if not is_finite_number(self.limit_mps) or not 0.0 < self.limit_mps <= 100.0:
            raise ConfigError("tsr.limit_mps", self.limit_mps, "a speed in (0, 100] m/s")
        if not (is_finite_number(self.valid_from_s) and is_finite_number(self.valid_until_s)):
            raise ConfigError("tsr.valid_until_s", self.valid_until_s, "finite validity times [s]")
        if not self.valid_from_s < self.valid_until_s:
            raise ConfigError(
                "tsr.valid_until_s",
                self.valid_until_s,
                f"a time after valid_from_s = {self.valid_from_s}",
            )

    @property
    def message(self) -> TsrSet:
        """The ``TsrSet`` the link carries to each train."""
        return TsrSet(
            self.session,
            self.start_m,
            self.end_m,
            self.limit_mps,
            self.valid_from_s,
            self.valid_until_s,
        )


@dataclass(frozen=True)
class TrainRoute:
    """Where a train is and where it goes: head km post [m], direction, length [m] and the
    km post of its destination (the end of its route) [m]."""

    train_id: int
    direction: TravelDirection
    head_m: float
    length_m: float
    destination_m: float

    def __post_init__(self) -> None:
        if type(self.train_id) is not int or not 0 <= self.train_id <= U32_MAX:
            raise ConfigError("route.train_id", self.train_id, f"an integer in [0, {U32_MAX}]")
        if self.direction not in (TravelDirection.UP, TravelDirection.DOWN):
            raise ConfigError(
                "route.direction", self.direction, "TravelDirection.UP or TravelDirection.DOWN"
            )
        for name in ("head_m", "destination_m"):
            value = getattr(self, name)
            if not is_finite_number(value) or not 0.0 <= value <= MAX_POSITION_M:
                raise ConfigError(f"route.{name}", value, "a km post [m] on the line")
        if not is_finite_number(self.length_m) or not 0.0 <= self.length_m <= 10_000.0:
            raise ConfigError("route.length_m", self.length_m, "a length in [0, 10000] m")

    def remaining(self) -> tuple[float, float]:
        """The km range [m] the train still occupies or will: tail to destination."""
        if self.direction == UP:
            return min(self.head_m - self.length_m, self.destination_m), self.destination_m
        return self.destination_m, max(self.head_m + self.length_m, self.destination_m)

    def distance_to_m(self, position_m: float) -> float:
        """Distance [m] the head runs before reaching ``position_m`` (0 if it has)."""
        ahead = position_m - self.head_m if self.direction == UP else self.head_m - position_m
        return max(ahead, 0.0)


@dataclass(frozen=True)
class Deliver:
    """Deliver ``tsr`` to ``train_id`` (resent until acknowledged)."""

    train_id: int
    tsr: LineTsr


@dataclass(frozen=True)
class Cancel:
    """Cancel TSR ``session`` on ``train_id`` (resent until acknowledged)."""

    train_id: int
    session: int


@dataclass(frozen=True)
class Withdraw:
    """TSR ``session`` expired: stop delivering it to ``train_ids`` (nothing is sent)."""

    session: int
    train_ids: tuple[int, ...]


Action = Deliver | Cancel | Withdraw


@dataclass
class _Entry:
    tsr: LineTsr
    state: LineTsrState = LineTsrState.ACTIVE
    delivered_to: set[int] = field(default_factory=set)


class TsrManager:
    """The line's TSRs and to which trains each went.

    ``top_speed_mps`` [m/s]: the line's highest permitted speed, for the earliest a train
    can reach a restriction (a train that cannot reach it before it expires is spared it).
    """

    def __init__(self, top_speed_mps: float) -> None:
        if not is_finite_number(top_speed_mps) or not top_speed_mps > 0:
            raise ConfigError("top_speed_mps", top_speed_mps, "a speed > 0 [m/s]")
        self.top_speed_mps = float(top_speed_mps)
        self._tsrs: dict[int, _Entry] = {}
        self._routes: dict[int, TrainRoute] = {}

    # --- queries

    def tsrs(self) -> tuple[LineTsr, ...]:
        """Every TSR ever set, by session."""
        return tuple(self._tsrs[s].tsr for s in sorted(self._tsrs))

    def state(self, session: int) -> LineTsrState:
        return self._entry(session).state

    def delivered_to(self, session: int) -> tuple[int, ...]:
        return tuple(sorted(self._entry(session).delivered_to))

    def concerns(self, tsr: LineTsr, route: TrainRoute, now_s: float) -> bool:
        """Does ``tsr`` concern the train on ``route`` at ``now_s`` [s] (module docstring)?"""
        low, high = route.remaining()
        if not (low < tsr.end_m and tsr.start_m < high):
            return False
        entry = tsr.start_m if route.direction == UP else tsr.end_m
        earliest_s = now_s + route.distance_to_m(entry) / self.top_speed_mps
        return earliest_s < tsr.valid_until_s

    # --- the dispatcher

    def set(self, tsr: LineTsr, now_s: float) -> list[Action]:
        """Set ``tsr`` for the line; deliver it to every train it concerns.

        Setting the same TSR again is idempotent; a session reused for another
        restriction is an error naming ``tsr.session``.
        """
        _check_time(now_s)
        existing = self._tsrs.get(tsr.session)
        if existing is not None:
            if existing.tsr != tsr:
                raise ConfigError(
                    "tsr.session", tsr.session, "a session not used for another restriction"
                )
            return []
        if not tsr.valid_until_s > now_s:
            raise ConfigError("tsr.valid_until_s", tsr.valid_until_s, f"a time after now ({now_s})")
        entry = self._tsrs[tsr.session] = _Entry(tsr)
        return self._deliver_to_concerned(entry, self._routes.values(), now_s)

    def cancel(self, session: int, now_s: float) -> list[Action]:
        """Cancel ``session`` everywhere it was delivered (an expired or cancelled one:
        nothing to do)."""
        _check_time(now_s)
        entry = self._entry(session)
        if entry.state is not LineTsrState.ACTIVE:
            return []
        entry.state = LineTsrState.CANCELLED
        return [Cancel(t, session) for t in sorted(entry.delivered_to)]

    def deliver_also(self, session: int, train_ids: Iterable[int]) -> list[Action]:
        """Deliver active TSR ``session`` to ``train_ids`` too, whether or not the
        manager's view says it concerns them (a dispatcher naming trains errs on the safe
        side: a train the ground has no position for yet still gets it)."""
        entry = self._entry(session)
        if entry.state is not LineTsrState.ACTIVE:
            return []
        actions: list[Action] = []
        for train_id in sorted(set(train_ids) - entry.delivered_to):
            entry.delivered_to.add(train_id)
            actions.append(Deliver(train_id, entry.tsr))
        return actions

    def restore(self, tsr: LineTsr, state: LineTsrState, delivered_to: Iterable[int]) -> None:
        """Take back a TSR from the store after a restart (nothing is sent: the link's
        records, restored beside it, resume each delivery where it stood)."""
        if tsr.session in self._tsrs:
            raise ConfigError("tsr.session", tsr.session, "a session not restored twice")
        self._tsrs[tsr.session] = _Entry(tsr, LineTsrState(state), set(delivered_to))

    def checkpoint(self) -> dict[int, tuple[LineTsrState, frozenset[int]]]:
        """Each TSR's state and the trains it went to, to :meth:`roll_back` to if the
        operation that follows is not kept (the store refused it)."""
        return {s: (e.state, frozenset(e.delivered_to)) for s, e in self._tsrs.items()}

    def roll_back(self, checkpoint: Mapping[int, tuple[LineTsrState, frozenset[int]]]) -> None:
        """Back to ``checkpoint``: a TSR set since is forgotten, the others' states and
        trains are as they were."""
        for session in [s for s in self._tsrs if s not in checkpoint]:
            del self._tsrs[session]
        for session, (state, trains) in checkpoint.items():
            entry = self._tsrs[session]
            entry.state = state
            entry.delivered_to = set(trains)

    def next_session(self) -> int:
        """One above every session set so far (1 for the first)."""
        return max(self._tsrs, default=0) + 1

    # --- the trains

    def update_route(self, route: TrainRoute, now_s: float) -> list[Action]:
        """A train registered, or its position or destination changed: deliver every
        active TSR that now concerns it and has not gone to it yet."""
        _check_time(now_s)
        self._routes[route.train_id] = route
        actions: list[Action] = []
        for session in sorted(self._tsrs):
            entry = self._tsrs[session]
            if entry.state is LineTsrState.ACTIVE:
                actions += self._deliver_to_concerned(entry, (route,), now_s)
        return actions

    def forget(self, train_id: int) -> None:
        """The train left the line (deregistered at its destination)."""
        self._routes.pop(train_id, None)

    # --- the clock

    def tick(self, now_s: float) -> list[Action]:
        """Withdraw every active TSR whose validity has ended by ``now_s`` [s]."""
        _check_time(now_s)
        actions: list[Action] = []
        for session in sorted(self._tsrs):
            entry = self._tsrs[session]
            if entry.state is LineTsrState.ACTIVE and entry.tsr.valid_until_s <= now_s:
                entry.state = LineTsrState.EXPIRED
                actions.append(Withdraw(session, tuple(sorted(entry.delivered_to))))
        return actions

    # --- internals

    def _entry(self, session: int) -> _Entry:
        entry = self._tsrs.get(session)
        if entry is None:
            known = ", ".join(str(s) for s in sorted(self._tsrs)) or "none"
            raise ConfigError("session", session, f"a session that was set (set: {known})")
        return entry

    def _deliver_to_concerned(
        self, entry: _Entry, routes: Iterable[TrainRoute], now_s: float
    ) -> list[Action]:
        actions: list[Action] = []
        for route in sorted(routes, key=lambda r: r.train_id):
            if route.train_id not in entry.delivered_to and self.concerns(entry.tsr, route, now_s):
                entry.delivered_to.add(route.train_id)
                actions.append(Deliver(route.train_id, entry.tsr))
        return actions


def _check_time(now_s: float) -> None:
    if not is_finite_number(now_s):
        raise ConfigError("now_s", now_s, "a finite time [s]")
