"""Heavy-haul automatic air brake: the brake-pipe wave, the pipe's flow and each group's cylinders.

The ATO's command sets the brake-pipe reduction at the locomotive. The first change of
pressure travels down the train as a wave; the full reduction follows more slowly, because
the air must flow along the pipe and out through the driver's brake valve; and each part of
the train fills its brake cylinders with its own lag. So the rear of a 1,600 m train brakes
seconds after the front, and completes its application tens of seconds later. Model,
sources and validation: docs/heavy-haul-brake.md.

Model (``n`` groups of wagons, ``j = 0 .. n-1``)::

    uc(t)   = clip(-u(t) / a_max, 0, 1)                  demanded fraction of full service
    x_j     = j L / (n - 1)                               group j's distance from the front [m]
    W(x), S2(x)                                           mean and variance [s, s^2] of the
                                                          arrival of the pipe's reduction at x
    M_j     = t_r + x_j / c + W(x_j) + T                  group j's mean response time [s]
    d_j     = max(t_r + x_j / c, M_j - sqrt(S2(x_j) + T^2))   its dead time [s]
    T_j     = M_j - d_j                                   its lag [s]
    r_j(t)  = max(uc(t - d_a,j), uc(t - d_r,j))          received target (min if d_a,j > d_r,j)
    dy_j/dt = (r_j - y_j) / T_a,j  if r_j > y_j           application (cylinder filling)
            = (r_j - y_j) / T_r,j  otherwise              release (cylinder venting)
    F_air   = sum_j y_j / n * a_max * m_eff               [N]

with ``c, T = c_a, T_a`` for an application and ``c_r, T_r`` for a release. ``L`` is the
train length, ``c_a`` / ``c_r`` the application / release wave speeds, ``t_r`` a reaction
(dead) time at the locomotive, ``T_a = t_app / ln 20`` the cylinder lag that reaches 95 % of
a step in the application time ``t_app`` and ``T_r = t_rel / ln(3.8 / 0.4)`` the one that
vents a full cylinder (3.8 bar) to 0.4 bar in the release time ``t_rel`` (the end points of
the UIC single-wagon test).

The pipe (:func:`pipe_reduction_moments`): the reduction diffuses along the pipe
(``r_t = D r_xx``, closed at the rear) and the driver's valve vents it through a limited
flow (``D r_x(0) = G (r(0) - uc)``), so with ``a = 1 / G`` and ``b = 1 / D``::

    W(x)  = a L + b x (2 L - x) / 2
    V(x)  = a (a L^2 + b L^3 / 3)
            + b (a L (L x - x^2 / 2) + b (2 L^3 x / 3 - L x^3 / 3 + x^4 / 12) / 2)
    S2(x) = 2 V(x) - W(x)^2

Each group is a dead time and a lag with the mean (exactly) and, where a dead time no
shorter than the wave's arrival allows, the variance of wave, pipe and cylinder together.
The train's equivalent build-up time, the mean of the ``M_j``, grows as ``a + b L + c L^2``,
the form of the ETCS conversion model, against which ``G`` and ``D`` are calibrated.

The kernel is exact for a command held over each step (zero-order hold): one command
history (a ring buffer, sized for the longest dead time) serves every group; a dead time
that is not a whole number of steps switches the delayed command within the step, and each
group's lag is advanced exactly (``exp(-h / T)``) over each part of the step, as in
brakes/lag_delay.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal, NamedTuple

import numpy as np
from scipy.optimize import brentq

from railpilot.brakes.base import PackContext
from railpilot.brakes.lag_delay import MAX_DELAY_STEPS, ring_back, ring_next
from railpilot.checks import check_count, check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import Num

# --- params layout -------------------------------------------------------------------------
#: number of groups; ring-buffer length; a_max [m/s^2]
P_N_SEG, P_BUF_LEN, P_A_MAX = range(3)
#: first group's block; each group has SEG_STRIDE floats
P_SEG0 = 3
#: per group: whole steps of the application / release dead time; 1.0 if the application
#: dead time's fractional part is the smaller one (it switches first within a step); the
#: group's share of the brake force [-]; then exp(-h/T_a,j), exp(-h/T_r,j) for the three
#: parts of a step (before, between and after the two switches); 1.0 if the application
#: reaches the group no later than a release (the received target is then the max of the
#: two delayed commands, else the min)
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
    SEG_APPLY_FIRST,
) = range(11)
SEG_STRIDE = 11
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

#: the pipe's two effective constants, CALIBRATED (not measured): the driver's brake valve
#: vents the pipe at G [m/s] (pipe length emptied per second) and the reduction diffuses
#: along the pipe with D [m^2/s]. Fitted so that the default G brake's equivalent build-up
#: time equals the ETCS conversion model's full-service value at 400 m and 1,500 m
#: (:func:`calibrate_pipe_to_etcs`, rounded to three digits); the lengths in between are
#: the validation (docs/heavy-haul-brake.md)
VALVE_FLOW_MPS = 141.0
PIPE_DIFFUSIVITY_M2PS = 21_900.0
#: the lengths the pipe is calibrated at [m]
CALIBRATION_LENGTHS_M = (400.0, 1500.0)

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


def pipe_reduction_moments(
    x_m: Num,
    train_length_m: float,
    valve_flow_mps: float = VALVE_FLOW_MPS,
    diffusivity_m2ps: float = PIPE_DIFFUSIVITY_M2PS,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean [s] and variance [s^2] of the arrival of the pipe's reduction at ``x_m`` [m].

    After a step of the command at the driver's brake valve (``x = 0``), on a pipe
    ``train_length_m`` [m] long. ``inf`` for either constant removes its term.

    Notes
    -----
    The pipe's reduction ``r`` (a fraction of the commanded one) diffuses along the pipe,
    which is closed at the rear, and the valve vents it through a limited flow::

        r_t = D r_xx,    D r_x(0, t) = G (r(0, t) - uc),    r_x(L, t) = 0,    r(x, 0) = 0

    ``1 - r(x, t)`` is the probability that the reduction has not yet arrived at ``x``,
    so its integral over time is the mean arrival ``W`` and twice its first moment
    ``V = integral t (1 - r) dt`` is the second moment. Integrating the equation over time
    (once, and once more with weight ``t``) gives the boundary-value problems
    ``D W'' = -1`` and ``D V'' = -W`` with the same boundary conditions, whose solutions,
    with ``a = 1 / G`` and ``b = 1 / D``, are::

        W(x) = a L + b x (2 L - x) / 2
        V(x) = a (a L^2 + b L^3 / 3)
               + b (a L (L x - x^2 / 2) + b (2 L^3 x / 3 - L x^3 / 3 + x^4 / 12) / 2)
        variance = 2 V - W^2

    Limits: an ideal pipe (``D = inf``) is a first-order lag ``L / G`` everywhere (mean
    and standard deviation both ``L / G``); an ideal valve (``G = inf``) gives the rear a
    mean of ``L^2 / (2 D)`` and a variance of ``L^4 / (6 D^2)``. The tests check both
    moments against a numerical solution of the equation (scipy).
    """
    x = np.asarray(x_m, dtype=float)
    length = float(train_length_m)
    a = 0.0 if np.isinf(valve_flow_mps) else 1.0 / float(valve_flow_mps)
    b = 0.0 if np.isinf(diffusivity_m2ps) else 1.0 / float(diffusivity_m2ps)
    mean = a * length + b * x * (2.0 * length - x) / 2.0
    second = a * (a * length**2 + b * length**3 / 3.0) + b * (
        a * length * (length * x - x**2 / 2.0)
        + b * (2.0 * length**3 * x / 3.0 - length * x**3 / 3.0 + x**4 / 12.0) / 2.0
    )
    variance = np.maximum(2.0 * second - mean**2, 0.0)
    return mean, variance


