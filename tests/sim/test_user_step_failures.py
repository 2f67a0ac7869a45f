"""A user's compiled step that gives no number stops the run with an error naming it.

A user's step runs behind a C function pointer (control/user.py ``step_pointer``), where
no exception can cross: a NaN it returns, or an exception it raises, ends the run at
that control update and the simulator names ``Class.step`` and the time. Before, a NaN
ran on silently (``simulate`` printed null metrics and exited 0). A step Numba cannot
compile for the step's signature is refused when it is bound.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numba import njit

from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import CompiledController, bind
from railpilot.errors import ConfigError
from railpilot.scenario import load_scenario
from railpilot.sim.batch import run_batch
from railpilot.sim.inputs import run_inputs
from railpilot.sim.layout import stack_runs
from railpilot.sim.run import simulate
from railpilot.sim.stepper import Stepper

ROOT = Path(__file__).resolve().parents[2]
PAPER002 = ROOT / "examples" / "paper002_qsmc_stop.toml"

#: the control update (counted from 1) at which the failing steps fail
FAIL_AT = 40


@njit
def _nan_late(params, state, ref_x, ref_v, ref_a, x, v, resist, u_min, u_max, dt):  # type: ignore[no-untyped-def]
    state[0] += 1.0
    if state[0] >= FAIL_AT:
        return np.nan
    return ref_a + resist


@njit
def _raises_late(params, state, ref_x, ref_v, ref_a, x, v, resist, u_min, u_max, dt):  # type: ignore[no-untyped-def]
    state[0] += 1.0
    if state[0] >= FAIL_AT:
        raise ValueError("the user's own error")
    return ref_a + resist


@njit
def _saturates(params, state, ref_x, ref_v, ref_a, x, v, resist, u_min, u_max, dt):  # type: ignore[no-untyped-def]
    # an infinite command is a number: the ATO clamps it to its brake limit
    return -np.inf


@njit
def _two_arguments(params, state):  # type: ignore[no-untyped-def]
    return 0.0


def _controller(step, name: str):  # type: ignore[no-untyped-def]
    cls = type(name, (CompiledController,), {"name": name.lower(), "step": step})
    return cls(params=np.zeros(1), state=np.zeros(1))


@pytest.fixture(scope="module")
def scenario():  # type: ignore[no-untyped-def]
    s = load_scenario(PAPER002)
    return replace(s, sim=replace(s.sim, duration_s=20.0))


@pytest.mark.parametrize(
    ("step", "name", "said"),
    [
        (_nan_late, "NanLate", "it returned NaN"),
        (_raises_late, "RaisesLate", "it raised ValueError: the user's own error"),
    ],
)
def test_a_step_without_a_number_stops_simulate_naming_it_the_time_and_what_it_did(
    scenario, step, name: str, said: str
) -> None:  # type: ignore[no-untyped-def]
    period = scenario.sim.dt_s * scenario.sim.control_every
    with pytest.raises(ConfigError) as caught:
        simulate(scenario, _controller(step, name))
    assert caught.value.field == f"{name}.step"
    # the first update is at t = 0, so the FAIL_AT-th is at (FAIL_AT - 1) periods
    assert f"t = {(FAIL_AT - 1) * period:g} s" in str(caught.value)
    # the step, called again from Python with that update's inputs, shows its own error
    assert said in str(caught.value)
    if step is _raises_late:
        assert isinstance(caught.value.__cause__, ValueError)


@njit
def _raises_beyond(params, state, ref_x, ref_v, ref_a, x, v, resist, u_min, u_max, dt):  # type: ignore[no-untyped-def]
    if x > params[0]:
        raise ZeroDivisionError("past the position in params[0]")
    return ref_a + resist


def test_the_error_shows_the_failing_updates_own_inputs(scenario) -> None:  # type: ignore[no-untyped-def]
    # a step that raises only past a position: called again with any other update's
    # inputs (the first, say) it would answer a number
    free = _controller(_raises_beyond, "RaisesBeyond")
    free.params[0] = np.inf
    x = simulate(scenario, free).series["position_m"]
    assert x[-1] > x[0] + 10.0  # the run moves far enough to pass the middle
    controller = _controller(_raises_beyond, "RaisesBeyond")
    controller.params[0] = float(0.5 * (x[0] + x[-1]))
    with pytest.raises(ConfigError, match="it raised ZeroDivisionError: past the position"):
        simulate(scenario, controller)


def test_a_batch_and_the_stepper_show_what_the_step_did_too(
    scenario,
) -> None:  # type: ignore[no-untyped-def]
    binding = bind(_controller(_raises_late, "RaisesLate"))
    inp = run_inputs(scenario, binding)
    with pytest.raises(ConfigError, match=r"RaisesLate\.step.*ValueError: the user's own error"):
        run_batch(stack_runs([inp, inp]), binding, brake_entry_of(scenario.brake).step)
    stepper = Stepper(scenario, _controller(_nan_late, "NanLate"))
    with pytest.raises(ConfigError, match=r"NanLate\.step.*it returned NaN"):
        stepper.run_to_end()
    period = scenario.sim.dt_s * scenario.sim.control_every
    # the run stopped at the failing update: nothing after it was simulated
    assert stepper.time_s == pytest.approx((FAIL_AT - 1) * period)


def test_an_infinite_command_is_clamped_not_refused(scenario) -> None:  # type: ignore[no-untyped-def]
    result = simulate(scenario, _controller(_saturates, "Saturates"))
    assert result.series["command_mps2"].min() == pytest.approx(
        -scenario.train.max_service_decel_mps2
    )


def test_a_step_of_another_signature_is_refused_when_bound() -> None:
    with pytest.raises(ConfigError, match=r"TwoArguments\.step.*control/base\.py"):
        bind(_controller(_two_arguments, "TwoArguments"))


def test_a_builtin_step_that_gives_no_number_stops_the_run_naming_the_controller(
    scenario,
) -> None:  # type: ignore[no-untyped-def]
    stepper = Stepper(scenario, "pid")
    stepper.advance_to(5.0)
    stepper.controller_params[:] = np.nan  # a line run changes these mid-run
    with pytest.raises(ConfigError, match=r"controller = 'pid'.*NaN at t = 5(\.0\d*)? s"):
        stepper.advance_to(10.0)
    assert stepper.time_s < 5.5  # stopped at the first update after, not run on
