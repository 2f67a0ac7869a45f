"""Bad input never crashes: mutated example files load or fail with a RailpilotError."""

from __future__ import annotations

import contextlib
import copy
import random
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import RailpilotError
from railpilot.scenario.loader import scenario_and_spec_from_mapping
from railpilot.sim.run import make_controller

EXAMPLES = sorted((Path(__file__).parents[2] / "examples").glob("*.toml"))
# values of every wrong kind: out of range, non-finite, wrong type, wrong shape
BAD_VALUES: list[Any] = [
    -1,
    0,
    1e30,
    -1e30,
    float("nan"),
    float("inf"),
    "x",
    [],
    [1],
    [1, 2, 3],
    {},
    {"a": 1},
    True,
    10**20,
    -0.0,
]
TRIALS = 300


def _paths(table: dict[str, Any], prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    for key, value in table.items():
        yield (*prefix, key)
        if isinstance(value, dict):
            yield from _paths(value, (*prefix, key))
        if isinstance(value, list):
            for i, item in enumerate(value):
                if isinstance(item, dict):
                    yield from _paths(item, (*prefix, key, i))


def _set(table: Any, path: tuple[Any, ...], value: Any) -> None:
    for key in path[:-1]:
        table = table[key]
    table[path[-1]] = value


def _load(data: dict[str, Any], folder: Path) -> None:
    if data.get("kind") == "eddy-brake":
        EddyScenario.from_mapping(data, base_dir=folder)
    else:
        scenario, _ = scenario_and_spec_from_mapping(data)
        make_controller(scenario)


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.name)
def test_mutated_example_loads_or_fails_cleanly(example: Path) -> None:
    base = tomllib.loads(example.read_text())
    paths = list(_paths(base))
    rng = random.Random(example.name)  # seeded per file: the same mutations every run
    for _ in range(TRIALS):
        data = copy.deepcopy(base)
        for _ in range(rng.randint(1, 3)):
            # an earlier mutation may have replaced a table on this path
            with contextlib.suppress(TypeError, KeyError, IndexError):
                _set(data, rng.choice(paths), rng.choice(BAD_VALUES))
        # a clear error naming the key is what bad input should get; anything else fails
        with contextlib.suppress(RailpilotError):
            _load(data, example.parent)
