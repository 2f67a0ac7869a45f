"""Read a line TOML file into a :class:`~railpilot.line.model.RailLine`.

km posts in km, limits in km/h, lengths and radii in m at the edge; metres and m/s inside
(units.py). Every key is checked: an unknown key, a wrong type or an out-of-range value
raises :class:`~railpilot.errors.LineError` naming the entry as the file writes it, e.g.
``gradients[3] (km 12.400-11.900).end_km``, the value and what is allowed, prefixed by the
file. Cross-entry rules (sorted, contiguous, inside the line, unique ids) are the model's
(model.py). docs/line-data.md describes the format; the layout::

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

Each list may equally be written as ``[[gradients]]`` tables.
"""

from __future__ import annotations

import functools
import os
import threading
import tomllib
from collections.abc import Callable, Mapping
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
from railpilot.textfile import TOO_MANY_DIGITS, read_text
from railpilot.units import MAX_KM_POST, km_post_to_m, kmh_to_mps

T = TypeVar("T")

#: Shipped lines: name -> file in railpilot/line/data/.
SHIPPED_LINES: dict[str, str] = {"heavy-haul": "heavy_haul.toml", "metro": "metro.toml"}

TOP_KEYS = (
    "name",
    "description",
    "start_km",
    "end_km",
    "start_elevation_m",
    "categories",
    "stations",
    "gradients",
    "curves",
    "speed_limits",
    "signals",
    "block_sections",
)
STATION_KEYS = ("id", "name", "km", "loop_length_m", "stop_up_km", "stop_down_km")
GRADIENT_KEYS = ("start_km", "end_km", "permille")
CURVE_KEYS = ("start_km", "end_km", "radius_m")
LIMIT_KEYS = ("category", "start_km", "end_km", "limit_kmh", "direction")
SIGNAL_KEYS = ("id", "km", "direction", "kind")
BLOCK_KEYS = ("id", "direction", "start_km", "end_km")

_DIRECTIONS: dict[str, TravelDirection] = {"up": UP, "down": DOWN}


def _km_text(value: Any) -> str | None:
    """A km post as an entry's label writes it (``"12.400"``), or None when the value is
    no km post to show: not a number, or beyond MAX_KM_POST (``1e300`` written out has
    300 digits, and ``10**400`` does not convert to a float at all)."""
    if is_finite_number(value) and abs(value) <= MAX_KM_POST:
        return f"{value:.3f}"
    return None


