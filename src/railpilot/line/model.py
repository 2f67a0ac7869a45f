"""Line data by km post: stations, gradients, curves, static limits, signals, block sections.

Positions are metres of km post inside (``position_m = km_post_to_m(km)``, units.py); the
file format (loader.py, docs/line-data.md) writes km posts in km. Directions are
:class:`~railpilot.link.messages.TravelDirection`: ``UP`` towards increasing km posts,
``DOWN`` towards decreasing km posts.

Sign conventions
----------------
- A gradient [per mille] is positive when the line rises towards increasing km posts (a
  train going ``UP`` climbs it); a train going ``DOWN`` sees its negative.
- A speed limit applies in both directions unless it names one.
- A signal protects the block section *after* it in its own direction: an ``UP`` signal at
  km ``x`` guards ``[x, next UP signal)``, a ``DOWN`` signal at ``x`` guards
  ``(previous DOWN signal, x]``.

Boundaries
----------
Every step function here is looked up as a train moving in the given direction sees it:
going ``UP`` a position on a boundary belongs to the section beginning there
(``[start, end)``), going ``DOWN`` to the section beginning there in the train's own
sense (``(start, end]``). So a train exactly at a signal is already past it (in the section
that signal protects), and ``to_vehicle_line`` agrees with the lookups here.

The train's own coordinate (``to_vehicle_line``, ``distance_along``) is the distance
travelled from where the train enters the line: ``position_m - start_m`` going ``UP``,
``end_m - position_m`` going ``DOWN``.
"""

from __future__ import annotations

import bisect
import dataclasses
import itertools
import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
import numpy.typing as npt

from railpilot.errors import LineError, is_finite_number
from railpilot.link.messages import TravelDirection
from railpilot.units import m_to_km_post, mps_to_kmh
from railpilot.vehicle.line import Line, Segment, StopPoint

FloatArray = npt.NDArray[np.float64]

UP = TravelDirection.UP
DOWN = TravelDirection.DOWN
#: The two directions a line can be run in.
DIRECTIONS: tuple[TravelDirection, TravelDirection] = (UP, DOWN)

#: Steepest gradient a line may carry [per mille], either sign.
MAX_GRADIENT_PERMILLE = 40.0
#: Smallest curve radius [m].
MIN_CURVE_RADIUS_M = 150.0
#: Range of a static speed limit [km/h] (checked in km/h, stored in m/s).
LIMIT_RANGE_KMH = (5.0, 200.0)
#: Range of a station's loop (receiving track or platform) length [m].
LOOP_RANGE_M = (20.0, 6000.0)
#: Largest km post [m]: what the train-ground link can carry (link/messages.py).
MAX_POSITION_M = 10_000_000.0
#: Kinds of signal: home (entry to a station), exit (leaving a station's loop), block
#: (automatic block signal between stations).
SIGNAL_KINDS = ("home", "exit", "block")
#: Largest station id (it travels as an unsigned 32-bit integer on the link).
MAX_STATION_ID = 2**32 - 1
#: Two km posts closer than this [m] are the same point (contiguity, stop points).
TOLERANCE_M = 1e-6

_CATEGORY = re.compile(r"^[a-z][a-z0-9_]*$")


def direction_name(direction: TravelDirection | None) -> str:
    """``"up"``, ``"down"`` or (for ``None``, a limit in force both ways) ``"both"``."""
    if direction is None:
        return "both"
    return "up" if direction == UP else "down"


def check_direction(direction: object, field: str = "direction") -> TravelDirection:
    """``direction`` as UP or DOWN; anything else (UNKNOWN included) is a LineError."""
    if isinstance(direction, TravelDirection) and direction in DIRECTIONS:
        return direction
    raise LineError(field, direction, "TravelDirection.UP or TravelDirection.DOWN")


def _km(position_m: float) -> str:
    """A position [m] as a km post with metre resolution, e.g. ``"12.400"``."""
    return f"{m_to_km_post(position_m):.3f}"


def _span(start_m: float, end_m: float) -> str:
    return f"km {_km(start_m)}-{_km(end_m)}"


def _check_span(start_m: float, end_m: float) -> None:
    """A section ``[start_m, end_m]`` of finite km posts with ``start_m < end_m``."""
    if not is_finite_number(start_m):
        raise LineError("start_km", start_m, "a finite km post")
    if not is_finite_number(end_m):
        raise LineError("end_km", end_m, "a finite km post")
    if not end_m > start_m:
        raise LineError(
            "end_km",
            m_to_km_post(end_m),
            f"a km post above start_km = {_km(start_m)} (start must be below end)",
        )


# ---------------------------------------------------------------------------- entries


@dataclass(frozen=True)
class Gradient:
    """A gradient [per mille, + rising towards increasing km] on ``[start_m, end_m]`` [m]."""

    start_m: float
    end_m: float
    permille: float

    def __post_init__(self) -> None:
        _check_span(self.start_m, self.end_m)
        if not is_finite_number(self.permille) or abs(self.permille) > MAX_GRADIENT_PERMILLE:
            raise LineError(
                "permille",
                self.permille,
                f"a gradient from -{MAX_GRADIENT_PERMILLE:g} to +{MAX_GRADIENT_PERMILLE:g} "
                "per mille",
            )


