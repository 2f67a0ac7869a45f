"""A line-run file with any one value replaced by a wrong one is refused with a
ScenarioError naming the field, never with another exception (a list where a station id
belongs was a TypeError: unhashable type).

Every value of examples/line_live_short.toml (its services, channel and events, and the
optional top-level keys and [retiming] table it leaves out) in turn is replaced by values
of the wrong kind, and every key in turn removed.
"""

from __future__ import annotations

import copy
import math
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from railpilot.cosim.scenario import LineScenario, line_scenario_from_mapping
from railpilot.errors import ConfigError

FILE = Path(__file__).parents[2] / "examples" / "line_live_short.toml"
WRONG: tuple[Any, ...] = ("x", -1, 10**30, math.nan, math.inf, True, [], {}, [1, 2], {"a": 1})


def _paths(node: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """The path of every value (tables and lists too) below ``node``."""
    children = node.items() if isinstance(node, dict) else enumerate(node)
    for key, child in children:
        yield (*path, key)
        if isinstance(child, dict | list):
            yield from _paths(child, (*path, key))


def _with(data: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    changed = copy.deepcopy(data)
    parent = changed
    for key in path[:-1]:
        parent = parent[key]
    if value is _REMOVED:
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return changed


_REMOVED = object()
#: the file, with the optional top-level keys it leaves to their defaults given
BASE = tomllib.loads(FILE.read_text()) | {
    "start_epoch_s": 1_800_000_000.0,
    "margin_kmh": 5.0,
    "retiming": {
        "enabled": True,
        "headway_min": 3.0,
        "energy_weight_s_per_kwh": 0.5,
        "off_plan_min": 1.0,
        "every_min": 5.0,
    },
}
CASES = [(p, v) for p in _paths(BASE) for v in (*WRONG, _REMOVED)]


def test_the_file_itself_loads() -> None:
    assert isinstance(line_scenario_from_mapping(BASE), LineScenario)


def test_one_wrong_value_is_refused_naming_a_field_or_still_allowed() -> None:
    crashed = []
    refused = 0
    for path, value in CASES:
        try:
            line_scenario_from_mapping(_with(BASE, path, value))
        except ConfigError as error:
            assert error.field, (path, value)  # it names what it refused
            refused += 1
        except Exception as error:  # any other exception is the finding: collected, fails below
            crashed.append((path, value, repr(error)))
        # else a wrong kind of value may still be allowed (a name "x" is)
    assert not crashed, crashed
    assert refused > 0.8 * len(CASES)  # the cases reached the checks
