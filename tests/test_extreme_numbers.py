"""Extreme numbers in every shipped input file: a railpilot error, never a crash.

TOML integers are unbounded (``km = 1000...0`` with 400 digits parses) and floats reach
1e300, nan and inf. For each shipped file (examples/, the shipped lines, the shipped
timetable, the key-file layout of tests/link/test_keys.py) every numeric leaf of the
parsed document (ints and floats in tables and lists, not bools) is replaced, one at a
time, by each extreme value, and the file's loader is called on the result. It must load
or raise a :class:`~railpilot.errors.RailpilotError` whose message is short and readable
(no 300-digit number); any other exception is a defect.

The loaders' mapping entry points are called (tomli_w is not a dependency, so the
document is not written back as TOML): the same checks the file loaders run, as
tomllib gives them the same ints and floats. Loaders only: nothing is simulated.
"""

from __future__ import annotations

import math
import random
import re
import tomllib
from collections.abc import Callable, Iterator
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from link.helpers import KEY_FILE
from railpilot.cosim.scenario import line_scenario_from_mapping as line_run_from_mapping
from railpilot.cosim.scenario import load_line_scenario as load_line_run
from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import RailpilotError
from railpilot.line.loader import line_from_mapping, parse_line
from railpilot.link.keys import load_key_file, parse_key_table
from railpilot.onboard.timetable import load_timetable, parse_timetable
from railpilot.scenario.consist_file import load_consist, parse_consist
from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
from railpilot.scenario.loader import load_scenario, scenario_and_spec_from_mapping

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
LINE_DATA = ROOT / "src" / "railpilot" / "line" / "data"
CONSISTS = ROOT / "src" / "railpilot" / "vehicle" / "data" / "consists"

EXTREMES: dict[str, Any] = {
    "10**400": 10**400,
    "-10**400": -(10**400),
    "1e300": 1e300,
    "-1e300": -1e300,
    "nan": math.nan,
    "inf": math.inf,
}
#: a readable message: this short, and no number written out to more digits than this
MAX_MESSAGE_CHARS = 600
LONG_DIGIT_RUN = re.compile(r"\d{31,}")
#: a file with more numeric leaves is sampled: the heavy-haul line has about 1,600, at
#: about 25 ms a load; all of them times six values would take minutes. The sample is
#: fixed (seeded) and holds every kind of leaf (its path with list indices dropped) at
#: least once, then random leaves up to this many.
MAX_LEAVES = 300
SEED = 20_270_115


Path_ = tuple[str | int, ...]


def _scenario(data: dict[str, Any]) -> object:
    """As railpilot.scenario.load_scenario / load_scenario_and_spec read a mapping."""
    if data.get("kind") == "eddy-brake":
        return EddyScenario.from_mapping(data)
    if data.get("kind") == "train-dynamics":
        return consist_scenario_from_mapping(data, EXAMPLES)
    return scenario_and_spec_from_mapping(data)


def _loader(name: str, data: dict[str, Any]) -> Callable[[dict[str, Any]], object]:
    if name == "key table":
        return parse_key_table
    if name == "heavy_haul_timetable.toml":
        return parse_timetable
    if name in ("heavy_haul.toml", "metro.toml"):
        return line_from_mapping
    if "services" in data:
        return line_run_from_mapping  # a line-run file (railpilot line ...)
    if name == "consist library.toml":
        # the library of vehicle types and draft gears: read as a file defining them all,
        # one vehicle of each (a type defined in a file is read as the library's are)
        return lambda mapping: parse_consist(
            {
                "name": "every type",
                **mapping,
                "train": [
                    {"type": "HXD1", "count": 1},
                    {"type": "C80", "count": 1, "load": "loaded"},
                    {"type": "C80", "count": 1, "load": "empty"},
                ],
            },
            name,
        )
    if name.startswith("consist "):
        return lambda mapping: parse_consist(mapping, name)
    return _scenario


FILES: dict[str, Callable[[], str]] = {
    **{p.name: p.read_text for p in sorted(EXAMPLES.glob("*.toml"))},
    **{
        n: (LINE_DATA / n).read_text
        for n in ("heavy_haul.toml", "metro.toml", "heavy_haul_timetable.toml")
    },
    "key table": lambda: KEY_FILE,
    **{f"consist {p.name}": p.read_text for p in sorted(CONSISTS.glob("*.toml"))},
}


