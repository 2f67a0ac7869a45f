"""Electro-pneumatic blended brake of a metro train (paper 000 section 1.1).

Signal path, per control step::

    ATO demand F_req [N]
      -> input delay (exact buffer, paper Table 1: 0.3 s)
      -> jerk limit on the demand (rate limit, N/s)
      -> brake manager: electric first, up to its speed-dependent limit
           E_cmd = min(F_cmd, E_max(v) * cars_in / cars, fade envelope)
         traction units deliver E with a first-order lag (electric_lag_s)
      -> air makes up what electric actually delivers short of the demand
           A_cmd = F_cmd - E   (the gateway valve reads applied electric from TCMS)
         brake cylinder: first-order lag (paper eq. 4, T = 0.65 s)
         shoe force = A * g(v), g = mu(v)/mu0 (paper eq. 3, 5)

Below the changeover speed (6 km/h) traction sends its pre-notice and, after
``prenotice_s``, fades the electric brake out at ``fade_rate_n_per_s``; on the
pre-notice the brake manager starts ramping air in at the same rate, so that air
(behind its cylinder lag) arrives as electric leaves. With ``prenotice_s = 0`` air
simply fills what electric no longer delivers, a lag late. A slide cut-out removes
one motor car's share of electric brake at once at ``cutout_time_s``; air takes it
over through the same path.

If the train speeds back above the changeover speed (a down-grade), the fade is
called off: traction ramps its electric brake envelope back up at the fade rate from
wherever the fade had taken it, the brake manager ramps its expectation of electric
back at the same rate, and air is released only as electric is actually delivered
(never ahead of it). Once the expectation has reached what electric can give, the
brake is back in its normal state, so the next fall below the changeover speed starts
a new fade -- a new pre-notice from the electric brake delivered then, and a ramp at
the fade rate -- never a cut. The phases (``PHASE_*``) are in ``state[S_PHASE]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from railpilot.brakes.base import PackContext
from railpilot.brakes.friction import BETA1, BETA2, BETA3
from railpilot.brakes.lag_delay import ring_back, ring_next
from railpilot.checks import check_count, check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import KMH_PER_MPS, kn_to_n, n_to_kn

(
    P_DELAY_N,
    P_JERK_RATE,
    P_E_FMAX,
    P_E_PMAX,
    P_CARS,
    P_CUT_CARS,
    P_CUT_T,
    P_V_CO,
    P_FADE,
    P_ALPHA_E,
    P_ALPHA_A,
    P_B1,
    P_B2,
    P_B3,
    P_PRENOTICE,
    P_BUF_LEN,
) = range(16)
N_PARAMS = 16
S_K, S_FCMD, S_E, S_A, S_ENV0, S_PHASE, S_T0, S_EXP0 = range(8)
N_STATE = 8
#: ``state[S_PHASE]``: electric brake unrestricted; fading out below the changeover
#: speed (pre-notice at ``S_T0``); returning after the speed rose back above it (since
#: ``S_T0``). ``S_ENV0`` and ``S_EXP0``: traction's envelope and the brake manager's
#: expected electric when the current phase began [N].
PHASE_NORMAL, PHASE_FADING, PHASE_RETURNING = 0.0, 1.0, 2.0


#: longest delay, lag or pre-notice the EP brake model accepts [s]
MAX_TIME_S = 60.0


@dataclass(frozen=True)
class EPBrake:
    """Parameters of the blended brake.

    Attributes
    ----------
    delay_s
        Input delay of the brake system [s] (paper Table 1: 0.3 s); a whole number of
        simulation steps.
    air_lag_s
        Brake cylinder time constant ``T`` [s] (paper Table 1: 0.65 s).
    electric_lag_s
        Traction units' electric brake time constant [s]. Not in the paper; 0.3 s.
    jerk_limit_mps3
        Rate limit on the demand, as deceleration rate [m/s^3] of the nominal train.
    changeover_kmh
        Electric/air changeover speed [km/h] (paper: 6).
    fade_rate_n_per_s
        Rate the electric brake fades out (and air ramps in) below changeover [N/s].
    prenotice_s
        Time [s] between traction's fade pre-notice and the start of its fade-out;
        default: the air lag, so the air ramp arrives in step with the fade.
    cutout_cars, cutout_time_s
        Motor cars whose electric brake is cut (slide) and when [s]; 0 cars = none.
    beta1, beta2, beta3
        Shoe friction coefficients of eq. 3.
    """

    delay_s: float = 0.3
    air_lag_s: float = 0.65
    electric_lag_s: float = 0.3
    jerk_limit_mps3: float = 0.75
    changeover_kmh: float = 6.0
    fade_rate_n_per_s: float = 300e3
    prenotice_s: float = 0.65
    cutout_cars: int = 0
    cutout_time_s: float = 0.0
    beta1: float = BETA1
    beta2: float = BETA2
    beta3: float = BETA3

    def __post_init__(self) -> None:
        for name in (
            "delay_s",
            "air_lag_s",
            "electric_lag_s",
            "changeover_kmh",
            "cutout_time_s",
            "beta1",
            "beta2",
            "prenotice_s",
        ):
            check_number(
                f"brake.{name}",
                getattr(self, name),
                minimum=0.0,
                error=ConfigError,
            )
        for name in ("jerk_limit_mps3", "fade_rate_n_per_s", "beta3"):
            check_number(
                f"brake.{name}",
                getattr(self, name),
                positive=True,
                error=ConfigError,
            )
        check_count(
            "brake.cutout_cars", self.cutout_cars, 0, allowed="an integer >= 0", error=ConfigError
        )
        # a brake slower than a minute is a configuration error, not a brake
        for name in ("delay_s", "air_lag_s", "electric_lag_s", "prenotice_s"):
            value = getattr(self, name)
            if value > MAX_TIME_S:
                raise ConfigError(f"brake.{name}", value, f"a number in [0, {MAX_TIME_S:g}] s")

    name: ClassVar[str] = "ep-blended"
    #: scenario-file keys written in other units or as one list (brakes/base.py)
    FILE_KEYS: ClassVar[dict[str, tuple[str, Any, Any]]] = {
        "fade_rate_kn_per_s": ("fade_rate_n_per_s", kn_to_n, n_to_kn)
    }
    FILE_LISTS: ClassVar[dict[str, tuple[str, ...]]] = {"beta": ("beta1", "beta2", "beta3")}

    @property
    def lead_s(self) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the air path (what the ATO must lead)."""
        return self.delay_s, self.air_lag_s

    def sizes(self, params: np.ndarray) -> tuple[int, int]:
        """Floats of state and of delay line (brakes/base.py)."""
        return N_STATE, int(params[P_BUF_LEN])

    def pack(self, context: PackContext) -> np.ndarray:
        """The kernel's parameters for the context's step, train and load-weighed mass."""
        eb = context.train.electric_brake
        return self.pack_arrays(
            context.dt_s,
            context.load_weighed_eff_mass_kg,
            eb.max_force_n,
            eb.max_power_w,
            context.train.motor_cars,
        )

    def pack_arrays(
        self,
        dt: float,
        effective_mass_kg: float,
        max_force_n: float,
        max_power_w: float,
        motor_cars: int,
    ) -> np.ndarray:
        """The kernel's parameter array for step ``dt`` [s] and the brake manager's mass."""
        steps = self.delay_s / dt
        n = round(steps)
        if abs(steps - n) > 1e-6:
            raise ConfigError(
                "brake.delay_s", self.delay_s, f"a whole number of simulation steps (dt = {dt} s)"
            )
        if self.cutout_cars > motor_cars:
            raise ConfigError(
                "brake.cutout_cars", self.cutout_cars, f"at most train.motor_cars = {motor_cars}"
            )
        p = np.zeros(N_PARAMS)
        p[P_DELAY_N] = n
        p[P_JERK_RATE] = self.jerk_limit_mps3 * effective_mass_kg
        p[P_E_FMAX] = max_force_n
        p[P_E_PMAX] = max_power_w
        p[P_CARS] = motor_cars
        p[P_CUT_CARS] = self.cutout_cars
        p[P_CUT_T] = self.cutout_time_s
        p[P_V_CO] = self.changeover_kmh / KMH_PER_MPS
        p[P_FADE] = self.fade_rate_n_per_s
        p[P_ALPHA_E] = np.exp(-dt / self.electric_lag_s) if self.electric_lag_s > 0 else 0.0
        p[P_ALPHA_A] = np.exp(-dt / self.air_lag_s) if self.air_lag_s > 0 else 0.0
        p[P_B1] = self.beta1
        p[P_B2] = self.beta2
        p[P_B3] = self.beta3
        p[P_PRENOTICE] = self.prenotice_s
        p[P_BUF_LEN] = n + 1
        return p


