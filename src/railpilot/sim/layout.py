"""The description of one run as the compiled loop takes it: one typed structure.

:class:`RunInputs` is a tuple of named parts, one per concern (simulation settings,
train, line, brake, controller, ATO, realism, disturbance, reference). The kernel reads
every input by name (``inp.train.p[T_MASS]``, ``inp.reference.v[k]``), so two inputs
cannot be swapped by position, and adding one touches its concern only. Numba compiles
these named tuples like any tuple: no Python object is touched inside the loop.

A Monte Carlo batch uses the same classes with one more leading dimension on every part
that varies per run (each ``p`` vector, the per-run random series): :func:`batch_row`
cuts run ``i`` out of it, so a batch runs exactly the single-run kernel on exactly the
inputs a single run of that scenario gets (tests/sim/test_inputs.py proves it).

The builders (one function per concern, from a scenario) are in railpilot.sim.inputs;
this module imports nothing of the scenario, so the physics modules can use its layouts.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from railpilot.jit import njit

# --- layouts of the ``p`` vectors --------------------------------------------------------

# train: the plant. T_BRAKE_GAIN: the brake's true effort relative to nominal (shoe
# friction above or below what the brake manager assumes; the air path of an EP brake);
# T_LENGTH: the train's length [m], over which gradient and curve forces are averaged
T_MEFF, T_MASS, T_A0, T_A1, T_A2, T_X0, T_V0, T_BRAKE_GAIN, T_LENGTH = range(9)
N_TRAIN = 9
# ATO: the controllers' side's view of the train. A_UMAX > 0: it may command traction;
# A_GRADE_FF = 1: its resistance feed-forward includes the line's gradients and curves
# A_PREVIEW: look-ahead [s] of the gradient feed-forward; A_UPOWER: traction power per
# effective mass [W/kg], so the ATO's traction clamp follows the envelope (inf: none)
(
    A_MEFF_LW,
    A_A0,
    A_A1,
    A_A2,
    A_MASS,
    A_UMIN,
    A_UMAX,
    A_STOP_M,
    A_V_CO,
    A_GRADE_FF,
    A_PREVIEW,
    A_UPOWER,
) = range(12)
N_ATO = 12
# realism (all 0 = the idealised papers' world)
(R_SPEED_RES, R_WHEEL_SCALE, R_SLIDE_SLIP, R_ADHESION, R_SLIDE_RATIO, R_NOTCHES) = range(6)
N_REAL = 6
# disturbance: a constant outside force [N]
D_CONST_N = 0
N_DIST = 1
# brake sizes: floats of state and of command history
B_N_STATE, B_N_BUFFER = range(2)
# a run's loop-carried scalars (RunState.c): steps run, the train, the held command, the
# ATO's reference, the counters and the metrics' accumulators (sim/engine.py run_kernel)
(
    C_STEPS_RUN,
    C_X,
    C_V,
    C_X_ODO,
    C_A,
    C_BRAKE_PREV,
    C_U,
    C_MOVING,
    C_SLIDING,
    C_STOP_T,
    C_MAX_VERR,
    C_SUM_VERR2,
    C_N_MOVING,
    C_VERR_CO,
    C_MAX_DECEL,
    C_MAX_JERK,
    C_MAX_XERR,
    C_E_ELEC,
    C_E_FRIC,
    C_E_TRAC,
    C_V_MAX,
    C_HAS_MOVED,
    C_SLIDE_T,
    C_NEXT_BALISE,
    C_NEXT_UPDATE,
    C_N_UPDATES,
    C_NEXT_RECORD,
    C_N_RECORDS,
    C_RX,
    C_RV,
    C_RAFF,
    C_E_TRAC_AIR,
) = range(32)
# the inputs of the control update at which the controller gave no number (ref_x, ref_v,
# ref_a, x, v, resist_mps2, u_min, u_max, dt: control/base.py's step after its two
# arrays), so the simulator can call a user's step again from Python and show what it
# raised (sim/run.py check_commands)
C_FAILED_CALL = 32
N_FAILED_CALL = 9
N_CARRY = C_FAILED_CALL + N_FAILED_CALL


class SimIn(NamedTuple):
    """Steps, step [s], controller updates every ``control_every`` steps."""

    n_steps: int
    dt: float
    control_every: int


class TrainIn(NamedTuple):
    """The plant train; ``p`` by ``T_*`` (SI)."""

    p: np.ndarray


class LineIn(NamedTuple):
    """Gradient + curve resistance [N/kN] as a step function over position [m]
    (``values`` on ``[edges[i], edges[i+1])``) and its running integral at the edges
    [N/kN m], for averages over the train's length (vehicle/profile.py)."""

    edges: np.ndarray
    values: np.ndarray
    cumulative: np.ndarray


