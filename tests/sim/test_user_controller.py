"""One description of a run, registries, your own controller.

What runs is what the user passed: a Python controller's own commands drive the plant, a
built-in's subclass that overrides ``update`` runs its ``update`` (not the built-in
kernel), a compiled user step runs in the fast path and in the Monte Carlo, and a single
run and a batch of one are the same run, bit for bit.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal, assert_equal

from railpilot.brakes.registry import BRAKES, brake_entry, brake_entry_of
from railpilot.cli import main
from railpilot.control.base import Controller
from railpilot.control.pid import TrackingPID
from railpilot.control.registry import CONTROLLERS, controller_entry
from railpilot.control.user import bind, load_controller
from railpilot.errors import ConfigError
from railpilot.scenario import load_scenario
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.batch import run_batch, run_montecarlo
from railpilot.sim.inputs import run_inputs
from railpilot.sim.layout import stack_runs
from railpilot.sim.run import make_controller, run_once, simulate

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "user_controller.py"
PAPER000 = ROOT / "examples" / "paper000_smarc_ep.toml"
PAPER002 = ROOT / "examples" / "paper002_qsmc_stop.toml"


@pytest.fixture(scope="module")
def scenario():  # type: ignore[no-untyped-def]
    # a short run: the curve's first 30 s are enough to see who drives
    s = load_scenario(PAPER000)
    return replace(s, sim=replace(s.sim, duration_s=30.0))


class Recorder:
    """A Python controller that says what it commanded: a fixed, distinctive schedule."""

    name = "recorder"

    def __init__(self) -> None:
        self.commands: list[float] = []

    def reset(self) -> None:
        self.commands = []

    def update(self, reference, measurement, dt):  # type: ignore[no-untyped-def]
        n = len(self.commands)
        command = -0.2 - 0.3 * ((n // 50) % 2)  # -0.2 and -0.5 m/s^2 by turns of 50
        self.commands.append(command)
        return command


@pytest.mark.slow
def test_the_python_controllers_commands_are_what_drives_the_plant(scenario) -> None:  # type: ignore[no-untyped-def]
    # no resistance model in the ATO, so its feed-forward adds nothing to the command
    s = replace(scenario, ato=replace(scenario.ato, davis=(0.0, 0.0, 0.0)))
    ctrl = Recorder()
    result = simulate(s, ctrl)
    every = s.sim.control_every
    commanded = result.series["command_mps2"][::every][: len(ctrl.commands)]
    # the plant's command channel is the user's schedule, update by update (clamped
    # to the service brake only where it would exceed it: it never does here)
    assert len(ctrl.commands) == s.sim.n_steps // every
    assert_array_equal(commanded, np.array(ctrl.commands[: len(commanded)]))
    # and the EP brake answered it: the force demand follows the command
    demand = result.series["demand_n"][::every][: len(commanded)]
    assert np.all(demand > 0)


def test_a_pid_subclass_that_overrides_update_runs_its_update(scenario) -> None:  # type: ignore[no-untyped-def]
    base = make_controller(scenario, "pid")

    class Halved(TrackingPID):
        calls = 0

        def update(self, setpoint, measurement, dt):  # type: ignore[no-untyped-def]
            Halved.calls += 1
            return 0.5 * super().update(setpoint, measurement, dt)

    mine = Halved.__new__(Halved)
    mine.__dict__.update(base.__dict__)
    mine.params, mine.state = base.params.copy(), base.state.copy()
    builtin = simulate(scenario, base)
    overridden = simulate(scenario, mine)
    assert Halved.calls == scenario.sim.n_steps // scenario.sim.control_every
    assert overridden.meta["controller"] == "pid"
    assert overridden.metrics["max_speed_error_mps"] != builtin.metrics["max_speed_error_mps"]


def test_a_subclass_that_changes_nothing_runs_the_builtin_kernel(scenario) -> None:  # type: ignore[no-untyped-def]
    base = make_controller(scenario, "smarc")
    same = type("SameSMARC", (type(base),), {})
    obj = same.__new__(same)
    obj.__dict__.update(base.__dict__)
    obj.params, obj.state = base.params.copy(), base.state.copy()
    assert bind(obj).step is CONTROLLERS["smarc"].step
    assert_equal(simulate(scenario, obj).metrics, simulate(scenario, base).metrics)


def test_a_controller_abc_subclass_of_the_users_is_accepted(scenario) -> None:  # type: ignore[no-untyped-def]
    class Mine(Controller):
        name = "mine"
        params = np.zeros(0)
        state = np.zeros(0)

        def reset(self) -> None:
            pass

        def update(self, reference, measurement, dt):  # type: ignore[no-untyped-def]
            return -0.4

        @property
        def components(self) -> dict[str, float]:
            return {}

    result = simulate(scenario, Mine())
    assert result.meta["controller"] == "mine"
    assert result.metrics["max_decel_mps2"] > 0.3


def test_python_and_compiled_versions_of_one_law_give_the_same_run(scenario) -> None:  # type: ignore[no-untyped-def]
    python = load_controller(f"{EXAMPLE}:SpeedPositionTracker")
    compiled = load_controller(f"{EXAMPLE}:CompiledTracker")
    assert bind(compiled).python is None and bind(python).python is python
    a = simulate(scenario, python)
    b = simulate(scenario, compiled)
    assert python.updates == scenario.sim.n_steps // scenario.sim.control_every
    assert_equal(a.metrics, b.metrics)
    for name in ("position_m", "speed_mps", "command_mps2"):
        assert_array_equal(a.series[name], b.series[name])


def test_a_single_run_and_a_batch_of_one_are_the_same_run() -> None:
    s = load_scenario(PAPER002)
    for name in CONTROLLERS:
        binding = bind(make_controller(s, name))
        inp = run_inputs(s, binding)
        step = brake_entry_of(s.brake).step
        single, _ = run_once(inp, binding, step)
        batch = run_batch(stack_runs([inp]), binding, step)
        assert_array_equal(batch[0], single)
        assert_array_equal(batch[0], run_batch(stack_runs([inp, inp, inp]), binding, step)[2])


def test_a_compiled_user_controller_runs_in_the_monte_carlo_like_alone() -> None:
    s = load_scenario(PAPER002)
    spec = MonteCarloSpec(
        runs=6, seed=3, chunk=3, vary=(Distribution("train.mass_t", "uniform", 300, 340),)
    )
    name = f"{EXAMPLE}:CompiledTracker"
    parallel = run_montecarlo(s, name, spec, progress=False)
    python = run_montecarlo(s, f"{EXAMPLE}:SpeedPositionTracker", spec, progress=False)
    assert np.isfinite(parallel.stop_errors).all()
    assert_array_equal(parallel.metrics, python.metrics)


def test_unknown_names_are_errors_that_name_the_allowed_ones() -> None:
    with pytest.raises(ConfigError, match="one of pid, smarc, qsmc"):
        controller_entry("lqr")
    with pytest.raises(ConfigError, match="one of ep-blended, lag-delay, brake-pipe"):
        brake_entry("disc")
    assert {"ep-blended", "lag-delay", "brake-pipe", "locomotive-drive"} <= set(BRAKES)
    with pytest.raises(ConfigError, match=r"existing file"):
        load_controller("no/such/file.py:Thing")
    with pytest.raises(ConfigError, match=r"named 'Nope'"):
        load_controller(f"{EXAMPLE}:Nope")
    with pytest.raises(ConfigError, match=r"reset\(\) and update"):
        bind(object())


def test_simulate_command_runs_a_users_controller(capsys) -> None:  # type: ignore[no-untyped-def]
    code = main(
        [
            "simulate",
            str(PAPER002),
            "--controller",
            f"{EXAMPLE}:CompiledTracker",
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["controller"] == "compiled-tracker"
    assert abs(out["metrics"]["stop_error_m"]) < 5.0


def test_simulate_command_refuses_an_unknown_controller(capsys) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(SystemExit) as stop:
        main(["simulate", str(PAPER002), "--controller", "lqr"])
    assert stop.value.code == 2
    assert "one of pid, smarc, qsmc" in capsys.readouterr().err


class Says:
    """A Python controller whose update answers ``answer`` (not an acceleration)."""

    def __init__(self, answer: object) -> None:
        self.answer = answer

    def reset(self) -> None:
        pass

    def update(self, reference, measurement, dt):  # type: ignore[no-untyped-def]
        return self.answer


@pytest.mark.parametrize("answer", ["fast", None, float("nan"), [0.1]])
def test_an_update_that_answers_no_number_is_an_error_naming_it(scenario, answer) -> None:  # type: ignore[no-untyped-def]
    # it was a ValueError from float() deep in the loop, or (NaN) a run of None metrics
    with pytest.raises(ConfigError) as info:
        simulate(scenario, Says(answer))
    assert info.value.field == "Says.update()"
    assert "the commanded acceleration" in info.value.allowed
