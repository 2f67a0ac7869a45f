"""``kind = "train-dynamics"`` scenario files: a consist driven along a line by a script.

The file names its consist (a shipped preset or a consist file, docs/consist.md), gives
the line as every scenario file does (``[line]``), the air brake's parameters
(``[air]``), the run's settings (``[sim]``) and the driver (``[driver]`` and its
``[[driver.commands]]``). Every key and its meaning: docs/consist-run.md. Errors name the
key as written, the value and what is allowed (railpilot.errors.ScenarioError).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.errors import ScenarioError
from railpilot.scenario.consist_file import load_consist
from railpilot.scenario.loader import _build, _line, _nested_config, _Table
from railpilot.sim.consist_run import (
    ConsistDriver,
    ConsistRunSettings,
    ConsistScenario,
    DriverCommand,
)
from railpilot.units import km_post_to_m
from railpilot.vehicle.consist import CONSIST_PRESETS, Consist, consist_preset

KIND = "train-dynamics"


def _consist(top: _Table, base_dir: Path) -> Consist:
    name = top.string("consist", CONSIST_PRESETS[0])
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


def _sim(t: _Table) -> ConsistRunSettings:
    kw: dict[str, Any] = {}
    t.put(kw, "dt_s", "dt_s", gt=0)
    t.put(kw, "duration_s", "duration_s", gt=0)
    t.put(kw, "record_every_s", "record_every_s", gt=0)
    t.put(kw, "distributed_power", "distributed_power", read="flag")
    t.put(
        kw,
        "compare_without_distributed_power",
        "compare_without_distributed_power",
        read="flag",
    )
    t.put(kw, "coupler_limit_kn", "coupler_limit_kn", gt=0)
    t.put(kw, "lump", "lump", read="integer")
    t.put(kw, "start_km", "start_m", km_post_to_m)
    t.put(kw, "start_kmh", "start_kmh", ge=0)
    sim = _build("sim", lambda: ConsistRunSettings(**kw))
    t.done()
    return sim


def _command(t: _Table) -> DriverCommand:
    kw: dict[str, Any] = {}
    t.put(kw, "at_s", "at_s", ge=0)
    t.put(kw, "at_km", "at_m", km_post_to_m)
    t.put(kw, "below_kmh", "below_kmh", ge=0)
    t.put(kw, "above_kmh", "above_kmh", ge=0)
    t.put(kw, "effort", "effort", ge=-1, le=1)
    t.put(kw, "hold_kmh", "hold_kmh", ge=0)
    t.put(kw, "reduction_kpa", "reduction_kpa", ge=0)
    t.put(kw, "release", "release", read="flag")
    t.put(kw, "emergency", "emergency", read="flag")
    if kw.pop("release", False):
        if "reduction_kpa" in kw:
            raise ScenarioError(t.key("release"), True, "either release or reduction_kpa")
        kw["reduction_kpa"] = 0.0
    command = _build(t.path, lambda: DriverCommand(**kw))
    t.done()
    return command


def _driver(t: _Table) -> ConsistDriver:
    kw: dict[str, Any] = {}
    for name in ("kp", "ki", "apply_above_kmh", "release_below_kmh", "min_release_kmh"):
        t.put(kw, name, name, ge=0)
    t.put(kw, "cycle_reduction_kpa", "cycle_reduction_kpa", gt=0)
    t.put(kw, "end_at_rest", "end_at_rest", read="flag")
    commands = tuple(_command(item) for item in t.tables("commands"))
    driver = _build("driver", lambda: ConsistDriver(commands=commands, **kw))
    t.done()
    return driver


def consist_scenario_from_mapping(
    data: Mapping[str, Any], base_dir: Path | str = "."
) -> ConsistScenario:
    """Build and validate a ``train-dynamics`` scenario; a consist file named in it is
    read relative to ``base_dir`` (the scenario file's folder)."""
    top = _Table(data, "")
    top.string("kind", KIND, (KIND,))
    if not top.has("name"):
        raise ScenarioError("name", None, "a scenario name (the key is required)")
    name = top.string("name", "")
    consist = _consist(top, Path(base_dir))
    line = _line(top.table("line"))
    air_table = top.table("air")
    if air_table.has("charged_kpa"):
        raise ScenarioError(
            "air.charged_kpa",
            air_table.raw("charged_kpa"),
            "no such key here: the pipe is charged to the consist's brake_pipe_kpa",
        )
    air = _nested_config(air_table, FreightAirBrake)
    sim = _sim(top.table("sim"))
    driver = _driver(top.table("driver"))
    top.done()
    return ConsistScenario(name, consist, line, driver, air, sim)
