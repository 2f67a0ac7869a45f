"""Public entry point: run a scenario, get a :class:`~railpilot.sim.result.SimResult`.

:func:`simulate` binds the controller (control/user.py: a built-in runs its registered
kernel, a user's object what it brings), builds the run's description
(railpilot.sim.inputs) and runs the compiled loop (railpilot.sim.engine) once with a
recorder; railpilot.sim.batch runs the same description for many runs.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from railpilot.brakes.registry import brake_entry_of
from railpilot.control.base import Controller
from railpilot.control.registry import controller_entry
from railpilot.control.user import Binding, bind, is_user_spec, load_controller
from railpilot.errors import ConfigError
from railpilot.sim import engine
from railpilot.sim.inputs import distance_table, run_inputs, tuning_model
from railpilot.sim.layout import C_FAILED_CALL, N_FAILED_CALL, RunInputs, RunState
from railpilot.sim.result import CHANNELS, SimResult
from railpilot.units import mps_to_kmh

__all__ = [
    "default_controller_params",
    "distance_table",
    "make_controller",
    "resolve_controller",
    "run_once",
    "simulate",
    "tuning_model",
]

if TYPE_CHECKING:  # the simulator never imports the scenario package at run time
    from railpilot.scenario.model import Scenario


def default_controller_params(scenario: Scenario, name: str) -> dict[str, Any]:
    """Controller parameters by the registered tuning rule for this scenario's brake.

    The ATO's model of the brake (``ato.brake_delay_s`` and ``ato.brake_lag_s``, else
    the true delay and lag) and half a control period go into the rule
    (:func:`~railpilot.sim.inputs.tuning_model`).
    """
    theta, lag = tuning_model(scenario)
    return controller_entry(name).tuning(theta, lag, scenario.sim.control_period_s)


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
    """Build the scenario's built-in controller (or ``name``): tuned defaults + overrides."""
    name = name or scenario.controller.name
    entry = controller_entry(name)
    params = default_controller_params(scenario, name)
    overrides = scenario.controller.params.get(name, {})
    cls = entry.cls
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
    if "stop_m" in accepted:
        # a controller that stops by prediction is told where (the reference's stop)
        params.setdefault("stop_m", float(scenario.reference.stop_m))
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


def resolve_controller(scenario: Scenario, controller: Any = None) -> Any:
    """The controller object to run: the one given, a built-in by name (tuned for this
    scenario), a user's ``module:Name``, or the scenario's own."""
    if controller is None or isinstance(controller, str):
        name = controller or scenario.controller.name
        if is_user_spec(name):
            return load_controller(name)
        return make_controller(scenario, name)
    return controller