def _dead_time_and_lag(
    wave_arrival_s: np.ndarray, pipe_mean_s: np.ndarray, pipe_variance_s2: np.ndarray, lag_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """A dead time and a lag [s] per group: wave, pipe and cylinder in series.

    The mean ``M = arrival + W + T`` is kept exactly; the variance ``S2 + T^2`` too where
    the dead time ``M - sqrt(S2 + T^2)`` is no shorter than the wave's arrival, which a
    group cannot respond before; else the dead time is the arrival and the lag the rest.
    """
    mean = wave_arrival_s + pipe_mean_s + lag_s
    spread = np.sqrt(pipe_variance_s2 + lag_s**2)
    delay = np.maximum(wave_arrival_s, mean - spread)
    return delay, mean - delay


class GroupTiming(NamedTuple):
    """Each group's position [m] and dead times and lags [s] (application, release)."""

    x_m: np.ndarray
    delay_app_s: np.ndarray
    lag_app_s: np.ndarray
    delay_rel_s: np.ndarray
    lag_rel_s: np.ndarray


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
    valve_flow_mps
        ``G`` [m/s]: how fast the driver's brake valve vents the pipe, as pipe length per
        second (141 m/s, calibrated to ETCS); ``inf`` = an ideal valve.
    pipe_diffusivity_m2ps
        ``D`` [m^2/s]: how fast the reduction spreads along the pipe (21,900 m^2/s,
        calibrated to ETCS); ``inf`` = an ideal pipe. With both ``inf`` every group
        receives the full reduction when the wave reaches it.

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
    valve_flow_mps: float = VALVE_FLOW_MPS
    pipe_diffusivity_m2ps: float = PIPE_DIFFUSIVITY_M2PS

    name: ClassVar[str] = "brake-pipe"
    #: no electric brake, so no changeover
    changeover_kmh: ClassVar[float] = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.position, str) and self.position in UIC_TIMES_S):
            raise ConfigError("brake.position", self.position, "'G' or 'P'")
        for name in ("application_time_s", "release_time_s"):
            value = getattr(self, name)
            if value is not None:
                check_number(
                    f"brake.{name}",
                    value,
                    positive=True,
                    maximum=MAX_TIME_S,
                    allowed=f"a number in (0, {MAX_TIME_S:g}] s",
                    error=ConfigError,
                )
        for name in ("application_wave_mps", "release_wave_mps"):
            check_number(
                f"brake.{name}",
                getattr(self, name),
                positive=True,
                maximum=MAX_WAVE_MPS,
                allowed=f"a speed in (0, {MAX_WAVE_MPS:g}] m/s",
                error=ConfigError,
            )
        check_count(
            "brake.n_segments",
            self.n_segments,
            2,
            MAX_SEGMENTS,
            allowed=f"an integer in [2, {MAX_SEGMENTS}]",
            error=ConfigError,
        )
        check_number(
            "brake.max_decel_mps2",
            self.max_decel_mps2,
            positive=True,
            error=ConfigError,
        )
        check_number(
            "brake.reaction_s",
            self.reaction_s,
            minimum=0.0,
            maximum=MAX_REACTION_S,
            allowed=f"a number in [0, {MAX_REACTION_S:g}] s",
            error=ConfigError,
        )
        for name in ("valve_flow_mps", "pipe_diffusivity_m2ps"):
            check_number(
                f"brake.{name}",
                getattr(self, name),
                positive=True,
                allow_inf=True,
                allowed="a number > 0 (inf: ideal)",
                error=ConfigError,
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
        """``(delay, lag)`` [s] of the locomotive's own cylinders: ``(t_r, T_a)``.

        brakes/base.py gives ``lead_s`` no train; for the whole train use
        :meth:`train_lead_s`, whose sum is the equivalent build-up time.
        """
        return self.reaction_s, application_lag_s(self.application_s)

    def group_timing(self, train_length_m: float) -> GroupTiming:
        """Each group's dead times and lags [s] on a train ``train_length_m`` [m] long."""
        if not (np.isfinite(train_length_m) and train_length_m > 0):
            raise ConfigError("train.length_m", train_length_m, "a finite number > 0")
        x = segment_positions_m(train_length_m, self.n_segments)
        mean, variance = pipe_reduction_moments(
            x, train_length_m, self.valve_flow_mps, self.pipe_diffusivity_m2ps
        )
        delay_app, lag_app = _dead_time_and_lag(
            self.reaction_s + x / self.application_wave_mps,
            mean,
            variance,
            application_lag_s(self.application_s),
        )
        delay_rel, lag_rel = _dead_time_and_lag(
            self.reaction_s + x / self.release_wave_mps,
            mean,
            variance,
            release_lag_s(self.release_s),
        )
        return GroupTiming(x, delay_app, lag_app, delay_rel, lag_rel)

    def train_lead_s(self, train_length_m: float) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the whole train's application, for the ATO's model.

        A dead time and a lag with the mean (the equivalent build-up time,
        :func:`equivalent_build_up_time_s`) and, where a non-negative dead time allows, the
        variance of the train's response to a full-service step (the mixture of the groups'
        dead-time-plus-lag responses).
        """
        timing = self.group_timing(train_length_m)
        return _mixture_lead_s(timing.delay_app_s, timing.lag_app_s)

    def train_release_lead_s(self, train_length_m: float) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the whole train's release, as :meth:`train_lead_s` is of
        its application (the release wave is slower and the cylinders empty slower)."""
        timing = self.group_timing(train_length_m)
        return _mixture_lead_s(timing.delay_rel_s, timing.lag_rel_s)

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
        n = self.n_segments
        timing = self.group_timing(train_length_m)  # checks the length
        longest = float(max(timing.delay_app_s.max(), timing.delay_rel_s.max()))
        if longest / dt > MAX_DELAY_STEPS:
            raise ConfigError(
                "sim.dt_s",
                dt,
                f"at least {longest / MAX_DELAY_STEPS:.3g} s: the longest dead time is "
                f"{longest:.3g} s and the delay line has at most {MAX_DELAY_STEPS:,} steps",
            )
        p = np.zeros(P_SEG0 + n * SEG_STRIDE)
        p[P_N_SEG] = n
        p[P_A_MAX] = self.max_decel_mps2
        n_max = 0
        for j in range(n):
            n_a, f_a = _whole_and_fraction(timing.delay_app_s[j] / dt)
            n_r, f_r = _whole_and_fraction(timing.delay_rel_s[j] / dt)
            n_max = max(n_max, n_a, n_r)
            first, second = min(f_a, f_r), max(f_a, f_r)
            parts = (first * dt, (second - first) * dt, (1.0 - second) * dt)
            b = P_SEG0 + j * SEG_STRIDE
            p[b + SEG_N_APP] = n_a
            p[b + SEG_N_REL] = n_r
            p[b + SEG_APP_FIRST] = 1.0 if f_a <= f_r else 0.0
            p[b + SEG_SHARE] = 1.0 / n
            for i, h in enumerate(parts):
                p[b + SEG_ALPHA1_APP + 2 * i] = np.exp(-h / timing.lag_app_s[j])
                p[b + SEG_ALPHA1_REL + 2 * i] = np.exp(-h / timing.lag_rel_s[j])
            p[b + SEG_APPLY_FIRST] = 1.0 if timing.delay_app_s[j] <= timing.delay_rel_s[j] else 0.0
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
    total = 0.0
    for j in range(int(p[P_N_SEG])):
        b = P_SEG0 + j * SEG_STRIDE
        n_a = int(p[b + SEG_N_APP])
        n_r = int(p[b + SEG_N_REL])
        app_old = buffer[ring_back(k, n_a + 1, length)]
        app_new = buffer[ring_back(k, n_a, length)]
        rel_old = buffer[ring_back(k, n_r + 1, length)]
        rel_new = buffer[ring_back(k, n_r, length)]
        apply_faster = p[b + SEG_APPLY_FIRST] > 0.0
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
    brake: BrakePipeBrake,
    t_s: Num,
    train_length_m: float,
    *,
    to_fraction: float = 1.0,
    from_fraction: float = 0.0,
) -> np.ndarray:
    """Each group's cylinder fraction [-] at ``t_s`` [s] after a step of the command.

    The command steps from ``from_fraction`` (held long enough to be steady) to
    ``to_fraction`` at ``t = 0``, on a train ``train_length_m`` [m] long. Returns shape
    ``t_s.shape + (n_segments,)``.

    Notes
    -----
    An application (``to > from``) reaches group ``j`` after its dead time ``d = d_a,j``
    and fills with its lag ``T = T_a,j``; a release uses ``d_r,j`` and ``T_r,j``
    (:meth:`BrakePipeBrake.group_timing`)::

        y(t) = from                                          for t < d
        y(t) = to + (from - to) exp(-(t - d) / T)            for t >= d
    """
    timing = brake.group_timing(train_length_m)
    t = np.asarray(t_s, dtype=float)[..., np.newaxis]
    if to_fraction >= from_fraction:
        delay, lag = timing.delay_app_s, timing.lag_app_s
    else:
        delay, lag = timing.delay_rel_s, timing.lag_rel_s
    elapsed = t - delay
    decay = np.exp(-np.maximum(elapsed, 0.0) / lag)
    return np.where(
        elapsed >= 0.0, to_fraction + (from_fraction - to_fraction) * decay, from_fraction
    )