@dataclass(frozen=True)
class Curve:
    """A curve of ``radius_m`` [m] on ``[start_m, end_m]`` [m] (either hand)."""

    start_m: float
    end_m: float
    radius_m: float

    def __post_init__(self) -> None:
        _check_span(self.start_m, self.end_m)
        if not is_finite_number(self.radius_m) or self.radius_m < MIN_CURVE_RADIUS_M:
            raise LineError(
                "radius_m", self.radius_m, f"a finite radius >= {MIN_CURVE_RADIUS_M:g} m"
            )


@dataclass(frozen=True)
class SpeedLimit:
    """A static limit ``limit_mps`` [m/s] for one train category on ``[start_m, end_m]`` [m].

    ``direction`` ``None`` means the limit holds in both directions.
    """

    category: str
    start_m: float
    end_m: float
    limit_mps: float
    direction: TravelDirection | None = None

    def __post_init__(self) -> None:
        _check_span(self.start_m, self.end_m)
        low, high = LIMIT_RANGE_KMH
        if not is_finite_number(self.limit_mps) or not (
            low - 1e-9 <= mps_to_kmh(self.limit_mps) <= high + 1e-9
        ):
            value = (
                mps_to_kmh(self.limit_mps) if is_finite_number(self.limit_mps) else self.limit_mps
            )
            raise LineError("limit_kmh", value, f"a limit from {low:g} to {high:g} km/h")
        if self.direction is not None:
            check_direction(self.direction)

    def applies_to(self, direction: TravelDirection) -> bool:
        """Whether the limit is in force for a train going ``direction``."""
        return self.direction is None or self.direction == direction


@dataclass(frozen=True)
class Station:
    """A station: its centre [m], its loop (or platform) and a stop point per direction.

    The loop is ``[centre_m - loop_length_m / 2, centre_m + loop_length_m / 2]``; a train
    stopping there stops with its head at ``stop_up_m`` (going UP) or ``stop_down_m``
    (going DOWN), both inside the loop.
    """

    id: int
    name: str
    centre_m: float
    loop_length_m: float
    stop_up_m: float
    stop_down_m: float

    def __post_init__(self) -> None:
        if (
            isinstance(self.id, bool)
            or not isinstance(self.id, int)
            or not 0 <= self.id <= MAX_STATION_ID
        ):
            raise LineError("id", self.id, f"an integer from 0 to {MAX_STATION_ID}")
        if not isinstance(self.name, str) or not self.name.strip():
            raise LineError("name", self.name, "a non-empty string")
        if not is_finite_number(self.centre_m):
            raise LineError("km", self.centre_m, "a finite km post")
        low, high = LOOP_RANGE_M
        if not is_finite_number(self.loop_length_m) or not low <= self.loop_length_m <= high:
            raise LineError(
                "loop_length_m", self.loop_length_m, f"a length from {low:g} to {high:g} m"
            )
        for key, stop in (("stop_up_km", self.stop_up_m), ("stop_down_km", self.stop_down_m)):
            if not is_finite_number(stop) or not (
                self.loop_start_m - TOLERANCE_M <= stop <= self.loop_end_m + TOLERANCE_M
            ):
                value = m_to_km_post(stop) if is_finite_number(stop) else stop
                raise LineError(
                    key,
                    value,
                    "a stop point inside the station's loop, "
                    f"{_span(self.loop_start_m, self.loop_end_m)}",
                )

    @property
    def loop_start_m(self) -> float:
        """Low-km end of the loop [m]."""
        return self.centre_m - 0.5 * self.loop_length_m

    @property
    def loop_end_m(self) -> float:
        """High-km end of the loop [m]."""
        return self.centre_m + 0.5 * self.loop_length_m

    def stop_m(self, direction: TravelDirection) -> float:
        """Stop point [m] of a train going ``direction``."""
        return self.stop_up_m if check_direction(direction) == UP else self.stop_down_m


@dataclass(frozen=True)
class Signal:
    """A fixed signal at ``position_m`` [m] facing trains going ``direction``."""

    id: str
    position_m: float
    direction: TravelDirection
    kind: str

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id.strip():
            raise LineError("id", self.id, "a non-empty string")
        if not is_finite_number(self.position_m):
            raise LineError("km", self.position_m, "a finite km post")
        check_direction(self.direction)
        if self.kind not in SIGNAL_KINDS:
            raise LineError("kind", self.kind, f"one of {', '.join(SIGNAL_KINDS)}")


