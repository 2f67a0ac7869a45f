"""A timetable for the onboard: planned running times between consecutive stops.

The ground sends running times per station pair (link ``RunningTimes``); a timetable file
gives the same for a whole run, for ``railpilot drive --timetable FILE``. TOML::

    name = "heavy-haul loaded, Shenchi South to Huanghua Port"
    [[sections]]
    from = 1                # station ids of the line
    to = 2
    running_time_s = 1640.0

Sections must chain (each starts where the previous one ended). Errors name the entry
(``sections[3].running_time_s``), the value and what is allowed.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError, is_finite_number
from railpilot.textfile import read_toml

#: the keys of a section, and of the file
SECTION_KEYS = ("from", "to", "running_time_s")
FILE_KEYS = ("name", "sections")


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


def parse_timetable(data: dict[str, Any], source: str = "<timetable>") -> Timetable:
    """A :class:`Timetable` from parsed TOML, validated (module docstring)."""
    for key in data:
        if key not in FILE_KEYS:
            raise ConfigError(f"{source}: {key}", data[key], f"one of {', '.join(FILE_KEYS)}")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise ConfigError("name", name, "a string")
    raw = data.get("sections")
    if not isinstance(raw, list) or not raw:
        raise ConfigError("sections", raw, "a non-empty list of [[sections]] tables")
    sections: list[TimetableSection] = []
    for i, entry in enumerate(raw):
        where = f"sections[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(where, entry, "a table with from, to, running_time_s")
        for key in entry:
            if key not in SECTION_KEYS:
                raise ConfigError(f"{where}.{key}", entry[key], f"one of {', '.join(SECTION_KEYS)}")
        for key in ("from", "to"):
            value = entry.get(key)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ConfigError(f"{where}.{key}", value, "a station id (an integer >= 0)")
        time = entry.get("running_time_s")
        if isinstance(time, bool) or not (
            isinstance(time, int | float) and is_finite_number(time) and 0 < time <= 86_400
        ):
            raise ConfigError(f"{where}.running_time_s", time, "a running time in (0, 86400] s")
        if entry["from"] == entry["to"]:
            raise ConfigError(f"{where}.to", entry["to"], "a station other than from")
        if sections and sections[-1].to_id != entry["from"]:
            raise ConfigError(
                f"{where}.from",
                entry["from"],
                f"{sections[-1].to_id}, where sections[{i - 1}] ends (sections must chain)",
            )
        sections.append(TimetableSection(entry["from"], entry["to"], float(time)))
    return Timetable(name, tuple(sections))


#: the shipped timetables, by the name of their line
SHIPPED = {"heavy-haul": "heavy_haul_timetable.toml"}


def load_timetable(name_or_path: str | Path) -> Timetable:
    """A shipped timetable by its line's name ("heavy-haul") or a file; errors name the
    file and the entry."""
    if isinstance(name_or_path, str) and name_or_path in SHIPPED:
        from importlib.resources import files

        text = files("railpilot.line.data").joinpath(SHIPPED[name_or_path]).read_text("utf-8")
        return parse_timetable(tomllib.loads(text), SHIPPED[name_or_path])
    p = Path(name_or_path)
    return parse_timetable(read_toml(p, "--timetable", "timetable file"), str(p))
