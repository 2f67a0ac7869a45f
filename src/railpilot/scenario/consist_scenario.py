"""``kind = "train-dynamics"`` scenario files: a consist driven along a line by a script.

The file names its consist (a shipped preset or a consist file, docs/consist.md), gives
the line as every scenario file does (``[line]``), the air brake's parameters
(``[air]``), the run's settings (``[sim]``) and the driver (``[driver]`` and its
``[[driver.commands]]``). Every key and its meaning: docs/consist-run.md; its JSON Schema:
``railpilot schema train-dynamics``. Errors name the key as written, the value and what is
allowed (railpilot.errors.ScenarioError).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.errors import ScenarioError
from railpilot.scenario.consist_file import consist_preset, load_consist
from railpilot.scenario.loader import _build, line_from_table
from railpilot.schema.config import ConfigTable, config_kwargs, given_values
from railpilot.schema.consist_run import (
    KIND,
    ConsistRunFileTable,
    ConsistSimTable,
    DriverCommandTable,
    DriverTable,
)
from railpilot.schema.validate import check
from railpilot.sim.consist_run import (
    ConsistDriver,
    ConsistRunSettings,
    ConsistScenario,
    DriverCommand,
)
from railpilot.units import km_post_to_m
from railpilot.vehicle.consist import CONSIST_PRESETS, Consist

__all__ = ["KIND", "consist_scenario_from_mapping"]


def _consist(name: str, base_dir: Path) -> Consist:
    if name in CONSIST_PRESETS:
        return consist_preset(name)
    path = Path(name)
    if not path.is_absolute():
        path = base_dir / path
    if path.suffix != ".toml":
        raise ScenarioError(
            "consist", name, f"one of {', '.join(CONSIST_PRESETS)} or a consist file (.toml)"
        )
    return load_consist(path)


def _sim(t: ConsistSimTable) -> ConsistRunSettings:
    kw = given_values(
        t,
        "dt_s",
        "duration_s",
        "record_every_s",
        "distributed_power",
        "compare_without_distributed_power",
        "coupler_limit_kn",
        "lump",
        "start_kmh",
    )
    if t.given("start_km"):
        kw["start_m"] = km_post_to_m(float(t.start_km))
    return _build("sim", lambda: ConsistRunSettings(**kw))


def _command(index: int, t: DriverCommandTable) -> DriverCommand:
    path = f"driver.commands[{index}]"
    kw = given_values(t, "at_s", "below_kmh", "above_kmh", "effort", "hold_kmh", "reduction_kpa")
    if t.given("at_km"):
        kw["at_m"] = km_post_to_m(float(t.at_km))
    if t.given("emergency"):
        kw["emergency"] = t.emergency
    if t.given("release") and t.release:
        if "reduction_kpa" in kw:
            raise ScenarioError(f"{path}.release", True, "either release or reduction_kpa")
        kw["reduction_kpa"] = 0.0
    return _build(path, lambda: DriverCommand(**kw))


def _driver(t: DriverTable) -> ConsistDriver:
    kw = given_values(
        t,
        "kp",
        "ki",
        "apply_above_kmh",
        "release_below_kmh",
        "min_release_kmh",
        "cycle_reduction_kpa",
        "end_at_rest",
    )
    commands = tuple(_command(i, command) for i, command in enumerate(t.commands))
    return _build("driver", lambda: ConsistDriver(commands=commands, **kw))


def _air(t: ConfigTable) -> FreightAirBrake:
    kw = config_kwargs(t, FreightAirBrake, nested=lambda *_: None)
    return _build("air", lambda: FreightAirBrake(**kw))


def consist_scenario_from_mapping(
    data: Mapping[str, Any], base_dir: Path | str = "."
) -> ConsistScenario:
    """Build and validate a ``train-dynamics`` scenario; a consist file named in it is
    read relative to ``base_dir`` (the scenario file's folder)."""
    air = data.get("air") if isinstance(data, Mapping) else None
    if isinstance(air, Mapping) and "charged_kpa" in air:
        raise ScenarioError(
            "air.charged_kpa",
            air["charged_kpa"],
            "no such key here: the pipe is charged to the consist's brake_pipe_kpa",
        )
    top = check(ConsistRunFileTable, data, ScenarioError)
    consist = _consist(top.consist, Path(base_dir))
    line = line_from_table(top.line)
    return ConsistScenario(
        top.name, consist, line, _driver(top.driver), _air(top.air), _sim(top.sim)
    )
