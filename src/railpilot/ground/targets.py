"""Target points on the ground (paper 001, section 2.4): no I/O, time passed in.

The ground detects what holds a signal at red in front of a train and sends that
signal's km post as a ``TargetPoint``; the onboard stops a safety distance before it
(``onboard.target_point``). On a fixed-block line a signal is red when the block section
it protects is not free:

- a train ahead occupies it (its tail is in it): ``TRAIN_AHEAD``;
- the dispatcher has declared a section fault on it: ``SECTION_FAULT``;
- the dispatcher has declared a switch indication lost in it: ``SWITCH_INDICATION_LOST``.

The dispatcher's declarations are :class:`DeclaredRestriction` values (a block id, or a
km span on one or both tracks); the dispatcher sets one by adding it to the set passed
to :meth:`TargetPointTracker.update` and clears it by leaving it out.

A train's target (:func:`find_target`) is the nearest signal ahead of its head, in its
direction, whose block is not free, looking no further than its *horizon*: its next
station stop or the end of its route (default: the end of the line). Signals at or
beyond the horizon are not targets: the train stops before them anyway, and a red exit
signal would otherwise pull its stop short of the platform. When a block is not free for
several reasons the reason sent is the first of :data:`REASON_PRECEDENCE`: a declared
condition outlasts the train ahead, so the driver is told the lasting one and the target
does not change (nor get resent) when the train ahead moves on.

A train already *inside* a block held at red (a train ahead in its own head's section,
or a declaration on it: it has passed the red signal, or the ground's view lags a cycle)
gets that section's entry signal, behind it: the onboard's target stop is then behind
the train and it stops at once. This errs on the safe side.

Events and "clear"
------------------
:class:`TargetPointTracker` remembers what it last sent each train and returns only the
changes, in ascending train id: a :class:`TargetPointSet` when a train's target appears,
moves or changes reason, and a :class:`TargetPointCleared` when the train's path is free
up to its horizon. Every event carries the ``TargetPoint`` to send, each under a fresh
``target_id`` from one counter (increasing by one per event, so the same updates give
the same ids), so an acknowledgement always names exactly one content (the link's
delivery book is keyed by target id, docs/protocol.md 8.4).

The link has no message to clear or cancel a target point (link/messages.py: only
``TARGET_POINT`` and its acknowledgement). A clear is therefore sent as a
``TargetPoint`` under a fresh id at the **end of the line in the train's direction**
with reason ``OTHER``: the onboard's most restrictive speed profile ends there already
(its ``LINE_END`` governor), so it restricts nothing. The convention that makes a clear
(and a moved target) take effect on the onboard: **a train's newest target id supersedes
every older one** (each event also names the id it replaces).

A train missing from an update (no report this time) keeps what was last sent to it and
gets no event; when it comes back the comparison picks up from there. :meth:`forget` drops
a train (deregistered). The tracker's counter must survive a ground restart
(``first_target_id``): an id the onboard has seen must not come back with other content.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from functools import lru_cache

from railpilot.errors import ConfigError, is_finite_number
from railpilot.line.model import BlockSection, RailLine
from railpilot.link.messages import U32_MAX, TargetPoint, TargetReason, TravelDirection

from .occupancy import (
    Occupancy,
    TrainOccupancy,
    blocks_by_id,
    check_train_id,
    check_travel_direction,
    direction_sign,
    line_end_m,
)

#: The reasons a dispatcher declares (TRAIN_AHEAD comes from the occupancy).
DECLARED_REASONS: tuple[TargetReason, ...] = (
    TargetReason.SECTION_FAULT,
    TargetReason.SWITCH_INDICATION_LOST,
)
#: Which reason is sent when a block is held at red for several (module docstring).
REASON_PRECEDENCE: tuple[TargetReason, ...] = (
    TargetReason.SECTION_FAULT,
    TargetReason.SWITCH_INDICATION_LOST,
    TargetReason.TRAIN_AHEAD,
)
#: Reason of the ``TargetPoint`` that represents a clear (module docstring).
CLEAR_REASON = TargetReason.OTHER


def is_clear(target: TargetPoint, line: RailLine) -> bool:
    """Whether ``target`` is a clear as the tracker sends one (module docstring): reason
    :data:`CLEAR_REASON` at an end of ``line``."""
    return target.reason is CLEAR_REASON and target.position_m in (line.start_m, line.end_m)


# ---------------------------------------------------------------------------- declarations


@dataclass(frozen=True)
class DeclaredRestriction:
    """A dispatcher's declaration that holds signals at red.

    Either ``block_id`` (one block section, of its own direction) or a km span
    ``start_m < end_m`` [m] with ``direction`` (``None``: both tracks, e.g. a crossover's
    switch). A span restricts every block it shares more than a point with.

    Build with :meth:`on_block` or :meth:`on_span`.
    """

    reason: TargetReason
    block_id: str | None = None
    start_m: float | None = None
    end_m: float | None = None
    direction: TravelDirection | None = None

    def __post_init__(self) -> None:
        if self.reason not in DECLARED_REASONS:
            names = ", ".join(f"TargetReason.{r.name}" for r in DECLARED_REASONS)
            raise ConfigError("restriction.reason", self.reason, f"one of {names}")
        span = (self.start_m, self.end_m)
        if self.block_id is not None:
            if not isinstance(self.block_id, str) or not self.block_id.strip():
                raise ConfigError("restriction.block_id", self.block_id, "a block section id")
            if span != (None, None) or self.direction is not None:
                raise ConfigError(
                    "restriction.start_m",
                    span,
                    "no span and no direction with a block_id (a block has its own direction)",
                )
            return
        for name in ("start_m", "end_m"):
            value = getattr(self, name)
            if not is_finite_number(value) or value < 0:
                raise ConfigError(
                    f"restriction.{name}", value, "a finite km post >= 0 [m] (or give a block_id)"
                )
        assert self.start_m is not None and self.end_m is not None
        if not self.start_m < self.end_m:
            raise ConfigError(
                "restriction.end_m", self.end_m, f"a km post above start_m = {self.start_m:g} m"
            )
        if self.direction is not None:
            check_travel_direction(self.direction, "restriction.direction")

    @classmethod
    def on_block(cls, block_id: str, reason: TargetReason) -> DeclaredRestriction:
        """A declaration on one block section."""
        return cls(reason, block_id=block_id)

    @classmethod
    def on_span(
        cls,
        start_m: float,
        end_m: float,
        reason: TargetReason,
        direction: TravelDirection | None = None,
    ) -> DeclaredRestriction:
        """A declaration on km ``start_m``-``end_m`` [m], one track or (``None``) both."""
        return cls(reason, start_m=start_m, end_m=end_m, direction=direction)

    def blocks(self, line: RailLine) -> tuple[BlockSection, ...]:
        """The block sections of ``line`` this declaration holds at red."""
        if self.block_id is not None:
            section = blocks_by_id(line).get(self.block_id)
            if section is None:
                raise ConfigError(
                    "restriction.block_id",
                    self.block_id,
                    f"the id of a block section of line '{line.name}'",
                )
            return (section,)
        assert self.start_m is not None and self.end_m is not None
        if self.start_m < line.start_m or self.end_m > line.end_m:
            raise ConfigError(
                "restriction.start_m",
                (self.start_m, self.end_m),
                f"a span inside line '{line.name}', {line.start_m:g}-{line.end_m:g} m",
            )
        return tuple(
            s
            for s in line.block_sections
            if (self.direction is None or s.direction is self.direction)
            and s.start_m < self.end_m
            and s.end_m > self.start_m
        )


def restricted_blocks(
    line: RailLine, restrictions: Iterable[DeclaredRestriction]
) -> dict[str, TargetReason]:
    """Block id -> the declared reason holding it at red (by :data:`REASON_PRECEDENCE`)."""
    out: dict[str, TargetReason] = {}
    for i, restriction in enumerate(restrictions):
        if not isinstance(restriction, DeclaredRestriction):
            raise ConfigError(f"restrictions[{i}]", restriction, "a DeclaredRestriction")
        for section in restriction.blocks(line):
            held = out.get(section.id)
            if held is None or REASON_PRECEDENCE.index(restriction.reason) < (
                REASON_PRECEDENCE.index(held)
            ):
                out[section.id] = restriction.reason
    return out


# ---------------------------------------------------------------------------- the target


@dataclass(frozen=True)
class Target:
    """A red signal a train must stop before.

    Attributes
    ----------
    position_m
        The signal's km post [m] (the block's entry; the line's end for a block entered
        from beyond the line, which has no signal).
    reason
        Why the block beyond it is not free.
    block_id
        The block section held at red.
    signal_id
        The signal's id (``None`` for a block entered from beyond the line).
    """

    position_m: float
    reason: TargetReason
    block_id: str
    signal_id: str | None

    def __post_init__(self) -> None:
        if not is_finite_number(self.position_m):
            raise ConfigError("target.position_m", self.position_m, "a finite km post [m]")
        if not isinstance(self.reason, TargetReason):
            raise ConfigError("target.reason", self.reason, "a TargetReason")


def _check_horizon(line: RailLine, train_id: int, horizon_m: object) -> float:
    if (
        isinstance(horizon_m, int | float)
        and is_finite_number(horizon_m)
        and line.start_m <= horizon_m <= line.end_m
    ):
        return float(horizon_m)
    raise ConfigError(
        f"horizons[{train_id}]",
        horizon_m,
        f"a km post on line '{line.name}', {line.start_m:g}-{line.end_m:g} m",
    )


def _reason(
    section: BlockSection,
    occupancy: Occupancy,
    me: TrainOccupancy,
    restricted: Mapping[str, TargetReason],
) -> TargetReason | None:
    declared = restricted.get(section.id)
    if declared is not None:
        return declared  # declarations come first (REASON_PRECEDENCE)
    for t in occupancy.occupants(section.id):
        if t != me.train_id and occupancy.train(t).is_ahead_of(me):
            return TargetReason.TRAIN_AHEAD
    return None


@lru_cache(maxsize=16)
def _walk(
    line: RailLine, direction: TravelDirection
) -> tuple[tuple[BlockSection, ...], tuple[str, ...], list[float]]:
    """The block sections of ``direction`` in travel order, their ids, and where a train
    enters each as a distance along its direction (``sign * entry_m``, ascending: what
    :func:`find_target` bisects its horizon in)."""
    sections = line.block_sections_for(direction)
    sign = direction_sign(direction)
    return sections, tuple(s.id for s in sections), [sign * s.entry_m for s in sections]


def find_target(
    line: RailLine,
    occupancy: Occupancy,
    train_id: int,
    restricted: Mapping[str, TargetReason] | None = None,
    horizon_m: float | None = None,
) -> Target | None:
    """The target of ``train_id``: the nearest red signal ahead before its horizon, or None.

    ``restricted`` maps block ids to declared reasons (:func:`restricted_blocks`);
    ``horizon_m`` [m] is the train's next station stop or route end (default: the end of
    the line in its direction). Only trains whose head is not behind this train's head
    count as trains ahead (a stale train behind cannot hold a block in front of it).
    """
    me = occupancy.train(train_id)
    held = restricted if restricted is not None else {}
    sign = direction_sign(me.direction)
    horizon = (
        line_end_m(line, me.direction)
        if horizon_m is None
        else _check_horizon(line, train_id, horizon_m)
    )
    sections, ids, travelled = _walk(line, me.direction)
    first = line.block_index(me.head_block_id, me.direction)
    if first is None:
        raise ConfigError(
            "occupancy.head_block_id",
            me.head_block_id,
            f"a block section of line '{line.name}' going {me.direction.name}",
        )
    # The head's own section is always looked at (the train is inside it); a section
    # ahead only when its signal stands before the horizon.
    end = max(bisect.bisect_left(travelled, sign * horizon), first + 1)
    occupied = occupancy.by_block
    for k in range(first, end):
        block_id = ids[k]
        if block_id not in occupied and block_id not in held:
            continue  # free and not declared (most of them: the ground asks every second)
        section = sections[k]
        reason = _reason(section, occupancy, me, held)
        if reason is not None:
            return Target(float(section.entry_m), reason, section.id, section.entry_signal)
    return None


# ---------------------------------------------------------------------------- events


@dataclass(frozen=True)
class TargetPointSet:
    """Send ``message`` to ``train_id``: its target appeared, moved or changed reason.

    ``replaces`` is the target id it supersedes (``None`` for the train's first).
    """

    train_id: int
    at_s: float
    target: Target
    message: TargetPoint
    replaces: int | None


@dataclass(frozen=True)
class TargetPointCleared:
    """Send ``message`` to ``train_id``: its path is free up to its horizon.

    ``message`` is the clear as the link carries it (module docstring): a fresh id at the
    end of the line in the train's direction, reason ``OTHER``; ``replaces`` the target id
    it clears.
    """

    train_id: int
    at_s: float
    message: TargetPoint
    replaces: int


TargetEvent = TargetPointSet | TargetPointCleared


@dataclass(frozen=True)
class _Sent:
    target: Target | None  # None: the last thing sent was a clear
    target_id: int


#: A target held since before a restart whose signal the tracker does not know.
_UNKNOWN = Target(-1.0, TargetReason.OTHER, "", None)  # no real block has id ""


class TargetPointTracker:
    """Turns occupancy and declarations into the target point events to send.

    Parameters
    ----------
    line
        The fixed-block line the occupancy is computed on.
    first_target_id
        The id of the first event (ids then increase by one per event); a restarted
        ground resumes from its stored :attr:`next_target_id`.
    """

    def __init__(self, line: RailLine, *, first_target_id: int = 1) -> None:
        if not isinstance(line, RailLine):
            raise ConfigError("line", line, "a RailLine")
        if type(first_target_id) is not int or not 0 <= first_target_id <= U32_MAX:
            raise ConfigError("first_target_id", first_target_id, f"an integer in [0, {U32_MAX}]")
        blocks_by_id(line)  # unique block ids (occupancy and declarations name blocks by id)
        self.line = line
        self._next_id = first_target_id
        self._sent: dict[int, _Sent] = {}
        self._last_now_s = -math.inf

    @property
    def next_target_id(self) -> int:
        """The id the next event will carry (store it to resume after a restart)."""
        return self._next_id

    def current(self, train_id: int) -> Target | None:
        """The target last sent to ``train_id`` (``None``: none sent, or cleared)."""
        sent = self._sent.get(train_id)
        return None if sent is None else sent.target

    def current_target_id(self, train_id: int) -> int | None:
        """The id of the last event sent to ``train_id`` (``None``: none yet)."""
        sent = self._sent.get(train_id)
        return None if sent is None else sent.target_id

    def forget(self, train_id: int) -> None:
        """Drop ``train_id`` (deregistered): nothing is sent to it any more."""
        self._sent.pop(check_train_id(train_id), None)

    def take_id(self) -> int:
        """An id for a target point sent by other means (a dispatcher's, by hand): ids
        come from this one counter so a train never sees one id with two contents."""
        target_id = self._check_id(self._next_id)
        self._next_id += 1
        return target_id

    def resume(self, train_id: int, target_id: int, *, holding: bool) -> None:
        """After a restart: ``train_id`` holds target ``target_id`` as the store says.

        ``holding``: that target holds the train (not a clear). The tracker does not know
        which signal it was, so its next update sends the train what holds now, a target
        or a clear, under a fresh id; a train the store shows clear is left as it is.
        """
        check_train_id(train_id)
        self._next_id = max(self._next_id, target_id + 1)
        self._sent[train_id] = _Sent(_UNKNOWN if holding else None, target_id)

    def _check_id(self, target_id: int) -> int:
        if target_id > U32_MAX:
            raise ConfigError(
                "target_id",
                target_id,
                f"an id <= {U32_MAX} (every target id is used: restart the ids with a new "
                "first_target_id once the trains hold none of the old ones)",
            )
        return target_id

    def update(
        self,
        occupancy: Occupancy,
        restrictions: Iterable[DeclaredRestriction] = (),
        horizons: Mapping[int, float] | None = None,
        *,
        now_s: float,
    ) -> tuple[TargetEvent, ...]:
        """The events to send at ``now_s`` [s] for ``occupancy`` and the declarations in
        force, in ascending train id; nothing when nothing changed.

        ``horizons`` maps a train id to the km post [m] of its next station stop or route
        end; trains not in it look to the end of the line (ids of trains not in the
        occupancy are ignored: they may report again later).
        """
        if not isinstance(occupancy, Occupancy):
            raise ConfigError("occupancy", occupancy, "an Occupancy")
        if occupancy.line_name != self.line.name:
            raise ConfigError(
                "occupancy.line_name", occupancy.line_name, f"'{self.line.name}', the tracker's"
            )
        if not is_finite_number(now_s) or now_s < self._last_now_s:
            raise ConfigError(
                "now_s", now_s, f"a finite time not before the last update, {self._last_now_s}"
            )
        restricted = restricted_blocks(self.line, restrictions)
        wanted = dict(horizons) if horizons is not None else {}
        for train_id, horizon in wanted.items():
            _check_horizon(self.line, train_id, horizon)
        # Work on copies and commit at the end: an update that fails leaves the tracker as
        # it was, so no event is lost between what was computed and what was returned.
        sent_now = dict(self._sent)
        next_id = self._next_id
        events: list[TargetEvent] = []
        for train in occupancy.trains:  # ascending train id
            ident = train.train_id
            target = find_target(self.line, occupancy, ident, restricted, wanted.get(ident))
            sent = sent_now.get(ident)
            if target is None:
                if sent is None or sent.target is None:
                    continue  # clear and already known clear (or never told otherwise)
                end_m = float(line_end_m(self.line, train.direction))
                message = TargetPoint(self._check_id(next_id), end_m, CLEAR_REASON)
                events.append(TargetPointCleared(ident, float(now_s), message, sent.target_id))
                sent_now[ident] = _Sent(None, message.target_id)
            elif sent is None or sent.target != target:
                message = TargetPoint(self._check_id(next_id), target.position_m, target.reason)
                replaces = None if sent is None else sent.target_id
                events.append(TargetPointSet(ident, float(now_s), target, message, replaces))
                sent_now[ident] = _Sent(target, message.target_id)
            else:
                continue
            next_id += 1
        self._sent = sent_now
        self._next_id = next_id
        self._last_now_s = float(now_s)
        return tuple(events)
