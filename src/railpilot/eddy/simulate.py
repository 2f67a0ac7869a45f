"""The eddy-brake torque-control loop of paper 003 (fig. 3 and 5), compiled with Numba.

Per fixed step ``dt`` (paper: 1e-4 s), in this order:

1. brake body: ``M = table(I, v)`` (bilinear lookup, :mod:`railpilot.eddy.table`);
2. torque controller: ``u = controller(M_demand, M, dt)``, the reference-current change
   rate [A/s] (PID, fuzzy or fuzzy adaptive PI -- their own Numba kernels); the open
   loop's command is the reference level [A] itself;
3. current reference ``I_ref <- clip(I_ref + u dt, I - lead, I + lead, 0, I_max)``
   (:func:`railpilot.eddy.coil.reference_step`);
4. hysteresis current controller -> chopper switch command (band +-0.1 A);
5. chopper + coil: exact R-L update over the step (free-wheel when the switch is open);
6. train: explicit Euler step of eq. 29 with the torque of step 1.

The recorded series hold the values at the start of every ``record_every``-th step
(``t = k dt``; default every 10th step = 1 ms, so 100 s give 10,001 rows per column).
Use ``record_every=1`` for metrics that must see every chopper ripple
(:mod:`railpilot.eddy.metrics` runs on whatever it is given).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from railpilot.control.base import Controller
from railpilot.control.fuzzy import FuzzyController, FuzzyPI, fuzzy_pi_step, fuzzy_step
from railpilot.control.open_loop import OpenLoop, open_loop_step
from railpilot.control.pid import PID, pid_step
from railpilot.eddy.coil import (
    C_BAND,
    C_IMAX,
    C_LEAD,
    CoilParams,
    coil_decay,
    coil_step,
    hysteresis_step,
    reference_step,
)
from railpilot.eddy.table import TorqueTable, table_torque_nm
from railpilot.eddy.train import TrainParams, train_step
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.sim.result import SimResult
from railpilot.units import mps_to_kmh

KIND_OPEN_LOOP, KIND_PID, KIND_FUZZY, KIND_FUZZY_PI = range(4)

#: Most steps one run may take (``duration_s / dt_s``): the longest scenario run (an
#: hour, eddy/scenario.py ``MAX_DURATION_S``) at the paper's 1e-4 s step, 36 times the
#: paper's (and the examples') 100 s runs of 1e6 steps. A scenario run keeps every step
#: for the metrics (8 channels; about 100 bytes and 1.5 us a step measured): about 3.6 GB
#: and a minute at the limit. A finer step is allowed for a shorter run; without a bound
#: ``dt_s = 1e-12`` asked for 1e14 steps (memory error) and 5e-324 for infinitely many.
MAX_STEPS = 36_000_000

#: Controller classes the compiled loop can run, and their kernel codes.
CONTROLLER_KINDS: dict[type[Controller], int] = {
    OpenLoop: KIND_OPEN_LOOP,
    PID: KIND_PID,
    FuzzyController: KIND_FUZZY,
    FuzzyPI: KIND_FUZZY_PI,
}


@njit(cache=True)
def _control(
    kind: int, cparams: np.ndarray, cstate: np.ndarray, sp: float, meas: float, dt: float
) -> float:
    if kind == KIND_PID:
        return pid_step(cparams, cstate, sp, meas, dt)
    if kind == KIND_FUZZY:
        return fuzzy_step(cparams, cstate, sp, meas, dt)
    if kind == KIND_FUZZY_PI:
        return fuzzy_pi_step(cparams, cstate, sp, meas, dt)
    return open_loop_step(cparams, cstate, sp, meas, dt)


@njit(cache=True)
def _loop(
    kind: int,
    cparams: np.ndarray,
    cstate: np.ndarray,
    currents_a: np.ndarray,
    speeds_mps: np.ndarray,
    torque_nm: np.ndarray,
    coil: np.ndarray,
    decay: float,
    train: np.ndarray,
    demand_nm: float,
    speed0_mps: float,
    current0_a: float,
    dt: float,
    n_steps: int,
    record_every: int,
    out: np.ndarray,
) -> None:
    """Run ``n_steps`` steps; ``out`` rows: t, v, x, I, I_ref, M, switch, u."""
    v = speed0_mps
    x = 0.0
    i = current0_a
    i_ref = current0_a
    on = False
    limit = coil[C_IMAX]
    band = coil[C_BAND]
    lead = coil[C_LEAD]
    r = 0
    for k in range(n_steps + 1):
        m = table_torque_nm(currents_a, speeds_mps, torque_nm, i, v)
        if k == n_steps:
            u = 0.0
        else:
            u = _control(kind, cparams, cstate, demand_nm, m, dt)
            if kind == KIND_OPEN_LOOP:
                # the open loop commands the reference level itself (no integration)
                i_ref = min(max(u, 0.0), limit)
            else:
                i_ref = reference_step(i_ref, u, i, lead, limit, dt)
            on = hysteresis_step(i_ref, i, on, band, limit)
        if k % record_every == 0:
            out[0, r] = k * dt
            out[1, r] = v
            out[2, r] = x
            out[3, r] = i
            out[4, r] = i_ref
            out[5, r] = m
            out[6, r] = 1.0 if on else 0.0
            out[7, r] = u
            r += 1
        if k == n_steps:
            break
        i = coil_step(i, on, coil, decay)
        v_next = train_step(v, m, train, dt)
        x += 0.5 * (v + v_next) * dt
        v = v_next


@dataclass
class EddyResult:
    """One eddy-brake run: columnar time series (NumPy arrays) plus metadata.

    Every array has one entry per recorded step (see ``metadata["record_every"]``).
    """

    time_s: np.ndarray
    speed_mps: np.ndarray
    distance_m: np.ndarray
    current_a: np.ndarray
    current_ref_a: np.ndarray
    torque_nm: np.ndarray
    switch_on: np.ndarray
    command: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def speed_kmh(self) -> np.ndarray:
        return mps_to_kmh(self.speed_mps)

    @property
    def columns(self) -> dict[str, np.ndarray]:
        return {
            "time_s": self.time_s,
            "speed_mps": self.speed_mps,
            "distance_m": self.distance_m,
            "current_a": self.current_a,
            "current_ref_a": self.current_ref_a,
            "torque_nm": self.torque_nm,
            "switch_on": self.switch_on,
            "command": self.command,
        }

    def as_result(self, metrics: Mapping[str, float] | None = None) -> SimResult:
        """The same kind of result as the stopping simulator's (railpilot.sim.result)."""
        return SimResult(
            series=dict(self.columns), metrics=dict(metrics or {}), meta=dict(self.metadata)
        )

    def to_csv(self, path: Path) -> Path:
        """Write the time series as CSV (header = channel names), as :class:`SimResult`."""
        return self.as_result().to_csv(path)

    def to_parquet(self, path: Path) -> Path:
        """Write the time series as Parquet, as :class:`SimResult`."""
        return self.as_result().to_parquet(path)

    def to_pandas(self) -> Any:
        """The series as a ``pandas.DataFrame`` indexed by time (pandas imported lazily)."""
        import pandas as pd

        cols = self.columns
        return pd.DataFrame({k: v for k, v in cols.items() if k != "time_s"}, index=cols["time_s"])

    def every(self, stride: int) -> EddyResult:
        """A thinned copy keeping every ``stride``-th row (for plots and storage)."""
        cols = {k: v[::stride].copy() for k, v in self.columns.items()}
        meta = dict(self.metadata)
        meta["record_every"] = int(meta.get("record_every", 1)) * stride
        return EddyResult(**cols, metadata=meta)


