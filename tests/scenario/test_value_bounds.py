"""Finite but absurd values in an example file are a ConfigError at load, naming the key.

Each case loads an example file, replaces one value in the parsed mapping (as the audit
did: 1e308 overflowed a ``round`` or a ``**`` mid-run, a 64-bit period overflowed the
kernel's integers, negative bands passed silently) and expects the error to name the key
as the file writes it.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import ConfigError
from railpilot.scenario.loader import read_toml, scenario_and_spec_from_mapping

EXAMPLES = Path(__file__).parents[2] / "examples"
HUGE = 1e308
#: a km post far beyond any line, still finite in metres
FAR = 1e300
#: the smallest float > 0 (subnormal): duration / TINY is inf
TINY = 5e-324
INT64_MAX = 2**63 - 1


def _load(example: str, path: tuple[Any, ...], value: Any) -> None:
    _load_changed(example, {path: value})


def _load_changed(example: str, changes: dict[tuple[Any, ...], Any]) -> None:
    data = read_toml(EXAMPLES / f"{example}.toml")
    for path, value in changes.items():
        table = data
        for key in path[:-1]:
            table = table[key]
        table[path[-1]] = value
    if data.get("kind") == "eddy-brake":
        EddyScenario.from_mapping(data, base_dir=EXAMPLES)
    else:
        scenario_and_spec_from_mapping(data)


CASES = [
    # eddy-brake files (railpilot.eddy.scenario)
    ("eddy_case2", ("table", "max_speed_kmh"), HUGE, "table.max_speed_kmh"),
    ("eddy_case2", ("table", "current_step_a"), HUGE, "table.current_step_a"),
    ("eddy_case2", ("table", "speed_step_kmh"), HUGE, "table.speed_step_kmh"),
    ("eddy_case1", ("duration_s",), HUGE, "duration_s"),
    ("eddy_case2", ("torque_demand_nm",), HUGE, "torque_demand_nm"),
    ("eddy_case2", ("metrics", "hold_band"), -1, "metrics.hold_band"),
    ("eddy_case2", ("metrics", "settling_band"), -1, "metrics.settling_band"),
    ("eddy_case2", ("metrics", "steady_start_s"), -1, "metrics.steady_start_s"),
    ("eddy_case2", ("metrics", "steady_start_s"), HUGE, "metrics.steady_start_s"),
    ("eddy_case2", ("metrics", "steady_end_speed_kmh"), HUGE, "metrics.steady_end_speed_kmh"),
    # steps of a run (eddy/simulate.py MAX_STEPS): 1e14 steps, or infinitely many
    ("eddy_case1", ("dt_s",), 1e-12, "dt_s"),
    ("eddy_case2", ("dt_s",), TINY, "dt_s"),
    # braking scenarios (railpilot.scenario.loader)
    ("paper000_smarc_ep", ("reference", "v0_kmh"), HUGE, "reference.v0_kmh"),
    ("paper000_smarc_ep", ("reference", "coast_s"), HUGE, "reference.coast_s"),
    ("paper000_smarc_ep", ("reference", "start_km"), HUGE, "reference.start_km"),
    ("paper002_qsmc_stop", ("reference", "coast_s"), HUGE, "reference.coast_s"),
    ("heavy_haul_stop", ("reference", "v0_kmh"), HUGE, "reference.v0_kmh"),
    ("heavy_haul_stop", ("disturbance", "random_hold_s"), HUGE, "disturbance.random_hold_s"),
    ("heavy_haul_stop", ("sim", "control_period_s"), INT64_MAX, "sim.control_period_s"),
    ("paper002_realistic", ("sim", "control_period_s"), INT64_MAX, "sim.control_period_s"),
    # steps of a run (scenario/model.py MAX_STEPS): 7e13, 2e8 and infinitely many
    ("paper000_smarc_ep", ("sim", "dt_s"), 1e-12, "sim.dt_s"),
    ("heavy_haul_stop", ("sim", "dt_s"), 1e-6, "sim.dt_s"),
    ("paper000_smarc_ep", ("sim", "dt_s"), TINY, "sim.dt_s"),
    # a stride beyond 64 bits: the kernel refused its arguments mid-run
    ("paper000_smarc_ep", ("sim", "record_every"), 2**64, "sim.record_every"),
    (
        "heavy_haul_run",
        ("line", "speed_limits", 0, "limit_kmh"),
        HUGE,
        "line.speed_limits[0].limit_kmh",
    ),
    ("heavy_haul_run", ("reference", "cruise_kmh"), HUGE, "reference.cruise_kmh"),
    ("heavy_haul_run", ("reference", "v0_kmh"), HUGE, "reference.v0_kmh"),
    ("heavy_haul_run", ("reference", "stop_km"), HUGE, "reference.stop_km"),
    ("heavy_haul_run", ("train", "length_m"), HUGE, "train.length_m"),
    (
        "paper000_montecarlo",
        ("montecarlo", "vary", "brake.delay_s", "max"),
        HUGE,
        # the other variables' out-of-range bounds are named so too (sim/batch.py)
        "montecarlo.vary.brake.delay_s",
    ),
    (
        "paper000_montecarlo",
        ("montecarlo", "vary", "initial_speed_kmh"),
        {"dist": "uniform", "min": 60.0, "max": HUGE},
        "montecarlo.vary.initial_speed_kmh",
    ),
    # factors and a coefficient with no upper bound of their own (sim/sweep.py
    # VARIABLE_MAXIMA): they passed and ran to nonsense stops
    (
        "paper000_montecarlo",
        ("montecarlo", "vary", "train.davis_scale", "max"),
        HUGE,
        "montecarlo.vary.train.davis_scale.max",
    ),
    (
        "heavy_haul_stop",
        ("montecarlo", "vary", "brake.gain", "max"),
        HUGE,
        "montecarlo.vary.brake.gain.max",
    ),
    (
        "paper002_realistic",
        ("montecarlo", "vary", "realism.adhesion", "max"),
        HUGE,
        "montecarlo.vary.realism.adhesion.max",
    ),
    (
        "paper002_realistic",
        ("montecarlo", "vary", "realism.adhesion"),
        {"dist": "normal", "mean": 0.14, "std": 0.02, "min": 0.1},  # no max: up to inf
        "montecarlo.vary.realism.adhesion.max",
    ),
    ("paper002_realistic", ("realism", "adhesion"), HUGE, "realism.adhesion"),
    # km posts beyond the reference's range (loader.py MAX_KM_POST): they passed and ran
    ("heavy_haul_run", ("line", "stations", 0, "stop_km"), HUGE, "line.stations[0].stop_km"),
    ("paper002_realistic", ("realism", "balises_km", 1), FAR, "realism.balises_km[1]"),
    (
        "paper000_smarc_ep",
        ("disturbance", "regions", 0, "start_km"),
        -FAR,
        "disturbance.regions[0].start_km",
    ),
    (
        "paper000_smarc_ep",
        ("disturbance", "regions", 0, "end_km"),
        FAR,
        "disturbance.regions[0].end_km",
    ),
    ("heavy_haul_run", ("line", "gradients", 0, "end_km"), FAR, "line.gradients[0].end_km"),
    (
        "paper002_realistic",
        ("line", "gradients", 0, "start_km"),
        -FAR,
        "line.gradients[0].start_km",
    ),
    ("heavy_haul_run", ("line", "speed_limits", 0, "end_km"), FAR, "line.speed_limits[0].end_km"),
    (
        "heavy_haul_run",
        ("line", "curves"),
        [{"start_km": 1.0, "end_km": FAR, "radius_m": 800.0}],
        "line.curves[0].end_km",
    ),
    # a reference that comes to rest beyond any line (km 2e8): it ran and never stopped
    ("paper002_qsmc_stop", ("reference", "decel_mps2"), 1e-9, "reference.decel_mps2"),
    ("paper000_smarc_ep", ("reference", "start_km"), 9_999.9, "reference.decel_mps2"),
]


@pytest.mark.parametrize(
    ("example", "path", "value", "field"),
    CASES,
    ids=[
        f"{c[0]}:{'.'.join(map(str, c[1]))}={c[2]:g}"
        if not isinstance(c[2], dict | list)
        else f"{c[0]}:{'.'.join(map(str, c[1]))}"
        for c in CASES
    ],
)
def test_an_absurd_value_is_an_error_naming_the_key_as_written(
    example: str, path: tuple[Any, ...], value: Any, field: str
) -> None:
    with pytest.raises(ConfigError) as info:
        _load(example, path, value)
    assert info.value.field == field
    assert info.value.allowed


@pytest.mark.parametrize(
    ("example", "path", "value"),
    [
        ("heavy_haul_run", ("train", "length_m"), 10_000.0),
        ("heavy_haul_stop", ("sim", "control_period_s"), 60.0),
        ("heavy_haul_stop", ("disturbance", "random_hold_s"), 86_400.0),
        ("paper000_smarc_ep", ("reference", "v0_kmh"), 600.0),
        ("paper000_smarc_ep", ("reference", "start_km"), -10_000.0),
        ("heavy_haul_run", ("line", "speed_limits", 0, "limit_kmh"), 600.0),
        ("eddy_case2", ("metrics", "steady_start_s"), 0.0),
        ("eddy_case2", ("table", "current_step_a"), 500.0),
        # the finest steps: 36e6 steps of eddy_case1's 100 s, 1e7 of heavy_haul_stop's
        # 200 s (whole steps of its 0.2 s control period); and the usual ones
        ("eddy_case1", ("dt_s",), 100.0 / 36_000_000),
        ("eddy_case1", ("dt_s",), 1e-4),
        ("heavy_haul_stop", ("sim", "dt_s"), 200.0 / 10_000_000),
        ("paper000_smarc_ep", ("sim", "dt_s"), 0.01),
        ("paper000_smarc_ep", ("sim", "record_every"), 10_000_000),
        # the largest factors and adhesion, and usual ones
        ("paper000_montecarlo", ("montecarlo", "vary", "train.davis_scale", "max"), 10.0),
        ("heavy_haul_stop", ("montecarlo", "vary", "brake.gain", "max"), 10.0),
        ("heavy_haul_stop", ("montecarlo", "vary", "brake.gain", "max"), 1.2),
        ("paper002_realistic", ("montecarlo", "vary", "realism.adhesion", "max"), 1.0),
        ("paper002_realistic", ("realism", "adhesion"), 1.0),
        ("paper002_realistic", ("realism", "adhesion"), 0.15),
        # km posts at the ends of the range, and usual ones
        ("heavy_haul_run", ("line", "stations", 0, "stop_km"), 10_000.0),
        ("heavy_haul_run", ("line", "stations", 0, "stop_km"), 29.0),
        ("paper002_realistic", ("realism", "balises_km", 0), -10_000.0),
        ("paper002_realistic", ("realism", "balises_km", 0), 0.2),
        ("paper000_smarc_ep", ("disturbance", "regions", 0, "end_km"), 10_000.0),
        ("paper000_smarc_ep", ("disturbance", "regions", 0, "start_km"), -10_000.0),
        ("heavy_haul_run", ("line", "gradients", 0, "end_km"), 10_000.0),
        ("heavy_haul_run", ("line", "speed_limits", 0, "start_km"), -10_000.0),
    ],
)
def test_the_bounds_themselves_are_allowed(example: str, path: tuple[Any, ...], value: Any) -> None:
    _load(example, path, value)


#: errors that named the constructor's field in metres (or a key no file has) where the
#: file writes a km post: (example, changes, the key as written, the value as written)
NAMED_AS_WRITTEN = [
    # a drive's stop before its start: reference.stop_m = -5000.0, "> reference.start_m"
    ("heavy_haul_run", {("reference", "stop_km"): -5.0}, "reference.stop_km", -5.0),
    ("heavy_haul_run", {("reference", "stop_km"): 0.0}, "reference.stop_km", 0.0),
    # a drive longer than its profile tabulates: reference.dx_m = 1.0, a key no file has
    (
        "heavy_haul_run",
        {("reference", "start_km"): -9000.0, ("reference", "stop_km"): 9000.0},
        "reference.stop_km",
        9000.0,
    ),
    # a start speed above what the profile allows: "... m/s (... at reference.start_m)"
    (
        "heavy_haul_run",
        {("reference", "start_km"): 28.0, ("reference", "v0_kmh"): 79.0},
        "reference.v0_kmh",
        79.0,
    ),
    # a train lighter than its locomotive: brake.train.mass_kg = 100000.0, in kg
    ("heavy_haul_run", {("train", "mass_t"): 100.0}, "train.mass_t", 100.0),
    # a brake's delay line too long for the step: brake.sim.dt_s, a key no file has
    ("heavy_haul_run", {("sim", "duration_s"): 40.0, ("sim", "dt_s"): 4e-6}, "sim.dt_s", 4e-6),
]


@pytest.mark.parametrize(
    ("example", "changes", "field", "value"),
    NAMED_AS_WRITTEN,
    ids=[f"{c[0]}:{c[2]}={c[3]:g}" for c in NAMED_AS_WRITTEN],
)
def test_an_error_names_the_key_and_value_as_the_file_writes_them(
    example: str, changes: dict[tuple[Any, ...], Any], field: str, value: float
) -> None:
    with pytest.raises(ConfigError) as info:
        _load_changed(example, changes)
    assert (info.value.field, info.value.value) == (field, value)
    # what is allowed names the file's keys and units, not the constructor's metres
    assert not re.search(r"\w_m\b", info.value.allowed), info.value.allowed
    if field.endswith("_kmh"):
        assert "km/h" in info.value.allowed


@pytest.mark.parametrize(
    "changes",
    [
        # the longest drive, and a usual one
        {("reference", "start_km"): -5000.0, ("reference", "stop_km"): 5000.0},
        {("reference", "start_km"): 2.0, ("reference", "stop_km"): 29.5},
    ],
)
@pytest.mark.slow
def test_drives_within_the_profile_s_reach_load(changes: dict[tuple[Any, ...], Any]) -> None:
    _load_changed("heavy_haul_run", changes)
