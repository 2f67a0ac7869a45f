"""PID controller with output limits, anti-windup and a filtered derivative.

The textbook parallel form ``u = Kp e + Ki integral(e) + Kd de/dt`` with

* a first-order filter on the derivative term (time constant ``derivative_filter_s``;
  0 means no filter), discretised by backward Euler so it is stable for any ``dt``;
* derivative on the measurement by default (no derivative kick on set-point steps);
* anti-windup by clamping the integral term into the output limits (the simple-pid
  behaviour) or by back-calculation with gain ``backcalc_gain`` [1/s].

With no filter, derivative on measurement and clamping, the sequence of outputs is
the same as simple-pid's (checked in tests/control/test_pid.py).
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from railpilot.control.base import Controller, check_dt, check_limits, check_number
from railpilot.errors import shown
from railpilot.jit import njit

# params layout
P_KP, P_KI, P_KD, P_TF, P_LO, P_HI, P_MODE, P_KAW, P_DMEAS = range(9)
N_PARAMS = 9
# state layout
S_INT, S_DFILT, S_PREV_E, S_PREV_Y, S_HAS_PREV, S_P, S_I, S_D = range(8)
N_STATE = 8

MODE_CLAMP = 0.0
MODE_BACKCALC = 1.0


@njit(cache=True)
def pid_step(
    params: np.ndarray, state: np.ndarray, setpoint: float, measurement: float, dt: float
) -> float:
    """One PID update; mutates ``state`` and returns the limited output."""
    kp = params[P_KP]
    ki = params[P_KI]
    kd = params[P_KD]
    tf = params[P_TF]
    lo = params[P_LO]
    hi = params[P_HI]
    error = setpoint - measurement

    proportional = kp * error

    if state[S_HAS_PREV] > 0.5:
        if params[P_DMEAS] > 0.5:
            raw_d = -kd * (measurement - state[S_PREV_Y]) / dt
        else:
            raw_d = kd * (error - state[S_PREV_E]) / dt
    else:
        raw_d = 0.0
    derivative = (tf * state[S_DFILT] + dt * raw_d) / (tf + dt)

    if params[P_MODE] == MODE_CLAMP:
        integral = state[S_INT] + ki * error * dt
        integral = min(max(integral, lo), hi)
        unsat = proportional + integral + derivative
        output = min(max(unsat, lo), hi)
    else:
        integral = state[S_INT]
        unsat = proportional + integral + derivative
        output = min(max(unsat, lo), hi)
        # back-calculation: bleed the integrator by the saturation excess
        integral = integral + (ki * error + params[P_KAW] * (output - unsat)) * dt

    state[S_INT] = integral
    state[S_DFILT] = derivative
    state[S_PREV_E] = error
    state[S_PREV_Y] = measurement
    state[S_HAS_PREV] = 1.0
    state[S_P] = proportional
    state[S_I] = integral
    state[S_D] = derivative
    return output


class PID(Controller):
    """Parallel-form PID.

    Parameters
    ----------
    kp, ki, kd
        Proportional [out/in], integral [out/(in s)] and derivative [out s/in] gains.
    derivative_filter_s
        Time constant of the first-order derivative filter [s]; 0 = unfiltered.
    output_limits
        ``(low, high)`` limits on the output; ``None`` = unbounded on that side.
    anti_windup
        ``"clamp"`` keeps the integral term inside the output limits;
        ``"backcalc"`` feeds the saturation excess back into the integrator.
    backcalc_gain
        Back-calculation gain [1/s]; default ``ki / kp`` if both are non-zero else 1.
    derivative_on
        ``"measurement"`` (default, no kick on set-point steps) or ``"error"``.
    """

    name = "pid"

    def __init__(
        self,
        kp: float,
        ki: float = 0.0,
        kd: float = 0.0,
        *,
        derivative_filter_s: float = 0.0,
        output_limits: tuple[float | None, float | None] = (None, None),
        anti_windup: Literal["clamp", "backcalc"] = "clamp",
        backcalc_gain: float | None = None,
        derivative_on: Literal["measurement", "error"] = "measurement",
    ) -> None:
        low, high = check_limits(output_limits)
        derivative_filter_s = check_number(
            "derivative_filter_s", derivative_filter_s, minimum=0.0, unit="s"
        )
        if not (isinstance(anti_windup, str) and anti_windup in ("clamp", "backcalc")):
            raise ValueError(
                f"anti_windup = {shown(anti_windup)} is not allowed: expected 'clamp' or 'backcalc'"
            )
        if not (isinstance(derivative_on, str) and derivative_on in ("measurement", "error")):
            raise ValueError(
                f"derivative_on = {shown(derivative_on)} is not allowed: "
                "expected 'measurement' or 'error'"
            )
        kp = check_number("kp", kp)
        ki = check_number("ki", ki)
        kd = check_number("kd", kd)
        if backcalc_gain is None:
            backcalc_gain = ki / kp if (kp != 0 and ki != 0) else 1.0
            if not math.isfinite(backcalc_gain):
                raise ValueError(
                    f"backcalc_gain = None is not allowed with ki = {ki!r}, kp = {kp!r}: its "
                    "default ki / kp is no finite number; give a finite number >= 0 [1/s]"
                )
        else:
            backcalc_gain = check_number("backcalc_gain", backcalc_gain, minimum=0.0, unit="1/s")
        self.params = np.zeros(N_PARAMS)
        self.params[P_KP] = kp
        self.params[P_KI] = ki
        self.params[P_KD] = kd
        self.params[P_TF] = derivative_filter_s
        self.params[P_LO] = low
        self.params[P_HI] = high
        self.params[P_MODE] = MODE_CLAMP if anti_windup == "clamp" else MODE_BACKCALC
        self.params[P_KAW] = backcalc_gain
        self.params[P_DMEAS] = 1.0 if derivative_on == "measurement" else 0.0
        self.state = np.zeros(N_STATE)

    def reset(self) -> None:
        self.state[:] = 0.0

    def update(self, setpoint: float, measurement: float, dt: float) -> float:
        """Return the output for this sample; ``dt`` [s] since the previous one."""
        return float(
            pid_step(self.params, self.state, float(setpoint), float(measurement), check_dt(dt))
        )

    @property
    def components(self) -> dict[str, float]:
        return {
            "p": float(self.state[S_P]),
            "i": float(self.state[S_I]),
            "d": float(self.state[S_D]),
        }

    @property
    def output_limits(self) -> tuple[float, float]:
        return float(self.params[P_LO]), float(self.params[P_HI])


class TrackingPID(PID):
    """PID on speed error for tracking a braking curve, with position correction.

    The speed set-point is the reference speed corrected by the position error,
    ``v_set = v_ref - position_gain (x - x_ref)`` [m/s] (a position P loop around
    the speed PID: the usual ATO cascade), so a position error left by a transient is
    corrected, not just held. ``update((x_ref, v_ref), (x, v), dt)``.

    Parameters
    ----------
    position_gain
        Gain [1/s] of the outer position loop; 0 = plain speed PID.
    **kwargs
        As :class:`PID`.
    """

    name = "pid"

    def __init__(
        self,
        kp: float,
        ki: float = 0.0,
        kd: float = 0.0,
        *,
        position_gain: float = 0.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(kp, ki, kd, **kwargs)
        position_gain = check_number("position_gain", position_gain, minimum=0.0, unit="1/s")
        self.params = np.append(self.params, position_gain)

    def update(self, setpoint: Any, measurement: Any, dt: float) -> float:
        """``setpoint = (x_ref [m], v_ref [m/s][, a_ref])``, ``measurement = (x, v)``.

        A third reference item (the acceleration the simulator hands every controller,
        control/base.py) is ignored: the ATO feeds it forward outside the PID.
        """
        x_ref, v_ref = setpoint[0], setpoint[1]
        x, v = measurement
        return float(
            pid_step(
                self.params,
                self.state,
                tracking_setpoint(self.params, x_ref, v_ref, x),
                float(v),
                check_dt(dt),
            )
        )


@njit(cache=True)
def tracking_setpoint(params: np.ndarray, x_ref: float, v_ref: float, x: float) -> float:
    """Speed set-point [m/s] of :class:`TrackingPID`: ``v_ref - k_x (x - x_ref)``."""
    return v_ref - params[P_POSITION_GAIN] * (x - x_ref)


P_POSITION_GAIN = N_PARAMS


@njit(cache=True)
def pid_ato_step(
    params: np.ndarray,
    state: np.ndarray,
    ref_x: float,
    ref_v: float,
    ref_a: float,
    x: float,
    v: float,
    resist_mps2: float,
    u_min: float,
    u_max: float,
    dt: float,
) -> float:
    """:class:`TrackingPID` in the simulator (the step of control/base.py).

    The ATO feeds forward the reference acceleration and its resistance model and adds
    the PID's output; the PID's limits are moved to where the ATO's clamp of the sum
    lies, so its anti-windup sees the real saturation (a braking-only ATO cannot pull,
    and an integrator that wants traction would otherwise wind up and release the brake
    late). ``params`` is changed (the limits): the simulator passes a private copy.
    """
    ff = ref_a + resist_mps2
    params[P_LO] = u_min - ff
    params[P_HI] = u_max - ff
    v_set = tracking_setpoint(params, ref_x, ref_v, x)
    return ff + pid_step(params, state, v_set, v, dt)
