"""Block occupancy on a fixed-block line from the trains' running info (paper 001, 2.3-2.4).

The ground knows each train's head km post and direction from its periodic running info
(``RunningInfo``) and its length from its registration (``RegisterRequest.train_length_m``).
From these it works out which block sections each train occupies; the target points
(:mod:`railpilot.ground.targets`) follow from which blocks are not free. No I/O, no clock:
the time of "now" and of each report is passed in [s, ground clock].

Rules
-----
- **One track per direction.** Block sections belong to one direction
  (:class:`~railpilot.line.model.BlockSection`); a train going ``UP`` occupies ``UP``
  sections only, a train going ``DOWN`` ``DOWN`` sections only (the shipped heavy-haul
  line is double track). So trains running in opposite directions never share a block.
- **Head to tail, both ends included.** A train occupies every block section of its
  direction whose closed span ``[start_m, end_m]`` meets the closed span from its tail to
  its head (tail = head - length going ``UP``, head + length going ``DOWN``). A train
  straddling a boundary occupies both sections. On a boundary exactly: the head is in
  the section it is entering (the line's own convention: a train at a signal is already
  in the section that signal protects) and also still in the one behind; a tail exactly
  on a boundary still holds the section it is leaving (a track circuit clears only once
  the last axle is past, so the ground releases a block only when the tail is strictly
  beyond it).
- **The line's ends.** A tail that would lie beyond the line's end (a train still entering
  the described line) is cut at that end: the line describes no blocks beyond it.
- **Stale reports are conservative.** A report older than ``validity_s`` makes the train's
  position unknown: the ground cannot know how far it has run since, nor that its tail
  has left any block. It then occupies the blocks of its last report *plus*
  ``stale_blocks_ahead`` (default 1) sections ahead of its head's, and is flagged
  ``known = False``. Beyond that the dispatcher decides (a train silent for long is a
  dispatching matter, not something to guess).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from types import MappingProxyType
from typing import Any, TypeVar

from railpilot.errors import ConfigError, is_finite_number
from railpilot.line.model import BlockSection, RailLine
from railpilot.link.messages import U32_MAX, RunningInfo, TravelDirection

UP = TravelDirection.UP
DOWN = TravelDirection.DOWN

#: Longest train [m] (the link's RegisterRequest.train_length_m carries up to 10 km).
MAX_TRAIN_LENGTH_M = 10_000.0
#: Default validity of a report [s]: the link declares running info timed out after more
#: than 3 missed cycles of 1 s (LinkTimers defaults), so 4 s.
DEFAULT_VALIDITY_S = 4.0

_T = TypeVar("_T")


def check_train_id(value: object, field: str = "train_id") -> int:
    """``value`` as a train id: the link's device id, an integer in ``[0, 2**32 - 1]``."""
    if type(value) is not int or not 0 <= value <= U32_MAX:
        raise ConfigError(field, value, f"an integer train id in [0, {U32_MAX}]")
    return value


def check_travel_direction(value: object, field: str = "direction") -> TravelDirection:
    """``value`` as ``UP`` or ``DOWN``; ``UNKNOWN`` cannot be placed on a track."""
    if value is UP or value is DOWN:
        return value
    raise ConfigError(
        field,
        value,
        "TravelDirection.UP or TravelDirection.DOWN (a train of unknown direction cannot be "
        "placed on a track: keep its last known direction)",
    )


def direction_sign(direction: TravelDirection) -> float:
    """``+1.0`` going ``UP`` (increasing km posts), ``-1.0`` going ``DOWN``."""
    return 1.0 if check_travel_direction(direction) is UP else -1.0


def line_end_m(line: RailLine, direction: TravelDirection) -> float:
    """The km post [m] where a train going ``direction`` leaves the line."""
    return line.end_m if check_travel_direction(direction) is UP else line.start_m


