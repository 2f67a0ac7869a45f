"""The train's own braking, as the onboard predicts it: regenerative-only and full service.

Paper 001 section 2.5 has the onboard decide, for a temporary speed restriction ahead,
whether the locomotive's maximum regenerative brake alone brings the train under the limit
in time, integrating the gradient, the running resistance and the regenerative envelope;
and if not, to apply the air brake early. This module is the
prediction both need: a point-mass train with length-averaged gradient forces
(vehicle/profile.py), Davis resistance (vehicle/resistance.py), the locomotive's regenerative
envelope (vehicle/traction.py) and the brake-pipe air brake's build-up along the train
(brakes/brake_pipe.py), integrated in time. Pure functions, no I/O; the loop is compiled.

Braking force (the model; docs/onboard.md "Braking prediction")::

    F_E(v)     = regenerative envelope at v                         (immediate; no lag)
    F_A(t)     = a_air m_eff phi(t - t_air),   phi(s) = mean_j (1 - exp(-(s - d_j) / T_j))+
    F_B(t, v)  = F_E(v)                                             regenerative only
               = min(a_sb m_eff, F_E(v) + F_A(t))                   full service
    m_eff dv/dt = -F_B - (w_0(v) + w_line(x)) m g / 1000

with ``d_j, T_j`` the air brake's groups' dead times and lags (``BrakePipeBrake.group_timing``),
``a_air`` its full-service deceleration, ``a_sb`` the train's service-braking limit (the
ATO's demand cap, ``Train.max_service_decel_mps2``), ``w_0`` Davis and ``w_line`` the
length-averaged gradient and curve resistance [N/kN]. Fixed-step classical Runge-Kutta in
time (``dt`` 0.05 s by default); crossings of a target speed or position are interpolated
linearly within the step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle.profile import FORWARD, ResistanceTable, mean_specific_resistance
from railpilot.vehicle.resistance import davis_specific_resistance
from railpilot.vehicle.traction import Locomotive, regen_force_max
from railpilot.vehicle.train import Train

#: integration step [s]
DEFAULT_DT_S = 0.05
#: longest prediction [s]: a train that has not reached its target by then never will
MAX_HORIZON_S = 3600.0
#: finest integration step [s]: a prediction over the longest horizon keeps its trace
#: (3 floats a step) within about 90 MB
MIN_DT_S = 1e-3

# params layout of the compiled loop
(
    B_MASS,
    B_MEFF,
    B_LENGTH,
    B_A0,
    B_A1,
    B_A2,
    B_REGEN_F,
    B_REGEN_P,
    B_REGEN_FADE,
    B_AIR_DECEL,
    B_SERVICE_DECEL,
    B_DIRECTION,
) = range(12)
N_PARAMS = 12


@dataclass(frozen=True)
class BrakingTrain:
    """What the onboard knows of its own train's braking.

    Attributes
    ----------
    train
        Mass, rotating mass, length, Davis coefficients and the service-braking limit
        ``max_service_decel_mps2`` [m/s^2] (the cap on the total braking demand).
    locomotive
        Its regenerative envelope (``regen``); None: no electric brake.
    air
        The brake-pipe air brake: full-service deceleration and build-up along the train.
    """

    train: Train
    locomotive: Locomotive | None
    air: BrakePipeBrake

    def __post_init__(self) -> None:
        if not isinstance(self.train, Train):
            raise ConfigError("train", self.train, "a railpilot.vehicle.train.Train")
        if self.locomotive is not None and not isinstance(self.locomotive, Locomotive):
            raise ConfigError("locomotive", self.locomotive, "a Locomotive or None")
        if not isinstance(self.air, BrakePipeBrake):
            raise ConfigError("air", self.air, "a BrakePipeBrake")

    def params(self, direction: float) -> np.ndarray:
        """The compiled loop's parameters for travel in ``direction`` (+1 / -1)."""
        t = self.train
        p = np.zeros(N_PARAMS)
        p[B_MASS] = t.mass_kg
        p[B_MEFF] = t.effective_mass_kg
        p[B_LENGTH] = t.length_m
        p[B_A0], p[B_A1], p[B_A2] = t.davis_a0, t.davis_a1, t.davis_a2
        if self.locomotive is not None:
            regen = self.locomotive.regen
            p[B_REGEN_F] = regen.max_force_n
            p[B_REGEN_P] = regen.max_power_w
            p[B_REGEN_FADE] = regen.fade_below_mps
        p[B_AIR_DECEL] = self.air.max_decel_mps2
        p[B_SERVICE_DECEL] = t.max_service_decel_mps2
        p[B_DIRECTION] = 1.0 if direction >= 0 else -1.0
        return p

    def air_timing(self) -> tuple[np.ndarray, np.ndarray]:
        """The air brake's groups' application dead times and lags [s] on this train."""
        timing = self.air.group_timing(self.train.length_m)
        return timing.delay_app_s, timing.lag_app_s


