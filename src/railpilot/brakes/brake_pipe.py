"""Heavy-haul automatic air brake: the brake-pipe wave and each wagon group's cylinder.

The ATO's command sets the brake-pipe reduction at the locomotive; the reduction travels
down the train as a wave, and each part of the train fills its brake cylinders with its
own lag once the wave reaches it. So the rear of a 1,600 m train brakes seconds after the
front (issue 9, item 6). Model, sources and validation: docs/heavy-haul-brake.md.

Model (``n`` groups of wagons, ``j = 0 .. n-1``)::

    uc(t)    = clip(-u(t) / a_max, 0, 1)               demanded fraction of full service
    x_j      = j L / (n - 1)                            group j's distance from the front [m]
    d_a,j    = t_r + x_j / c_a,   d_r,j = t_r + x_j / c_r   wave arrival delays [s]
    r_j(t)   = max(uc(t - d_a,j), uc(t - d_r,j))       received target (c_a >= c_r; min else)
    dy_j/dt  = (r_j - y_j) / T_a   if r_j > y_j         application (cylinder filling)
             = (r_j - y_j) / T_r   otherwise            release (cylinder venting)
    F_air    = sum_j y_j / n * a_max * m_eff            [N]

``L`` the train length, ``c_a`` / ``c_r`` the application / release wave speeds, ``t_r`` a
reaction (dead) time at the locomotive, ``T_a = t_app / ln 20`` so that a group reaches
95 % of a step in the application time ``t_app``, and ``T_r = t_rel / ln(3.8 / 0.4)`` so
that a full cylinder (3.8 bar) vents to 0.4 bar in the release time ``t_rel`` (the end
points of the UIC single-wagon test). Application waves travel at ``c_a`` and release
waves at ``c_r``: with ``c_a > c_r`` a release that a re-application overtakes never
reaches the rear, which ``max`` gives.

The kernel is exact for a command held over each step (zero-order hold): one command
history (a ring buffer, sized for the slowest wave to the rear) serves every group; a
delay that is not a whole number of steps switches the delayed command within the step,
and each group's lag is advanced exactly (``exp(-h / T)``) over each part of the step, as
in brakes/lag_delay.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numba import njit
from scipy.optimize import brentq

from railpilot.brakes.base import PackContext
from railpilot.brakes.lag_delay import MAX_DELAY_STEPS, ring_back, ring_next
from railpilot.errors import ConfigError
from railpilot.units import Num

# --- params layout -------------------------------------------------------------------------
#: number of groups; ring-buffer length; a_max [m/s^2]; 1.0 if the application wave is at
#: least as fast as the release wave (the received target is then the max of the two
#: delayed commands, else the min)
P_N_SEG, P_BUF_LEN, P_A_MAX, P_APPLY_FASTER = range(4)
#: first group's block; each group has SEG_STRIDE floats
P_SEG0 = 4
#: per group: whole steps of the application / release delay; 1.0 if the application
#: delay's fractional part is the smaller one (it switches first within a step); the
#: group's share of the brake force [-]; then exp(-h/T_a), exp(-h/T_r) for the three parts
#: of a step (before, between and after the two switches)
(
    SEG_N_APP,
    SEG_N_REL,
    SEG_APP_FIRST,
    SEG_SHARE,
    SEG_ALPHA1_APP,
    SEG_ALPHA1_REL,
    SEG_ALPHA2_APP,
    SEG_ALPHA2_REL,
    SEG_ALPHA3_APP,
    SEG_ALPHA3_REL,
) = range(10)
SEG_STRIDE = 10
# --- state layout: step index, then each group's cylinder fraction [-] ----------------------
ST_K = 0
ST_Y0 = 1

# --- published and assumed numbers ---------------------------------------------------------
#: application wave speed [m/s]: 250-280 m/s with the distributors' accelerators, 90-180 m/s
#: without (de.wikipedia "Durchschlagsgeschwindigkeit"); the low end of the first range
APPLICATION_WAVE_MPS = 250.0
#: release wave speed [m/s], ASSUMED: no accelerator helps a release, so a value inside the
#: 90-180 m/s the same source gives for a pipe without them
RELEASE_WAVE_MPS = 150.0
#: UIC application time (to 95 % of the maximum cylinder pressure) and release time (to
#: 0.4 bar) ranges per brake position [s]: G 18-30 / 45-60, P 3-5 / 15-20
UIC_TIMES_S: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {
    "G": ((18.0, 30.0), (45.0, 60.0)),
    "P": ((3.0, 5.0), (15.0, 20.0)),
}
#: the middle of each range, the default of a brake position: (application, release) [s]
NOMINAL_TIMES_S: dict[str, tuple[float, float]] = {
    pos: (sum(app) / 2.0, sum(rel) / 2.0) for pos, (app, rel) in UIC_TIMES_S.items()
}
#: the application time ends at 95 % of the maximum cylinder pressure
APPLIED_FRACTION = 0.95
#: the release time ends when a 3.8 bar cylinder has vented to 0.4 bar
RELEASED_FRACTION = 0.4 / 3.8

#: bounds of the configuration (a configuration error beyond them, not a brake)
MAX_SEGMENTS = 200
MAX_WAVE_MPS = 400.0  # a pressure wave in the pipe does not outrun sound (~340 m/s)
MAX_TIME_S = 120.0
MAX_REACTION_S = 60.0

BrakePosition = Literal["G", "P"]


def application_lag_s(application_time_s: float) -> float:
    """First-order time constant [s] that reaches 95 % in ``application_time_s`` [s]."""
    return application_time_s / np.log(1.0 / (1.0 - APPLIED_FRACTION))


def release_lag_s(release_time_s: float) -> float:
    """First-order time constant [s] that vents 3.8 to 0.4 bar in ``release_time_s`` [s]."""
    return release_time_s / np.log(1.0 / RELEASED_FRACTION)


def segment_positions_m(train_length_m: float, n_segments: int) -> np.ndarray:
    """Each group's distance from the front [m]: ``x_j = j L / (n - 1)``.

    The first group is at the locomotive's brake valve, the last at the rear end; every
    group carries the same share ``1 / n`` of the brake force.
    """
    return np.linspace(0.0, float(train_length_m), int(n_segments))


@dataclass(frozen=True)
class BrakePipeBrake:
    """Parameters of the brake-pipe model (module docstring).

    Attributes
    ----------
    position
        Brake position, ``"G"`` (goods) or ``"P"`` (passenger): the default application
        and release times are the middle of its UIC range (G 24 s / 52.5 s, P 4 s /
        17.5 s).
    application_time_s
        Time [s] for a group's cylinder to reach 95 % of a step once the wave has reached
        it; None = the position's. UIC: G 18-30 s, P 3-5 s.
    release_time_s
        Time [s] for a full cylinder (3.8 bar) to vent to 0.4 bar once the release wave has
        reached it; None = the position's. UIC: G 45-60 s, P 15-20 s.
    application_wave_mps
        Speed [m/s] of the application wave along the brake pipe (250 m/s; 250-280 m/s
        with accelerators).
    release_wave_mps
        Speed [m/s] of the release wave (150 m/s, assumed).
    n_segments
        Groups of wagons the train is split into (2 to 200), equal shares of the brake
        force, spread evenly from the locomotive (x = 0) to the rear (x = L).
    max_decel_mps2
        ``a_max`` [m/s^2]: the full-service air brake's deceleration of the train; all
        groups fully applied give ``a_max`` times the true effective mass.
    reaction_s
        Dead time [s] between the command and the start of the brake-pipe reduction at the
        locomotive (brake controller, driver's brake valve); 0 by default.

    The train length is the run's (``PackContext.train.length_m``).
    """

    position: BrakePosition = "G"
    application_time_s: float | None = None
    release_time_s: float | None = None
    application_wave_mps: float = APPLICATION_WAVE_MPS
    release_wave_mps: float = RELEASE_WAVE_MPS
    n_segments: int = 40
    max_decel_mps2: float = 0.5
    reaction_s: float = 0.0

    name: ClassVar[str] = "brake-pipe"
    #: no electric brake, so no changeover
    changeover_kmh: ClassVar[float] = 0.0

    def __post_init__(self) -> None:
        if self.position not in UIC_TIMES_S:
            raise ConfigError("brake.position", self.position, "'G' or 'P'")
        for name in ("application_time_s", "release_time_s"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and 0 < value <= MAX_TIME_S):
                raise ConfigError(f"brake.{name}", value, f"a number in (0, {MAX_TIME_S:g}] s")
        for name in ("application_wave_mps", "release_wave_mps"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 < value <= MAX_WAVE_MPS):
                raise ConfigError(f"brake.{name}", value, f"a speed in (0, {MAX_WAVE_MPS:g}] m/s")
        if not (
            isinstance(self.n_segments, int | np.integer)
            and not isinstance(self.n_segments, bool)
            and 2 <= self.n_segments <= MAX_SEGMENTS
        ):
            raise ConfigError(
                "brake.n_segments", self.n_segments, f"an integer in [2, {MAX_SEGMENTS}]"
            )
        if not (np.isfinite(self.max_decel_mps2) and self.max_decel_mps2 > 0):
            raise ConfigError("brake.max_decel_mps2", self.max_decel_mps2, "a number > 0")
        if not (np.isfinite(self.reaction_s) and 0 <= self.reaction_s <= MAX_REACTION_S):
            raise ConfigError(
                "brake.reaction_s", self.reaction_s, f"a number in [0, {MAX_REACTION_S:g}] s"
            )

    @property
    def application_s(self) -> float:
        """The application time in use [s] (the position's unless given)."""
        if self.application_time_s is not None:
            return float(self.application_time_s)
        return NOMINAL_TIMES_S[self.position][0]

    @property
    def release_s(self) -> float:
        """The release time in use [s] (the position's unless given)."""
        if self.release_time_s is not None:
            return float(self.release_time_s)
        return NOMINAL_TIMES_S[self.position][1]

    @property
    def lead_s(self) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the front of the train: ``(t_r, T_a)``.

        brakes/base.py gives ``lead_s`` no train; for the whole train use
        :meth:`train_lead_s`, whose sum is the equivalent build-up time.
        """
        return self.reaction_s, application_lag_s(self.application_s)

    def train_lead_s(self, train_length_m: float) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the whole train: ``(t_r + L / (2 c_a), T_a)``.

        The mean wave delay plus the group lag: a dead time and a lag with the same
        equivalent build-up time (:func:`equivalent_build_up_time_s`).
        """
        delay = self.reaction_s + float(train_length_m) / (2.0 * self.application_wave_mps)
        return delay, application_lag_s(self.application_s)

    def sizes(self, params: np.ndarray) -> tuple[int, int]:
        """Floats of state (step index, one fraction per group) and of command history."""
        params = np.asarray(params, dtype=float)
        if params.ndim != 1 or params.size < P_SEG0:
            raise ConfigError("brake.params", params.shape, "a brake-pipe params array")
        n = int(params[P_N_SEG])
        if params.size != P_SEG0 + n * SEG_STRIDE or not 2 <= n <= MAX_SEGMENTS:
            raise ConfigError(
                "brake.params", params.size, f"{P_SEG0} + {SEG_STRIDE} floats per group"
            )
        return ST_Y0 + n, int(params[P_BUF_LEN])

    def pack(self, context: PackContext) -> np.ndarray:
        """The kernel's params for the context's step and train (brakes/base.py)."""
        return self.pack_arrays(context.dt_s, context.train.length_m)

    def pack_arrays(self, dt: float, train_length_m: float) -> np.ndarray:
        """The kernel's params for step ``dt`` [s] and a train ``train_length_m`` [m] long."""
        if not (np.isfinite(dt) and dt > 0):
            raise ConfigError("sim.dt_s", dt, "a finite number > 0 [s]")
        if not (np.isfinite(train_length_m) and train_length_m > 0):
            raise ConfigError("train.length_m", train_length_m, "a finite number > 0")
        n = self.n_segments
        x = segment_positions_m(train_length_m, n)
        delay_app = self.reaction_s + x / self.application_wave_mps
        delay_rel = self.reaction_s + x / self.release_wave_mps
        longest = float(max(delay_app[-1], delay_rel[-1]))
        if longest / dt > MAX_DELAY_STEPS:
            raise ConfigError(
                "sim.dt_s",
                dt,
                f"at least {longest / MAX_DELAY_STEPS:.3g} s: the slowest wave takes "
                f"{longest:.3g} s to the rear and the delay line has at most "
                f"{MAX_DELAY_STEPS:,} steps",
            )
        lag_app = application_lag_s(self.application_s)
        lag_rel = release_lag_s(self.release_s)
        p = np.zeros(P_SEG0 + n * SEG_STRIDE)
        p[P_N_SEG] = n
        p[P_A_MAX] = self.max_decel_mps2
        p[P_APPLY_FASTER] = 1.0 if self.application_wave_mps >= self.release_wave_mps else 0.0
        n_max = 0
        for j in range(n):
            n_a, f_a = _whole_and_fraction(delay_app[j] / dt)
            n_r, f_r = _whole_and_fraction(delay_rel[j] / dt)
            n_max = max(n_max, n_a, n_r)
            first, second = min(f_a, f_r), max(f_a, f_r)
            parts = (first * dt, (second - first) * dt, (1.0 - second) * dt)
            b = P_SEG0 + j * SEG_STRIDE
            p[b + SEG_N_APP] = n_a
            p[b + SEG_N_REL] = n_r
            p[b + SEG_APP_FIRST] = 1.0 if f_a <= f_r else 0.0
            p[b + SEG_SHARE] = 1.0 / n
            for i, h in enumerate(parts):
                p[b + SEG_ALPHA1_APP + 2 * i] = np.exp(-h / lag_app)
                p[b + SEG_ALPHA1_REL + 2 * i] = np.exp(-h / lag_rel)
        # the oldest command read is n + 1 steps back, and the newest is written first
        p[P_BUF_LEN] = n_max + 2
        return p


def _whole_and_fraction(steps: float) -> tuple[int, float]:
    """``steps = n + f`` with ``n`` whole and ``0 <= f < 1`` (a whole number if within 1e-9)."""
    n = int(np.floor(steps + 1e-9))
    frac = steps - n
    return n, (frac if frac > 1e-9 else 0.0)


@njit(cache=True)
def _toward(y: float, target: float, alpha_app: float, alpha_rel: float) -> float:
    """Advance a first-order lag one part of a step toward a held target."""
    if target > y:
        return target + (y - target) * alpha_app
    return target + (y - target) * alpha_rel


@njit(cache=True)
def _received(applied: float, released: float, apply_faster: bool) -> float:
    """The target a group holds from the command as the two waves deliver it."""
    if apply_faster:
        return max(applied, released)
    return min(applied, released)


@njit(cache=True)
def brake_pipe_ato_step(
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
    """The brake-pipe brake in the simulator (the step of brakes/base.py).

    The ATO's command becomes the demanded fraction ``uc = clip(-u / a_max, 0, 1)``; each
    group follows it as the waves deliver it (module docstring); the air force acts with
    ``a_max`` on the true effective mass. No electric brake. ``state``: the step index and
    each group's cylinder fraction (all zeros: released); ``buffer``: the command history.
    """
    a_max = p[P_A_MAX]
    uc = min(max(-u / a_max, 0.0), 1.0)
    length = int(p[P_BUF_LEN])
    k = int(state[ST_K])  # the ring's write slot
    buffer[k] = uc
    state[ST_K] = ring_next(k, length)
    apply_faster = p[P_APPLY_FASTER] > 0.0
    total = 0.0
    for j in range(int(p[P_N_SEG])):
        b = P_SEG0 + j * SEG_STRIDE
        n_a = int(p[b + SEG_N_APP])
        n_r = int(p[b + SEG_N_REL])
        app_old = buffer[ring_back(k, n_a + 1, length)]
        app_new = buffer[ring_back(k, n_a, length)]
        rel_old = buffer[ring_back(k, n_r + 1, length)]
        rel_new = buffer[ring_back(k, n_r, length)]
        y = state[ST_Y0 + j]
        # before either delayed command switches within this step
        target = _received(app_old, rel_old, apply_faster)
        y = _toward(y, target, p[b + SEG_ALPHA1_APP], p[b + SEG_ALPHA1_REL])
        # between the two switches
        if p[b + SEG_APP_FIRST] > 0.0:
            target = _received(app_new, rel_old, apply_faster)
        else:
            target = _received(app_old, rel_new, apply_faster)
        y = _toward(y, target, p[b + SEG_ALPHA2_APP], p[b + SEG_ALPHA2_REL])
        # after both
        target = _received(app_new, rel_new, apply_faster)
        y = _toward(y, target, p[b + SEG_ALPHA3_APP], p[b + SEG_ALPHA3_REL])
        state[ST_Y0 + j] = y
        total += y * p[b + SEG_SHARE]
    return 0.0, total * a_max * m_eff, uc * a_max * m_eff


# --- analytic responses (tests, docs, ATO tuning) ------------------------------------------


def segment_pressure_fraction(
    t_s: Num,
    x_m: Num,
    *,
    to_fraction: float = 1.0,
    from_fraction: float = 0.0,
    application_time_s: float = NOMINAL_TIMES_S["G"][0],
    release_time_s: float = NOMINAL_TIMES_S["G"][1],
    application_wave_mps: float = APPLICATION_WAVE_MPS,
    release_wave_mps: float = RELEASE_WAVE_MPS,
    reaction_s: float = 0.0,
) -> np.ndarray:
    """Brake-pipe model: cylinder fraction [-] at ``x_m`` [m] at ``t_s`` [s] after a step.

    The command steps from ``from_fraction`` (held long enough to be steady) to
    ``to_fraction`` at ``t = 0``. Broadcasts over ``t_s`` and ``x_m``.

    Notes
    -----
    An application (``to > from``) reaches ``x`` after ``d = t_r + x / c_a`` and fills with
    ``T_a = t_app / ln 20``; a release after ``t_r + x / c_r`` with ``T_r = t_rel /
    ln(3.8 / 0.4)``::

        y(t, x) = from                                              for t < d
        y(t, x) = to + (from - to) exp(-(t - d) / T)                for t >= d
    """
    t = np.asarray(t_s, dtype=float)
    x = np.asarray(x_m, dtype=float)
    if to_fraction >= from_fraction:
        delay = reaction_s + x / application_wave_mps
        lag = application_lag_s(application_time_s)
    else:
        delay = reaction_s + x / release_wave_mps
        lag = release_lag_s(release_time_s)
    elapsed = t - delay
    decay = np.exp(-np.maximum(elapsed, 0.0) / lag)
    return np.where(
        elapsed >= 0.0, to_fraction + (from_fraction - to_fraction) * decay, from_fraction
    )


def train_force_fraction(
    t_s: Num,
    train_length_m: float,
    *,
    n_segments: int | None = 40,
    application_time_s: float = NOMINAL_TIMES_S["G"][0],
    wave_speed_mps: float = APPLICATION_WAVE_MPS,
    reaction_s: float = 0.0,
) -> np.ndarray:
    """Brake-pipe model: the train's air force [fraction of full service] after a full step.

    ``n_segments`` groups at :func:`segment_positions_m`, equal shares; ``None`` = the
    continuous limit (brake force spread evenly along the train). Vectorised over ``t_s``.

    Notes
    -----
    The mean of the groups' step responses. In the continuous limit, with ``D = L / c``,
    ``s = t - t_r`` and ``T = T_a``::

        F(s) = 0                                               s < 0
        F(s) = (s - T (1 - exp(-s / T))) / D                   0 <= s < D
        F(s) = 1 - T exp(-s / T) (exp(D / T) - 1) / D          s >= D
    """
    t = np.asarray(t_s, dtype=float)
    lag = application_lag_s(application_time_s)
    if n_segments is not None:
        x = segment_positions_m(train_length_m, n_segments)
        y = segment_pressure_fraction(
            t[..., np.newaxis],
            x,
            application_time_s=application_time_s,
            application_wave_mps=wave_speed_mps,
            reaction_s=reaction_s,
        )
        return np.asarray(y.mean(axis=-1))
    span = float(train_length_m) / wave_speed_mps
    s = t - reaction_s
    s_pos = np.maximum(s, 0.0)
    ramp = (s_pos - lag * (1.0 - np.exp(-s_pos / lag))) / span
    # exp(-(s - D)/T) - exp(-s/T), written so neither factor overflows
    tail = 1.0 - lag * np.exp(-np.maximum(s - span, 0.0) / lag) * (-np.expm1(-span / lag)) / span
    return np.where(s < 0.0, 0.0, np.where(s < span, ramp, tail))


def build_up_time_s(
    train_length_m: Num,
    *,
    fraction: float = APPLIED_FRACTION,
    n_segments: int | None = 40,
    application_time_s: float = NOMINAL_TIMES_S["G"][0],
    wave_speed_mps: float = APPLICATION_WAVE_MPS,
    reaction_s: float = 0.0,
) -> np.ndarray:
    """Brake-pipe model: time [s] for the train's air force to reach ``fraction`` (95 %).

    After a full-service step at ``t = 0``; vectorised over ``train_length_m`` [m]. The
    quantity SUBSET-026 calls ``t2``, the end of ``T_brake_increase`` (3.13.2.2.3.2.3).

    Notes
    -----
    The root of ``train_force_fraction(t) = fraction`` (scipy.optimize.brentq); the force is
    continuous and strictly increasing after ``t_r``, 0 before, and reaches ``fraction`` by
    ``t_r + L / c + T_a ln(1 / (1 - fraction))`` (every group by then).
    """
    if not 0.0 < fraction < 1.0:
        raise ConfigError("fraction", fraction, "a number in (0, 1)")
    lengths = np.asarray(train_length_m, dtype=float)
    out = np.empty(lengths.shape)
    for index, length in np.ndenumerate(lengths):
        out[index] = _time_to_fraction(
            float(length),
            fraction,
            n_segments=n_segments,
            application_time_s=application_time_s,
            wave_speed_mps=wave_speed_mps,
            reaction_s=reaction_s,
        )
    return out


def _time_to_fraction(
    train_length_m: float,
    fraction: float,
    *,
    n_segments: int | None,
    application_time_s: float,
    wave_speed_mps: float,
    reaction_s: float,
) -> float:
    """The root of ``train_force_fraction(t) = fraction`` for one train (build_up_time_s)."""

    def short_of(t: float) -> float:
        force = train_force_fraction(
            t,
            train_length_m,
            n_segments=n_segments,
            application_time_s=application_time_s,
            wave_speed_mps=wave_speed_mps,
            reaction_s=reaction_s,
        )
        return float(force) - fraction

    lag = application_lag_s(application_time_s)
    upper = reaction_s + train_length_m / wave_speed_mps + lag * np.log(1.0 / (1.0 - fraction))
    return float(brentq(short_of, reaction_s, upper + 1e-9, xtol=1e-12, rtol=1e-14))


def equivalent_build_up_time_s(
    train_length_m: Num,
    *,
    application_time_s: float = NOMINAL_TIMES_S["G"][0],
    wave_speed_mps: float = APPLICATION_WAVE_MPS,
    reaction_s: float = 0.0,
) -> np.ndarray:
    """Brake-pipe model: equivalent brake build-up time [s] of a full-service step.

    ``T_e = integral_0^inf (1 - F(t)) dt``: the dead time after which full force would give
    the same speed loss as the real build-up ``F``. SUBSET-026 3.13.2.2.3.2.4 defines its
    ``T_brake_build_up = T_brake_react + T_brake_increase / 2``, which is this integral for
    its ramp model. Vectorised over ``train_length_m`` [m].

    Notes
    -----
    The integral of a delayed first-order step is ``d + T``; averaged over groups spread
    evenly from 0 to ``L`` (any number of them, or the continuous limit)::

        T_e = t_r + L / (2 c_a) + T_a,    T_a = t_app / ln 20
    """
    length = np.asarray(train_length_m, dtype=float)
    return reaction_s + length / (2.0 * wave_speed_mps) + application_lag_s(application_time_s)


# --- the published reference: ETCS conversion model ----------------------------------------

#: SUBSET-026-3 A.3.8.6 and A.3.9.8: T_brake_emergency_react and T_brake_service_react [s]
#: of freight trains in G and in P
ETCS_REACT_S: dict[tuple[str, str], float] = {
    ("G", "emergency"): 9.30,
    ("G", "service"): 5.70,
    ("P", "emergency"): 2.99,
    ("P", "service"): 2.07,
}
#: SUBSET-026-3 A.3.8.3 and A.3.9.1-3: the conversion model's longest freight train [m]
ETCS_MAX_LENGTH_M = 1500.0


def etcs_build_up_time_s(
    train_length_m: Num,
    position: BrakePosition,
    brake: Literal["service", "emergency"] = "service",
    *,
    extrapolate: bool = False,
) -> np.ndarray:
    """ETCS conversion model: basic equivalent brake build-up time [s] of a freight train.

    ``T_brake_basic_sb`` (A.3.9.2-3) or ``T_brake_basic_eb`` (A.3.8.2-3) of ERA SUBSET-026-3
    (ETCS SRS, chapter 3 appendix), which the model uses as ``T_brake_service_cm0`` /
    ``T_brake_emergency_cm0`` for a target at zero speed. Valid up to 1,500 m; longer
    ``train_length_m`` [m] is an error unless ``extrapolate``.

    Notes
    -----
    ``T = a + b (L/100) + c (L/100)^2`` with ``L`` in m and

    ===========  =========  ==========================  ==========================
    brake        position   L <= 900 m: a, b, c          900 < L <= 1500 m: a, b, c
    ===========  =========  ==========================  ==========================
    service      P          3.00, 2.77, 0.00             10.50, 0.32, 0.18
    service      G          3.00, 2.77, 0.00 (*)         10.50, 0.32, 0.18 (*)
    emergency    P          2.30, 0.00, 0.17 (*)         -0.40, 1.60, 0.03 (*)
    emergency    G          12.00, 0.00, 0.05            -0.40, 1.60, 0.03
    ===========  =========  ==========================  ==========================

    (*) with ``L = max(400 m, train length)``. A.3.9.6: the service values "shall be
    considered as maximum ones"; a brake system may justify shorter ones.
    """
    if position not in ("G", "P"):
        raise ConfigError("position", position, "'G' or 'P'")
    if brake not in ("service", "emergency"):
        raise ConfigError("brake", brake, "'service' or 'emergency'")
    length = np.asarray(train_length_m, dtype=float)
    if np.any(length <= 0) or (not extrapolate and np.any(length > ETCS_MAX_LENGTH_M)):
        raise ConfigError(
            "train_length_m", train_length_m, f"a length in (0, {ETCS_MAX_LENGTH_M:g}] m"
        )
    if brake == "service":
        short, long = (3.00, 2.77, 0.00), (10.50, 0.32, 0.18)
        floor_400 = position == "G"
    elif position == "P":
        short, long = (2.30, 0.00, 0.17), (-0.40, 1.60, 0.03)
        floor_400 = True
    else:
        short, long = (12.00, 0.00, 0.05), (-0.40, 1.60, 0.03)
        floor_400 = False
    hundreds = (np.maximum(length, 400.0) if floor_400 else length) / 100.0
    a, b, c = (np.where(length <= 900.0, s, g) for s, g in zip(short, long, strict=True))
    return np.asarray(a + b * hundreds + c * hundreds**2)


def etcs_full_force_time_s(
    train_length_m: Num,
    position: BrakePosition,
    brake: Literal["service", "emergency"] = "service",
    *,
    extrapolate: bool = False,
) -> np.ndarray:
    """ETCS conversion model: ``t2`` [s], when the ramp model reaches 95 % of full force.

    ``t2 = 2 T_brake_build_up - T_brake_react`` (SUBSET-026-3 A.3.12.2.1, from
    ``T_brake_build_up = T_brake_react + T_brake_increase / 2``, 3.13.2.2.3.2.4).
    """
    build_up = etcs_build_up_time_s(train_length_m, position, brake, extrapolate=extrapolate)
    return np.asarray(2.0 * build_up - ETCS_REACT_S[(position, brake)])
