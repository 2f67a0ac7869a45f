"""Rules that check a file's values against each other or against another file: a km post
on the file's line, a station id of that line, a running time the train can run, a line
run's number of trains.

A format's models check each key alone; the readers call these once they hold what a rule
needs (the line, the train's fastest run). Each raises the reader's error (``(field,
value, allowed) -> error``) naming the entry, the value and what is allowed. The line is
taken by the few attributes a rule reads (:class:`LineExtent`, :class:`LineStations`), as
the schema layer sits below the line and the onboard that it checks.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Protocol

from railpilot.errors import ConfigError
from railpilot.units import km_post_to_m, m_to_km_post

#: the reader's error: ``(field, value, allowed) -> error``
ErrorType = Callable[[str, Any, str], ConfigError]


class LineExtent(Protocol):
    """What a km-post rule reads of a line (railpilot.line.model.RailLine)."""

    @property
    def name(self) -> str: ...

    @property
    def start_m(self) -> float: ...

    @property
    def end_m(self) -> float: ...


class _Station(Protocol):
    @property
    def id(self) -> int: ...


class LineStations(Protocol):
    """What a station rule reads of a line (railpilot.line.model.RailLine)."""

    @property
    def name(self) -> str: ...

    @property
    def stations(self) -> Sequence[_Station]: ...


class TimedSection(Protocol):
    """A timetable's section (railpilot.onboard.timetable.TimetableSection)."""

    @property
    def from_id(self) -> int: ...

    @property
    def to_id(self) -> int: ...

    @property
    def running_time_s(self) -> float: ...


def km_posts_words(line: LineExtent) -> str:
    """``a km post on line heavy-haul, 0 to 590``: the words of the ground's operations."""
    lo, hi = m_to_km_post(line.start_m), m_to_km_post(line.end_m)
    return f"a km post on line {line.name}, {lo:g} to {hi:g}"


def on_line(field: str, km: float, line: LineExtent, error: ErrorType) -> None:
    """``km`` [km post] lies on ``line``, between its first and last km post: a dead zone or
    a restriction beyond its ends would never be met, and the run would silently ignore it."""
    if not line.start_m <= km_post_to_m(km) <= line.end_m:
        raise error(field, km, km_posts_words(line))


def station_ids_words(line: LineStations) -> str:
    """``a station id of line heavy-haul: 1, 2, ... 20``."""
    ids = ", ".join(str(s.id) for s in line.stations) or "none"
    return f"a station id of line {line.name}: {ids}"


def station_of(field: str, station_id: Any, line: LineStations, error: ErrorType) -> int:
    """``station_id`` as the id of one of ``line``'s stations, or the error naming the
    line's ids. A number is taken as the id it equals (``3.0`` is station 3)."""
    ids = {s.id for s in line.stations}
    if isinstance(station_id, bool) or station_id not in ids:
        raise error(field, station_id, station_ids_words(line))
    return int(station_id)


def timetable_stations(
    sections: Sequence[TimedSection], line: LineStations, error: ErrorType
) -> None:
    """Every section of a timetable runs between stations of ``line`` (a station the line
    does not have is named as the timetable writes it, ``sections[2].to``)."""
    for i, section in enumerate(sections):
        station_of(f"sections[{i}].from", section.from_id, line, error)
        station_of(f"sections[{i}].to", section.to_id, line, error)


def running_times_possible(
    sections: Iterable[tuple[int, TimedSection]],
    fastest_s: Callable[[int, int], float],
    train: str,
    error: ErrorType,
    how: str = "",
) -> None:
    """No section's running time is below ``train``'s fastest run of it (``fastest_s(from,
    to)`` [s]): the train could not keep it, and the run would only show it late.
    ``sections``: each with its index in the timetable, for the error's name; ``how``: what
    the fastest run assumed, quoted in the error (``--margin 5 km/h``)."""
    for i, section in sections:
        quickest = fastest_s(section.from_id, section.to_id)
        if section.running_time_s < quickest:
            raise error(
                f"sections[{i}].running_time_s",
                section.running_time_s,
                f"a running time of at least {math.ceil(quickest * 10.0) / 10.0:.1f} s, the "
                f"fastest run of {train} from station {section.from_id} to {section.to_id}"
                + (f" ({how})" if how else ""),
            )


def trains_within(field: str, trains: int, cap: int, why: str, error: ErrorType) -> None:
    """At most ``cap`` trains in all (``why``: the cap's reason, quoted in the error)."""
    if trains > cap:
        raise error(field, trains, f"at most {cap} trains in all ({why})")
