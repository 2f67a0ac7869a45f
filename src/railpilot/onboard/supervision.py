"""Supervision curves for a decrease of the speed profile or a target point.

In the manner of ETCS (SUBSET-026 3.13): from the train's own braking model
(onboard/braking.py), a deceleration curve backwards from the target (a lower speed at a
position, or 0 at a stop point), and ahead of it the points at which the onboard must act::

    curve        s_c(v): distance before the target from which full braking force, acting
                 at once, just reaches the target speed: d(v^2/2)/ds = A(v, x),
                 A(v, x) = (F_brake(v) + resistance(v) + gradient(x)) / m_eff
    intervention s_I(v): distance before the target from which full service, applied now
                 and building up along the train as the air brake does, just reaches it
    indication   s_W(v) = s_I(v) + v t_driver             the driver's reaction
    (each looked up at v + dv, the speed-measurement margin)

ETCS sets the intervention ahead of the curve by the equivalent build-up time,
``s_I = s_c + v T_e``. For a heavy-haul air brake whose build-up (61 s equivalent at 1,600 m)
outlasts much of the stop, and with regeneration acting at once, that is hundreds of
metres too cautious (measured 400-700 m at 40-80 km/h on the level; docs/onboard.md), so
the intervention distance here is found by predicting the braking itself
(``predict_braking``, a few iterations per speed on a grid). Two modes per target: full
service (regeneration plus the air brake, capped at the service-braking limit) and
regeneration alone, the paper's preferred brake, whose curve ends where regeneration can no
longer decelerate the train (a steep descent). Positions run in the direction of travel;
the parameters are documented in docs/onboard.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.onboard.braking import B_DIRECTION, BrakingTrain, braking_decel, predict_braking
from railpilot.units import KMH_PER_MPS
from railpilot.vehicle.profile import FORWARD, ResistanceTable

#: distance step of the backward integration [m]
DEFAULT_STEP_M = 2.0
#: the curves stop at this speed [m/s] (160 km/h: above any train here)
CURVE_TOP_MPS = 160.0 / KMH_PER_MPS
#: speeds at which the intervention distance is predicted (interpolated between)
INTERVENTION_GRID = 24

BrakeMode = Literal["service", "regen"]


@dataclass(frozen=True)
class SupervisionParameters:
    """The times and margins between the deceleration curve and the onboard's actions.

    Attributes
    ----------
    driver_reaction_s
        ``t_driver`` [s] between the indication and the driver's action (ETCS uses 4 s).
    speed_margin_mps
        ``dv`` [m/s]: the train may be this much faster than measured (0.6 m/s).
    """

    driver_reaction_s: float = 4.0
    speed_margin_mps: float = 0.6

    def __post_init__(self) -> None:
        for name in ("driver_reaction_s", "speed_margin_mps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (
                isinstance(value, int | float) and math.isfinite(value) and value >= 0
            ):
                raise ConfigError(f"supervision.{name}", value, "a finite number >= 0")


@njit(cache=True)
def _backward(
    p: np.ndarray,
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    x_target: float,
    v_target: float,
    v_top: float,
    step: float,
    service: bool,
    x_out: np.ndarray,
    v_out: np.ndarray,
) -> int:
    """Integrate ``d(v^2/2)/ds = A(v, x)`` backwards from the target (RK4 in ``e = v^2/2``,
    ``s`` the distance before the target), until ``v_top`` or ``A <= 0`` (the brake
    cannot decelerate the train there). Returns the number of points written."""
    d = p[B_DIRECTION]
    e = 0.5 * v_target * v_target
    s = 0.0
    x_out[0] = x_target
    v_out[0] = v_target
    n = 1
    while n < x_out.shape[0]:
        v1 = math.sqrt(2.0 * e)
        k1 = braking_decel(p, edges, cumulative, values, x_target - d * s, v1, service, 1.0)
        e2 = e + 0.5 * step * k1
        k2 = braking_decel(
            p,
            edges,
            cumulative,
            values,
            x_target - d * (s + 0.5 * step),
            math.sqrt(2 * e2),
            service,
            1.0,
        )
        e3 = e + 0.5 * step * k2
        k3 = braking_decel(
            p,
            edges,
            cumulative,
            values,
            x_target - d * (s + 0.5 * step),
            math.sqrt(2 * e3),
            service,
            1.0,
        )
        e4 = e + step * k3
        k4 = braking_decel(
            p,
            edges,
            cumulative,
            values,
            x_target - d * (s + step),
            math.sqrt(2 * max(e4, 0.0)),
            service,
            1.0,
        )
        if min(k1, k2, k3, k4) <= 0.0:
            break
        e += step * (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
        s += step
        x_out[n] = x_target - d * s
        v_out[n] = math.sqrt(2.0 * e)
        n += 1
        if v_out[n - 1] >= v_top:
            break
    return n


@dataclass(frozen=True)
class SupervisionCurve:
    """One target's deceleration curve and the action points derived from it.

    ``distance_m`` [m] before the target (ascending from 0) and ``speed_mps`` [m/s]
    (ascending from the target speed): the curve. ``intervention_speed_mps`` and
    ``intervention_at_m``: the predicted intervention distance [m] before the target at
    each speed of a grid (ascending). ``complete``: the curve reaches the top speed; else
    the brake cannot decelerate the train farther back (a steep descent for the
    regenerative brake) and no speed above the curve's last can be supervised.
    """

    mode: BrakeMode
    target_m: float
    target_speed_mps: float
    direction: float
    distance_m: np.ndarray
    speed_mps: np.ndarray
    intervention_speed_mps: np.ndarray
    intervention_at_m: np.ndarray
    params: SupervisionParameters
    complete: bool

    @property
    def curve_x_m(self) -> np.ndarray:
        """The curve's positions [m] (``target - direction * distance``)."""
        return np.asarray(self.target_m - self.direction * self.distance_m)

    def curve_distance_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """``s_c(v)``: distance [m] before the target at which the curve has speed ``v``.

        0 at or below the target speed; ``inf`` above an incomplete curve's last speed.
        """
        v = np.asarray(speed_mps, dtype=float)
        s = np.interp(v, self.speed_mps, self.distance_m, left=0.0, right=np.inf)
        if self.complete:
            s = np.where(v > self.speed_mps[-1], self.distance_m[-1], s)
        return np.asarray(s)

    def intervention_distance_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """Distance [m] before the target of the intervention point at speed ``v``."""
        v = np.asarray(speed_mps, dtype=float) + self.params.speed_margin_mps
        right = np.inf if not self.complete else float(self.intervention_at_m[-1])
        return np.asarray(
            np.interp(v, self.intervention_speed_mps, self.intervention_at_m, left=0.0, right=right)
        )

    def indication_distance_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """Distance [m] before the target of the indication point at speed ``v``."""
        v = np.asarray(speed_mps, dtype=float) + self.params.speed_margin_mps
        return np.asarray(
            self.intervention_distance_m(speed_mps) + v * self.params.driver_reaction_s
        )

    def intervention_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """``x_I(v)`` [m]: the last head position at which the brake must be applied."""
        return np.asarray(self.target_m - self.direction * self.intervention_distance_m(speed_mps))

    def indication_m(self, speed_mps: float | np.ndarray) -> np.ndarray:
        """``x_W(v)`` [m]: where the driver is told to brake."""
        return np.asarray(self.target_m - self.direction * self.indication_distance_m(speed_mps))

    def permitted_speed_mps(self, position_m: float | np.ndarray) -> np.ndarray:
        """The highest speed [m/s] at ``position_m`` [m] not yet past its intervention point.

        The target speed at or beyond the point where even that must brake.
        """
        x = np.asarray(position_m, dtype=float)
        dist = self.direction * (self.target_m - x)
        top = float(self.speed_mps[-1])
        speeds = np.linspace(self.target_speed_mps, top, 2000)
        reach = self.intervention_distance_m(speeds)  # increasing with speed
        finite = np.isfinite(reach)
        return np.asarray(
            np.interp(dist, reach[finite], speeds[finite], left=self.target_speed_mps)
        )