@dataclass(frozen=True)
class BlockSection:
    """A block section ``[start_m, end_m]`` [m] of one direction.

    A train going ``direction`` enters it at ``entry_m`` (``start_m`` going UP, ``end_m``
    going DOWN), past the signal ``entry_signal`` (``None`` for the section a train enters
    the line into, when no signal stands at the line's end).
    """

    id: str
    direction: TravelDirection
    start_m: float
    end_m: float
    entry_signal: str | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id.strip():
            raise LineError("id", self.id, "a non-empty string")
        check_direction(self.direction)
        _check_span(self.start_m, self.end_m)

    @property
    def entry_m(self) -> float:
        """Where a train going ``direction`` enters the section [m]."""
        return self.start_m if self.direction == UP else self.end_m

    @property
    def exit_m(self) -> float:
        """Where a train going ``direction`` leaves the section [m]."""
        return self.end_m if self.direction == UP else self.start_m


# ---------------------------------------------------------------------------- labels


def _section_label(kind: str, index: int, start_m: float, end_m: float, extra: str = "") -> str:
    return f"{kind}[{index}] ({extra}{_span(start_m, end_m)})"


def _limit_label(index: int, entry: SpeedLimit) -> str:
    extra = f"{entry.category}, {direction_name(entry.direction)}, "
    return _section_label("speed_limits", index, entry.start_m, entry.end_m, extra)


def _station_label(index: int, station: Station) -> str:
    return f"stations[{index}] (id {station.id} '{station.name}', km {_km(station.centre_m)})"


def _signal_label(index: int, signal: Signal) -> str:
    return (
        f"signals[{index}] ('{signal.id}', {direction_name(signal.direction)}, "
        f"km {_km(signal.position_m)})"
    )


def _block_label(index: int, section: BlockSection) -> str:
    extra = f"'{section.id}', {direction_name(section.direction)}, "
    return _section_label("block_sections", index, section.start_m, section.end_m, extra)


def _check_inside(
    label: str, start_m: float, end_m: float, line_start: float, line_end: float
) -> None:
    if start_m < line_start - TOLERANCE_M:
        raise LineError(
            f"{label}.start_km",
            m_to_km_post(start_m),
            f"a km post inside the line, {_span(line_start, line_end)}",
        )
    if end_m > line_end + TOLERANCE_M:
        raise LineError(
            f"{label}.end_km",
            m_to_km_post(end_m),
            f"a km post inside the line, {_span(line_start, line_end)}",
        )


def _check_order(label: str, start_m: float, prev_label: str, prev_start_m: float) -> None:
    if start_m < prev_start_m - TOLERANCE_M:
        raise LineError(
            f"{label}.start_km",
            m_to_km_post(start_m),
            f"a km post at or after the start of the entry before it, {prev_label} "
            "(entries must be sorted by km post)",
        )


def _check_tiling(
    what: str,
    entries: Sequence[tuple[str, float, float]],
    line_start: float,
    line_end: float,
) -> None:
    """``entries`` (label, start, end), in file order, cover the line without gap or overlap."""
    if not entries:
        raise LineError(
            what, None, f"entries covering the whole line, {_span(line_start, line_end)}"
        )
    for label, start, end in entries:
        _check_inside(label, start, end, line_start, line_end)
    first_label, first_start, _ = entries[0]
    if first_start > line_start + TOLERANCE_M:
        raise LineError(
            f"{first_label}.start_km",
            m_to_km_post(first_start),
            f"km {_km(line_start)}, the start of the line ({what} must cover the whole line; "
            f"gap {_span(line_start, first_start)})",
        )
    for (prev_label, prev_start, _), (label, start, _) in itertools.pairwise(entries):
        _check_order(label, start, prev_label, prev_start)
    for (prev_label, _, prev_end), (label, start, _) in itertools.pairwise(entries):
        if start < prev_end - TOLERANCE_M:
            raise LineError(
                f"{label}.start_km",
                m_to_km_post(start),
                f"km {_km(prev_end)}, the end of {prev_label} ({what} must not overlap: "
                f"this entry overlaps {prev_label})",
            )
        if start > prev_end + TOLERANCE_M:
            raise LineError(
                f"{label}.start_km",
                m_to_km_post(start),
                f"km {_km(prev_end)}, the end of {prev_label} ({what} must leave no gap: "
                f"gap {_span(prev_end, start)} between {prev_label} and this entry)",
            )
    last_label, _, last_end = entries[-1]
    if last_end < line_end - TOLERANCE_M:
        raise LineError(
            f"{last_label}.end_km",
            m_to_km_post(last_end),
            f"km {_km(line_end)}, the end of the line ({what} must cover the whole line; "
            f"gap {_span(last_end, line_end)})",
        )


def _steps(entries: Sequence[tuple[float, float, float]]) -> tuple[FloatArray, FloatArray]:
    """Edges and values of contiguous sections ``(start, end, value)``; equal neighbours merge."""
    edges = [entries[0][0]]
    values: list[float] = []
    for _, end, value in entries:
        if values and values[-1] == value:
            edges[-1] = end
        else:
            values.append(value)
            edges.append(end)
    return np.asarray(edges, dtype=float), np.asarray(values, dtype=float)


def _index(
    edges: FloatArray, position_m: FloatArray, direction: TravelDirection
) -> npt.NDArray[np.intp]:
    """Section index of ``position_m`` in the steps ``edges``, seen going ``direction``."""
    side: Literal["left", "right"] = "right" if direction == UP else "left"
    idx = np.searchsorted(edges, position_m, side=side) - 1
    return np.clip(idx, 0, len(edges) - 2)


