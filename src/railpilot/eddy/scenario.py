"""Eddy-brake scenario: a typed, validated configuration built from a plain mapping.

``railpilot simulate file.toml`` routes files with ``kind = "eddy-brake"`` here:
``EddyScenario.from_mapping(tomllib.load(f))``. Layout (every section and key optional
except ``torque_demand_nm`` and ``initial_speed_kmh``; defaults = the documented set)::

    kind = "eddy-brake"
    name = "case 1"
    torque_demand_nm = 3500
    initial_speed_kmh = 160
    duration_s = 100
    dt_s = 1e-4
    record_every = 10              # thins the stored series; metrics use every step
    controller = "fuzzy_pi"        # open_loop | pid | fuzzy | fuzzy_pi

    [pid]       kp, ki, kd, derivative_filter_s
    [fuzzy]     e_scale, ce_scale, u_scale, ce_filter_s, n_grid
    [fuzzy_pi]  kp1, ki1, kp_span, ki_span, e_scale, ce_scale, ce_filter_s, n_grid
    [brake]     fields of EddyBrakeParams (geometry and materials)
    [coil]      fields of CoilParams
    [train]     fields of TrainParams
    [table]     csv = "path.csv" (relative to the scenario file) or max_current_a,
                current_step_a, max_speed_kmh, speed_step_kmh (grid of the analytic model)
    [metrics]   settling_band, hold_band, steady_start_s, steady_end_speed_kmh

Every key is checked by the format's models (railpilot.schema.eddy, its JSON Schema:
``railpilot schema eddy-brake``); an unknown key, a wrong type or a value out of range is a
:class:`~railpilot.errors.ScenarioError` naming the key, the value and what is allowed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from pydantic import Field

from railpilot.checks import check_count, check_number
from railpilot.control.base import Controller
from railpilot.control.fuzzy import FuzzyController, FuzzyPI
from railpilot.control.open_loop import OpenLoop
from railpilot.control.pid import PID
from railpilot.eddy.coil import CoilParams
from railpilot.eddy.metrics import StepMetrics, step_metrics
from railpilot.eddy.simulate import MAX_STEPS, EddyResult, simulate_eddy
from railpilot.eddy.table import TorqueTable, load_torque_table_csv
from railpilot.eddy.torque_model import EddyBrakeParams
from railpilot.eddy.train import TrainParams
from railpilot.errors import ConfigError, ScenarioError
from railpilot.schema.config import ConfigTable, config_kwargs, config_table
from railpilot.schema.eddy import (
    CONTROLLERS,
    FUZZY_DEFAULTS,
    FUZZY_PI_DEFAULTS,
    KIND,
    MAX_DT_S,
    MAX_DURATION_S,
    MAX_INITIAL_SPEED_KMH,
    MAX_TORQUE_DEMAND_NM,
    METRICS_DEFAULTS,
    PID_DEFAULTS,
    TABLE_GRID_DEFAULTS,
    EddyScenarioKeys,
    FuzzyPiTable,
    FuzzyTable,
    MetricsTable,
    ParamsWords,
    PidTable,
    TableGridTable,
)
from railpilot.schema.fields import FileTable
from railpilot.schema.validate import check
from railpilot.units import kmh_to_mps, mps_to_kmh

T = TypeVar("T")

__all__ = [
    "CONTROLLERS",
    "FUZZY_DEFAULTS",
    "FUZZY_PI_DEFAULTS",
    "KIND",
    "METRICS_DEFAULTS",
    "PID_DEFAULTS",
    "TABLE_GRID_DEFAULTS",
    "EddyScenario",
    "EddyScenarioFile",
]


class EddyScenarioFile(EddyScenarioKeys):
    """An eddy-current brake scenario file (railpilot.schema.eddy), with the brake's,
    coil's and train's tables derived from their config dataclasses."""

    brake: config_table(EddyBrakeParams, words=ParamsWords) = Field(  # type: ignore[valid-type]
        default_factory=config_table(EddyBrakeParams, words=ParamsWords)
    )
    coil: config_table(CoilParams, words=ParamsWords) = Field(  # type: ignore[valid-type]
        default_factory=config_table(CoilParams, words=ParamsWords)
    )
    train: config_table(TrainParams, words=ParamsWords) = Field(  # type: ignore[valid-type]
        default_factory=config_table(TrainParams, words=ParamsWords)
    )


def _check_metrics(metrics: Mapping[str, float]) -> None:
    """The ``[metrics]`` keys: bands are fractions of the demand, the steady window starts
    and ends in a run's range (else the metrics silently read a meaningless window). A
    start after a short run's end is allowed: the default 5 s with a 2 s test run."""
    for key in ("settling_band", "hold_band"):
        if not 0 < metrics[key] < 1:
            raise ScenarioError(
                f"metrics.{key}", metrics[key], "a fraction of the demand in (0, 1)"
            )
    start = metrics["steady_start_s"]
    if not 0 <= start <= MAX_DURATION_S:
        raise ScenarioError("metrics.steady_start_s", start, f"a time in [0, {MAX_DURATION_S:g}] s")
    end_kmh = metrics["steady_end_speed_kmh"]
    if not 0 <= end_kmh <= MAX_INITIAL_SPEED_KMH:
        raise ScenarioError(
            "metrics.steady_end_speed_kmh",
            end_kmh,
            f"a speed in [0, {MAX_INITIAL_SPEED_KMH:g}] km/h (initial_speed_kmh's range)",
        )