def train_force_fraction(brake: BrakePipeBrake, t_s: Num, train_length_m: float) -> np.ndarray:
    """The train's air force [fraction of full service] ``t_s`` [s] after a full step.

    The mean of the groups' step responses (:func:`segment_pressure_fraction`), which
    carry equal shares. Vectorised over ``t_s``.
    """
    return np.asarray(segment_pressure_fraction(brake, t_s, train_length_m).mean(axis=-1))


def build_up_time_s(
    brake: BrakePipeBrake, train_length_m: Num, *, fraction: float = APPLIED_FRACTION
) -> np.ndarray:
    """Time [s] for the train's air force to reach ``fraction`` (95 %) after a full step.

    Vectorised over ``train_length_m`` [m]. The quantity SUBSET-026 calls ``t2``, the end
    of ``T_brake_increase`` (3.13.2.2.3.2.3).

    Notes
    -----
    The root of ``train_force_fraction(t) = fraction`` (scipy.optimize.brentq); the force is
    continuous and non-decreasing, 0 before the first dead time, and reaches ``fraction``
    by the time every group has (``max_j d_j + T_j ln(1 / (1 - fraction))``).
    """
    if not 0.0 < fraction < 1.0:
        raise ConfigError("fraction", fraction, "a number in (0, 1)")
    lengths = np.asarray(train_length_m, dtype=float)
    out = np.empty(lengths.shape)
    for index, value in np.ndenumerate(lengths):
        train_m_here: float = float(value)
        timing = brake.group_timing(train_m_here)

        def short_of(t: float, train_m: float = train_m_here) -> float:
            return float(train_force_fraction(brake, t, train_m)) - fraction

        lower = float(timing.delay_app_s.min())
        upper = float(np.max(timing.delay_app_s - timing.lag_app_s * np.log(1.0 - fraction)))
        out[index] = brentq(short_of, lower, upper + 1e-9, xtol=1e-12, rtol=1e-14)
    return out