@njit(cache=True)
def air_fraction(s: float, delays: np.ndarray, lags: np.ndarray) -> float:
    """``phi(s)``: the air brake's force [fraction of full service] ``s`` [s] after applying."""
    total = 0.0
    for j in range(delays.shape[0]):
        if s > delays[j]:
            total += 1.0 - math.exp(-(s - delays[j]) / lags[j])
    return total / delays.shape[0]


@njit(cache=True)
def braking_decel(
    p: np.ndarray,
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    x: float,
    v: float,
    service: bool,
    air_share: float,
) -> float:
    """Deceleration [m/s^2] (positive brakes) of the braking train at ``x`` [m], ``v`` [m/s].

    Regeneration at its envelope; with ``service`` also the air brake at ``air_share`` of
    its full service, the sum capped at the service-braking limit (module docstring); plus
    Davis and the length-averaged line resistance.
    """
    speed = max(v, 0.0)
    brake = regen_force_max(speed, p[B_REGEN_F], p[B_REGEN_P], p[B_REGEN_FADE])
    if service:
        air = p[B_AIR_DECEL] * p[B_MEFF] * air_share
        brake = min(p[B_SERVICE_DECEL] * p[B_MEFF], brake + air)
    w = davis_specific_resistance(speed * KMH_PER_MPS, p[B_A0], p[B_A1], p[B_A2])
    w += mean_specific_resistance(edges, cumulative, values, x, p[B_LENGTH], p[B_DIRECTION])
    return (brake + w * p[B_MASS] * G_MPS2 / 1000.0) / p[B_MEFF]


@njit(cache=True)
def _accel(
    p: np.ndarray,
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    delays: np.ndarray,
    lags: np.ndarray,
    x: float,
    v: float,
    t: float,
    t_air: float,
) -> float:
    """Acceleration [m/s^2] at ``t`` [s] with the air brake applied at ``t_air`` [s]."""
    if t >= t_air:
        share = air_fraction(t - t_air, delays, lags)
        return -braking_decel(p, edges, cumulative, values, x, v, True, share)
    return -braking_decel(p, edges, cumulative, values, x, v, False, 0.0)


@njit(cache=True)
def _integrate(
    p: np.ndarray,
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    delays: np.ndarray,
    lags: np.ndarray,
    x0: float,
    v0: float,
    t_air: float,
    v_target: float,
    x_end: float,
    dt: float,
    max_steps: int,
    out: np.ndarray,
) -> int:
    """Brake from ``(x0, v0)`` at ``t = 0`` until ``v <= v_target`` or the head reaches
    ``x_end`` (in the direction of travel) or ``max_steps``; air from ``t_air`` [s].

    Writes ``t, x, v`` per step into ``out`` (shape ``(max_steps + 1, 3)``), the last row
    interpolated to the crossing; returns the number of rows. Stops early, without a
    crossing, once the speed exceeds ``v0 + 30 m/s`` (a brake that cannot hold the train).
    """
    d = p[B_DIRECTION]
    x = x0
    v = v0
    t = 0.0
    out[0, 0] = t
    out[0, 1] = x
    out[0, 2] = v
    n = 1
    for _ in range(max_steps):
        h = dt
        k1v = _accel(p, edges, cumulative, values, delays, lags, x, v, t, t_air)
        k1x = d * v
        v2 = v + 0.5 * h * k1v
        x2 = x + 0.5 * h * k1x
        k2v = _accel(p, edges, cumulative, values, delays, lags, x2, v2, t + 0.5 * h, t_air)
        k2x = d * v2
        v3 = v + 0.5 * h * k2v
        x3 = x + 0.5 * h * k2x
        k3v = _accel(p, edges, cumulative, values, delays, lags, x3, v3, t + 0.5 * h, t_air)
        k3x = d * v3
        v4 = v + h * k3v
        x4 = x + h * k3x
        k4v = _accel(p, edges, cumulative, values, delays, lags, x4, v4, t + h, t_air)
        k4x = d * v4
        v_next = v + h * (k1v + 2.0 * k2v + 2.0 * k3v + k4v) / 6.0
        x_next = x + h * (k1x + 2.0 * k2x + 2.0 * k3x + k4x) / 6.0
        # crossings within the step, linearly interpolated
        f = 2.0
        if v_next <= v_target < v:
            f = (v - v_target) / (v - v_next)
        if d * (x_next - x_end) >= 0.0 > d * (x - x_end):
            f = min(f, (x_end - x) / (x_next - x))
        if f <= 1.0:
            out[n, 0] = t + f * h
            out[n, 1] = x + f * (x_next - x)
            out[n, 2] = v + f * (v_next - v)
            return n + 1
        x = x_next
        v = v_next
        t += h
        out[n, 0] = t
        out[n, 1] = x
        out[n, 2] = v
        n += 1
        if v > v0 + 30.0:
            break
    return n


