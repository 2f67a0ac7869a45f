"""Most restrictive speed profile (MRSP) (paper 001, sections 2.4-2.5).

The MRSP is the pointwise minimum of everything that limits the train's speed along the
line: the static limits of the line, the temporary speed restrictions (TSRs) in force, each
extended by one train length on its exit side so that the tail obeys it too (2.5), and the
target points, each an end of authority beyond which the train must not run (2.4). The
supervision curves (onboard/supervision.py) brake towards its decreases; the dashboard
names the input that governs each stretch. Rules in docs/onboard.md, "Most restrictive
speed profile".

Coordinates
-----------
Positions are km-post metres (``km_post_to_m``, units.py), the coordinate of the link's
messages and of the line data, with an explicit :class:`TravelDirection`: ``UP`` towards
increasing km posts, ``DOWN`` towards decreasing. :func:`travelled_m` and
:func:`km_post_m` convert to and from the train's travelled distance;
:func:`direction_sign` gives the ``+1 / -1`` of ``vehicle.profile.FORWARD / BACKWARD``.

Boundaries
----------
A :class:`SpeedProfile` is piecewise constant: ``speeds_mps[i]`` [m/s] on the open stretch
``(edges_m[i], edges_m[i+1])``. Exactly at an edge the stricter (lower) of the two sides
applies, in either direction of travel, so a boundary never lets a train be faster than
either side and the pointwise minimum of profiles is again such a profile. Outside
``[edges_m[0], edges_m[-1]]`` (the line the profile describes) the speed is 0: nothing is
permitted beyond the described line, and by the same rule the two end points are 0 as well.
(The line model's own lookups, line/model.py, put a boundary in the section a train enters;
the MRSP deliberately does not: at a boundary it is never more permissive than either.)

Canonical form
--------------
Neighbouring pieces with equal speeds are merged and no piece has zero length, so two
profiles that are the same function are equal (``==``) and hash alike.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from railpilot.errors import ConfigError
from railpilot.link.events import AppliedTsr, tsr_zone
from railpilot.link.messages import TargetPoint, TravelDirection, TsrSet

FloatArray = npt.NDArray[np.float64]

UP = TravelDirection.UP
DOWN = TravelDirection.DOWN


# ---------------------------------------------------------------------------- coordinates


def _check_travel_direction(direction: object, field: str = "direction") -> TravelDirection:
    """``UP`` or ``DOWN``; anything else (``UNKNOWN`` included) is a :class:`ConfigError`."""
    if direction is UP or direction is DOWN:
        return direction
    raise ConfigError(
        field, direction, "TravelDirection.UP (increasing km posts) or TravelDirection.DOWN"
    )


def direction_sign(direction: TravelDirection) -> float:
    """``+1.0`` going ``UP``, ``-1.0`` going ``DOWN`` (``vehicle.profile.FORWARD/BACKWARD``)."""
    return 1.0 if _check_travel_direction(direction) is UP else -1.0


def travelled_m(
    position_m: npt.ArrayLike, direction: TravelDirection, origin_m: float = 0.0
) -> FloatArray:
    """Distance [m] travelled from km post ``origin_m`` [m] to ``position_m`` [m].

    ``position_m - origin_m`` going ``UP``, ``origin_m - position_m`` going ``DOWN``;
    negative behind the origin. Vectorised; inverse of :func:`km_post_m`.
    """
    return np.asarray(direction_sign(direction) * (np.asarray(position_m, dtype=float) - origin_m))


def km_post_m(
    travelled: npt.ArrayLike, direction: TravelDirection, origin_m: float = 0.0
) -> FloatArray:
    """Km-post position [m] after travelling ``travelled`` [m] from ``origin_m`` [m]."""
    return np.asarray(origin_m + direction_sign(direction) * np.asarray(travelled, dtype=float))


def train_span_m(
    head_m: npt.ArrayLike, direction: TravelDirection, length_m: float
) -> tuple[FloatArray, FloatArray]:
    """``(low_m, high_m)`` [m]: the km posts between which a train of ``length_m`` [m]
    stands, its head at ``head_m`` [m] going ``direction`` (vectorised), for
    :meth:`SpeedProfile.lowest_along`."""
    head = np.asarray(head_m, dtype=float)
    tail = head - direction_sign(direction) * length_m
    return np.minimum(head, tail), np.maximum(head, tail)


# ---------------------------------------------------------------------------- the profile


def _frozen(values: npt.ArrayLike) -> FloatArray:
    """A read-only float copy; ``-0.0`` becomes ``0.0`` so equal profiles hash alike."""
    array = np.array(values, dtype=float) + 0.0
    array.setflags(write=False)
    return array


def _positions(position_m: npt.ArrayLike) -> FloatArray:
    x = np.asarray(position_m, dtype=float)
    if np.any(np.isnan(x)):
        raise ConfigError("position_m", position_m, "positions [m] that are not NaN")
    return x


class Decrease(NamedTuple):
    """A step down of a profile met in the direction of travel.

    The train's head must be at ``to_mps`` [m/s] or below on reaching ``position_m`` [m]
    (the boundary itself already has the lower speed). ``governor`` names the input that
    imposes ``to_mps`` (``None`` from a bare :class:`SpeedProfile`, which knows no inputs).
    """

    position_m: float
    from_mps: float
    to_mps: float
    governor: Governor | None = None


class SpeedProfile:
    """A validated, immutable, piecewise-constant speed limit over km-post position.

    Parameters
    ----------
    edges_m
        Km-post positions [m] of the boundaries: finite, strictly increasing, at least two.
    speeds_mps
        ``len(edges_m) - 1`` speeds [m/s]: ``speeds_mps[i]`` holds between ``edges_m[i]``
        and ``edges_m[i+1]``; each ``>= 0``, ``inf`` for "unrestricted".

    Equal neighbours are merged on construction (module docstring, "Canonical form"); the
    stored ``edges_m`` and ``speeds_mps`` are read-only arrays. Boundaries and the outside
    follow the module docstring: the stricter side at an edge, 0 outside.
    """

    __slots__ = ("edges_m", "speeds_mps")

    edges_m: FloatArray
    speeds_mps: FloatArray

    def __init__(self, edges_m: npt.ArrayLike, speeds_mps: npt.ArrayLike) -> None:
        try:
            edges = np.array(edges_m, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError("edges_m", edges_m, "a sequence of positions [m]") from None
        try:
            speeds = np.array(speeds_mps, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError("speeds_mps", speeds_mps, "a sequence of speeds [m/s]") from None
        if edges.ndim != 1 or edges.size < 2:
            raise ConfigError("edges_m", edges_m, "a 1-D sequence of at least two positions [m]")
        bad = np.flatnonzero(~np.isfinite(edges))
        if bad.size:
            i = int(bad[0])
            raise ConfigError(f"edges_m[{i}]", float(edges[i]), "a finite position [m]")
        bad = np.flatnonzero(np.diff(edges) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise ConfigError(
                f"edges_m[{i}]",
                float(edges[i]),
                f"a position > edges_m[{i - 1}] = {float(edges[i - 1])!r} (strictly increasing)",
            )
        if speeds.ndim != 1 or speeds.size != edges.size - 1:
            raise ConfigError(
                "speeds_mps",
                speeds_mps,
                f"a 1-D sequence of len(edges_m) - 1 = {edges.size - 1} speeds [m/s]",
            )
        bad = np.flatnonzero(np.isnan(speeds) | (speeds < 0))
        if bad.size:
            i = int(bad[0])
            raise ConfigError(
                f"speeds_mps[{i}]", float(speeds[i]), "a speed >= 0 [m/s] (inf: unrestricted)"
            )
        keep = np.concatenate(([True], speeds[1:] != speeds[:-1]))
        object.__setattr__(self, "speeds_mps", _frozen(speeds[keep]))
        object.__setattr__(self, "edges_m", _frozen(np.append(edges[:-1][keep], edges[-1])))

    @classmethod
    def constant(cls, start_m: float, end_m: float, speed_mps: float) -> SpeedProfile:
        """One speed [m/s] from ``start_m`` to ``end_m`` [m]."""
        return cls([start_m, end_m], [speed_mps])

    # -- immutability and structural equality ----------------------------------------

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"SpeedProfile is immutable: cannot set {name!r}")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SpeedProfile):
            return NotImplemented
        return np.array_equal(self.edges_m, other.edges_m) and np.array_equal(
            self.speeds_mps, other.speeds_mps
        )

    def __hash__(self) -> int:
        return hash((self.edges_m.tobytes(), self.speeds_mps.tobytes()))

    def __repr__(self) -> str:
        return (
            f"SpeedProfile(edges_m={self.edges_m.tolist()}, speeds_mps={self.speeds_mps.tolist()})"
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (SpeedProfile, (self.edges_m, self.speeds_mps))

    # -- reading ---------------------------------------------------------------------

    @property
    def start_m(self) -> float:
        """The lowest km post [m] the profile describes."""
        return float(self.edges_m[0])

    @property
    def end_m(self) -> float:
        """The highest km post [m] the profile describes."""
        return float(self.edges_m[-1])

    def at(self, position_m: npt.ArrayLike) -> FloatArray:
        """Permitted speed [m/s] at ``position_m`` [m] (vectorised).

        Inside a piece its speed; exactly at an edge the lower of the two sides; outside
        ``[start_m, end_m]``, and at those two end points, 0. NaN positions are a
        :class:`ConfigError`.
        """
        x = _positions(position_m)
        padded = np.concatenate(([0.0], self.speeds_mps, [0.0]))
        left = padded[np.searchsorted(self.edges_m, x, side="left")]
        right = padded[np.searchsorted(self.edges_m, x, side="right")]
        return np.asarray(np.minimum(left, right))

    def lowest_along(self, low_m: npt.ArrayLike, high_m: npt.ArrayLike) -> FloatArray:
        """The lowest speed [m/s] anywhere on each closed stretch ``[low_m, high_m]`` [m]
        (vectorised; ``low_m <= high_m``): what a whole train between those km posts may
        run at.

        Edges count as the stricter side, as in :meth:`at`: a stretch touching an edge is
        held to both pieces. A stretch is clipped to ``[start_m, end_m]`` first: the part
        of a train beyond the described line (a long train standing at a terminus) is held
        to the end piece, not to the 0 :meth:`at` gives out there.
        """
        edges, speeds = self.edges_m, self.speeds_mps
        low = np.clip(_positions(low_m), edges[0], edges[-1])
        if low.size == 0:
            return np.empty(low.shape)
        high = np.clip(_positions(high_m), edges[0], edges[-1])
        # pieces (edges[k], edges[k+1]) the closed stretch [low, high] touches: from the
        # first whose end is at or past low to the last whose start is at or before high
        last_piece = len(speeds) - 1
        first = np.clip(np.searchsorted(edges, low, side="left") - 1, 0, last_piece)
        last = np.clip(np.searchsorted(edges, high, side="right") - 1, first, last_piece)
        # the minimum over pieces first..last of every stretch at once: reduceat takes it
        # over padded[first:last + 1] at the even positions
        padded = np.append(speeds, np.inf)
        bounds = np.empty(2 * first.size, dtype=np.intp)
        bounds[0::2], bounds[1::2] = first.ravel(), last.ravel() + 1
        return np.minimum.reduceat(padded, bounds)[0::2].reshape(first.shape)

    def minimum(self, other: SpeedProfile) -> SpeedProfile:
        """The pointwise minimum of two profiles, over the stretch both describe.

        Outside either profile the speed is 0, so the result describes the overlap of the
        two; profiles that do not overlap (or only touch) are a :class:`ConfigError`.
        """
        start = max(self.start_m, other.start_m)
        end = min(self.end_m, other.end_m)
        if not start < end:
            raise ConfigError(
                "other",
                other,
                f"a profile overlapping [{self.start_m!r}, {self.end_m!r}] m",
            )
        grid = _grid(start, end, self.edges_m, other.edges_m)
        low = grid[:-1]
        speeds = np.minimum(
            self.speeds_mps[_piece(self.edges_m, low)], other.speeds_mps[_piece(other.edges_m, low)]
        )
        return SpeedProfile(grid, speeds)

    def restricted_stretches(self) -> list[tuple[float, float, float]]:
        """``(start_m, end_m, speed_mps)`` of every piece with a finite speed, ascending."""
        finite = np.flatnonzero(np.isfinite(self.speeds_mps))
        return [
            (float(self.edges_m[i]), float(self.edges_m[i + 1]), float(self.speeds_mps[i]))
            for i in finite
        ]

    def decreases(self, direction: TravelDirection) -> list[Decrease]:
        """Where the profile steps down for a train going ``direction``, in travel order.

        Going ``UP`` a step at ``edges_m[i]`` from ``speeds_mps[i-1]`` to ``speeds_mps[i]``;
        going ``DOWN`` from ``speeds_mps[i]`` to ``speeds_mps[i-1]``. The far end of the
        profile in the direction of travel is a step down to 0 (nothing is permitted beyond
        it) unless the last piece is already 0.
        """
        return _decreases(
            self.edges_m, self.speeds_mps, (None,) * self.speeds_mps.size, direction, None
        )


def _grid(start: float, end: float, *edge_sets: Iterable[float]) -> FloatArray:
    """Sorted unique ``start``, ``end`` and every given position strictly between them."""
    points = np.concatenate([np.asarray(list(e), dtype=float) for e in edge_sets] + [[start, end]])
    points = points[(points >= start) & (points <= end)]
    return np.unique(points)


def _piece(edges: FloatArray, low: FloatArray) -> npt.NDArray[np.intp]:
    """Index of the piece of ``edges`` containing ``[low, next grid point)``."""
    return np.searchsorted(edges, low, side="right") - 1


def _decreases(
    edges: FloatArray,
    speeds: FloatArray,
    governors: tuple[Governor | None, ...],
    direction: TravelDirection,
    end_governor: Governor | None,
) -> list[Decrease]:
    if _check_travel_direction(direction) is UP:
        steps = np.flatnonzero(speeds[1:] < speeds[:-1]) + 1
        found = [
            Decrease(float(edges[i]), float(speeds[i - 1]), float(speeds[i]), governors[i])
            for i in steps
        ]
        if speeds[-1] > 0:
            found.append(Decrease(float(edges[-1]), float(speeds[-1]), 0.0, end_governor))
        return found
    steps = np.flatnonzero(speeds[:-1] < speeds[1:])[::-1] + 1
    found = [
        Decrease(float(edges[i]), float(speeds[i]), float(speeds[i - 1]), governors[i - 1])
        for i in steps
    ]
    if speeds[0] > 0:
        found.append(Decrease(float(edges[0]), float(speeds[0]), 0.0, end_governor))
    return found


# ---------------------------------------------------------------------------- TSRs


def extend_tsr(
    start_m: float, end_m: float, train_length_m: float, direction: TravelDirection
) -> tuple[float, float]:
    """The zone ``(low_m, high_m)`` [m] a TSR on ``start_m..end_m`` [m] is enforced on.

    The received stretch (either order) extended by ``train_length_m`` [m] on its exit
    side so that the tail obeys the limit too (paper 001, 2.5): going ``UP`` the high end
    moves up, going ``DOWN`` the low end moves down (not below km 0), direction
    ``UNKNOWN``: both ends, the safe side. The checked front of the link's one rule,
    :func:`railpilot.link.events.tsr_zone`, which the onboard endpoint applies too.
    """
    for name, value in (("start_m", start_m), ("end_m", end_m)):
        if not math.isfinite(value):
            raise ConfigError(f"tsr.{name}", value, "a finite km-post position [m]")
    if start_m == end_m:
        raise ConfigError("tsr.end_m", end_m, f"a position different from start_m = {start_m!r}")
    if not (math.isfinite(train_length_m) and train_length_m >= 0):
        raise ConfigError("train_length_m", train_length_m, "a finite length >= 0 [m]")
    if not isinstance(direction, TravelDirection):
        raise ConfigError("direction", direction, "a TravelDirection (UP, DOWN or UNKNOWN)")
    return tsr_zone(float(start_m), float(end_m), float(train_length_m), direction)


def apply_tsr(tsr: TsrSet, train_length_m: float, direction: TravelDirection) -> AppliedTsr:
    """The :class:`AppliedTsr` the onboard enforces for a received TSR (:func:`extend_tsr`).

    For a co-simulation or test without the link; the link's endpoint makes the same.
    """
    extend_tsr(tsr.start_m, tsr.end_m, train_length_m, direction)  # checks the inputs
    return AppliedTsr.of(tsr, float(train_length_m), direction)


def _check_tsr(tsr: object) -> AppliedTsr:
    if not isinstance(tsr, AppliedTsr):
        raise ConfigError("tsrs[]", tsr, "an AppliedTsr (railpilot.link.events)")
    label = f"tsrs[session {tsr.session}]"
    if not math.isfinite(tsr.zone_start_m):
        raise ConfigError(f"{label}.zone_start_m", tsr.zone_start_m, "a finite position [m]")
    if not (math.isfinite(tsr.zone_end_m) and tsr.zone_end_m > tsr.zone_start_m):
        raise ConfigError(
            f"{label}.zone_end_m",
            tsr.zone_end_m,
            f"a finite position > zone_start_m = {tsr.zone_start_m!r} [m]",
        )
    if not (math.isfinite(tsr.limit_mps) and tsr.limit_mps >= 0):
        raise ConfigError(f"{label}.limit_mps", tsr.limit_mps, "a finite speed >= 0 [m/s]")
    for name in ("valid_from_s", "valid_until_s"):
        if math.isnan(getattr(tsr, name)):
            raise ConfigError(f"{label}.{name}", getattr(tsr, name), "a time [s], not NaN")
    return tsr


def tsr_in_force(tsr: AppliedTsr, now_s: float) -> bool:
    """Whether ``tsr`` is in force at ``now_s`` [s, ground clock].

    ``valid_from_s <= now_s < valid_until_s``: the end is exclusive, as the link
    expires a TSR at ``now >= valid_until_s``.
    """
    return tsr.valid_from_s <= now_s < tsr.valid_until_s


class ActiveTsrs(Mapping[int, AppliedTsr]):
    """The TSRs the onboard has applied: an immutable mapping session -> :class:`AppliedTsr`.

    :meth:`insert` and :meth:`cancel` return new sets. Inserting a TSR already held, or
    cancelling a session not held, returns an equal set (idempotent, as the link's resends
    need); the result does not depend on the order of inserts and cancels of different
    sessions. A different restriction under a session already held is a
    :class:`ConfigError`, as the link refuses it (``TsrSetResult.INVALID``). Iterates
    sessions in ascending order.
    """

    __slots__ = ("_by_session",)

    def __init__(self, tsrs: Iterable[AppliedTsr] = ()) -> None:
        by_session: dict[int, AppliedTsr] = {}
        for tsr in tsrs:
            _check_tsr(tsr)
            held = by_session.get(tsr.session)
            if held is not None and held != tsr:
                raise ConfigError(
                    f"tsrs[session {tsr.session}]",
                    tsr,
                    f"the restriction already held under that session ({held!r}) or a new session",
                )
            by_session[tsr.session] = tsr
        self._by_session = {s: by_session[s] for s in sorted(by_session)}

    def __getitem__(self, session: int) -> AppliedTsr:
        return self._by_session[session]

    def __iter__(self) -> Iterator[int]:
        return iter(self._by_session)

    def __len__(self) -> int:
        return len(self._by_session)

    def __hash__(self) -> int:
        return hash(frozenset(self._by_session.items()))

    def __repr__(self) -> str:
        return f"ActiveTsrs({list(self._by_session.values())!r})"

    def insert(self, tsr: AppliedTsr) -> ActiveTsrs:
        """The set with ``tsr`` applied (the same set if it is already held)."""
        return ActiveTsrs([*self._by_session.values(), tsr])

    def cancel(self, session: int) -> ActiveTsrs:
        """The set without ``session`` (the same set if it is not held)."""
        return ActiveTsrs(t for s, t in self._by_session.items() if s != session)

    def in_force(self, now_s: float) -> ActiveTsrs:
        """The TSRs in force at ``now_s`` [s, ground clock] (:func:`tsr_in_force`)."""
        return ActiveTsrs(t for t in self._by_session.values() if tsr_in_force(t, now_s))


# ---------------------------------------------------------------------------- targets


@dataclass(frozen=True, slots=True)
class TargetStop:
    """A target stop point: the train must stop at or before ``position_m`` [m].

    For a train going ``UP`` the speed is 0 from ``position_m`` onwards (``[p, inf)``),
    going ``DOWN`` on ``(-inf, p]``; ``target_id`` is the ground's target id (paper 001,
    2.4) for the dashboard and the acknowledgement.
    """

    position_m: float
    target_id: int

    def __post_init__(self) -> None:
        if isinstance(self.position_m, bool) or not (
            isinstance(self.position_m, int | float) and math.isfinite(self.position_m)
        ):
            raise ConfigError("target.position_m", self.position_m, "a finite position [m]")
        if isinstance(self.target_id, bool) or not (
            isinstance(self.target_id, int) and self.target_id >= 0
        ):
            raise ConfigError("target.target_id", self.target_id, "an integer >= 0")
        object.__setattr__(self, "position_m", float(self.position_m) + 0.0)

    @classmethod
    def from_target_point(
        cls, point: TargetPoint, safety_distance_m: float, direction: TravelDirection
    ) -> TargetStop:
        """The stop point ``safety_distance_m`` [m] before the red signal ``point`` (2.4).

        Before = on the approach side for a train going ``direction``
        (``onboard.target_point.safety_distance_m`` computes the distance).
        """
        if not (math.isfinite(safety_distance_m) and safety_distance_m >= 0):
            raise ConfigError("safety_distance_m", safety_distance_m, "a finite distance >= 0 [m]")
        stop = point.position_m - direction_sign(direction) * safety_distance_m
        return cls(float(stop), point.target_id)


# ---------------------------------------------------------------------------- governors


class GovernorKind(Enum):
    STATIC = "static"  # the line's static limit
    TSR = "tsr"  # a temporary speed restriction (ident: its session)
    TARGET = "target"  # a target stop point (ident: its target id)
    LINE_END = "line end"  # the end of the described line (only in decreases)


@dataclass(frozen=True, slots=True)
class Governor:
    """The input that imposes the MRSP on a stretch: its kind and (TSR, target) its id."""

    kind: GovernorKind
    ident: int | None = None

    def __str__(self) -> str:
        if self.kind is GovernorKind.TSR:
            return f"TSR session {self.ident}"
        if self.kind is GovernorKind.TARGET:
            return f"target {self.ident}"
        return "static limit" if self.kind is GovernorKind.STATIC else "end of line"


STATIC = Governor(GovernorKind.STATIC)


class Stretch(NamedTuple):
    """One piece of an :class:`Mrsp`: ``speed_mps`` [m/s] on ``start_m..end_m`` [m]."""

    start_m: float
    end_m: float
    speed_mps: float
    governor: Governor


# ---------------------------------------------------------------------------- the MRSP


class Mrsp:
    """The most restrictive speed profile and, for each stretch, the input governing it.

    ``edges_m`` / ``speeds_mps`` / ``governors`` are pieces in ascending km post, split
    wherever the speed or the governor changes (so a TSR equal to its neighbour's limit
    still shows); :attr:`profile` is the speed alone in canonical form. ``targets`` are the
    target stops given, in travel order (the first is the end of authority). Built by
    :func:`most_restrictive_profile`; equality is structural.
    """

    __slots__ = ("direction", "edges_m", "governors", "profile", "speeds_mps", "targets")

    direction: TravelDirection
    edges_m: FloatArray
    speeds_mps: FloatArray
    governors: tuple[Governor, ...]
    targets: tuple[TargetStop, ...]
    profile: SpeedProfile

    def __init__(
        self,
        direction: TravelDirection,
        edges_m: npt.ArrayLike,
        speeds_mps: npt.ArrayLike,
        governors: Iterable[Governor],
        targets: Iterable[TargetStop] = (),
    ) -> None:
        profile = SpeedProfile(edges_m, speeds_mps)  # validates (and merges by speed)
        edges = _frozen(edges_m)
        speeds = _frozen(speeds_mps)
        govs = tuple(governors)
        if len(govs) != speeds.size:
            raise ConfigError("governors", govs, f"one Governor per piece ({speeds.size})")
        keep = np.ones(speeds.size, dtype=bool)
        for i in range(1, speeds.size):
            keep[i] = speeds[i] != speeds[i - 1] or govs[i] != govs[i - 1]
        init = object.__setattr__
        init(self, "direction", _check_travel_direction(direction))
        init(self, "speeds_mps", _frozen(speeds[keep]))
        init(self, "edges_m", _frozen(np.append(edges[:-1][keep], edges[-1])))
        init(self, "governors", tuple(g for g, k in zip(govs, keep, strict=True) if k))
        init(self, "targets", _travel_order(targets, direction))
        init(self, "profile", profile)

    def __setattr__(self, name: str, value: object) -> None:
        raise AttributeError(f"Mrsp is immutable: cannot set {name!r}")

    def _key(self) -> tuple[Any, ...]:
        return (
            self.direction,
            self.edges_m.tobytes(),
            self.speeds_mps.tobytes(),
            self.governors,
            self.targets,
        )

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Mrsp):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        pieces = ", ".join(
            f"{s.start_m:g}..{s.end_m:g}: {s.speed_mps:g} ({s.governor})" for s in self.stretches()
        )
        return f"Mrsp({self.direction.name}, [{pieces}], targets={list(self.targets)!r})"

    def at(self, position_m: npt.ArrayLike) -> FloatArray:
        """Permitted speed [m/s] at ``position_m`` [m] (:meth:`SpeedProfile.at`)."""
        return self.profile.at(position_m)

    def governor_at(self, position_m: npt.ArrayLike) -> list[Governor]:
        """The input governing the speed at each position [m].

        At an edge: the stricter side's; between equal speeds, the side the train enters.
        Outside the profile (and at its ends): ``LINE_END``.
        """
        x = np.atleast_1d(_positions(position_m))
        end = Governor(GovernorKind.LINE_END)
        governors = (end, *self.governors, end)
        speeds = np.concatenate(([0.0], self.speeds_mps, [0.0]))
        left = np.searchsorted(self.edges_m, x, side="left")
        right = np.searchsorted(self.edges_m, x, side="right")
        entered, other = (right, left) if self.direction is UP else (left, right)
        index = np.where(speeds[other] < speeds[entered], other, entered)
        return [governors[i] for i in index.tolist()]

    def stretches(self) -> list[Stretch]:
        """Every piece as a :class:`Stretch`, ascending km post."""
        return [
            Stretch(float(self.edges_m[i]), float(self.edges_m[i + 1]), float(v), g)
            for i, (v, g) in enumerate(zip(self.speeds_mps.tolist(), self.governors, strict=True))
        ]

    def decreases(self) -> list[Decrease]:
        """Where the MRSP steps down in the direction of travel, in travel order, each with
        the governor of the lower speed (:meth:`SpeedProfile.decreases`)."""
        return _decreases(
            self.edges_m,
            self.speeds_mps,
            self.governors,
            self.direction,
            Governor(GovernorKind.LINE_END),
        )

    @property
    def end_of_authority(self) -> TargetStop | None:
        """The first target stop in the direction of travel, or ``None``."""
        return self.targets[0] if self.targets else None


def _travel_order(
    targets: Iterable[TargetStop], direction: TravelDirection
) -> tuple[TargetStop, ...]:
    """Unique target stops, first met first (ties by id)."""
    sign = direction_sign(direction)
    unique: set[TargetStop] = set()
    for target in targets:
        if not isinstance(target, TargetStop):
            raise ConfigError("targets[]", target, "a TargetStop")
        unique.add(target)
    return tuple(sorted(unique, key=lambda t: (sign * t.position_m, t.target_id)))


def most_restrictive_profile(
    static: SpeedProfile,
    tsrs: Iterable[AppliedTsr] | Mapping[int, AppliedTsr],
    targets: Iterable[TargetStop],
    *,
    direction: TravelDirection,
    now_s: float | None = None,
) -> Mrsp:
    """The MRSP over the line ``static`` describes: the pointwise minimum of its inputs.

    Parameters
    ----------
    static
        The line's static limit for this train and direction [m/s] over km post [m]
        (e.g. ``SpeedProfile(*rail_line.static_limit(category, direction))``); its extent
        is the MRSP's.
    tsrs
        The applied TSRs (an :class:`ActiveTsrs` or any iterable of :class:`AppliedTsr`):
        ``limit_mps`` on the closed zone ``[zone_start_m, zone_end_m]``, which already
        carries the train-length extension (:func:`extend_tsr`). Two different TSRs under
        one session are a :class:`ConfigError`.
    targets
        Target stops: speed 0 from each onwards in the direction of travel; only the first
        one met matters for the speed, all are kept in :attr:`Mrsp.targets`.
    direction
        ``UP`` or ``DOWN`` (``UNKNOWN`` is a :class:`ConfigError`: a target point has no
        meaning without it).
    now_s
        Ground-clock time [s]; when given, TSRs not in force then (:func:`tsr_in_force`)
        are ignored. ``None``: every TSR given applies.

    Returns
    -------
    Mrsp
        The speeds and, per stretch, the governing input. On a tie the most permanent
        input is named: the static limit, else the TSR with the lowest session, else the
        target.
    """
    if not isinstance(static, SpeedProfile):
        raise ConfigError("static", static, "a SpeedProfile")
    direction = _check_travel_direction(direction)
    if now_s is not None and math.isnan(now_s):
        raise ConfigError("now_s", now_s, "a time [s] or None")
    held = ActiveTsrs(tsrs.values() if isinstance(tsrs, Mapping) else tsrs)
    if now_s is not None:
        held = held.in_force(now_s)
    stops = _travel_order(targets, direction)
    first = stops[0] if stops else None

    start, end = static.start_m, static.end_m
    zones = np.array([[t.zone_start_m, t.zone_end_m] for t in held.values()], dtype=float)
    limits = np.array([t.limit_mps for t in held.values()], dtype=float)
    grid = _grid(
        start,
        end,
        static.edges_m,
        zones.ravel(),
        [first.position_m] if first is not None else [],
    )
    low, high = grid[:-1], grid[1:]
    # candidate speed of each input on each grid piece: rows static, TSRs, target
    candidates = [static.speeds_mps[_piece(static.edges_m, low)]]
    if limits.size:
        inside = (zones[:, :1] <= low) & (high <= zones[:, 1:])
        candidates.extend(np.where(inside, limits[:, None], np.inf))
    if first is not None:
        beyond = low >= first.position_m if direction is UP else high <= first.position_m
        candidates.append(np.where(beyond, 0.0, np.inf))
    stacked = np.vstack(candidates)
    winner = np.argmin(stacked, axis=0)  # first minimum: static, then sessions, then target
    speeds = stacked[winner, np.arange(low.size)]
    names = [STATIC, *(Governor(GovernorKind.TSR, s) for s in held)]
    if first is not None:
        names.append(Governor(GovernorKind.TARGET, first.target_id))
    return Mrsp(direction, grid, speeds, [names[w] for w in winner.tolist()], stops)