def equivalent_build_up_time_s(brake: BrakePipeBrake, train_length_m: Num) -> np.ndarray:
    """Equivalent build-up time [s] of a full-service step on a train ``train_length_m`` [m].

    ``T_e = integral_0^inf (1 - F(t)) dt``: the dead time after which full force would give
    the same speed loss as the real build-up ``F``. SUBSET-026 3.13.2.2.3.2.4 defines its
    ``T_brake_build_up = T_brake_react + T_brake_increase / 2``, which is this integral for
    its ramp model. Vectorised over ``train_length_m``.

    Notes
    -----
    The integral of a delayed first-order step is its dead time plus its lag, which each
    group's timing makes ``M_j = t_r + x_j / c_a + W(x_j) + T_a``; ``T_e`` is their mean,
    with ``x_j = j L / (n - 1)``::

        T_e = t_r + L / (2 c_a) + T_a + L / G + (L^2 / (2 D)) (1 - (2 n - 1) / (6 (n - 1)))

    (``L^2 / (3 D)`` for the last term as ``n -> inf``), computed here as the mean of the
    ``M_j`` themselves.
    """
    lengths = np.asarray(train_length_m, dtype=float)
    out = np.empty(lengths.shape)
    for index, length in np.ndenumerate(lengths):
        timing = brake.group_timing(float(length))
        out[index] = float(np.mean(timing.delay_app_s + timing.lag_app_s))
    return out


