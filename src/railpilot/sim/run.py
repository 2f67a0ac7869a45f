"""Public entry point: run a scenario, get a :class:`~railpilot.sim.result.SimResult`."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np

from railpilot.brakes.ep_blend import N_STATE as N_BRAKE_STATE
from railpilot.control.base import Controller
from railpilot.control.pid import TrackingPID
from railpilot.control.smarc import SMARC
from railpilot.control.tuning import simc_pid_integrating, smarc_from_simc
from railpilot.errors import ConfigError
from railpilot.scenario.model import Scenario
from railpilot.sim import engine
from railpilot.sim.result import CHANNELS, SimResult
from railpilot.units import kmh_to_mps


def default_controller_params(scenario: Scenario, name: str) -> dict[str, Any]:
    """Controller parameters by the documented tuning rule for this scenario's brake.

    The ATO's model of the brake (``ato.lead_s`` split as in the plant, else the
    true delay and air lag) goes into SIMC (control/tuning.py); both controllers
    get the same loop bandwidth.
    """
    delay, lag = _ato_brake_model(scenario)
    # tau_c and the remaining free parameters come from the grid search that
    # docs/paper-000-smarc-ep.md describes (same grid effort for both controllers)
    if name == "pid":
        return dict(
            simc_pid_integrating(1.0, delay, lag, tau_c_s=0.75 * delay),
            anti_windup="backcalc",
            position_gain=0.8,
        )
    if name == "smarc":
        return dict(
            smarc_from_simc(1.0, delay, lag, tau_c_s=0.25 * (delay + lag)),
            alpha=1.0,
            eta=0.1,
            phi=0.05,
            gamma=(0.05, 0.2),
            theta_bounds=((0.7, 1.5), (-0.3, 0.3)),
        )
    raise ConfigError("controller.name", name, "one of pid, smarc")


def _ato_brake_model(scenario: Scenario) -> tuple[float, float]:
    brake = scenario.brake
    if scenario.ato.lead_s is None:
        return brake.delay_s, brake.air_lag_s
    # the ATO knows only the total lead; split it in the plant's proportion
    total = brake.delay_s + brake.air_lag_s
    share = brake.delay_s / total if total > 0 else 0.5
    return scenario.ato.lead_s * share, scenario.ato.lead_s * (1 - share)


def make_controller(scenario: Scenario, name: str | None = None) -> Controller:
    """Build the scenario's controller (or ``name``) with tuned defaults + overrides."""
    name = name or scenario.controller.name
    params = default_controller_params(scenario, name)
    overrides = scenario.controller.params.get(name, {})
    cls = TrackingPID if name == "pid" else SMARC
    allowed = _parameter_names(cls)
    for key, value in overrides.items():
        if key not in allowed:
            raise ConfigError(
                f"controller.{name}.{key}",
                value,
                f"a parameter of {cls.__name__}: {', '.join(allowed)}",
            )
    params.update(overrides)
    a_max = scenario.train.max_service_decel_mps2
    try:
        if name == "pid":
            params.setdefault("output_limits", (-a_max, a_max))
            return TrackingPID(**params)
        params.setdefault("output_limits", (-a_max, a_max))
        return SMARC(**params)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"controller.{name}", overrides, f"valid parameters ({exc})") from exc


def _parameter_names(cls: type) -> list[str]:
    """Keyword parameters a controller class takes, following ``**kwargs`` to its base."""
    names: list[str] = []
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        params = inspect.signature(init).parameters.values()
        names += [
            p.name
            for p in params
            if p.name != "self"
            and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)
            and p.name not in names
        ]
        if not any(p.kind == p.VAR_KEYWORD for p in params):
            break
    return names


@dataclass
class KernelInputs:
    """Everything :func:`engine.run_ep_kernel` takes except the per-run state."""

    n_steps: int
    dt: float
    control_every: int
    train: np.ndarray
    brake_p: np.ndarray
    line_edges: np.ndarray
    line_values: np.ndarray
    dist_const: float
    reg_start: np.ndarray
    reg_end: np.ndarray
    reg_force: np.ndarray
    random_n: np.ndarray
    ref_x: np.ndarray
    ref_v: np.ndarray
    ref_a: np.ndarray
    ref_a_ff: np.ndarray
    ato: np.ndarray
    kind: int
    ctrl_p: np.ndarray
    ctrl_s0: np.ndarray