@lru_cache(maxsize=16)
def blocks_by_id(line: RailLine) -> Mapping[str, BlockSection]:
    """The line's block sections by id (read-only); ids must be unique across both
    directions. Built once per line: the ground asks every second."""
    out: dict[str, BlockSection] = {}
    for section in line.block_sections:
        if section.id in out:
            raise ConfigError(
                "line.block_sections.id",
                section.id,
                f"block section ids unique on line '{line.name}' (occupancy is keyed by "
                "block id, in both directions)",
            )
        out[section.id] = section
    return MappingProxyType(out)


# ---------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class TrainReport:
    """What the ground last heard of one train.

    Attributes
    ----------
    train_id
        The train's link device id.
    head_m
        Km post of the train's head [m] (``RunningInfo.position_m``).
    direction
        ``UP`` or ``DOWN`` (``RunningInfo.direction``).
    length_m
        Train length [m] (``RegisterRequest.train_length_m``), ``0 < length <= 10 km``.
    reported_s
        When the ground received the report [s, ground clock].
    """

    train_id: int
    head_m: float
    direction: TravelDirection
    length_m: float
    reported_s: float

    def __post_init__(self) -> None:
        check_train_id(self.train_id, "report.train_id")
        if not is_finite_number(self.head_m) or self.head_m < 0:
            raise ConfigError("report.head_m", self.head_m, "a finite km post >= 0 [m]")
        check_travel_direction(self.direction, "report.direction")
        if not is_finite_number(self.length_m) or not 0 < self.length_m <= MAX_TRAIN_LENGTH_M:
            raise ConfigError(
                "report.length_m",
                self.length_m,
                f"a train length > 0 and <= {MAX_TRAIN_LENGTH_M:g} m",
            )
        if not is_finite_number(self.reported_s):
            raise ConfigError("report.reported_s", self.reported_s, "a finite time [s]")

    @classmethod
    def from_running_info(
        cls, train_id: int, info: RunningInfo, length_m: float, received_s: float
    ) -> TrainReport:
        """The report of a received ``info`` of a train ``length_m`` [m] long, at ``received_s``."""
        return cls(train_id, float(info.position_m), info.direction, length_m, received_s)


@dataclass(frozen=True)
class OccupancyConfig:
    """How old a report may be before the train's occupancy turns conservative.

    Attributes
    ----------
    validity_s
        A report older than this [s] (``now_s - reported_s > validity_s``) is stale.
    stale_blocks_ahead
        Sections beyond its last head's that a stale train is taken to occupy (>= 0).
    """

    validity_s: float = DEFAULT_VALIDITY_S
    stale_blocks_ahead: int = 1

    def __post_init__(self) -> None:
        if not is_finite_number(self.validity_s) or self.validity_s <= 0:
            raise ConfigError("occupancy.validity_s", self.validity_s, "a finite time > 0 [s]")
        blocks = self.stale_blocks_ahead
        if type(blocks) is not int or blocks < 0:
            raise ConfigError("occupancy.stale_blocks_ahead", blocks, "an integer >= 0")


# ---------------------------------------------------------------------------- results


@dataclass(frozen=True)
class TrainOccupancy:
    """The block sections one train occupies.

    Attributes
    ----------
    train_id, direction
        As reported.
    head_m
        Km post of the head [m] as last reported.
    tail_m
        Km post of the tail [m], cut at the line's end.
    block_ids
        Occupied sections in travel order: the rear-most first, then up to the head's
        section and, when the report is stale, the sections held ahead of it.
    head_block_id
        The section the head is in (a train at a signal is in the section it protects).
    known
        ``False`` when the report is stale (module docstring).
    reported_s
        When the report was received [s].
    """

    train_id: int
    direction: TravelDirection
    head_m: float
    tail_m: float
    block_ids: tuple[str, ...]
    head_block_id: str
    known: bool
    reported_s: float

    def __post_init__(self) -> None:
        check_train_id(self.train_id, "occupancy.train_id")
        check_travel_direction(self.direction, "occupancy.direction")
        for name in ("head_m", "tail_m", "reported_s"):
            if not is_finite_number(getattr(self, name)):
                raise ConfigError(f"occupancy.{name}", getattr(self, name), "a finite number")
        ids = tuple(self.block_ids)
        if not ids or not all(isinstance(i, str) for i in ids):
            raise ConfigError("occupancy.block_ids", self.block_ids, "a non-empty tuple of ids")
        object.__setattr__(self, "block_ids", ids)
        if self.head_block_id not in ids:
            raise ConfigError(
                "occupancy.head_block_id", self.head_block_id, f"one of block_ids {ids}"
            )
        if not isinstance(self.known, bool):
            raise ConfigError("occupancy.known", self.known, "True or False")

    def is_ahead_of(self, other: TrainOccupancy) -> bool:
        """Whether this train runs in ``other``'s direction and its head is not behind
        ``other``'s head (equal heads count as ahead, to be on the safe side)."""
        if self.direction is not other.direction:
            return False
        return direction_sign(self.direction) * (self.head_m - other.head_m) >= 0.0