class _Entry:
    """One TOML table being read: its label for errors, and typed getters."""

    def __init__(self, data: Any, label: str, allowed: tuple[str, ...]) -> None:
        if not isinstance(data, Mapping):
            raise LineError(label, data, f"a table with keys {', '.join(allowed)}")
        self.data = data
        self.label = label
        self.allowed = allowed

    def check_keys(self) -> None:
        """Reject a key the format does not know, listing the ones it does."""
        allowed = self.allowed
        for key in self.data:
            if key not in allowed:
                raise LineError(
                    self.key(key),
                    self.data[key],
                    f"a known key instead of '{key}' (allowed here: {', '.join(allowed)})",
                )

    def key(self, key: str) -> str:
        """The dotted name of ``key`` in this table, for errors."""
        return f"{self.label}.{key}" if self.label else key

    def number(self, key: str, default: float | None = None) -> float:
        if key not in self.data:
            if default is None:
                raise LineError(self.key(key), None, "a number (the key is required)")
            return default
        value = self.data[key]
        if not is_finite_number(value):  # nan, inf, and an int no float holds (10**400)
            raise LineError(self.key(key), value, "a finite number")
        return float(value)

    def km_post(self, key: str, default: float | None = None) -> float:
        """A km post [km] within MAX_KM_POST either way, the bound of scenario files too.
        The model then checks it lies on the line; this bound comes first so that no
        label or message writes out ``1e300`` km (300 digits)."""
        value = self.number(key, default)
        if not -MAX_KM_POST <= value <= MAX_KM_POST:
            raise LineError(
                self.key(key), value, f"a km post in [{-MAX_KM_POST:g}, {MAX_KM_POST:g}]"
            )
        return value

    def integer(self, key: str) -> int:
        value = self.data.get(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise LineError(self.key(key), value, "an integer (the key is required)")
        return value

    def string(self, key: str, default: str | None = None) -> str:
        if key not in self.data and default is not None:
            return default
        value = self.data.get(key)
        if not isinstance(value, str):
            raise LineError(self.key(key), value, "a string (the key is required)")
        return value

    def choice(self, key: str, choices: tuple[str, ...], default: str | None = None) -> str:
        value = self.string(key, default)
        if value not in choices:
            raise LineError(self.key(key), value, f"one of {', '.join(choices)}")
        return value

    def span_label(self, kind: str, index: int, extra: str = "") -> str:
        """``kind[index] (extra, km a-b)`` when both km posts read as km posts."""
        start, end = _km_text(self.data.get("start_km")), _km_text(self.data.get("end_km"))
        if start is not None and end is not None:
            return f"{kind}[{index}] ({extra}km {start}-{end})"
        return f"{kind}[{index}]" + (f" ({extra.rstrip(', ')})" if extra else "")


def _build(label: str, make: Callable[[], T]) -> T:
    """Run an entry's constructor; prefix its LineError's field with the entry's label."""
    try:
        return make()
    except LineError as exc:
        if exc.field.startswith(label):  # a getter's error already names the entry
            raise
        raise LineError(f"{label}.{exc.field}", exc.value, exc.allowed) from exc


def _tables(data: Mapping[str, Any], key: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise LineError(key, value, "a list of tables")
    return value


def _station(index: int, raw: Any) -> Station:
    entry = _Entry(raw, f"stations[{index}]", STATION_KEYS)
    km = _km_text(raw.get("km"))
    if km is not None:
        entry.label = f"stations[{index}] (id {raw.get('id')!r} {raw.get('name')!r}, km {km})"
    entry.check_keys()
    centre_km = entry.km_post("km")
    return _build(
        entry.label,
        lambda: Station(
            id=entry.integer("id"),
            name=entry.string("name"),
            centre_m=km_post_to_m(centre_km),
            loop_length_m=entry.number("loop_length_m"),
            stop_up_m=km_post_to_m(entry.km_post("stop_up_km", centre_km)),
            stop_down_m=km_post_to_m(entry.km_post("stop_down_km", centre_km)),
        ),
    )


def _gradient(index: int, raw: Any) -> Gradient:
    entry = _Entry(raw, f"gradients[{index}]", GRADIENT_KEYS)
    entry.label = entry.span_label("gradients", index)
    entry.check_keys()
    return _build(
        entry.label,
        lambda: Gradient(
            km_post_to_m(entry.km_post("start_km")),
            km_post_to_m(entry.km_post("end_km")),
            entry.number("permille"),
        ),
    )


def _curve(index: int, raw: Any) -> Curve:
    entry = _Entry(raw, f"curves[{index}]", CURVE_KEYS)
    entry.label = entry.span_label("curves", index)
    entry.check_keys()
    return _build(
        entry.label,
        lambda: Curve(
            km_post_to_m(entry.km_post("start_km")),
            km_post_to_m(entry.km_post("end_km")),
            entry.number("radius_m"),
        ),
    )


def _speed_limit(index: int, raw: Any) -> SpeedLimit:
    entry = _Entry(raw, f"speed_limits[{index}]", LIMIT_KEYS)
    extra = f"{raw.get('category')}, {raw.get('direction', 'both')}, "
    entry.label = entry.span_label("speed_limits", index, extra)
    entry.check_keys()
    direction = entry.choice("direction", ("both", "up", "down"), "both")
    return _build(
        entry.label,
        lambda: SpeedLimit(
            category=entry.string("category"),
            start_m=km_post_to_m(entry.km_post("start_km")),
            end_m=km_post_to_m(entry.km_post("end_km")),
            limit_mps=kmh_to_mps(entry.number("limit_kmh")),
            direction=_DIRECTIONS.get(direction),
        ),
    )


def _signal(index: int, raw: Any) -> Signal:
    entry = _Entry(raw, f"signals[{index}]", SIGNAL_KEYS)
    km = _km_text(raw.get("km"))
    if km is not None:
        entry.label = f"signals[{index}] ({raw.get('id')!r}, {raw.get('direction')}, km {km})"
    entry.check_keys()
    return _build(
        entry.label,
        lambda: Signal(
            id=entry.string("id"),
            position_m=km_post_to_m(entry.km_post("km")),
            direction=_DIRECTIONS[entry.choice("direction", ("up", "down"))],
            kind=entry.choice("kind", ("home", "exit", "block")),
        ),
    )


def _block_section(index: int, raw: Any) -> BlockSection:
    entry = _Entry(raw, f"block_sections[{index}]", BLOCK_KEYS)
    entry.label = entry.span_label(
        "block_sections", index, f"{raw.get('id')!r}, {raw.get('direction')}, "
    )
    entry.check_keys()
    return _build(
        entry.label,
        lambda: BlockSection(
            id=entry.string("id"),
            direction=_DIRECTIONS[entry.choice("direction", ("up", "down"))],
            start_m=km_post_to_m(entry.km_post("start_km")),
            end_m=km_post_to_m(entry.km_post("end_km")),
        ),
    )


def line_from_mapping(data: Mapping[str, Any], source: str | None = None) -> RailLine:
    """Build a :class:`RailLine` from a parsed TOML document (see the module docstring).

    Raises
    ------
    LineError
        Naming the offending entry and key, the value and what is allowed; prefixed by
        ``source`` when given.
    """
    try:
        top = _Entry(data, "", TOP_KEYS)
        top.check_keys()
        categories = data.get("categories")
        if not isinstance(categories, list) or not categories:
            raise LineError("categories", categories, "a non-empty list of category names")
        description = top.string("description", "")
        return RailLine(
            name=top.string("name"),
            start_m=km_post_to_m(top.number("start_km", 0.0)),
            end_m=km_post_to_m(top.number("end_km")),
            start_elevation_m=top.number("start_elevation_m", 0.0),
            description=description,
            categories=tuple(categories),
            stations=tuple(_station(i, raw) for i, raw in enumerate(_tables(data, "stations"))),
            gradients=tuple(_gradient(i, raw) for i, raw in enumerate(_tables(data, "gradients"))),
            curves=tuple(_curve(i, raw) for i, raw in enumerate(_tables(data, "curves"))),
            speed_limits=tuple(
                _speed_limit(i, raw) for i, raw in enumerate(_tables(data, "speed_limits"))
            ),
            signals=tuple(_signal(i, raw) for i, raw in enumerate(_tables(data, "signals"))),
            block_sections=tuple(
                _block_section(i, raw) for i, raw in enumerate(_tables(data, "block_sections"))
            ),
        )
    except LineError as exc:
        if source is None or exc.source is not None:
            raise
        raise LineError(exc.field, exc.value, exc.allowed, source=source) from exc


def parse_line(text: str, source: str = "<string>") -> RailLine:
    """Parse the TOML ``text`` of a line file; errors are prefixed by ``source``."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise LineError("LINE", source, f"valid TOML ({exc})", source=source) from exc
    except ValueError:  # tomllib's int() of a literal past Python's digit limit
        raise LineError("LINE", source, f"valid TOML ({TOO_MANY_DIGITS})", source=source) from None
    return line_from_mapping(data, source=source)


def read_line(path: str | os.PathLike[str]) -> RailLine:
    """Read the line file at ``path``."""
    file = Path(path)
    return parse_line(read_text(file, "LINE", "line TOML file", LineError), source=str(file))


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
