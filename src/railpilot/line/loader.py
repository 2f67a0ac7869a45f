"""Read a line TOML file into a :class:`~railpilot.line.model.RailLine`.

km posts in km, limits in km/h, lengths and radii in m at the edge; metres and m/s inside
(units.py). Every key is checked, by the format's models (railpilot.schema.line_file, its
JSON Schema: ``railpilot schema line``): an unknown key, a wrong type or an out-of-range
value raises :class:`~railpilot.errors.LineError` naming the entry as the file writes it,
e.g. ``gradients[3] (km 12.400-11.900).end_km``, the value and what is allowed, prefixed by
the file. Values' ranges and cross-entry rules (sorted, contiguous, inside the line, unique
ids) are the model's (model.py). docs/line-data.md describes the format; the layout::

    name = "..."                    # required
    description = "..."             # optional free text
    start_km = 0.0                  # optional, default 0
    end_km = 590.0                  # required
    start_elevation_m = 1533.0      # optional, default 0
    categories = ["freight_loaded", "freight_empty"]     # required
    stations = [{id, name, km, loop_length_m, stop_up_km, stop_down_km}]
    gradients = [{start_km, end_km, permille}]           # + rising towards increasing km
    curves = [{start_km, end_km, radius_m}]
    speed_limits = [{category, start_km, end_km, limit_kmh, direction = "both"}]
    signals = [{id, km, direction = "up" | "down", kind = "home" | "exit" | "block"}]
    block_sections = [{id, direction, start_km, end_km}] # optional: derived from signals

Each list may equally be written as ``[[gradients]]`` tables. A line file may be written in
JSON too (a name ending in ``.json``; the same keys).
"""

from __future__ import annotations

import functools
import os
import threading
from collections.abc import Callable, Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any, TypeVar

from railpilot.errors import LineError, is_finite_number
from railpilot.line.model import (
    DOWN,
    UP,
    BlockSection,
    Curve,
    Gradient,
    RailLine,
    Signal,
    SpeedLimit,
    Station,
)
from railpilot.link.messages import TravelDirection
from railpilot.schema.fields import FileTable
from railpilot.schema.line_file import (
    BlockSectionTable,
    LineCurveTable,
    LineFile,
    LineGradientTable,
    LineSpeedLimitTable,
    LineStationTable,
    SignalTable,
)
from railpilot.schema.reading import parse_text, read_document
from railpilot.schema.validate import Loc, check, dotted
from railpilot.units import MAX_KM_POST, km_post_to_m, kmh_to_mps

T = TypeVar("T")
M = TypeVar("M", bound=FileTable)

#: Shipped lines: name -> file in railpilot/line/data/.
SHIPPED_LINES: dict[str, str] = {"heavy-haul": "heavy_haul.toml", "metro": "metro.toml"}

_DIRECTIONS: dict[str, TravelDirection | None] = {"up": UP, "down": DOWN, "both": None}


def _km_text(value: Any) -> str | None:
    """A km post as an entry's label writes it (``"12.400"``), or None when the value is
    no km post to show: not a number, or beyond MAX_KM_POST (``1e300`` written out has
    300 digits, and ``10**400`` does not convert to a float at all)."""
    if is_finite_number(value) and abs(value) <= MAX_KM_POST:
        return f"{value:.3f}"
    return None


def _span_label(kind: str, index: int, raw: Mapping[str, Any], extra: str = "") -> str:
    """``kind[index] (extra, km a-b)`` when both km posts read as km posts."""
    start, end = _km_text(raw.get("start_km")), _km_text(raw.get("end_km"))
    if start is not None and end is not None:
        return f"{kind}[{index}] ({extra}km {start}-{end})"
    return f"{kind}[{index}]" + (f" ({extra.rstrip(', ')})" if extra else "")


