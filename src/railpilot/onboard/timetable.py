"""A timetable for the onboard: planned running times between consecutive stops.

The ground sends running times per station pair (link ``RunningTimes``); a timetable file
gives the same for a whole run, for ``railpilot drive --timetable FILE``. TOML::

    name = "heavy-haul loaded, Shenchi South to Huanghua Port"
    [[sections]]
    from = 1                # station ids of the line
    to = 2
    running_time_s = 1640.0

Sections must chain (each starts where the previous one ended). Errors name the entry
(``sections[3].running_time_s``), the value and what is allowed. The file may be JSON too
(a name ending in ``.json``); its JSON Schema: ``railpilot schema timetable``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError
from railpilot.schema.cross_checks import LineStations, station_of
from railpilot.schema.reading import parse_text, read_document
from railpilot.schema.timetable import TimetableFile
from railpilot.schema.validate import check


@dataclass(frozen=True)
class TimetableSection:
    """One planned run from station ``from_id`` to station ``to_id`` [s]."""

    from_id: int
    to_id: int
    running_time_s: float


@dataclass(frozen=True)
class Timetable:
    name: str
    sections: tuple[TimetableSection, ...]

    def between(self, from_id: int, to_id: int) -> tuple[TimetableSection, ...]:
        """The chained sections from station ``from_id`` to ``to_id``; an error naming
        ``--from`` or ``--to`` if the timetable does not run between them."""
        starts = [i for i, s in enumerate(self.sections) if s.from_id == from_id]
        if not starts:
            ids = sorted({s.from_id for s in self.sections})
            raise ConfigError("--from", from_id, f"a station the timetable departs from: {ids}")
        first = starts[0]
        for last in range(first, len(self.sections)):
            if self.sections[last].to_id == to_id:
                return self.sections[first : last + 1]
        raise ConfigError("--to", to_id, f"a station the timetable reaches after {from_id}")


def parse_timetable(
    data: Mapping[str, Any], source: str = "<timetable>", line: LineStations | None = None
) -> Timetable:
    """A :class:`Timetable` from a parsed file, validated (module docstring; the format:
    railpilot.schema.timetable). With the ``line`` it runs on, each section's stations are
    checked to be the line's before the sections' chaining: a station the line lacks is
    named as such, not as the next section's break in the chain."""

    top = check(TimetableFile, data, ConfigError)
    sections: list[TimetableSection] = []
    for i, entry in enumerate(top.sections):
        where = f"sections[{i}]"
        if line is not None:
            station_of(f"{where}.from", entry.from_, line, ConfigError)
            station_of(f"{where}.to", entry.to, line, ConfigError)
        if entry.from_ == entry.to:
            raise ConfigError(f"{where}.to", entry.to, "a station other than from")
        if sections and sections[-1].to_id != entry.from_:
            raise ConfigError(
                f"{where}.from",
                entry.from_,
                f"{sections[-1].to_id}, where sections[{i - 1}] ends (sections must chain)",
            )
        sections.append(TimetableSection(entry.from_, entry.to, entry.running_time_s))
    name = top.name if top.given("name") else Path(source).stem
    return Timetable(name, tuple(sections))


#: the shipped timetables, by the name of their line
SHIPPED = {"heavy-haul": "heavy_haul_timetable.toml"}


def load_timetable(name_or_path: str | Path, line: LineStations | None = None) -> Timetable:
    """A shipped timetable by its line's name ("heavy-haul") or a file; errors name the
    file and the entry; with the ``line`` it runs on, its stations are checked first
    (:func:`parse_timetable`)."""
    if isinstance(name_or_path, str) and name_or_path in SHIPPED:
        from importlib.resources import files

        source = SHIPPED[name_or_path]
        text = files("railpilot.line.data").joinpath(source).read_text("utf-8")
        data = parse_text(text, source, "--timetable", ConfigError)
    else:
        source = str(name_or_path)
        data = read_document(Path(source), "--timetable", "timetable file", ConfigError)
    try:
        return parse_timetable(data, source, line)
    except ConfigError as error:
        # named with the file, as a line-run file's and a line file's errors are
        named = ConfigError(error.field, error.value, error.allowed)
        named.args = (f"{Path(source).name}: {error}",)
        raise named from None