@dataclass(frozen=True)
class Occupancy:
    """Which train occupies which block section of ``line_name`` at ``now_s`` [s].

    ``trains`` is sorted by train id; :attr:`by_block` maps each occupied block id to the
    ids of the trains in it (ascending). A block missing from it is free.
    """

    line_name: str
    now_s: float
    trains: tuple[TrainOccupancy, ...]
    _by_block: Mapping[str, tuple[int, ...]] = field(init=False, repr=False, compare=False)
    _by_id: Mapping[int, TrainOccupancy] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not is_finite_number(self.now_s):
            raise ConfigError("occupancy.now_s", self.now_s, "a finite time [s]")
        trains = tuple(self.trains)
        seen: set[int] = set()
        for i, train in enumerate(trains):
            if not isinstance(train, TrainOccupancy):
                raise ConfigError(f"occupancy.trains[{i}]", train, "a TrainOccupancy")
            if train.train_id in seen:
                raise ConfigError(
                    f"occupancy.trains[{i}].train_id", train.train_id, "a train id listed once"
                )
            seen.add(train.train_id)
        self.__dict__.update(_indexed(trains))

    @property
    def by_block(self) -> Mapping[str, tuple[int, ...]]:
        """Occupied block id -> ids of the trains in it (ascending); read-only."""
        return self._by_block

    @property
    def train_ids(self) -> tuple[int, ...]:
        """Ids of the trains placed, ascending."""
        return tuple(t.train_id for t in self.trains)

    def train(self, train_id: int) -> TrainOccupancy:
        """The occupancy of ``train_id``."""
        train = self._by_id.get(train_id)
        if train is not None:
            return train
        raise ConfigError("train_id", train_id, f"one of the trains placed: {self.train_ids}")

    def occupants(self, block_id: str) -> tuple[int, ...]:
        """Ids of the trains in ``block_id`` (empty when it is free)."""
        return self._by_block.get(block_id, ())

    def is_free(self, block_id: str) -> bool:
        """Whether no train occupies ``block_id``."""
        return block_id not in self._by_block


def _derived(cls: type[_T], **fields: Any) -> _T:
    """An instance of the frozen dataclass ``cls`` with ``fields``, without the checks of
    its ``__post_init__``: for what :func:`compute_occupancy` derived from reports it
    checked, where every field holds by construction (the ground and the trackside build
    an occupancy of every train every second)."""
    instance = object.__new__(cls)
    instance.__dict__.update(fields)
    return instance


def _indexed(trains: Iterable[TrainOccupancy]) -> dict[str, Any]:
    """An :class:`Occupancy`'s fields that follow from its trains: the trains sorted by
    id, and the look-ups by id and by block (each block's ids ascending)."""
    ordered = tuple(sorted(trains, key=lambda t: t.train_id))
    by_block: dict[str, list[int]] = {}
    for train in ordered:
        for block_id in train.block_ids:
            by_block.setdefault(block_id, []).append(train.train_id)
    return {
        "trains": ordered,
        "_by_id": {t.train_id: t for t in ordered},
        "_by_block": MappingProxyType({b: tuple(ids) for b, ids in sorted(by_block.items())}),
    }


# ---------------------------------------------------------------------------- functions