@dataclass(frozen=True)
class BrakingTrace:
    """A predicted braking run: time [s], head position [m] and speed [m/s] per step.

    ``reached_speed``: the run ended at the target speed; ``reached_position``: at the end
    position; neither: the horizon ran out (the brake cannot do it).
    """

    t_s: np.ndarray
    x_m: np.ndarray
    v_mps: np.ndarray
    reached_speed: bool
    reached_position: bool


def predict_braking(
    braking: BrakingTrain,
    table: ResistanceTable,
    x0_m: float,
    v0_mps: float,
    *,
    direction: float = FORWARD,
    air_from_s: float = math.inf,
    until_speed_mps: float = 0.0,
    until_position_m: float | None = None,
    dt_s: float = DEFAULT_DT_S,
    horizon_s: float = MAX_HORIZON_S,
) -> BrakingTrace:
    """Predict the train braking from head position ``x0_m`` [m] at ``v0_mps`` [m/s].

    Regenerative brake at its envelope from ``t = 0``; the air brake's full service applied
    at ``air_from_s`` [s] (``inf``: never; 0: at once). Until the speed falls to
    ``until_speed_mps`` [m/s] or the head reaches ``until_position_m`` [m] (in the direction
    of travel; None: no end) or ``horizon_s`` [s] passes. ``table``: the line's
    :func:`railpilot.vehicle.profile.elevation_table` for ``direction``.
    """
    if not (np.isfinite(v0_mps) and v0_mps >= 0):
        raise ConfigError("v0_mps", v0_mps, "a finite speed >= 0 [m/s]")
    if not (np.isfinite(dt_s) and MIN_DT_S <= dt_s <= 1.0):
        raise ConfigError("dt_s", dt_s, f"a step in [{MIN_DT_S:g}, 1] s")
    if not (np.isfinite(horizon_s) and 0 < horizon_s <= MAX_HORIZON_S):
        raise ConfigError("horizon_s", horizon_s, f"a time in (0, {MAX_HORIZON_S:g}] s")
    if not (np.isfinite(until_speed_mps) and until_speed_mps >= 0):
        raise ConfigError("until_speed_mps", until_speed_mps, "a finite speed >= 0 [m/s]")
    direction = 1.0 if direction >= 0 else -1.0
    x_end = direction * math.inf if until_position_m is None else float(until_position_m)
    steps = math.ceil(horizon_s / dt_s)
    out = np.empty((steps + 1, 3))
    delays, lags = braking.air_timing()
    if v0_mps <= until_speed_mps:
        return BrakingTrace(np.array([0.0]), np.array([x0_m]), np.array([v0_mps]), True, False)
    n = _integrate(
        braking.params(direction),
        *table,
        delays,
        lags,
        float(x0_m),
        float(v0_mps),
        float(air_from_s),
        float(until_speed_mps),
        x_end,
        float(dt_s),
        steps,
        out,
    )
    t, x, v = out[:n, 0], out[:n, 1], out[:n, 2]
    reached_speed = bool(v[-1] <= until_speed_mps + 1e-9)
    reached_position = bool(direction * (x[-1] - x_end) >= -1e-9) and not reached_speed
    return BrakingTrace(t.copy(), x.copy(), v.copy(), reached_speed, reached_position)


