"""Public entry point: run a scenario, get a :class:`~railpilot.sim.result.SimResult`.

:func:`prepare` packs a scenario and a controller into the kernel's flat arrays
(:class:`KernelInputs`), :func:`run_inputs` runs them once, :func:`simulate` does both
and names the results. railpilot.sim.batch reuses ``prepare`` for Monte Carlo runs.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

import numpy as np

from railpilot.brakes.ep_blend import EPBrake
from railpilot.control.base import Controller
from railpilot.control.pid import TrackingPID
from railpilot.control.qsmc import QSMC
from railpilot.control.smarc import SMARC
from railpilot.control.tuning import (
    qsmc_defaults,
    simc_pid_integrating,
    smarc_from_simc,
    tracking_position_gain,
)
from railpilot.errors import ConfigError
from railpilot.scenario.model import CONTROLLERS, Scenario
from railpilot.sim import engine
from railpilot.sim.reference import BrakingCurve
from railpilot.sim.result import CHANNELS, SimResult
from railpilot.units import kmh_to_mps

CONTROLLER_CLASSES: dict[str, type[Controller]] = {
    "pid": TrackingPID,
    "smarc": SMARC,
    "qsmc": QSMC,
}
KINDS = {"pid": engine.KIND_PID, "smarc": engine.KIND_SMARC, "qsmc": engine.KIND_QSMC}


def default_controller_params(scenario: Scenario, name: str) -> dict[str, Any]:
    """Controller parameters by the documented tuning rule for this scenario's brake.

    The ATO's model of the brake (``ato.brake_delay_s`` and ``ato.brake_lag_s``, else
    the true delay and lag) goes into the tuning rules of control/tuning.py.
    """
    delay, lag = tuning_model(scenario)
    # tau_c and the remaining free parameters: the winners of the grid search in
    # railpilot/reproduce/tune_smarc_ep.py (same method and objective for both)
    if name == "pid":
        tau_c = 1.0 * delay
        return dict(
            simc_pid_integrating(1.0, delay, lag, tau_c_s=tau_c),
            anti_windup="backcalc",
            position_gain=tracking_position_gain(delay, lag, tau_c, factor=0.75),
        )
    if name == "smarc":
        return dict(
            smarc_from_simc(1.0, delay, lag, tau_c_s=0.5 * (delay + lag)),
            alpha=1.0,
            eta=0.1,
            phi=0.05,
            gamma=(0.05, 0.05),
            theta_bounds=((0.7, 1.5), (-0.3, 0.3)),
        )
    if name == "qsmc":
        return qsmc_defaults(delay, lag, scenario.sim.control_period_s)
    raise ConfigError("controller.name", name, f"one of {', '.join(CONTROLLERS)}")


def ato_brake_model(scenario: Scenario) -> tuple[float, float]:
    """The ATO's model of the brake's ``(delay, lag)`` [s].

    ``ato.brake_delay_s`` and ``ato.brake_lag_s``; each one not given is the plant's.
    """
    delay, lag = scenario.brake_lead_s
    ato = scenario.ato
    return (
        delay if ato.brake_delay_s is None else ato.brake_delay_s,
        lag if ato.brake_lag_s is None else ato.brake_lag_s,
    )


def tuning_model(scenario: Scenario) -> tuple[float, float]:
    """The ``(theta, T)`` the tuning rules get: the ATO's brake model plus sampling.

    A controller that updates every ``control_period_s`` adds half a period of
    effective delay (Skogestad 2003, section 3.2: the zero-order hold), so the rules see
    ``theta = brake delay + period / 2``; that also keeps ``theta > 0``, which SIMC needs.
    """
    delay, lag = ato_brake_model(scenario)
    return delay + scenario.sim.control_period_s / 2.0, lag


def _constructor_parameters(cls: type) -> dict[str, inspect.Parameter]:
    """Keyword parameters a controller class takes, following ``**kwargs`` to its base."""
    found: dict[str, inspect.Parameter] = {}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None or klass is object:  # object's slot wrapper has no Python signature
            continue
        params = inspect.signature(init).parameters.values()
        for p in params:
            if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
                found.setdefault(p.name, p)
        if not any(p.kind == p.VAR_KEYWORD for p in params):
            break
    return found


def make_controller(scenario: Scenario, name: str | None = None) -> Controller:
    """Build the scenario's controller (or ``name``) with tuned defaults + overrides."""
    name = name or scenario.controller.name
    if name not in CONTROLLER_CLASSES:
        raise ConfigError("controller.name", name, f"one of {', '.join(CONTROLLERS)}")
    params = default_controller_params(scenario, name)
    overrides = scenario.controller.params.get(name, {})
    cls = CONTROLLER_CLASSES[name]
    accepted = _constructor_parameters(cls)
    allowed = list(accepted)
    for key, value in overrides.items():
        if key not in allowed:
            raise ConfigError(
                f"controller.{name}.{key}",
                value,
                f"a parameter of {cls.__name__}: {', '.join(allowed)}",
            )
    # each value must have the shape of the parameter's default, before any arithmetic
    a_max = scenario.train.max_service_decel_mps2
    params.setdefault("output_limits", (-a_max, a_max))
    defaults = {k: None if p.default is p.empty else p.default for k, p in accepted.items()}
    defaults.update(params)
    for key, value in overrides.items():
        if not _same_shape(value, defaults.get(key)):
            raise ConfigError(f"controller.{name}.{key}", value, _describe_shape(defaults.get(key)))
    params.update(overrides)
    try:
        return cls(**params)
    except (TypeError, ValueError, IndexError) as exc:
        # the constructors' messages start with the parameter's name: point at its key
        message = str(exc)
        key = message.split(" = ", 1)[0]
        if key in overrides and ": expected " in message:
            raise ConfigError(
                f"controller.{name}.{key}", overrides[key], message.split(": expected ", 1)[1]
            ) from exc
        raise ConfigError(f"controller.{name}", overrides, f"valid parameters ({message})") from exc


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _same_shape(value: Any, reference: Any) -> bool:
    """Does a user's value have the shape of the parameter's default (number, text, pair)?"""
    if reference is None:
        return value is None or _is_number(value)
    if isinstance(reference, bool):
        return isinstance(value, bool)
    if _is_number(reference):
        return _is_number(value)
    if isinstance(reference, str):
        return isinstance(value, str)
    if isinstance(reference, tuple | list):
        return (
            isinstance(value, tuple | list)
            and len(value) == len(reference)
            and all(_same_shape(v, r) for v, r in zip(value, reference, strict=True))
        )
    return True  # a kind of default we do not know: the constructor judges