def _check_on_line(line: RailLine, position_m: float, field: str) -> None:
    if not is_finite_number(position_m) or not line.start_m <= position_m <= line.end_m:
        raise ConfigError(
            field,
            position_m,
            f"a km post on line '{line.name}', {line.start_m:g}-{line.end_m:g} m",
        )


def occupied_blocks(
    line: RailLine, head_m: float, direction: TravelDirection, length_m: float
) -> tuple[BlockSection, ...]:
    """Block sections of ``direction`` a train occupies, rear-most first (module docstring).

    ``head_m`` [m] the head's km post on the line, ``length_m`` [m] > 0. The last section
    returned is the head's (``line.block_section_at(head_m, direction)``).
    """
    direction = check_travel_direction(direction)
    _check_on_line(line, head_m, "head_m")
    if not is_finite_number(length_m) or length_m <= 0:
        raise ConfigError("length_m", length_m, "a train length > 0 [m]")
    return _occupied(line, head_m, direction, length_m)[0]


def _occupied(
    line: RailLine, head_m: float, direction: TravelDirection, length_m: float
) -> tuple[tuple[BlockSection, ...], float]:
    """:func:`occupied_blocks` of a checked train, and its tail's km post [m] (cut at the
    line's end)."""
    sign = direction_sign(direction)
    tail_m = min(max(head_m - sign * length_m, line.start_m), line.end_m)
    low, high = (head_m, tail_m) if head_m <= tail_m else (tail_m, head_m)
    # Closed spans on both sides: a touch at a boundary counts (module docstring).
    return line.block_sections_between(low, high, direction), tail_m


def compute_occupancy(
    line: RailLine,
    reports: Iterable[TrainReport],
    now_s: float,
    config: OccupancyConfig | None = None,
) -> Occupancy:
    """Block occupancy of ``line`` at ``now_s`` [s] from each train's latest report.

    One report per train; a report may not be newer than ``now_s``. Reports older than
    ``config.validity_s`` give a conservative occupancy (module docstring).
    """
    cfg = config if config is not None else OccupancyConfig()
    if not is_finite_number(now_s):
        raise ConfigError("now_s", now_s, "a finite time [s]")
    blocks_by_id(line)  # ids must be unique: the occupancy is keyed by them
    trains: list[TrainOccupancy] = []
    seen: set[int] = set()
    for i, report in enumerate(reports):
        if not isinstance(report, TrainReport):
            raise ConfigError(f"reports[{i}]", report, "a TrainReport")
        if report.train_id in seen:
            raise ConfigError(
                f"{_label(i, report)}.train_id",
                report.train_id,
                "a train not reported before (one each)",
            )
        seen.add(report.train_id)
        if report.reported_s > now_s:
            raise ConfigError(
                f"{_label(i, report)}.reported_s",
                report.reported_s,
                f"a time at or before now_s = {now_s}",
            )
        head_m = report.head_m
        if not line.start_m <= head_m <= line.end_m:  # finite: a TrainReport's is
            _check_on_line(line, head_m, f"{_label(i, report)}.head_m")
        # the report's direction and length were checked when it was made
        direction = report.direction
        sections, tail_m = _occupied(line, head_m, direction, report.length_m)
        known = now_s - report.reported_s <= cfg.validity_s
        ids = tuple(s.id for s in sections)
        if not known:
            order = line.block_sections_for(direction)
            head_index = line.block_index(sections[-1].id, direction)
            assert head_index is not None  # the section came from this direction
            extra = order[head_index + 1 : head_index + 1 + cfg.stale_blocks_ahead]
            ids += tuple(s.id for s in extra)
        trains.append(
            _derived(
                TrainOccupancy,
                train_id=report.train_id,
                direction=direction,
                head_m=float(head_m),
                tail_m=float(tail_m),
                block_ids=ids,
                head_block_id=sections[-1].id,
                known=known,
                reported_s=float(report.reported_s),
            )
        )
    return _derived(Occupancy, line_name=line.name, now_s=float(now_s), **_indexed(trains))


def _label(i: int, report: TrainReport) -> str:
    """How an error names the ``i``-th report (made only for an error: the ground
    computes the occupancy every second)."""
    return f"reports[{i}] (train {report.train_id})"