def calibrate_pipe_to_etcs(
    brake: BrakePipeBrake | None = None,
    lengths_m: tuple[float, float] = CALIBRATION_LENGTHS_M,
) -> tuple[float, float]:
    """``(valve_flow_mps, pipe_diffusivity_m2ps)`` that fit the ETCS service build-up time.

    Solves for the pipe constants ``G`` [m/s] and ``D`` [m^2/s] with which ``brake`` (the
    default G brake when None; its own pipe constants are ignored) has the ETCS conversion
    model's full-service equivalent build-up time (:func:`etcs_build_up_time_s`, in the
    brake's position) at the two ``lengths_m`` [m].

    Notes
    -----
    ``T_e`` is linear in ``a = 1 / G`` and ``b = 1 / D``: ``T_e(L) = T_0(L) + a L + b
    mean_j(x_j (2 L - x_j)) / 2`` with ``T_0`` the ideal pipe's. Two lengths give a 2 x 2
    linear system (numpy.linalg.solve).
    """
    from dataclasses import replace

    base = replace(brake or BrakePipeBrake(), valve_flow_mps=np.inf, pipe_diffusivity_m2ps=np.inf)
    rows, rhs = [], []
    for length in lengths_m:
        x = segment_positions_m(length, base.n_segments)
        rows.append([length, float(np.mean(x * (2.0 * length - x))) / 2.0])
        published = float(etcs_build_up_time_s(length, base.position, "service"))
        rhs.append(published - float(equivalent_build_up_time_s(base, length)))
    a, b = np.linalg.solve(np.array(rows), np.array(rhs))
    if a <= 0 or b <= 0:
        raise ConfigError(
            "lengths_m", lengths_m, "lengths at which the ETCS time exceeds the ideal pipe's"
        )
    return 1.0 / float(a), 1.0 / float(b)


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


def _mixture_lead_s(delays_s: np.ndarray, lags_s: np.ndarray) -> tuple[float, float]:
    """One dead time and lag [s] with the mean and, where a non-negative dead time allows,
    the variance of the mixture of the groups' dead-time-plus-lag step responses."""
    means = delays_s + lags_s
    mean = float(means.mean())
    variance = float(np.mean(lags_s**2) + np.mean(means**2) - mean**2)
    lag = min(float(np.sqrt(max(variance, 0.0))), mean)
    return mean - lag, lag