# ---------------------------------------------------------------------------- the line


@dataclass(frozen=True)
class RailLine:
    """A line between km posts ``start_m`` and ``end_m`` [m], both directions.

    Parameters
    ----------
    name
        Short name, e.g. ``"heavy-haul"``.
    start_m, end_m
        The line's first and last km post [m]; ``0 <= start_m < end_m <= 10,000 km``.
    categories
        Train categories with static limits, e.g. ``("freight_loaded", "freight_empty")``.
    gradients
        Contiguous sections covering the whole line, sorted [per mille, + rising UP].
    speed_limits
        For every category and every direction, the entries in force tile the line.
    stations
        Sorted by km post; loops inside the line and not overlapping; unique ids and names.
    curves
        Sorted, not overlapping, inside the line; straight track elsewhere.
    signals
        Sorted by km post, unique ids, inside the line; two signals of one direction never
        share a km post.
    block_sections
        Given: per direction they tile the line and begin (in their direction) at that
        direction's signals. Empty: derived from the signals (the ``entry_signal`` field is
        always filled in from the signals).
    start_elevation_m
        Elevation of ``start_m`` [m]; the elevation profile integrates the gradients from it.
    description
        Free text (where the numbers come from).
    """

    name: str
    start_m: float
    end_m: float
    categories: tuple[str, ...]
    gradients: tuple[Gradient, ...]
    speed_limits: tuple[SpeedLimit, ...]
    stations: tuple[Station, ...] = ()
    curves: tuple[Curve, ...] = ()
    signals: tuple[Signal, ...] = ()
    block_sections: tuple[BlockSection, ...] = ()
    start_elevation_m: float = 0.0
    description: str = ""

    def __post_init__(self) -> None:
        for name in (
            "categories",
            "gradients",
            "speed_limits",
            "stations",
            "curves",
            "signals",
            "block_sections",
        ):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if not isinstance(self.name, str) or not self.name.strip():
            raise LineError("name", self.name, "a non-empty string")
        if not is_finite_number(self.start_m) or not 0.0 <= self.start_m < MAX_POSITION_M:
            value = m_to_km_post(self.start_m) if is_finite_number(self.start_m) else self.start_m
            raise LineError(
                "start_km", value, f"a finite km post from 0 to {m_to_km_post(MAX_POSITION_M):g}"
            )
        if not is_finite_number(self.end_m) or not self.start_m < self.end_m <= MAX_POSITION_M:
            value = m_to_km_post(self.end_m) if is_finite_number(self.end_m) else self.end_m
            raise LineError(
                "end_km",
                value,
                f"a km post above start_km = {_km(self.start_m)} and at most "
                f"{m_to_km_post(MAX_POSITION_M):g}",
            )
        if not is_finite_number(self.start_elevation_m):
            raise LineError("start_elevation_m", self.start_elevation_m, "a finite elevation [m]")
        self._check_categories()
        self._check_gradients()
        self._check_curves()
        self._check_stations()
        self._check_speed_limits()
        self._check_signals()
        object.__setattr__(self, "block_sections", self._checked_block_sections())

    def __hash__(self) -> int:
        # Hashed once: a line keys the caches of its routes, controllers and curves, which
        # a line run looks up for every train every second, and hashing its thousands of
        # items (the generated __hash__) took 0.2 ms each time.
        return self._hash

    @cached_property
    def _hash(self) -> int:
        return hash(tuple(getattr(self, f.name) for f in dataclasses.fields(self)))

    def __getstate__(self) -> dict[str, object]:
        # the hash of a string differs between processes: an unpickled line hashes afresh
        state = dict(self.__dict__)
        state.pop("_hash", None)
        return state

    # ------------------------------------------------------------------ validation

    def _check_categories(self) -> None:
        if not self.categories:
            raise LineError("categories", list(self.categories), "at least one train category")
        seen: set[str] = set()
        for i, category in enumerate(self.categories):
            if not isinstance(category, str) or not _CATEGORY.match(category):
                raise LineError(
                    f"categories[{i}]",
                    category,
                    "a lower-case name of letters, digits and '_' starting with a letter",
                )
            if category in seen:
                raise LineError(f"categories[{i}]", category, "a category not listed before")
            seen.add(category)

    def _check_gradients(self) -> None:
        entries = [
            (_section_label("gradients", i, g.start_m, g.end_m), g.start_m, g.end_m)
            for i, g in enumerate(self.gradients)
        ]
        _check_tiling("gradients", entries, self.start_m, self.end_m)

    def _check_curves(self) -> None:
        previous: tuple[str, Curve] | None = None
        for i, curve in enumerate(self.curves):
            label = _section_label("curves", i, curve.start_m, curve.end_m)
            _check_inside(label, curve.start_m, curve.end_m, self.start_m, self.end_m)
            if previous is not None:
                prev_label, prev = previous
                _check_order(label, curve.start_m, prev_label, prev.start_m)
                if curve.start_m < prev.end_m - TOLERANCE_M:
                    raise LineError(
                        f"{label}.start_km",
                        m_to_km_post(curve.start_m),
                        f"a km post at or after km {_km(prev.end_m)}, the end of {prev_label} "
                        f"(curves must not overlap: this entry overlaps {prev_label})",
                    )
            previous = (label, curve)

    def _check_stations(self) -> None:
        by_id: dict[int, str] = {}
        by_name: dict[str, str] = {}
        previous: tuple[str, Station] | None = None
        for i, station in enumerate(self.stations):
            label = _station_label(i, station)
            if station.id in by_id:
                raise LineError(
                    f"{label}.id",
                    station.id,
                    f"an id not used by {by_id[station.id]} (station ids must be unique)",
                )
            if station.name in by_name:
                raise LineError(
                    f"{label}.name",
                    station.name,
                    f"a name not used by {by_name[station.name]} (station names must be unique)",
                )
            by_id[station.id] = label
            by_name[station.name] = label
            if (
                station.loop_start_m < self.start_m - TOLERANCE_M
                or station.loop_end_m > self.end_m + TOLERANCE_M
            ):
                raise LineError(
                    f"{label}.km",
                    m_to_km_post(station.centre_m),
                    f"a station whose loop ({_span(station.loop_start_m, station.loop_end_m)}) "
                    f"lies inside the line, {_span(self.start_m, self.end_m)}",
                )
            if previous is not None:
                prev_label, prev = previous
                if station.centre_m < prev.centre_m:
                    raise LineError(
                        f"{label}.km",
                        m_to_km_post(station.centre_m),
                        f"a km post after {prev_label} (stations must be sorted by km post)",
                    )
                if station.loop_start_m < prev.loop_end_m - TOLERANCE_M:
                    raise LineError(
                        f"{label}.km",
                        m_to_km_post(station.centre_m),
                        f"a station whose loop ({_span(station.loop_start_m, station.loop_end_m)}) "
                        f"begins after the loop of {prev_label} ends, km {_km(prev.loop_end_m)} "
                        "(station loops must not overlap)",
                    )
            previous = (label, station)

    def _check_speed_limits(self) -> None:
        last_in_category: dict[str, tuple[str, float]] = {}
        for i, entry in enumerate(self.speed_limits):
            label = _limit_label(i, entry)
            if entry.category not in self.categories:
                raise LineError(
                    f"{label}.category",
                    entry.category,
                    f"one of the line's categories: {', '.join(self.categories)}",
                )
            if entry.category in last_in_category:
                prev_label, prev_start = last_in_category[entry.category]
                _check_order(label, entry.start_m, prev_label, prev_start)
            last_in_category[entry.category] = (label, entry.start_m)
        for category in self.categories:
            for direction in DIRECTIONS:
                entries = [
                    (_limit_label(i, e), e.start_m, e.end_m)
                    for i, e in enumerate(self.speed_limits)
                    if e.category == category and e.applies_to(direction)
                ]
                what = f"speed limits of category '{category}' going {direction_name(direction)}"
                if not entries:
                    raise LineError(
                        "speed_limits",
                        category,
                        f"entries of category '{category}' covering the whole line, "
                        f"{_span(self.start_m, self.end_m)}, going {direction_name(direction)}",
                    )
                _check_tiling(what, entries, self.start_m, self.end_m)

    def _check_signals(self) -> None:
        by_id: dict[str, str] = {}
        last_at: dict[TravelDirection, tuple[str, float]] = {}
        previous: tuple[str, Signal] | None = None
        for i, signal in enumerate(self.signals):
            label = _signal_label(i, signal)
            if signal.id in by_id:
                raise LineError(
                    f"{label}.id",
                    signal.id,
                    f"an id not used by {by_id[signal.id]} (signal ids must be unique)",
                )
            by_id[signal.id] = label
            if not self.start_m - TOLERANCE_M <= signal.position_m <= self.end_m + TOLERANCE_M:
                raise LineError(
                    f"{label}.km",
                    m_to_km_post(signal.position_m),
                    f"a km post inside the line, {_span(self.start_m, self.end_m)}",
                )
            if previous is not None:
                prev_label, prev = previous
                if signal.position_m < prev.position_m - TOLERANCE_M:
                    raise LineError(
                        f"{label}.km",
                        m_to_km_post(signal.position_m),
                        f"a km post at or after {prev_label} (signals must be sorted by km post)",
                    )
            same = last_at.get(signal.direction)
            if same is not None and abs(signal.position_m - same[1]) <= TOLERANCE_M:
                raise LineError(
                    f"{label}.km",
                    m_to_km_post(signal.position_m),
                    f"a km post other than that of {same[0]} (two signals of one direction "
                    "at one km post would make an empty block section)",
                )
            last_at[signal.direction] = (label, signal.position_m)
            previous = (label, signal)

    def _checked_block_sections(self) -> tuple[BlockSection, ...]:
        if not self.block_sections:
            return tuple(s for d in DIRECTIONS for s in self._derived_block_sections(d))
        out: list[BlockSection] = []
        for direction in DIRECTIONS:
            indexed = [
                (i, s) for i, s in enumerate(self.block_sections) if s.direction == direction
            ]
            labels = [(_block_label(i, s), s.start_m, s.end_m) for i, s in indexed]
            _check_tiling(
                f"block sections going {direction_name(direction)}",
                labels,
                self.start_m,
                self.end_m,
            )
            signals = {
                round(s.position_m, 6): (_signal_label(i, s), s)
                for i, s in enumerate(self.signals)
                if s.direction == direction
            }
            used: set[float] = set()
            for (_, section), (label, _, _) in zip(indexed, labels, strict=True):
                at_line_end = (
                    abs(section.entry_m - (self.start_m if direction == UP else self.end_m))
                    <= TOLERANCE_M
                )
                entry = signals.get(round(section.entry_m, 6))
                if entry is None and not at_line_end:
                    key = "start_km" if direction == UP else "end_km"
                    raise LineError(
                        f"{label}.{key}",
                        m_to_km_post(section.entry_m),
                        f"the km post of a {direction_name(direction)} signal (a block section "
                        "begins, in its direction, at the signal protecting it)",
                    )
                if entry is not None:
                    used.add(round(section.entry_m, 6))
                out.append(
                    dataclasses.replace(
                        section, entry_signal=None if entry is None else entry[1].id
                    )
                )
            exit_end = self.end_m if direction == UP else self.start_m
            for where, (signal_label, signal) in signals.items():
                if where not in used and abs(signal.position_m - exit_end) > TOLERANCE_M:
                    raise LineError(
                        f"{signal_label}.km",
                        m_to_km_post(signal.position_m),
                        f"the km post where one of the {direction_name(direction)} block "
                        "sections begins in its direction (every signal protects a block section)",
                    )
        return tuple(out)

    def _derived_block_sections(self, direction: TravelDirection) -> list[BlockSection]:
        signals = sorted(
            (s for s in self.signals if s.direction == direction), key=lambda s: s.position_m
        )
        inner = [
            s.position_m
            for s in signals
            if self.start_m + TOLERANCE_M < s.position_m < self.end_m - TOLERANCE_M
        ]
        bounds = [self.start_m, *inner, self.end_m]
        by_position = {round(s.position_m, 6): s.id for s in signals}
        n = len(bounds) - 1
        sections = []
        for k in range(n):
            entry_m = bounds[k] if direction == UP else bounds[k + 1]
            travel_index = k + 1 if direction == UP else n - k
            sections.append(
                BlockSection(
                    id=f"{direction_name(direction)}-{travel_index:03d}",
                    direction=direction,
                    start_m=bounds[k],
                    end_m=bounds[k + 1],
                    entry_signal=by_position.get(round(entry_m, 6)),
                )
            )
        return sections

    # ------------------------------------------------------------------ basics

    @property
    def length_m(self) -> float:
        """Length of the line [m]."""
        return self.end_m - self.start_m

    def _positions(self, position_m: npt.ArrayLike) -> FloatArray:
        x = np.asarray(position_m, dtype=float)
        if (
            np.any(~np.isfinite(x))
            or np.any(x < self.start_m - TOLERANCE_M)
            or np.any(x > self.end_m + TOLERANCE_M)
        ):
            bad = x[~np.isfinite(x) | (x < self.start_m) | (x > self.end_m)].ravel()
            raise LineError(
                "position_m",
                float(bad[0]) if bad.size else position_m,
                f"a position inside the line, {self.start_m:g}-{self.end_m:g} m "
                f"({_span(self.start_m, self.end_m)})",
            )
        return x

    def distance_along(self, position_m: npt.ArrayLike, direction: TravelDirection) -> FloatArray:
        """Distance [m] a train going ``direction`` has run from where it entered the line.

        ``position_m - start_m`` going UP, ``end_m - position_m`` going DOWN: the
        coordinate of :meth:`to_vehicle_line`.
        """
        x = self._positions(position_m)
        return x - self.start_m if check_direction(direction) == UP else self.end_m - x

    def position_at(self, distance_m: npt.ArrayLike, direction: TravelDirection) -> FloatArray:
        """Km post [m] a train going ``direction`` reaches after ``distance_m`` [m] (inverse
        of :meth:`distance_along`)."""
        s = np.asarray(distance_m, dtype=float)
        x = self.start_m + s if check_direction(direction) == UP else self.end_m - s
        return self._positions(x)

    def station(self, station_id: int) -> Station:
        """The station with id ``station_id``."""
        for station in self.stations:
            if station.id == station_id:
                return station
        known = ", ".join(str(s.id) for s in self.stations) or "none"
        raise LineError("station_id", station_id, f"the id of a station of the line ({known})")

    # ------------------------------------------------------------------ gradients

    @cached_property
    def _gradient_steps(self) -> tuple[FloatArray, FloatArray]:
        return _steps([(g.start_m, g.end_m, g.permille) for g in self.gradients])

    def gradient_profile(self, direction: TravelDirection = UP) -> tuple[FloatArray, FloatArray]:
        """The gradient as a step function of km post.

        Returns ``(edges_m [m], permille)``: ``permille[i]`` holds between ``edges_m[i]``
        and ``edges_m[i+1]`` (ascending km posts), as seen by a train going ``direction``
        (UP: the file's gradients; DOWN: their negatives). Neighbours with equal values merge.
        """
        edges, values = self._gradient_steps
        sign = 1.0 if check_direction(direction) == UP else -1.0
        return edges.copy(), sign * values

    def gradient_at(self, position_m: npt.ArrayLike, direction: TravelDirection = UP) -> FloatArray:
        """Gradient [per mille, + uphill for the train] at ``position_m`` [m], going ``direction``.

        Vectorised over ``position_m``.
        """
        edges, values = self.gradient_profile(direction)
        return values[_index(edges, self._positions(position_m), direction)]

    def elevation_profile(self) -> tuple[FloatArray, FloatArray]:
        """Elevation [m] at every gradient edge (piecewise linear in between).

        Returns ``(edges_m, elevation_m)``, ``elevation_m[0] = start_elevation_m`` and
        ``elevation_m[i+1] = elevation_m[i] + permille[i] / 1000 * (edges_m[i+1] - edges_m[i])``.
        """
        edges, values = self._gradient_steps
        rise = values / 1000.0 * np.diff(edges)
        return edges.copy(), self.start_elevation_m + np.concatenate(([0.0], np.cumsum(rise)))

    def elevation_at(self, position_m: npt.ArrayLike) -> FloatArray:
        """Elevation [m] of the line at ``position_m`` [m]."""
        edges, elevation = self.elevation_profile()
        return np.interp(self._positions(position_m), edges, elevation)

    # ------------------------------------------------------------------ curves

    def curve_radius_at(self, position_m: npt.ArrayLike) -> FloatArray:
        """Curve radius [m] at ``position_m`` [m]; ``inf`` on straight track."""
        x = self._positions(position_m)
        radius = np.full(x.shape, np.inf)
        for curve in self.curves:
            radius = np.where((x >= curve.start_m) & (x <= curve.end_m), curve.radius_m, radius)
        return radius

    # ------------------------------------------------------------------ speed limits

    @cached_property
    def _limit_steps(self) -> dict[tuple[str, TravelDirection], tuple[FloatArray, FloatArray]]:
        return {
            (category, direction): _steps(
                [
                    (e.start_m, e.end_m, e.limit_mps)
                    for e in self.speed_limits
                    if e.category == category and e.applies_to(direction)
                ]
            )
            for category in self.categories
            for direction in DIRECTIONS
        }

    def _check_category(self, category: str) -> str:
        if category not in self.categories:
            raise LineError(
                "category", category, f"one of the line's categories: {', '.join(self.categories)}"
            )
        return category

    def static_limit(
        self, category: str, direction: TravelDirection
    ) -> tuple[FloatArray, FloatArray]:
        """Static speed limit of ``category`` going ``direction`` as a step function.

        Returns ``(edges_m [m], limit_mps [m/s])``: ``limit_mps[i]`` holds between
        ``edges_m[i]`` and ``edges_m[i+1]`` (ascending km posts; look up with the boundary
        convention of the module docstring, or use :meth:`limit_at`). Neighbours with
        equal limits merge.
        """
        edges, values = self._limit_steps[
            (self._check_category(category), check_direction(direction))
        ]
        return edges.copy(), values.copy()

    def limit_at(
        self, category: str, direction: TravelDirection, position_m: npt.ArrayLike
    ) -> FloatArray:
        """Static speed limit [m/s] of ``category`` at ``position_m`` [m] going ``direction``."""
        edges, values = self.static_limit(category, direction)
        return values[_index(edges, self._positions(position_m), direction)]

    # ------------------------------------------------------------------ signals and blocks

    @cached_property
    def _blocks(self) -> dict[TravelDirection, tuple[FloatArray, tuple[BlockSection, ...]]]:
        out = {}
        for direction in DIRECTIONS:
            sections = tuple(
                sorted(
                    (s for s in self.block_sections if s.direction == direction),
                    key=lambda s: s.start_m,
                )
            )
            edges = np.asarray([s.start_m for s in sections] + [sections[-1].end_m])
            out[direction] = (edges, sections)
        return out

    def block_sections_for(self, direction: TravelDirection) -> tuple[BlockSection, ...]:
        """The block sections of ``direction`` in the order a train going that way meets them."""
        return self._travel_order[check_direction(direction)]

    @cached_property
    def _travel_order(self) -> dict[TravelDirection, tuple[BlockSection, ...]]:
        # built once: a line run asks for every train every second
        return {
            d: sections if d == UP else sections[::-1] for d, (_, sections) in self._blocks.items()
        }

    @cached_property
    def _block_spans(
        self,
    ) -> dict[TravelDirection, tuple[list[float], list[float], dict[str, int]]]:
        """Per direction: section starts and ends in km order (for bisection), and each
        section's index in travel order."""
        out = {}
        for direction in DIRECTIONS:
            sections = self._blocks[direction][1]
            travel = self.block_sections_for(direction)
            out[direction] = (
                [s.start_m for s in sections],
                [s.end_m for s in sections],
                {s.id: k for k, s in enumerate(travel)},
            )
        return out

    def block_sections_between(
        self, low_m: float, high_m: float, direction: TravelDirection
    ) -> tuple[BlockSection, ...]:
        """The block sections of ``direction`` sharing at least a point with the closed span
        ``[low_m, high_m]`` [m], in travel order (bisection: a line of a thousand sections
        costs what one of ten does)."""
        d = check_direction(direction)
        starts, ends, _ = self._block_spans[d]
        sections = self._blocks[d][1]
        first = bisect.bisect_left(ends, low_m)
        last = bisect.bisect_right(starts, high_m)
        found = sections[first:last]
        return found if d == UP else found[::-1]

    def block_index(self, block_id: str, direction: TravelDirection) -> int | None:
        """Where section ``block_id`` comes in ``block_sections_for(direction)`` (None: it
        is not a section of that direction)."""
        return self._block_spans[check_direction(direction)][2].get(block_id)

    @cached_property
    def _signals_by_position(self) -> dict[TravelDirection, tuple[list[float], list[str]]]:
        out = {}
        for direction in DIRECTIONS:
            ordered = sorted((s.position_m, s.id) for s in self.signals if s.direction == direction)
            out[direction] = ([p for p, _ in ordered], [i for _, i in ordered])
        return out

    def signal_near(
        self, position_m: float, direction: TravelDirection, tolerance_m: float = 1.0
    ) -> str | None:
        """The id of the signal of ``direction`` within ``tolerance_m`` [m] of
        ``position_m`` [m], if there is one."""
        positions, ids = self._signals_by_position[check_direction(direction)]
        k = bisect.bisect_left(positions, position_m - tolerance_m)
        if k < len(positions) and abs(positions[k] - position_m) <= tolerance_m:
            return ids[k]
        return None

    def block_section_at(self, position_m: float, direction: TravelDirection) -> BlockSection:
        """The block section of ``direction`` a train at ``position_m`` [m] occupies.

        A train exactly at a signal is in the section that signal protects.
        """
        edges, sections = self._blocks[check_direction(direction)]
        x = self._positions(float(position_m))
        return sections[int(_index(edges, x, direction))]

    def signals_for(self, direction: TravelDirection) -> tuple[Signal, ...]:
        """The signals of ``direction`` in the order a train going that way meets them."""
        d = check_direction(direction)
        signals = sorted((s for s in self.signals if s.direction == d), key=lambda s: s.position_m)
        return tuple(signals) if d == UP else tuple(signals[::-1])

    def signals_ahead(self, position_m: float, direction: TravelDirection) -> tuple[Signal, ...]:
        """Signals of ``direction`` still ahead of a train at ``position_m`` [m], nearest first.

        A signal exactly at ``position_m`` is behind (the train is passing it).
        """
        x = float(self._positions(float(position_m)))
        signals = self.signals_for(direction)
        if direction == UP:
            return tuple(s for s in signals if s.position_m > x)
        return tuple(s for s in signals if s.position_m < x)

    # ------------------------------------------------------------------ the simulation's line

    def to_vehicle_line(self, category: str, direction: TravelDirection) -> Line:
        """The simulation core's :class:`~railpilot.vehicle.line.Line` for one train.

        Positions are the train's own coordinate (:meth:`distance_along`): metres run from
        the line's start km post going UP, from its end km post going DOWN. Gradients are
        as the train sees them (negated going DOWN), speed limits are ``category``'s for
        ``direction`` [m/s], curves keep their radius, and each station's stop point is the
        one for ``direction``. Segments are in increasing train coordinate; a segment
        ``[s0, s1)`` going DOWN is the km-post section ``(end_m - s1, end_m - s0]``.
        """
        d = check_direction(direction)

        def to_train(
            values: Sequence[tuple[float, float, float]], negate: bool = False
        ) -> tuple[Segment, ...]:
            if d == UP:
                return tuple(Segment(a - self.start_m, b - self.start_m, v) for a, b, v in values)
            sign = -1.0 if negate else 1.0
            return tuple(
                Segment(self.end_m - b, self.end_m - a, sign * v) for a, b, v in reversed(values)
            )

        def pairs(edges: FloatArray, values: FloatArray) -> list[tuple[float, float, float]]:
            return [
                (float(a), float(b), float(v))
                for a, b, v in zip(edges[:-1], edges[1:], values, strict=True)
            ]

        gradients = to_train(pairs(*self._gradient_steps), negate=True)
        curves = to_train([(c.start_m, c.end_m, c.radius_m) for c in self.curves])
        limits = to_train(pairs(*self.static_limit(category, d)))
        stations = tuple(
            StopPoint(s.name, float(self.distance_along(s.stop_m(d), d)))
            for s in (self.stations if d == UP else self.stations[::-1])
        )
        return Line(gradients=gradients, curves=curves, speed_limits=limits, stations=stations)