def _describe_shape(reference: Any) -> str:
    if reference is None or _is_number(reference):
        return "a number"
    if isinstance(reference, bool):
        return "true or false"
    if isinstance(reference, str):
        return "a string"
    if isinstance(reference, tuple | list):
        return f"a list of {len(reference)}: [{', '.join(_describe_shape(r) for r in reference)}]"
    return "a valid value"


@dataclass
class KernelInputs:
    """Everything :func:`engine.run_kernel` takes (see its docstring)."""

    n_steps: int
    dt: float
    control_every: int
    train: np.ndarray
    act_kind: int
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
    dist_ref: np.ndarray
    ato: np.ndarray
    kind: int
    ctrl_p: np.ndarray
    ctrl_s0: np.ndarray
    real: np.ndarray
    speed_noise: np.ndarray
    balises: np.ndarray


def feed_forward_acceleration(ref: BrakingCurve, t: np.ndarray, lead_s: float) -> np.ndarray:
    """Reference acceleration [m/s^2] to command at ``t`` for a brake ``lead_s`` slow.

    ``a_ref(t + lead)``, except over the last ``lead`` before the stop: there the
    reference is at rest at ``t + lead`` only because the train will have stopped, not
    because the brake is to be released, so the deceleration the curve stops with is
    held (a train stops on its brakes).
    """
    _, _, a_ahead = ref.sample(t + lead_s)
    end = ref.duration_s
    _, _, (a_final,) = ref.sample(np.array([end - 1e-9]))
    holding = (t < end) & (t + lead_s >= end)
    return np.where(holding, np.minimum(a_ahead, a_final), a_ahead)


def distance_table(ref: BrakingCurve, dt: float, lead_s: float) -> np.ndarray:
    """The braking curve by position: ``[x, v(x), fed-forward a(x)]`` rows, x increasing.

    For a distance-based reference the ATO looks these up at the measured position.
    Sampled at the simulation step over the curve's moving part; the fed-forward
    acceleration at a position is the one the time-based ATO would command when the
    reference passes it (``feed_forward_acceleration``), and beyond the stop point the
    last row holds (at rest, braking with the final deceleration).
    """
    t = np.arange(0.0, ref.duration_s + dt, dt)
    x, v, _ = ref.sample(t)
    a_ff = feed_forward_acceleration(ref, t, lead_s)
    keep = np.concatenate(([True], np.diff(x) > 0))  # interp needs increasing positions
    return np.vstack([x[keep], v[keep], a_ff[keep]])


def pack_brake(scenario: Scenario, load_weighed_eff_mass_kg: float) -> tuple[int, np.ndarray]:
    """``(actuator kind, params)`` of the scenario's brake for step ``sim.dt_s``."""
    brake = scenario.brake
    if isinstance(brake, EPBrake):
        eb = scenario.train.electric_brake
        return engine.ACT_EP, brake.pack(
            scenario.sim.dt_s,
            load_weighed_eff_mass_kg,
            eb.max_force_n,
            eb.max_power_w,
            scenario.train.motor_cars,
        )
    return engine.ACT_LAG_DELAY, brake.pack(scenario.sim.dt_s)