def _leaves(node: Any, path: Path_ = ()) -> Iterator[Path_]:
    """The path of every int or float (not bool) under ``node``."""
    if isinstance(node, bool):
        return
    if isinstance(node, int | float):
        yield path
    elif isinstance(node, dict):
        for key, value in node.items():
            yield from _leaves(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _leaves(value, (*path, i))


def _sample(paths: list[Path_]) -> list[Path_]:
    if len(paths) <= MAX_LEAVES:
        return paths
    first_of_kind: dict[tuple[str, ...], Path_] = {}
    for p in paths:
        first_of_kind.setdefault(tuple(k for k in p if isinstance(k, str)), p)
    chosen = set(first_of_kind.values())
    rest = [p for p in paths if p not in chosen]
    chosen |= set(random.Random(SEED).sample(rest, MAX_LEAVES - len(chosen)))
    return [p for p in paths if p in chosen]  # in file order


@cache
def _document(name: str) -> tuple[dict[str, Any], tuple[Path_, ...]]:
    """The parsed file (parsed once: never modified) and the leaves to try."""
    data = tomllib.loads(FILES[name]())
    return data, tuple(_sample(list(_leaves(data))))


def _replaced(node: Any, path: Path_, value: Any) -> Any:
    """A copy of ``node`` with the leaf at ``path`` set to ``value``: only the tables and
    lists on the path are copied, the rest is shared (the loaders do not modify it)."""
    if not path:
        return value
    copy = dict(node) if isinstance(node, dict) else list(node)
    copy[path[0]] = _replaced(node[path[0]], path[1:], value)
    return copy


def _written(path: Path_) -> str:
    """A leaf's path as a file writes it: ``stations[3].km``."""
    out = ""
    for k in path:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
    return out


def test_every_file_has_numeric_leaves_and_a_loader_that_accepts_it() -> None:
    for name in FILES:
        data, leaves = _document(name)
        assert leaves, name
        _loader(name, data)(data)  # the unmodified file loads


@pytest.mark.parametrize("shown", list(EXTREMES))
@pytest.mark.parametrize("name", list(FILES))
def test_an_extreme_number_is_a_railpilot_error_or_loads(name: str, shown: str) -> None:
    data, leaves = _document(name)
    load = _loader(name, data)
    value = EXTREMES[shown]
    defects = []
    for path in leaves:
        where = f"{name}: {_written(path)} = {shown}"
        try:
            load(_replaced(data, path, value))
        except RailpilotError as exc:
            message = str(exc)
            if len(message) >= MAX_MESSAGE_CHARS:
                defects.append(f"{where}: a message of {len(message)} characters: {message:.200}")
            elif LONG_DIGIT_RUN.search(message):
                defects.append(f"{where}: a number of more than 30 digits in {message!r}")
        except Exception as exc:
            defects.append(f"{where}: {type(exc).__name__}: {exc}")
    assert not defects, f"{len(defects)} of {len(leaves)} leaves:\n" + "\n".join(defects)


#: tomllib itself fails on an integer past Python's digit limit (4,300 digits), with a
#: ValueError that is no TOMLDecodeError
TOO_LONG = "1" * 5000
READERS: dict[str, Callable[[Path], object]] = {
    "line": lambda path: parse_line(path.read_text(), str(path)),
    "scenario": load_scenario,
    "line run": load_line_run,
    "timetable": load_timetable,
    "key file": load_key_file,
    "consist": load_consist,
}


@pytest.mark.parametrize("reader", list(READERS))
def test_an_integer_tomllib_cannot_convert_is_a_railpilot_error(
    reader: str, tmp_path: Path
) -> None:
    path = tmp_path / "file.toml"
    path.write_text(f'name = "x"\nseed = {TOO_LONG}\n')
    path.chmod(0o600)  # a key file must be private
    with pytest.raises(RailpilotError, match="4300 digits") as caught:
        READERS[reader](path)
    assert len(str(caught.value)) < MAX_MESSAGE_CHARS
