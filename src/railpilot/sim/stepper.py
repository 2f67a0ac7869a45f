"""A run that stops and goes on: the onboard re-plans mid-run (a TSR received, a target
point set or cleared), so the simulator must pause at that instant, take a new planned
curve and a new stop point, and carry on from the same state.

:class:`Stepper` holds one run's description and its state (sim/layout.py ``RunState``)
and advances the same compiled loop (sim/engine.py ``run_kernel``) step range by step
range. Between two calls nothing of the train, the brake or the controller is lost, so a
run advanced in pieces is the run advanced at once, to the bit (tests/sim/test_stepper.py).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numba
import numpy as np

from railpilot.brakes.registry import brake_entry_of
from railpilot.control.user import bind
from railpilot.errors import ConfigError
from railpilot.sim import engine
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.inputs import ato_brake_model, distance_table, run_inputs
from railpilot.sim.layout import (
    A_STOP_M,
    C_HAS_MOVED,
    C_MOVING,
    C_N_RECORDS,
    C_STEPS_RUN,
    C_STOP_T,
    C_V,
    C_X,
)
from railpilot.sim.result import SimResult
from railpilot.sim.run import check_commands, resolve_controller, sim_result

if TYPE_CHECKING:
    from railpilot.scenario.model import Scenario


class Stepper:
    """One run of ``scenario`` advanced piece by piece, recording every step.

    ``controller`` as :func:`railpilot.sim.run.simulate` takes it. The reference may be
    replaced between pieces (:meth:`replace_reference`); so may the controller's
    parameters (:attr:`controller_params`, the run's private copy).
    """

    def __init__(self, scenario: Scenario, controller: Any = None) -> None:
        self.scenario = scenario
        self._binding = bind(resolve_controller(scenario, controller))
        self._inputs = run_inputs(scenario, self._binding)
        self._brake_step = brake_entry_of(scenario.brake).step
        self._state = engine.fresh_state(self._inputs)
        n = self._inputs.sim.n_steps
        self._record_every = max(scenario.sim.record_every, 1)
        self._record = np.zeros((-(-n // self._record_every), engine.N_CHANNELS))
        self._metrics = np.zeros(engine.N_METRICS)
        self._compiled: Any = None  # the kernel's compiled entry for these arguments
        # read once: a line run asks a stepper to advance several times a second per train,
        # and most asks fall within the step already run
        self._dt = self._inputs.sim.dt
        #: steps the run has (the end of its time, ``sim.duration_s``)
        self.n_steps = n

    @property
    def step(self) -> int:
        """Steps run so far."""
        return int(self._state.c[C_STEPS_RUN])

    @property
    def time_s(self) -> float:
        return self.step * self._dt

    @property
    def position_m(self) -> float:
        return float(self._state.c[C_X])

    @property
    def speed_mps(self) -> float:
        return float(self._state.c[C_V])

    @property
    def stop_time_s(self) -> float:
        """When the train came to its last stop [s] (nan: it has not stopped)."""
        return float(self._state.c[C_STOP_T])

    @property
    def at_rest(self) -> bool:
        """True once the train has come to its final stop (it does not move again)."""
        return self._state.c[C_MOVING] < 0.5

    @property
    def finished(self) -> bool:
        return self.at_rest or self.step >= self.n_steps

    @property
    def controller_params(self) -> np.ndarray:
        """The run's copy of the controller's parameters (changes act from the next step)."""
        return self._state.ctrl_p

    @property
    def controller_state(self) -> np.ndarray:
        """The run's copy of the controller's state (changes act from the next step)."""
        return self._state.ctrl_s

    def restart(self) -> None:
        """Let a train at rest move again (a target point cleared): it is held until its
        traction overcomes the resistance, as at the start of a run."""
        self._state.c[C_MOVING] = 1.0
        self._state.c[C_HAS_MOVED] = 0.0

    def hold(self) -> None:
        """Hold a train at rest where it stands (nothing ahead of it may be entered): it
        does not move until :meth:`restart`, whatever its reference says."""
        if self.speed_mps > 0.0:
            raise ConfigError("speed_mps", self.speed_mps, "a train at rest (0 m/s) to hold")
        self._state.c[C_MOVING] = 0.0

    def advance_to(self, time_s: float) -> None:
        """Run the steps that start before ``time_s`` [s] (or to the end of the run)."""
        if not math.isfinite(time_s):
            raise ConfigError("time_s", time_s, "a finite time [s]")
        k_stop = min(math.ceil(time_s / self._dt - 1e-9), self.n_steps)
        if k_stop <= self._state.c[C_STEPS_RUN]:
            return
        args = (
            self._inputs,
            self._binding.step,
            self._brake_step,
            self._record,
            self._record_every,
            self._metrics,
            self._state,
            k_stop,
        )
        with self._binding:
            if self._compiled is None:
                engine.run_kernel(*args)  # compiled (or loaded) for these argument types
                self._compiled = _compiled_entry(engine.run_kernel, args)
            else:
                self._compiled(*args)
        if not math.isnan(self._metrics[engine.M_NO_COMMAND_T]):
            check_commands(self._binding, self._metrics, lambda _run: self._state)

    def run_to_end(self) -> None:
        self.advance_to(self.n_steps * self._dt)

    def replace_reference(self, profile: PlannedProfile) -> None:
        """Track ``profile`` by distance from the next step on, stopping at its end.

        A distance-based run only (``ato.reference = "distance"``): the ATO looks the new
        curve up at the measured position; the stop point the metrics measure against
        is the new curve's end.
        """
        reference = self._inputs.reference
        if reference.by_distance.shape[1] == 0:
            raise ConfigError(
                "ato.reference", "time", "'distance' to replace the reference mid-run"
            )
        delay, lag = ato_brake_model(self.scenario)
        table = distance_table(profile, self._dt, delay + lag)
        ato = self._inputs.ato.p.copy()
        ato[A_STOP_M] = profile.stop_m
        before = (reference.by_distance, self._inputs.ato.p)
        self._inputs = self._inputs._replace(
            reference=reference._replace(by_distance=table),
            ato=self._inputs.ato._replace(p=ato),
        )
        # The compiled entry serves on while the new arrays have the types of the old (they
        # do: a line run replaces a train's reference at every change of what it knows, and
        # looking the types of all the arguments up again costs about half a millisecond)
        if any(
            numba.typeof(a) != numba.typeof(b) for a, b in zip((table, ato), before, strict=True)
        ):
            self._compiled = None

    def result(self) -> SimResult:
        """The run so far as one result (what :func:`simulate` returns for a whole run)."""
        rows = self._record[: int(self._state.c[C_N_RECORDS])]
        stop = float(self._inputs.ato.p[A_STOP_M])
        return sim_result(self.scenario, self._binding.name, stop, self._metrics, rows)


def _compiled_entry(kernel: Any, args: tuple[Any, ...]) -> Any:
    """The compiled specialisation of ``kernel`` for the types of ``args``, called directly.

    Why: a line run calls the loop once or twice a second per train for a few steps, and
    Numba's dispatcher types every argument on every call: the run's inputs are a tuple of
    tuples of arrays and the steps are compiled functions, which it types in Python (about
    25 us a call against about 2 us for the entry itself; benchmarks/line_speed.py). The
    types of a stepper's arguments do not change between calls (the same arrays, the same
    steps), so they are looked up once. Falls back to the dispatcher if Numba has no entry
    for them.
    """
    signature = tuple(numba.typeof(a) for a in args)
    compiled = kernel.overloads.get(signature)
    return compiled.entry_point if compiled is not None else kernel