def run_once(
    inp: RunInputs, binding: Binding, brake_step: Any, record_every: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Run one description with a bound controller and the brake's compiled step.

    Returns ``(metrics, record)``; the record is empty for ``record_every = 0``.
    """
    n = inp.sim.n_steps
    n_rec = (n + record_every - 1) // record_every if record_every > 0 else 0
    record = np.zeros((n_rec, engine.N_CHANNELS))
    metrics, state = run_from_start(inp, binding, brake_step, record, max(record_every, 1))
    check_commands(binding, metrics, lambda _run: state)
    return metrics, record


def run_from_start(
    inp: RunInputs,
    binding: Binding,
    brake_step: Any,
    record: np.ndarray | None = None,
    record_every: int = 1,
) -> tuple[np.ndarray, RunState]:
    """One run of ``inp`` from its start to where the loop ends it, recording into
    ``record`` (None: nothing): its metrics and its state there, unchecked (a caller
    checks the commands, :func:`check_commands`)."""
    record = np.zeros((0, engine.N_CHANNELS)) if record is None else record
    metrics = np.zeros(engine.N_METRICS)
    state = engine.fresh_state(inp)
    with binding:
        engine.run_kernel(
            inp, binding.step, brake_step, record, record_every, metrics, state, inp.sim.n_steps
        )
    return metrics, state


def check_commands(
    binding: Binding,
    metrics: np.ndarray,
    state_of: Callable[[int], RunState] | None = None,
) -> None:
    """A ConfigError naming the controller if it gave no number in a run (``metrics``:
    one run's, or a batch's rows): the loop stopped that run there, and a run cut short
    is never reported as a result.

    ``state_of(i)`` gives run ``i``'s state where the loop stopped it; with it, a user's
    compiled step is called again from Python with that update's inputs, so the error
    shows what it raised (no exception crosses the C function pointer the loop calls it
    through, control/user.py ``step_pointer``).
    """
    stopped_at = np.ravel(np.asarray(metrics)[..., engine.M_NO_COMMAND_T])
    failed = ~np.isnan(stopped_at)
    if not failed.any():
        return
    run = int(np.argmax(failed))
    t = float(stopped_at[run])
    if binding.user_step is not None:
        allowed = "a step that returns a number: the commanded acceleration [m/s^2]"
        if binding.user_dispatcher is None or state_of is None:
            raise ConfigError(binding.user_step, f"no number at t = {t:g} s", allowed)
        answer = _call_again(binding.user_dispatcher, state_of(run))
        if isinstance(answer, Exception):
            raise ConfigError(
                binding.user_step,
                f"no number at t = {t:g} s: it raised {type(answer).__name__}: {answer}",
                allowed,
            ) from answer
        said = (
            "it returned NaN"
            if math.isnan(answer)
            # the failed call changed the state it would have failed on again
            else f"NaN, or an exception; called again on the state it left, it gave {answer:g}"
        )
        raise ConfigError(binding.user_step, f"no number at t = {t:g} s ({said})", allowed)
    # a built-in's step: its parameters took it beyond floating point
    raise ConfigError(
        "controller",
        binding.name,
        f"parameters under which it commands a number (NaN at t = {t:g} s)",
    )


def _call_again(step: Any, state: RunState) -> float | Exception:
    """What ``step`` answers, called from Python with the inputs of the update at which
    the loop stopped ``state``'s run (sim/layout.py ``C_FAILED_CALL``), on copies of that
    run's parameters and state as the failed call left them: the number, or the exception
    it raises."""
    inputs = state.c[C_FAILED_CALL : C_FAILED_CALL + N_FAILED_CALL]
    try:
        return float(step(state.ctrl_p.copy(), state.ctrl_s.copy(), *map(float, inputs)))
    except Exception as exc:  # the user's error, shown to the user: every kind
        return exc


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
    "energy_traction_j": engine.M_E_TRACTION,
    "max_speed_mps": engine.M_MAX_SPEED,
    "energy_traction_against_air_j": engine.M_E_TRAC_AIR,
}

J_PER_KWH = 3.6e6


def derived_metrics(metrics: dict[str, float], brake: Any) -> dict[str, float]:
    """The metrics in the units a driver and a dispatcher read, with the actuator's
    efficiencies (vehicle/traction.py: from the wheel to the supply and back)."""
    locomotive = getattr(brake, "locomotive", None)
    traction_eff = 1.0 if locomotive is None else locomotive.traction_efficiency
    regen_eff = 1.0 if locomotive is None else locomotive.regen_efficiency
    return {
        "max_speed_kmh": mps_to_kmh(metrics["max_speed_mps"]),
        "running_time_s": metrics["stop_time_s"],
        "energy_traction_kwh": metrics["energy_traction_j"] / traction_eff / J_PER_KWH,
        "energy_regenerated_kwh": metrics["energy_electric_j"] * regen_eff / J_PER_KWH,
        "energy_traction_against_air_kwh": metrics["energy_traction_against_air_j"]
        / traction_eff
        / J_PER_KWH,
    }


def metrics_dict(metrics: np.ndarray) -> dict[str, float]:
    """Name the kernel's metrics array."""
    return {name: float(metrics[i]) for name, i in METRIC_INDEX.items()}


def simulate(scenario: Scenario, controller: Any = None) -> SimResult:
    """Run ``scenario`` and record everything.

    ``controller``: None (the scenario's), a built-in's name, ``module:Name`` (your own,
    control/user.py), or a controller object: a built-in, one with a compiled ``step``,
    or any object with ``reset()`` and ``update(reference, measurement, dt)``. What runs
    is what is given: a subclass of a built-in that overrides ``update`` runs its
    ``update``.
    """
    ctrl = resolve_controller(scenario, controller)
    binding = bind(ctrl)
    inp = run_inputs(scenario, binding)
    brake_step = brake_entry_of(scenario.brake).step
    metrics, record = run_once(inp, binding, brake_step, scenario.sim.record_every)
    return sim_result(scenario, binding.name, scenario.reference.stop_m, metrics, record)


def sim_result(
    scenario: Scenario,
    controller: str,
    stop_point_m: float,
    metrics: np.ndarray,
    record: np.ndarray,
) -> SimResult:
    """One result from the kernel's metrics and recorder arrays."""
    series = {name: record[:, i].copy() for i, (name, _) in enumerate(CHANNELS)}
    meta = {
        "scenario": scenario.name,
        "controller": controller,
        "stop_point_m": stop_point_m,
        "dt_s": scenario.sim.dt_s,
        "stopped": bool(metrics[engine.M_STOPPED]),
    }
    named = metrics_dict(metrics)
    named.update(derived_metrics(named, scenario.brake))
    return SimResult(series=series, metrics=named, meta=meta)