def prepare(scenario: Scenario, controller: Controller) -> KernelInputs:
    """Pack a scenario and a controller into the kernel's flat arrays."""
    sim = scenario.sim
    train = scenario.train
    dt = sim.dt_s
    n = sim.n_steps
    ref = scenario.reference
    t = np.arange(n + 1) * dt
    ref_x, ref_v, ref_a = ref.sample(t)
    delay, lag = _ato_brake_model(scenario)
    _, _, ref_a_ff = ref.sample(t + delay + lag)
    ato = scenario.ato
    mass_lw = ato.mass_kg if ato.mass_kg is not None else train.mass_kg
    davis = ato.davis if ato.davis is not None else (train.davis_a0, train.davis_a1, train.davis_a2)
    ato_arr = np.zeros(engine.N_ATO)
    ato_arr[engine.A_MEFF_LW] = mass_lw * (1 + train.rotating_mass_factor)
    ato_arr[engine.A_A0], ato_arr[engine.A_A1], ato_arr[engine.A_A2] = davis
    ato_arr[engine.A_MASS] = mass_lw
    ato_arr[engine.A_UMIN] = -train.max_service_decel_mps2
    ato_arr[engine.A_UMAX] = 0.0
    ato_arr[engine.A_STOP_M] = ref.stop_m
    ato_arr[engine.A_V_CO] = kmh_to_mps(scenario.brake.changeover_kmh)
    train_arr = np.array(
        [
            train.effective_mass_kg,
            train.mass_kg,
            train.davis_a0,
            train.davis_a1,
            train.davis_a2,
            ref.start_m,
            ref.v0_mps,
        ]
    )
    brake_p = scenario.brake.pack(
        dt,
        ato_arr[engine.A_MEFF_LW],
        train.electric_brake.max_force_n,
        train.electric_brake.max_power_w,
        train.motor_cars,
    )
    edges, values = scenario.line.resistance_profile()
    reg_start, reg_end, reg_force = scenario.disturbance.region_arrays()
    if isinstance(controller, TrackingPID):
        kind = engine.KIND_PID
    elif isinstance(controller, SMARC):
        kind = engine.KIND_SMARC
    else:
        raise ConfigError(
            "controller", type(controller).__name__, "a TrackingPID or SMARC controller"
        )
    controller.reset()
    return KernelInputs(
        n_steps=n,
        dt=dt,
        control_every=sim.control_every,
        train=train_arr,
        brake_p=brake_p,
        line_edges=edges,
        line_values=values,
        dist_const=scenario.disturbance.constant_n,
        reg_start=reg_start,
        reg_end=reg_end,
        reg_force=reg_force,
        random_n=scenario.disturbance.random_series(n, dt),
        ref_x=ref_x,
        ref_v=ref_v,
        ref_a=ref_a,
        ref_a_ff=ref_a_ff,
        ato=ato_arr,
        kind=kind,
        ctrl_p=controller.params.copy(),
        ctrl_s0=controller.state.copy(),
    )


def run_inputs(inp: KernelInputs, record_every: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Run packed inputs once; return ``(metrics, record)`` (record empty if 0)."""
    brake_s = np.zeros(N_BRAKE_STATE)
    brake_buf = np.zeros(int(inp.brake_p[-1]))
    n_rec = (inp.n_steps + record_every - 1) // record_every if record_every > 0 else 0
    record = np.zeros((n_rec, engine.N_CHANNELS))
    metrics = np.zeros(engine.N_METRICS)
    engine.run_ep_kernel(
        inp.n_steps,
        inp.dt,
        inp.control_every,
        inp.train,
        inp.brake_p,
        brake_s,
        brake_buf,
        inp.line_edges,
        inp.line_values,
        inp.dist_const,
        inp.reg_start,
        inp.reg_end,
        inp.reg_force,
        inp.random_n,
        inp.ref_x,
        inp.ref_v,
        inp.ref_a,
        inp.ref_a_ff,
        inp.ato,
        inp.kind,
        inp.ctrl_p,
        inp.ctrl_s0.copy(),
        np.zeros(0),
        record,
        max(record_every, 1),
        metrics,
    )
    return metrics, record


def metrics_dict(metrics: np.ndarray) -> dict[str, float]:
    """Name the kernel's metrics array (see railpilot.sim.result.METRICS)."""
    return {
        "stop_error_m": float(metrics[engine.M_STOP_ERR]),
        "stop_time_s": float(metrics[engine.M_STOP_T]),
        "max_speed_error_mps": float(metrics[engine.M_MAX_VERR]),
        "rms_speed_error_mps": float(metrics[engine.M_RMS_VERR]),
        "speed_error_at_changeover_mps": float(metrics[engine.M_VERR_CO]),
        "max_decel_mps2": float(metrics[engine.M_MAX_DECEL]),
        "max_jerk_mps3": float(metrics[engine.M_MAX_JERK]),
        "max_position_error_m": float(metrics[engine.M_MAX_XERR]),
        "energy_electric_j": float(metrics[engine.M_E_ELEC]),
        "energy_friction_j": float(metrics[engine.M_E_FRIC]),
    }


def simulate(scenario: Scenario, controller: Controller | str | None = None) -> SimResult:
    """Run ``scenario`` with its controller (or the one given) and record everything."""
    ctrl = (
        controller if isinstance(controller, Controller) else make_controller(scenario, controller)
    )
    inp = prepare(scenario, ctrl)
    metrics, record = run_inputs(inp, record_every=scenario.sim.record_every)
    series = {name: record[:, i].copy() for i, (name, _) in enumerate(CHANNELS)}
    meta = {
        "scenario": scenario.name,
        "controller": ctrl.name,
        "stop_point_m": scenario.reference.stop_m,
        "dt_s": scenario.sim.dt_s,
        "stopped": bool(metrics[engine.M_STOPPED]),
    }
    return SimResult(series=series, metrics=metrics_dict(metrics), meta=meta)