@njit(cache=True)
def ep_brake_step(
    p: np.ndarray,
    state: np.ndarray,
    buffer: np.ndarray,
    demand_n: float,
    speed_mps: float,
    t: float,
    dt: float,
) -> tuple[float, float]:
    """Advance the blended brake one step; return (electric [N], air shoe force [N]).

    ``state = [k, F_cmd, E, A, envelope at phase start, phase, phase start time, expected
    electric at phase start]`` (``S_*``; all zeros is the initial state); ``buffer`` has
    ``delay steps + 1`` slots.

    Notes
    -----
    The changeover is a three-phase machine on ``state[S_PHASE]``:

    * ``PHASE_NORMAL``: no envelope; at ``v <= v_co`` -> ``PHASE_FADING`` with the
      envelope and the expectation starting from the electric brake delivered then;
    * ``PHASE_FADING`` (pre-notice at ``t0``): the brake manager expects
      ``E0 - r (t - t0)``, traction allows ``E0 - r max(t - t0 - prenotice, 0)``; at
      ``v > v_co`` -> ``PHASE_RETURNING`` from both values at that instant;
    * ``PHASE_RETURNING`` (from ``t0``): both rise at ``r`` from where they were; at
      ``v <= v_co`` -> ``PHASE_FADING`` again (a new pre-notice); once the expectation
      reaches the available electric brake -> ``PHASE_NORMAL``.

    Envelope and expectation move at ``r`` (``fade_rate_n_per_s``) in every phase and
    are continuous across the transitions, so electric never steps (except a cut-out,
    which is one), and air, commanded to ``F_cmd - min(E, expected)``, never steps
    either: with a held demand the brake force changes at most ``r g(v)`` per second.
    """
    length = int(p[P_BUF_LEN])
    k = int(state[S_K])  # the ring's write slot
    buffer[k] = demand_n
    delayed = buffer[ring_back(k, int(p[P_DELAY_N]), length)]
    state[S_K] = ring_next(k, length)

    # jerk limit: the demand the brake manager acts on moves at a bounded rate
    step = p[P_JERK_RATE] * dt
    f_cmd = state[S_FCMD]
    if delayed > f_cmd + step:
        f_cmd += step
    elif delayed < f_cmd - step:
        f_cmd -= step
    else:
        f_cmd = delayed
    state[S_FCMD] = f_cmd

    v = max(speed_mps, 1e-9)
    cars_in = p[P_CARS]
    if t >= p[P_CUT_T]:
        cars_in -= p[P_CUT_CARS]
    e_avail = min(p[P_E_FMAX], p[P_E_PMAX] / v) * cars_in / p[P_CARS]
    rate = p[P_FADE]
    below = speed_mps <= p[P_V_CO]
    phase = state[S_PHASE]
    if phase == PHASE_FADING and not below:
        # the train sped back above changeover: the fade is called off where it stands
        elapsed = t - state[S_T0]
        env = max(state[S_ENV0] - rate * max(elapsed - p[P_PRENOTICE], 0.0), 0.0)
        state[S_EXP0] = max(state[S_EXP0] - rate * elapsed, 0.0)
        state[S_ENV0] = env
        state[S_T0] = t
        phase = PHASE_RETURNING
    elif phase != PHASE_FADING and below:
        # traction's pre-notice: fade out from the electric brake delivered now; the
        # brake manager's expectation starts there too, or lower if it was still
        # returning (air then never steps down)
        expected_now = np.inf
        if phase == PHASE_RETURNING:
            expected_now = state[S_EXP0] + rate * (t - state[S_T0])
        state[S_ENV0] = state[S_E]
        state[S_EXP0] = min(state[S_E], expected_now)
        state[S_T0] = t
        phase = PHASE_FADING
    # what the brake manager expects electric to deliver
    e_expected = np.inf
    if phase == PHASE_FADING:
        elapsed = t - state[S_T0]
        e_expected = max(state[S_EXP0] - rate * elapsed, 0.0)
        traction_env = max(state[S_ENV0] - rate * max(elapsed - p[P_PRENOTICE], 0.0), 0.0)
        e_avail = min(e_avail, traction_env)
    elif phase == PHASE_RETURNING:
        ramp = rate * (t - state[S_T0])
        e_expected = state[S_EXP0] + ramp
        if e_expected >= e_avail:
            phase = PHASE_NORMAL  # electric is fully back: no envelope any more
            e_expected = np.inf
        else:
            e_avail = min(e_avail, state[S_ENV0] + ramp)
    state[S_PHASE] = phase
    e_cmd = min(f_cmd, e_avail)
    # traction follows its command with a lag, but never above what is available:
    # a cut-out removes a car's share at once and the fade ramps out at its own rate
    e = min(e_cmd + (state[S_E] - e_cmd) * p[P_ALPHA_E], e_avail)
    state[S_E] = e

    a_cmd = max(f_cmd - min(e, e_expected), 0.0)
    a = a_cmd + (state[S_A] - a_cmd) * p[P_ALPHA_A]
    state[S_A] = a
    v_kmh = speed_mps * KMH_PER_MPS
    g = (p[P_B1] * np.exp(-p[P_B2] * v_kmh) + p[P_B3]) / p[P_B3]
    return e, a * g


@njit(cache=True)
def ep_ato_step(
    p: np.ndarray,
    state: np.ndarray,
    buffer: np.ndarray,
    u: float,
    speed_mps: float,
    t: float,
    dt: float,
    m_eff_lw: float,
    m_eff: float,
) -> tuple[float, float, float]:
    """The EP brake in the simulator (the step of brakes/base.py).

    The ATO's braking command becomes a force demand through the load-weighed mass.
    """
    demand = -u * m_eff_lw if u < 0.0 else 0.0
    e_n, air_n = ep_brake_step(p, state, buffer, demand, speed_mps, t, dt)
    return e_n, air_n, demand