def prepare(
    scenario: Scenario, controller: Controller, reference: KernelInputs | None = None
) -> KernelInputs:
    """Pack a scenario and a controller into the kernel's flat arrays.

    ``reference``: inputs of a scenario with the same reference, sim settings and ATO
    model, whose sampled reference arrays are reused (a Monte Carlo's runs).
    """
    sim = scenario.sim
    train = scenario.train
    dt = sim.dt_s
    n = sim.n_steps
    ref = scenario.reference
    if reference is not None:
        ref_x, ref_v, ref_a, ref_a_ff, dist_ref = (
            reference.ref_x,
            reference.ref_v,
            reference.ref_a,
            reference.ref_a_ff,
            reference.dist_ref,
        )
    else:
        t = np.arange(n + 1) * dt
        ref_x, ref_v, ref_a = ref.sample(t)
        delay, lag = ato_brake_model(scenario)
        ref_a_ff = feed_forward_acceleration(ref, t, delay + lag)
        dist_ref = (
            distance_table(ref, dt, delay + lag)
            if scenario.ato.reference == "distance"
            else np.zeros((3, 0))
        )
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
    ato_arr[engine.A_V_CO] = kmh_to_mps(scenario.changeover_kmh)
    train_arr = np.array(
        [
            train.effective_mass_kg,
            train.mass_kg,
            train.davis_a0,
            train.davis_a1,
            train.davis_a2,
            ref.start_m,
            ref.v0_mps if scenario.initial_speed_mps is None else scenario.initial_speed_mps,
            scenario.brake_gain,
        ]
    )
    act_kind, brake_p = pack_brake(scenario, ato_arr[engine.A_MEFF_LW])
    edges, values = scenario.line.resistance_profile()
    reg_start, reg_end, reg_force = scenario.disturbance.region_arrays()
    kind = KINDS.get(getattr(controller, "name", ""), -1)
    if kind < 0 or not isinstance(controller, tuple(CONTROLLER_CLASSES.values())):
        raise ConfigError(
            "controller", type(controller).__name__, "a TrackingPID, SMARC or QSMC controller"
        )
    controller.reset()
    realism = scenario.realism
    n_updates = (n + sim.control_every - 1) // sim.control_every
    return KernelInputs(
        n_steps=n,
        dt=dt,
        control_every=sim.control_every,
        train=train_arr,
        act_kind=act_kind,
        brake_p=brake_p,
        line_edges=edges,
        line_values=values,
        dist_const=scenario.disturbance.constant_n,
        reg_start=reg_start,
        reg_end=reg_end,
        reg_force=reg_force,
        random_n=scenario.disturbance.random_series(n, dt, ref_a, train.effective_mass_kg),
        ref_x=ref_x,
        ref_v=ref_v,
        ref_a=ref_a,
        ref_a_ff=ref_a_ff,
        dist_ref=dist_ref,
        ato=ato_arr,
        kind=kind,
        ctrl_p=controller.params.copy(),
        ctrl_s0=controller.state.copy(),
        real=realism.pack(),
        speed_noise=realism.speed_noise(n_updates),  # seeded by realism
        balises=realism.balises(),
    )


def run_inputs(inp: KernelInputs, record_every: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Run packed inputs once; return ``(metrics, record)`` (record empty if 0)."""
    n_rec = (inp.n_steps + record_every - 1) // record_every if record_every > 0 else 0
    record = np.zeros((n_rec, engine.N_CHANNELS))
    metrics = np.zeros(engine.N_METRICS)
    engine.run_kernel(
        inp.n_steps,
        inp.dt,
        inp.control_every,
        inp.train,
        inp.act_kind,
        inp.brake_p,
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
        inp.dist_ref,
        inp.ato,
        inp.kind,
        inp.ctrl_p,
        inp.ctrl_s0,
        inp.real,
        inp.speed_noise,
        inp.balises,
        record,
        max(record_every, 1),
        metrics,
    )
    return metrics, record


#: kernel metric index -> public name (railpilot.sim.result.METRICS defines them)
METRIC_INDEX: dict[str, int] = {
    "stop_error_m": engine.M_STOP_ERR,
    "stop_time_s": engine.M_STOP_T,
    "max_speed_error_mps": engine.M_MAX_VERR,
    "rms_speed_error_mps": engine.M_RMS_VERR,
    "speed_error_at_changeover_mps": engine.M_VERR_CO,
    "max_decel_mps2": engine.M_MAX_DECEL,
    "max_jerk_mps3": engine.M_MAX_JERK,
    "max_position_error_m": engine.M_MAX_XERR,
    "energy_electric_j": engine.M_E_ELEC,
    "energy_friction_j": engine.M_E_FRIC,
    "odometry_error_at_stop_m": engine.M_ODO_ERR,
    "slide_time_s": engine.M_SLIDE_T,
}


def metrics_dict(metrics: np.ndarray) -> dict[str, float]:
    """Name the kernel's metrics array."""
    return {name: float(metrics[i]) for name, i in METRIC_INDEX.items()}


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