def controller_kind(controller: Controller) -> int:
    """Kernel code of ``controller`` for the compiled loop; ConfigError if unsupported."""
    for cls, kind in CONTROLLER_KINDS.items():
        if type(controller) is cls:
            return kind
    raise ConfigError(
        "controller",
        type(controller).__name__,
        "one of " + ", ".join(c.__name__ for c in CONTROLLER_KINDS),
    )


def simulate_eddy(
    controller: Controller,
    *,
    table: TorqueTable,
    torque_demand_nm: float,
    initial_speed_mps: float,
    coil: CoilParams | None = None,
    train: TrainParams | None = None,
    duration_s: float = 100.0,
    dt_s: float = 1e-4,
    record_every: int = 10,
    initial_current_a: float = 0.0,
) -> EddyResult:
    """Simulate constant-torque braking with ``controller`` (reset first, then mutated).

    Parameters
    ----------
    controller
        :class:`OpenLoop`, :class:`PID`, :class:`FuzzyController` or :class:`FuzzyPI`;
        its output is the reference-current change rate [A/s].
    table
        Brake body ``M(I, v)``.
    torque_demand_nm
        Demanded braking torque [N m], applied as a step at ``t = 0``.
    initial_speed_mps
        Train speed at ``t = 0`` [m/s].
    coil, train
        Coil/chopper and train parameters (defaults: the documented set).
    duration_s, dt_s
        Simulated time and fixed step [s] (paper: 100 s, 1e-4 s).
    record_every
        Keep every ``record_every``-th step in the result.
    initial_current_a
        Coil current (and its reference) at ``t = 0`` [A].
    """
    coil = CoilParams() if coil is None else coil
    train = TrainParams() if train is None else train
    kind = controller_kind(controller)
    checks = (
        ("duration_s", duration_s, duration_s > 0),
        ("dt_s", dt_s, 0 < dt_s <= duration_s),
        ("torque_demand_nm", torque_demand_nm, torque_demand_nm >= 0),
        ("initial_speed_mps", initial_speed_mps, initial_speed_mps >= 0),
        ("initial_current_a", initial_current_a, 0 <= initial_current_a <= coil.current_limit_a),
    )
    for name, value, ok in checks:
        if not (np.isfinite(value) and ok):
            raise ConfigError(name, value, "a finite number in range (see simulate_eddy docs)")
    steps = duration_s / dt_s
    if not (np.isfinite(steps) and round(steps) <= MAX_STEPS):
        raise ConfigError(
            "dt_s", dt_s, f"a step >= duration_s / {MAX_STEPS:,} = {duration_s / MAX_STEPS:g} s"
        )
    if int(record_every) < 1:
        raise ConfigError("record_every", record_every, "an integer >= 1")
    n_steps = round(steps)
    record_every = int(record_every)
    n_rec = n_steps // record_every + 1
    out = np.empty((8, n_rec))
    controller.reset()
    t0 = time.perf_counter()
    _loop(
        kind,
        controller.params,
        controller.state,
        table.currents_a,
        table.speeds_mps,
        table.torque_nm,
        coil.packed(),
        coil_decay(coil, dt_s),
        train.packed(),
        float(torque_demand_nm),
        float(initial_speed_mps),
        float(initial_current_a),
        float(dt_s),
        n_steps,
        record_every,
        out,
    )
    wall = time.perf_counter() - t0
    meta: dict[str, Any] = {
        "controller": controller.name,
        "torque_demand_nm": float(torque_demand_nm),
        "initial_speed_mps": float(initial_speed_mps),
        "duration_s": float(duration_s),
        "dt_s": float(dt_s),
        "n_steps": n_steps,
        "record_every": record_every,
        "wall_time_s": wall,
        "coil": coil.to_dict(),
        "train": train.to_dict(),
        "table_source": table.source,
    }
    return EddyResult(
        time_s=out[0],
        speed_mps=out[1],
        distance_m=out[2],
        current_a=out[3],
        current_ref_a=out[4],
        torque_nm=out[5],
        switch_on=out[6],
        command=out[7],
        metadata=meta,
    )


def warm_up() -> float:
    """Compile (or load from cache) the loop and every kernel; returns the seconds it took."""
    t0 = time.perf_counter()
    table = TorqueTable.from_model(max_current_a=50.0, current_step_a=25.0, speed_step_kmh=100.0)
    for ctrl in (
        OpenLoop(1.0),
        PID(1.0),
        FuzzyController(1.0, 1.0, 1.0, n_grid=5),
        FuzzyPI(1.0, 0.0, 1.0, 0.0, 1.0, 1.0, n_grid=5),
    ):
        simulate_eddy(
            ctrl, table=table, torque_demand_nm=1.0, initial_speed_mps=10.0, duration_s=1e-3
        )
    return time.perf_counter() - t0