def entry_label(kind: str, index: int, raw: Any) -> str:
    """An entry of the line file as its errors name it, from the values the file gives:
    ``gradients[3] (km 12.400-11.900)``, ``stations[0] (id 1 'S', km 12.500)``,
    ``signals[2] ('U2', up, km 12.000)``, ``speed_limits[3] (b, both, km 10.000-13.000)``."""
    plain = f"{kind}[{index}]"
    if not isinstance(raw, Mapping):
        return plain
    if kind in ("stations", "signals"):
        km = _km_text(raw.get("km"))
        if km is None:
            return plain
        if kind == "stations":
            return f"{plain} (id {raw.get('id')!r} {raw.get('name')!r}, km {km})"
        return f"{plain} ({raw.get('id')!r}, {raw.get('direction')}, km {km})"
    if kind == "speed_limits":
        extra = f"{raw.get('category')}, {raw.get('direction', 'both')}, "
        return _span_label(kind, index, raw, extra)
    if kind == "block_sections":
        return _span_label(kind, index, raw, f"{raw.get('id')!r}, {raw.get('direction')}, ")
    if kind in ("gradients", "curves"):
        return _span_label(kind, index, raw)
    return plain


def _place(loc: Loc, data: Any) -> str:
    """A key's place as the errors write it: an entry by its label."""
    if len(loc) >= 2 and isinstance(loc[0], str) and isinstance(loc[1], int):
        entries = data.get(loc[0]) if isinstance(data, Mapping) else None
        raw = entries[loc[1]] if isinstance(entries, list) and loc[1] < len(entries) else None
        label = entry_label(loc[0], loc[1], raw)
        rest = dotted(loc[2:])
        return f"{label}.{rest}" if rest else label
    return dotted(loc)


def _station(t: LineStationTable) -> Station:
    centre_km = t.km
    return Station(
        id=t.id,
        name=t.name,
        centre_m=km_post_to_m(centre_km),
        loop_length_m=t.loop_length_m,
        stop_up_m=km_post_to_m(t.stop_up_km if t.given("stop_up_km") else centre_km),
        stop_down_m=km_post_to_m(t.stop_down_km if t.given("stop_down_km") else centre_km),
    )


def _gradient(t: LineGradientTable) -> Gradient:
    return Gradient(km_post_to_m(t.start_km), km_post_to_m(t.end_km), t.permille)


def _curve(t: LineCurveTable) -> Curve:
    return Curve(km_post_to_m(t.start_km), km_post_to_m(t.end_km), t.radius_m)


def _speed_limit(t: LineSpeedLimitTable) -> SpeedLimit:
    return SpeedLimit(
        category=t.category,
        start_m=km_post_to_m(t.start_km),
        end_m=km_post_to_m(t.end_km),
        limit_mps=kmh_to_mps(t.limit_kmh),
        direction=_DIRECTIONS[t.direction],
    )


def _signal(t: SignalTable) -> Signal:
    direction = _DIRECTIONS[t.direction]
    assert direction is not None
    return Signal(id=t.id, position_m=km_post_to_m(t.km), direction=direction, kind=t.kind)


def _block_section(t: BlockSectionTable) -> BlockSection:
    direction = _DIRECTIONS[t.direction]
    assert direction is not None
    return BlockSection(
        id=t.id,
        direction=direction,
        start_m=km_post_to_m(t.start_km),
        end_m=km_post_to_m(t.end_km),
    )


def _entries(
    data: Mapping[str, Any], kind: str, tables: Sequence[M], make: Callable[[M], T]
) -> tuple[T, ...]:
    """The entries of list ``kind``, each built from its checked table; the error of an
    entry's own rule is named by the entry's label."""
    out = []
    for i, table in enumerate(tables):
        try:
            out.append(make(table))
        except LineError as exc:
            label = entry_label(kind, i, data[kind][i])
            raise LineError(f"{label}.{exc.field}", exc.value, exc.allowed) from exc
    return tuple(out)


def _in_source(source: str | None) -> Callable[[str, Any, str], LineError]:
    """The error of a line file named ``source`` (None: of a mapping of no file)."""

    def error(field: str, value: Any, allowed: str) -> LineError:
        return LineError(field, value, allowed, source=source)

    return error