class BrakeIn(NamedTuple):
    """The brake's packed parameters (its own module's layout) and ``sizes`` by ``B_*``."""

    p: np.ndarray
    sizes: np.ndarray


class ControllerIn(NamedTuple):
    """The controller's parameters and initial state (its own module's layout)."""

    p: np.ndarray
    s0: np.ndarray


class AtoIn(NamedTuple):
    """What the ATO believes about the train; ``p`` by ``A_*``."""

    p: np.ndarray


class RealismIn(NamedTuple):
    """Real-train effects; ``p`` by ``R_*``; speed noise per controller update [m/s];
    balise positions [m] (sorted)."""

    p: np.ndarray
    speed_noise: np.ndarray
    balises: np.ndarray


class DisturbanceIn(NamedTuple):
    """Outside forces: ``p`` by ``D_*``; regions ``[start, end)`` [m] with a force [N];
    a random force [N] per step (may be empty)."""

    p: np.ndarray
    region_start: np.ndarray
    region_end: np.ndarray
    region_force: np.ndarray
    random_n: np.ndarray


class ReferenceIn(NamedTuple):
    """The braking curve sampled every step (``n_steps + 1`` samples): position [m],
    speed [m/s], acceleration [m/s^2] and the acceleration the ATO feeds forward
    (shifted ahead by its model of the brake's lead); ``by_distance`` is empty for a
    time-based reference, or ``(3, m)``: position, speed, fed-forward acceleration by
    position, looked up at the measured position (distance to go)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    a_ff: np.ndarray
    by_distance: np.ndarray


class RunInputs(NamedTuple):
    """Everything one run of the compiled loop takes, by concern."""

    sim: SimIn
    train: TrainIn
    line: LineIn
    brake: BrakeIn
    controller: ControllerIn
    ato: AtoIn
    realism: RealismIn
    disturbance: DisturbanceIn
    reference: ReferenceIn


class RunState(NamedTuple):
    """Where a run is between two calls of the compiled loop: ``c`` by ``C_*`` and the
    run's private copies of the controller's and the brake's parameters and state."""

    c: np.ndarray
    ctrl_p: np.ndarray
    ctrl_s: np.ndarray
    brake_p: np.ndarray
    brake_s: np.ndarray
    brake_buf: np.ndarray


@njit(cache=True)
def batch_row(batch: RunInputs, i: int) -> RunInputs:
    """Run ``i`` of a batch: its row of every per-run part, the shared parts as they are."""
    return RunInputs(
        batch.sim,
        TrainIn(batch.train.p[i]),
        batch.line,
        BrakeIn(batch.brake.p[i], batch.brake.sizes[i]),
        batch.controller,
        AtoIn(batch.ato.p[i]),
        RealismIn(batch.realism.p[i], batch.realism.speed_noise[i], batch.realism.balises),
        DisturbanceIn(
            batch.disturbance.p[i],
            batch.disturbance.region_start,
            batch.disturbance.region_end,
            batch.disturbance.region_force,
            batch.disturbance.random_n[i],
        ),
        batch.reference,
    )


def stack_runs(runs: list[RunInputs]) -> RunInputs:
    """A batch of runs that share the sim settings, line, controller and reference."""
    first = runs[0]
    return RunInputs(
        first.sim,
        TrainIn(np.stack([r.train.p for r in runs])),
        first.line,
        BrakeIn(np.stack([r.brake.p for r in runs]), np.stack([r.brake.sizes for r in runs])),
        first.controller,
        AtoIn(np.stack([r.ato.p for r in runs])),
        RealismIn(
            np.stack([r.realism.p for r in runs]),
            np.stack([r.realism.speed_noise for r in runs]),
            first.realism.balises,
        ),
        DisturbanceIn(
            np.stack([r.disturbance.p for r in runs]),
            first.disturbance.region_start,
            first.disturbance.region_end,
            first.disturbance.region_force,
            np.stack([r.disturbance.random_n for r in runs]),
        ),
        first.reference,
    )