@dataclass(frozen=True)
class TsrCheck:
    """The paper's TSR check (section 2.5) for one restriction ahead.

    Attributes
    ----------
    distance_m
        From the head to the restriction's start [m].
    regen_distance_m
        Distance [m] the regenerative brake alone needs to bring the train down to the
        limit (``inf``: it cannot, e.g. on a steep descent).
    regen_sufficient
        ``regen_distance_m <= distance_m``.
    air_brake_from_m
        None if regeneration suffices; else the head position [m] at which the air brake
        must be applied at the latest (full service with build-up, regeneration from now),
        or the current position if even that is too late (``feasible`` False).
    speed_at_restriction_mps
        The predicted speed [m/s] at the restriction's start with the decided braking.
    feasible
        The decided braking brings the train under the limit in time.
    """

    distance_m: float
    regen_distance_m: float
    regen_sufficient: bool
    air_brake_from_m: float | None
    speed_at_restriction_mps: float
    feasible: bool


def tsr_check(
    braking: BrakingTrain,
    table: ResistanceTable,
    x_m: float,
    v_mps: float,
    restriction_start_m: float,
    limit_mps: float,
    *,
    direction: float = FORWARD,
    dt_s: float = DEFAULT_DT_S,
    tolerance_m: float = 1.0,
) -> TsrCheck:
    """Decide how the train gets under ``limit_mps`` [m/s] by ``restriction_start_m`` [m].

    Paper 001 section 2.5: with the regenerative brake at its maximum from now, does the
    head reach the restriction at or under the limit? If not, the last time (found by
    bisection to ``tolerance_m`` of head travel) at which applying the air brake's full
    service, which builds up along the train, still makes it; reported as the head's
    position then.
    """
    direction = 1.0 if direction >= 0 else -1.0
    distance = direction * (restriction_start_m - x_m)
    if not (np.isfinite(limit_mps) and limit_mps >= 0):
        raise ConfigError("limit_mps", limit_mps, "a finite speed >= 0 [m/s]")
    if distance < 0:
        raise ConfigError(
            "restriction_start_m", restriction_start_m, "a position ahead of the train's head"
        )
    if v_mps <= limit_mps:
        return TsrCheck(distance, 0.0, True, None, v_mps, True)
    regen = predict_braking(
        braking, table, x_m, v_mps, direction=direction, until_speed_mps=limit_mps, dt_s=dt_s
    )
    regen_distance = direction * (regen.x_m[-1] - x_m) if regen.reached_speed else math.inf
    if regen_distance <= distance:
        return TsrCheck(distance, regen_distance, True, None, limit_mps, True)

    def speed_at_start(air_from_s: float) -> tuple[float, float]:
        """Speed at the restriction [m/s], and the head's position when the air goes on."""
        run = predict_braking(
            braking,
            table,
            x_m,
            v_mps,
            direction=direction,
            air_from_s=air_from_s,
            until_speed_mps=limit_mps,
            until_position_m=restriction_start_m,
            dt_s=dt_s,
        )
        speed = limit_mps if run.reached_speed else float(run.v_mps[-1])
        if not (run.reached_speed or run.reached_position):
            speed = math.inf
        return speed, float(np.interp(air_from_s, run.t_s, run.x_m))

    at_once, _ = speed_at_start(0.0)
    if at_once > limit_mps + 1e-9:
        return TsrCheck(distance, regen_distance, False, float(x_m), at_once, False)
    # bisection on the application time: early enough (lo) .. too late (hi)
    lo, x_lo = 0.0, float(x_m)
    hi = distance / max(limit_mps, 0.1)  # the head is at the restriction by then
    while True:
        speed, x_hi = speed_at_start(hi)
        if speed > limit_mps + 1e-9:
            break
        lo, x_lo, hi = hi, x_hi, 2.0 * hi
    while direction * (x_hi - x_lo) > tolerance_m:
        mid = 0.5 * (lo + hi)
        speed, x_mid = speed_at_start(mid)
        if speed <= limit_mps + 1e-9:
            lo, x_lo = mid, x_mid
        else:
            hi, x_hi = mid, x_mid
    return TsrCheck(distance, regen_distance, False, x_lo, limit_mps, True)