#: the run's bounded numbers: key -> (largest value, what it is, its unit); each > 0
_RUN_BOUNDS: dict[str, tuple[float, str, str]] = {
    "torque_demand_nm": (MAX_TORQUE_DEMAND_NM, "a torque", "N m"),
    "initial_speed_kmh": (MAX_INITIAL_SPEED_KMH, "a speed", "km/h"),
    "duration_s": (MAX_DURATION_S, "a time", "s"),
}


def _check_run_number(key: str, value: object) -> float:
    """``value`` of the run's ``key`` in (0, its largest] (:data:`_RUN_BOUNDS`)."""
    top, what, unit = _RUN_BOUNDS[key]
    return check_number(
        key,
        value,
        positive=True,
        maximum=top,
        allowed=f"{what} in (0, {top:g}] {unit}",
        error=ScenarioError,
    )


def _check_dt(value: object, duration: float) -> float:
    """The step [s] of a run ``duration`` [s] long: at most 10 ms and the whole run, and
    at most :data:`~railpilot.eddy.simulate.MAX_STEPS` steps."""
    top = min(duration, MAX_DT_S)
    dt = check_number(
        "dt_s",
        value,
        positive=True,
        maximum=top,
        allowed=f"a step in (0, {top}] s",
        error=ScenarioError,
    )
    steps = duration / dt  # inf for a subnormal step
    if not (math.isfinite(steps) and round(steps) <= MAX_STEPS):
        raise ScenarioError(
            "dt_s",
            value,
            f"a step in [{duration / MAX_STEPS:g}, {top}] s: at most "
            f"{MAX_STEPS:,} steps of duration_s = {duration:g} s (simulate.py MAX_STEPS)",
        )
    return dt


def _check_record_every(value: object) -> int:
    return check_count("record_every", value, 1, allowed="an integer >= 1", error=ScenarioError)


#: the scenario's sections of numbers: their keys' defaults and their model
_NUMBER_SECTIONS: dict[str, tuple[dict[str, float], type[FileTable]]] = {
    "pid": (PID_DEFAULTS, PidTable),
    "fuzzy": (FUZZY_DEFAULTS, FuzzyTable),
    "fuzzy_pi": (FUZZY_PI_DEFAULTS, FuzzyPiTable),
    "table_grid": (TABLE_GRID_DEFAULTS, TableGridTable),
    "metrics": (METRICS_DEFAULTS, MetricsTable),
}


def _settings(table: FileTable, defaults: Mapping[str, float]) -> dict[str, float]:
    """The defaults, with the numbers the file gives (as floats) in their place."""
    out = dict(defaults)
    out.update({key: float(getattr(table, key)) for key in table.model_fields_set})
    return out


def _params(table: ConfigTable, cls: type[T]) -> T:
    """A brake's, coil's or train's parameters from its table (the dataclass's defaults
    for the keys it leaves out; the dataclass checks the values)."""
    try:
        return cls(**config_kwargs(table, cls, lambda *_: None))
    except ConfigError as exc:
        raise ScenarioError(exc.field, exc.value, exc.allowed) from None