def line_from_mapping(data: Mapping[str, Any], source: str | None = None) -> RailLine:
    """Build a :class:`RailLine` from a parsed TOML document (see the module docstring).

    Raises
    ------
    LineError
        Naming the offending entry and key, the value and what is allowed; prefixed by
        ``source`` when given.
    """
    top = check(LineFile, data, _in_source(source), name=_place)
    try:
        return RailLine(
            name=top.name,
            start_m=km_post_to_m(top.start_km),
            end_m=km_post_to_m(top.end_km),
            start_elevation_m=top.start_elevation_m,
            description=top.description,
            categories=tuple(top.categories),
            stations=_entries(data, "stations", top.stations, _station),
            gradients=_entries(data, "gradients", top.gradients, _gradient),
            curves=_entries(data, "curves", top.curves, _curve),
            speed_limits=_entries(data, "speed_limits", top.speed_limits, _speed_limit),
            signals=_entries(data, "signals", top.signals, _signal),
            block_sections=_entries(data, "block_sections", top.block_sections, _block_section),
        )
    except LineError as exc:
        if source is None or exc.source is not None:
            raise
        raise LineError(exc.field, exc.value, exc.allowed, source=source) from exc


def parse_line(text: str, source: str = "<string>") -> RailLine:
    """Parse the TOML ``text`` of a line file; errors are prefixed by ``source``."""
    return line_from_mapping(parse_text(text, source, "LINE", _in_source(source)), source=source)


def read_line(path: str | os.PathLike[str]) -> RailLine:
    """Read the line file at ``path`` (TOML, or JSON if its name ends in ``.json``)."""
    file = Path(path)
    data = read_document(
        file, "LINE", "line TOML file", LineError, parse_error=_in_source(str(file))
    )
    return line_from_mapping(data, source=str(file))


def load_line(name_or_path: str | os.PathLike[str]) -> RailLine:
    """A shipped line by name (``"heavy-haul"``, ``"metro"``) or a line file by path.

    A shipped name wins over a file of the same name in the working directory.
    """
    if isinstance(name_or_path, str) and name_or_path in SHIPPED_LINES:
        return interned(_shipped_line(name_or_path))
    path = Path(name_or_path)
    if not path.exists():
        raise LineError(
            "LINE",
            str(name_or_path),
            f"a shipped line ({', '.join(SHIPPED_LINES)}) or the path of a line TOML file",
        )
    return interned(read_line(path))


@functools.cache
def _shipped_line(name: str) -> RailLine:
    """A shipped line, parsed once a process: its file is part of the package and does not
    change while we run (the heavy-haul line takes about 40 ms to parse, and every
    line-run file names it)."""
    resource = resources.files("railpilot.line.data") / SHIPPED_LINES[name]
    return parse_line(resource.read_text(encoding="utf-8"), source=f"line '{name}'")


#: the first instance of each line loaded in this process (the most recent few)
_INTERNED: dict[RailLine, RailLine] = {}
_INTERNED_MAX = 16
_INTERNED_LOCK = threading.Lock()


def interned(line: RailLine) -> RailLine:
    """The instance of ``line`` loaded first in this process, if an equal one was.

    Why: routes, plans, block tables and controllers are cached keyed by their line, and
    a cache finds an identical key at once but compares an equal copy item by item (the
    heavy-haul line: 0.75 ms a lookup, thousands of lookups a simulated second). A sweep
    loads its scenario, and so its line, once a run: without this, every run after a
    worker's first ran 2.6 times as slowly as the first.
    """
    with _INTERNED_LOCK:  # the dashboard's ground thread loads lines too
        first = _INTERNED.setdefault(line, line)
        if len(_INTERNED) > _INTERNED_MAX:
            del _INTERNED[next(iter(_INTERNED))]  # the oldest: a few lines at a time is the use
    return first