def supervision_curve(
    braking: BrakingTrain,
    table: ResistanceTable,
    target_m: float,
    target_speed_mps: float = 0.0,
    *,
    mode: BrakeMode = "service",
    direction: float = FORWARD,
    params: SupervisionParameters | None = None,
    step_m: float = DEFAULT_STEP_M,
    top_speed_mps: float = CURVE_TOP_MPS,
) -> SupervisionCurve:
    """The curves for a target ``target_speed_mps`` [m/s] at ``target_m`` [m] (docstring).

    ``mode``: "service" (regeneration plus the air brake) or "regen" (regeneration alone).
    """
    if mode not in ("service", "regen"):
        raise ConfigError("mode", mode, "'service' or 'regen'")
    if not (math.isfinite(target_speed_mps) and target_speed_mps >= 0):
        raise ConfigError("target_speed_mps", target_speed_mps, "a finite speed >= 0 [m/s]")
    if not (math.isfinite(step_m) and 0 < step_m <= 50):
        raise ConfigError("step_m", step_m, "a step in (0, 50] m")
    p_sup = params or SupervisionParameters()
    direction = 1.0 if direction >= 0 else -1.0
    n_max = 200_000
    x_out = np.empty(n_max)
    v_out = np.empty(n_max)
    n = _backward(
        braking.params(direction),
        *table,
        float(target_m),
        float(target_speed_mps),
        float(top_speed_mps),
        float(step_m),
        mode == "service",
        x_out,
        v_out,
    )
    distance = direction * (float(target_m) - x_out[:n])
    speed = v_out[:n].copy()
    grid = np.linspace(float(target_speed_mps), float(speed[-1]), INTERVENTION_GRID)
    if mode == "regen":
        # regeneration acts at once: the curve is the intervention
        at = np.interp(grid, speed, distance)
    else:
        at = np.array(
            [
                _predicted_intervention_m(
                    braking,
                    table,
                    direction,
                    float(target_m),
                    float(target_speed_mps),
                    v,
                    float(np.interp(v, speed, distance)),
                )
                for v in grid
            ]
        )
        at = np.maximum.accumulate(at)  # monotone in speed (rounding of the iterations)
    return SupervisionCurve(
        mode=mode,
        target_m=float(target_m),
        target_speed_mps=float(target_speed_mps),
        direction=direction,
        distance_m=distance,
        speed_mps=speed,
        intervention_speed_mps=grid,
        intervention_at_m=at,
        params=p_sup,
        complete=bool(speed[-1] >= top_speed_mps),
    )


def _predicted_intervention_m(
    braking: BrakingTrain,
    table: ResistanceTable,
    direction: float,
    target_m: float,
    target_speed_mps: float,
    speed_mps: float,
    curve_distance_m: float,
    *,
    iterations: int = 6,
    tolerance_m: float = 0.5,
) -> float:
    """Distance [m] before the target from which full service at ``speed_mps`` just makes it.

    Fixed-point iteration on the start: predict the braking from the current guess, move
    the start by the overshoot (the gradient under the train changes with it, so a few
    rounds). Starts from the curve's distance, which needs no build-up and so is too short.
    """
    if speed_mps <= target_speed_mps:
        return 0.0
    distance = curve_distance_m
    for _ in range(iterations):
        start = target_m - direction * distance
        run = predict_braking(
            braking,
            table,
            start,
            speed_mps,
            direction=direction,
            air_from_s=0.0,
            until_speed_mps=target_speed_mps,
        )
        if not run.reached_speed:
            return math.inf
        overshoot = direction * (float(run.x_m[-1]) - target_m)
        distance += overshoot
        if abs(overshoot) <= tolerance_m:
            break
    return distance