@dataclass(frozen=True)
class EddyScenario:
    """A validated eddy-brake scenario (see the module docstring for the file layout)."""

    torque_demand_nm: float
    initial_speed_kmh: float
    name: str = "eddy-brake"
    duration_s: float = 100.0
    dt_s: float = 1e-4
    record_every: int = 10
    controller: str = "fuzzy_pi"
    pid: dict[str, float] = field(default_factory=lambda: dict(PID_DEFAULTS))
    fuzzy: dict[str, float] = field(default_factory=lambda: dict(FUZZY_DEFAULTS))
    fuzzy_pi: dict[str, float] = field(default_factory=lambda: dict(FUZZY_PI_DEFAULTS))
    brake: EddyBrakeParams = field(default_factory=EddyBrakeParams)
    coil: CoilParams = field(default_factory=CoilParams)
    train: TrainParams = field(default_factory=TrainParams)
    table_csv: Path | None = None
    table_grid: dict[str, float] = field(default_factory=lambda: dict(TABLE_GRID_DEFAULTS))
    metrics: dict[str, float] = field(default_factory=lambda: dict(METRICS_DEFAULTS))

    def __post_init__(self) -> None:
        # what from_mapping checks, for a scenario built directly
        _check_run_number("torque_demand_nm", self.torque_demand_nm)
        _check_run_number("initial_speed_kmh", self.initial_speed_kmh)
        _check_dt(self.dt_s, _check_run_number("duration_s", self.duration_s))
        _check_record_every(self.record_every)
        if not isinstance(self.name, str):
            raise ScenarioError("name", self.name, "a string")
        if not (isinstance(self.controller, str) and self.controller in CONTROLLERS):
            raise ScenarioError("controller", self.controller, "one of " + ", ".join(CONTROLLERS))
        for key, (defaults, model) in _NUMBER_SECTIONS.items():
            value = getattr(self, key)
            check(model, value, ScenarioError, at=(key,))  # known keys, each a number
            if set(value) != set(defaults):
                raise ScenarioError(key, value, "a table of " + ", ".join(sorted(defaults)))
        _check_metrics(self.metrics)
        for key, cls in (("brake", EddyBrakeParams), ("coil", CoilParams), ("train", TrainParams)):
            if not isinstance(getattr(self, key), cls):
                raise ScenarioError(key, getattr(self, key), f"a {cls.__name__}")
        csv = self.table_csv
        if csv is not None and not (isinstance(csv, os.PathLike) or (isinstance(csv, str) and csv)):
            raise ScenarioError("table_csv", csv, "a path, or None (the analytic model's grid)")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], base_dir: Path | None = None) -> EddyScenario:
        """Validate a mapping as parsed from TOML; ``base_dir`` resolves ``table.csv``."""
        top = check(EddyScenarioFile, data, ScenarioError, top="scenario")
        duration = float(top.duration_s)
        dt = _check_dt(float(top.dt_s), duration)
        table_csv = None
        if top.table.given("csv"):
            grid_keys = sorted(top.table.model_fields_set - {"csv"})
            if grid_keys:
                raise ScenarioError(
                    "table", grid_keys, "either csv or the model grid keys, not both"
                )
            table_csv = (base_dir / top.table.csv) if base_dir is not None else Path(top.table.csv)
        metrics = _settings(top.metrics, METRICS_DEFAULTS)
        _check_metrics(metrics)

        scenario = cls(
            torque_demand_nm=float(top.torque_demand_nm),
            initial_speed_kmh=float(top.initial_speed_kmh),
            name=top.name,
            duration_s=duration,
            dt_s=dt,
            record_every=top.record_every,
            controller=top.controller,
            pid=_settings(top.pid, PID_DEFAULTS),
            fuzzy=_settings(top.fuzzy, FUZZY_DEFAULTS),
            fuzzy_pi=_settings(top.fuzzy_pi, FUZZY_PI_DEFAULTS),
            brake=_params(top.brake, EddyBrakeParams),
            coil=_params(top.coil, CoilParams),
            train=_params(top.train, TrainParams),
            table_csv=table_csv,
            table_grid=_settings(top.table, TABLE_GRID_DEFAULTS)
            if table_csv is None
            else dict(TABLE_GRID_DEFAULTS),
            metrics=metrics,
        )
        table = scenario.build_table()
        for name in CONTROLLERS:  # every section is checked, not only the selected one
            try:
                scenario.make_controller(name, table)
            except ConfigError as exc:
                raise ScenarioError(exc.field, exc.value, exc.allowed) from None
            except ValueError as exc:
                raise ScenarioError(name, dict(getattr(scenario, name, {})), str(exc)) from None
        return scenario

    @property
    def initial_speed_mps(self) -> float:
        return float(kmh_to_mps(self.initial_speed_kmh))

    def build_table(self) -> TorqueTable:
        """The brake body: the user's CSV if given, else the analytic model's grid."""
        if self.table_csv is not None:
            return load_torque_table_csv(self.table_csv)
        return TorqueTable.from_model(self.brake, **self.table_grid)

    def make_controller(self, name: str, table: TorqueTable) -> Controller:
        """Build controller ``name`` with this scenario's settings."""
        if name == "open_loop":
            # the coil current that gives the demand at the initial speed
            return OpenLoop(
                min(
                    table.current_for_torque_a(self.torque_demand_nm, self.initial_speed_mps),
                    self.coil.current_limit_a,
                )
            )
        if name == "pid":
            p = self.pid
            return PID(p["kp"], p["ki"], p["kd"], derivative_filter_s=p["derivative_filter_s"])
        if name == "fuzzy":
            f = self.fuzzy
            return FuzzyController(
                f["e_scale"],
                f["ce_scale"],
                f["u_scale"],
                ce_filter_s=f["ce_filter_s"],
                n_grid=int(f["n_grid"]),
            )
        if name == "fuzzy_pi":
            q = self.fuzzy_pi
            return FuzzyPI(
                q["kp1"],
                q["ki1"],
                q["kp_span"],
                q["ki_span"],
                q["e_scale"],
                q["ce_scale"],
                ce_filter_s=q["ce_filter_s"],
                n_grid=int(q["n_grid"]),
            )
        raise ScenarioError("controller", name, "one of " + ", ".join(CONTROLLERS))

    def holdable_down_to_kmh(self, table: TorqueTable) -> float:
        """Lowest speed [km/h] at which the current limit still gives the demand."""
        speeds = np.linspace(0.0, self.initial_speed_mps, 2001)
        ok = np.array(
            [table.torque(self.coil.current_limit_a, s) >= self.torque_demand_nm for s in speeds]
        )
        return float(mps_to_kmh(speeds[np.argmax(ok)])) if ok.any() else math.nan

    def run(
        self, controller: str | None = None, *, record_every: int | None = None
    ) -> tuple[EddyResult, StepMetrics]:
        """Simulate with ``controller`` (default: the scenario's) and compute the metrics.

        The metrics always see every step (the chopper ripple and the peak live between
        recorded samples otherwise); ``record_every`` (default: the scenario's) only thins
        the returned series, for storage and plots.
        The steady window ends at ``metrics.steady_end_speed_kmh`` or 10 km/h above the
        speed where the current limit makes the demand unreachable, whichever is higher.
        """
        stride = self.record_every if record_every is None else int(record_every)
        if stride < 1:
            raise ScenarioError("record_every", record_every, "an integer >= 1")
        table = self.build_table()
        ctrl = self.make_controller(controller or self.controller, table)
        result = simulate_eddy(
            ctrl,
            table=table,
            torque_demand_nm=self.torque_demand_nm,
            initial_speed_mps=self.initial_speed_mps,
            coil=self.coil,
            train=self.train,
            duration_s=self.duration_s,
            dt_s=self.dt_s,
            record_every=1,
        )
        limit_kmh = self.holdable_down_to_kmh(table)
        end_kmh = self.metrics["steady_end_speed_kmh"]
        if math.isfinite(limit_kmh):
            end_kmh = max(end_kmh, limit_kmh + 10.0)
        metrics = step_metrics(
            result.time_s,
            result.torque_nm,
            result.speed_kmh,
            self.torque_demand_nm,
            settling_band=self.metrics["settling_band"],
            hold_band=self.metrics["hold_band"],
            steady_start_s=self.metrics["steady_start_s"],
            steady_end_speed_kmh=end_kmh,
        )
        result.metadata["scenario"] = self.name
        result.metadata["holdable_down_to_kmh"] = limit_kmh
        return (result.every(stride) if stride > 1 else result), metrics
