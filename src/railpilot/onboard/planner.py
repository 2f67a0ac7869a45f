"""Energy-efficient planned curve for an inter-station running time (paper 001 section 2.3).

The onboard computes an advisory speed profile that meets the running time the ground
sends, with as little energy as it can: maximum traction, cruise, coast, regenerative hold
on descents, brake. The method is MARECO's economic allowance (SNCF; as
OSRD implements it, ``MarecoAllowance``): cap the speed at ``v1``, and coast wherever the
train can, before every braking and before every descent that would accelerate it beyond
``v1``, down to the speed ``vf(v1)`` at which braking pays; then search ``v1`` so that the
running time is met.

On a distance grid (step ``dx``, positions ``s`` from the departure stop, head of the
train), with the ceiling ``C(s)`` (the most restrictive speed profile, for the whole train)::

    backward  E(s) = min(C(s), back(E(s + dx)))                the coast-and-brake envelope
              back(v) = sqrt(v^2 + 2 dx w_coast(v, s))          if v >= vf: coasting
                      = sqrt(v^2 + 2 dx (w_coast(v, s) + b))    else: braking at b [m/s^2]
    forward   v(s + dx) = min(E(s + dx), coast(v))               if coast(v) >= v1 (a descent)
                        = min(E(s + dx), v1, full traction(v))   else
    vf(v1)    = psi v1 / (psi + R(v1) v1),  psi = v1^2 R'(v1)   (MARECO's coast-to-brake speed)

(``v1`` may exceed every ceiling: then only ``vf(v1)`` makes the train coast.)

``w_coast = (R(v) + line resistance) / m_eff`` the coasting deceleration (negative on a
descent), ``b`` the planning brake (the regenerative envelope, then the air brake, up to
``brake_mps2``); braking with the planning brake to a stop at the end that is a target
(a red signal, not the station), the net deceleration ``w_coast + b`` is at least
``stop_net`` (on a descent the air brake adds what the line takes away, up to the full
service). The forward pass accelerates at full traction up to ``v1`` and cruises there;
where the line alone would take the train above ``v1`` (a descent) it coasts, and it
follows the envelope wherever it meets it: coasting or braking before a lower ceiling or a
stop, and holding the ceiling with the regenerative brake on a descent. ``C = 0`` at both
ends gives the stops.

Deviation from MARECO: MARECO also coasts *before* a descent on which the train would exceed
``v1`` (``AcceleratingSlopeCoast``), arriving at its foot at ``v1``. That suits a train that
can only waste its braking energy; a train that regenerates recovers 80 % of it, and entering
the descent slowly to avoid braking costs more time than it saves energy (on the 15 km
test section with a 5 km 12 per mille descent, the accelerating-slope coast came out 385 kWh
worse than the numerical optimum). Here the train lets the descent take it up to the
ceiling and holds it there regenerating.

Energy: the force needed to follow the profile, ``F = m_eff dv/dt + R + line``; positive
is traction, drawn from the catenary at ``/ eta_t``; negative is braking, of which the
regenerative envelope returns ``x eta_r`` and the air brake the rest. The baseline is the
fastest profile (``v1`` = the ceiling) slowed by a uniform factor to the same running time
(OSRD's linear allowance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle.profile import FORWARD, ResistanceTable, length_averaged_resistance
from railpilot.vehicle.resistance import davis_specific_resistance
from railpilot.vehicle.traction import Locomotive, regen_force_max, traction_force_max
from railpilot.vehicle.train import Train

#: grid step [m]
DEFAULT_STEP_M = 10.0
#: the planning brake [m/s^2]: what the planned curve brakes with (regen first, then air)
DEFAULT_BRAKE_MPS2 = 0.1
#: a target stop (a red signal ahead, not the station) is braked to at no less than this
#: share of the planning brake, net of the line (docs/onboard.md, "Planned curve": on a
#: long descent the planning brake alone, less what the descent takes, planned a stop
#: behind a slow leader 14 km long; a full share made plans the ATO's tracking of the air
#: brake could not follow; at the station the long stop is the cheap one, and planned for)
TARGET_STOP_NET_SHARE = 0.5
#: running-time tolerance of the search [s] (one ATO control period or better)
TIME_TOLERANCE_S = 0.1
#: the speeds ``vb`` (as shares of the section's top speed) below which the planned curve
#: brakes with the full planning brake; above it, and below ``vf``, it brakes with the
#: regenerative brake alone. 1.0 and above: full braking only (MARECO). The planner keeps
#: the family member with the least energy.
REGEN_BRAKING_SHARES = (math.inf, 0.75, 0.5, 0.35, 0.2, 0.0)

# params of the compiled passes
(
    Q_MASS,
    Q_MEFF,
    Q_A0,
    Q_A1,
    Q_A2,
    Q_TRAC_F,
    Q_TRAC_P,
    Q_TRAC_VMAX,
    Q_REGEN_F,
    Q_REGEN_P,
    Q_REGEN_FADE,
    Q_BRAKE,
    Q_ETA_T,
    Q_ETA_R,
    Q_SERVICE,
) = range(15)
N_Q = 15


@dataclass(frozen=True)
class DrivingTrain:
    """The train as the planner drives it.

    Attributes
    ----------
    train
        Mass, rotating mass, length and Davis coefficients.
    locomotive
        Traction and regenerative envelopes and the chain's efficiencies.
    brake_mps2
        The planning brake [m/s^2]: the planned curve brakes at this deceleration (the
        regenerative envelope first, then the air brake); below the service limit.
    """

    train: Train
    locomotive: Locomotive
    brake_mps2: float = DEFAULT_BRAKE_MPS2

    def __post_init__(self) -> None:
        if not isinstance(self.train, Train):
            raise ConfigError("train", self.train, "a railpilot.vehicle.train.Train")
        if not isinstance(self.locomotive, Locomotive):
            raise ConfigError("locomotive", self.locomotive, "a Locomotive")
        b = self.brake_mps2
        if not (math.isfinite(b) and 0 < b <= self.train.max_service_decel_mps2):
            raise ConfigError(
                "brake_mps2",
                b,
                f"a deceleration in (0, {self.train.max_service_decel_mps2:g}] m/s^2 "
                "(the train's service limit)",
            )

    def params(self) -> np.ndarray:
        t, loco = self.train, self.locomotive
        q = np.zeros(N_Q)
        q[Q_MASS] = t.mass_kg
        q[Q_MEFF] = t.effective_mass_kg
        q[Q_A0], q[Q_A1], q[Q_A2] = t.davis_a0, t.davis_a1, t.davis_a2
        q[Q_TRAC_F] = loco.traction.max_force_n
        q[Q_TRAC_P] = loco.traction.max_power_w
        q[Q_TRAC_VMAX] = loco.traction.speed_limit_mps
        q[Q_REGEN_F] = loco.regen.max_force_n
        q[Q_REGEN_P] = loco.regen.max_power_w
        q[Q_REGEN_FADE] = loco.regen.fade_below_mps
        q[Q_BRAKE] = self.brake_mps2
        q[Q_ETA_T] = loco.traction_efficiency
        q[Q_ETA_R] = loco.regen_efficiency
        q[Q_SERVICE] = t.max_service_decel_mps2
        return q

    def resistance_n(self, speed_mps: float) -> float:
        """Davis resistance [N] at ``speed_mps`` [m/s]."""
        t = self.train
        w = davis_specific_resistance(speed_mps * KMH_PER_MPS, t.davis_a0, t.davis_a1, t.davis_a2)
        return float(w) * t.mass_kg * G_MPS2 / 1000.0

    def coast_decel_mps2(self, speed_mps: float, line_w: float) -> float:
        """Coasting deceleration [m/s^2] at ``speed_mps`` [m/s] on the line resistance
        ``line_w`` [N/kN] (negative: the line accelerates the train); the same arithmetic
        as the compiled passes' (:func:`_coast_decel`)."""
        t = self.train
        w = float(
            davis_specific_resistance(speed_mps * KMH_PER_MPS, t.davis_a0, t.davis_a1, t.davis_a2)
        )
        return (w + line_w) * t.mass_kg * G_MPS2 / 1000.0 / t.effective_mass_kg

    def coast_to_brake_speed_mps(self, v1_mps: float) -> float:
        """MARECO's ``vf(v1)`` [m/s]: below it braking pays, above it coasting does.

        ``vf = psi v1 / (psi + R(v1) v1)`` with ``psi = v1^2 R'(v1)`` (module docstring).
        """
        t = self.train
        slope = (t.davis_a1 + 2.0 * t.davis_a2 * v1_mps * KMH_PER_MPS) * KMH_PER_MPS
        r_prime = slope * t.mass_kg * G_MPS2 / 1000.0
        psi = v1_mps * v1_mps * r_prime
        return psi * v1_mps / (psi + self.resistance_n(v1_mps) * v1_mps)


@njit(cache=True)
def _coast_decel(q: np.ndarray, v: float, line_w: float) -> float:
    """Coasting deceleration [m/s^2] (negative: the line accelerates the train)."""
    w = davis_specific_resistance(v * KMH_PER_MPS, q[Q_A0], q[Q_A1], q[Q_A2]) + line_w
    return w * q[Q_MASS] * G_MPS2 / 1000.0 / q[Q_MEFF]


@njit(cache=True)
def _envelope(
    q: np.ndarray,
    line_w: np.ndarray,
    ceiling: np.ndarray,
    vf: float,
    vb: float,
    dx: float,
    stop_net: float,
) -> np.ndarray:
    """The backward coast-and-brake envelope ``E`` (module docstring); ``stop_net``
    [m/s^2] the least net deceleration of the planning brake's stop at the end (0: the
    planning brake's force, net of the line)."""
    n = ceiling.shape[0]
    e = np.empty(n)
    e[n - 1] = ceiling[n - 1]
    # braking to the stop at the end: until, going back, the envelope meets the ceiling
    to_stop = ceiling[n - 1] <= 0.0 and stop_net > 0.0
    for i in range(n - 2, -1, -1):
        v = e[i + 1]
        w = 0.5 * (line_w[i] + line_w[i + 1])
        coast = _coast_decel(q, v, w)
        sq = v * v + 2.0 * dx * coast
        if v < vf or coast < 0.0:
            # below vf braking pays; and where the line accelerates a coasting train (a
            # descent) the regenerative brake holds it rather than the train slowing down
            # beforehand to coast it (deviation from MARECO: module docstring). The brake
            # is the regenerative one while it has force, the planning brake below its fade
            regen = regen_force_max(v, q[Q_REGEN_F], q[Q_REGEN_P], q[Q_REGEN_FADE])
            if v >= vb and v >= q[Q_REGEN_FADE] and regen > 0.0:
                braking = coast + min(regen / q[Q_MEFF], q[Q_BRAKE])
            else:
                braking = coast + q[Q_BRAKE]
                if braking <= 0.0 and not (to_stop and stop_net >= q[Q_BRAKE]):
                    # the planning brake cannot hold the train here (a descent steeper
                    # than it): the plan brakes with the train's full service instead
                    braking = coast + q[Q_SERVICE]
                elif to_stop and braking < stop_net:
                    # a stop on a descent: the air brake adds what the descent takes away,
                    # up to the full service (the planning brake alone, net of 11.5 per
                    # mille, would plan a loaded train's stop behind a slow leader 14 km
                    # long). A stop planned at the planning brake's own deceleration (the
                    # consist's at the station: onboard/drive.py station_stop_net) is so
                    # however steep the descent: at the full service, a loaded train's
                    # stop on 12 per mille is a curve no air brake's build-up along the
                    # train follows. The regenerative phase and the braking for a lower
                    # speed stay as they are: what the ATO tracks there, the air brake's
                    # minute-long build-up could not follow (docs/onboard.md, "Planned
                    # curve")
                    braking = min(stop_net, coast + q[Q_SERVICE])
            sq = v * v + 2.0 * dx * braking
            if v < vf and sq > vf * vf and braking > 0.0:
                # braking reaches vf within the step: brake up to vf, coast the rest (so the
                # envelope, and the running time, are continuous in vf)
                braked = (vf * vf - v * v) / (2.0 * braking)
                sq = vf * vf + 2.0 * (dx - braked) * coast
        back = math.sqrt(sq) if sq > 0.0 else 0.0
        if ceiling[i] <= back:
            e[i] = ceiling[i]
            to_stop = False
        else:
            e[i] = back
    return e


@njit(cache=True, inline="always")
def _forward_next(
    q: np.ndarray,
    line_w: np.ndarray,
    ceiling: np.ndarray,
    envelope: np.ndarray,
    v1: float,
    dx: float,
    i: int,
    speed: float,
) -> float:
    """The forward pass's speed [m/s] at grid point ``i + 1``, one step ``dx`` [m] on from
    ``speed`` [m/s] at ``i``: towards the cruise speed ``min(v1, C)`` on the step's mean
    line resistance, bounded by the envelope (module docstring). :func:`_forward` and
    :func:`_forward_time` both step with it, so their profiles are the same to the bit."""
    w = 0.5 * (line_w[i] + line_w[i + 1])
    return min(envelope[i + 1], _towards_cruise(q, speed, min(v1, ceiling[i + 1]), w, dx))


@njit(cache=True, inline="always")
def _towards_cruise(q: np.ndarray, speed: float, cruise: float, w: float, dx: float) -> float:
    """The speed [m/s] one grid step ``dx`` [m] on from ``speed`` [m/s], towards ``cruise``
    [m/s] on the mean line resistance ``w`` [N/kN], before the envelope bounds it."""
    coast = _coast_decel(q, speed, w)
    sq = speed * speed - 2.0 * dx * coast
    coasting = math.sqrt(sq) if sq > 0.0 else 0.0
    if coasting >= cruise:
        # a descent: no traction; the regenerative brake holds the cruise speed if it
        # can, else brakes at its envelope while the train still gains speed
        # (recovering what would otherwise be braked away by air further down)
        regen = regen_force_max(speed, q[Q_REGEN_F], q[Q_REGEN_P], q[Q_REGEN_FADE])
        sq = speed * speed - 2.0 * dx * (coast + regen / q[Q_MEFF])
        braked = math.sqrt(sq) if sq > 0.0 else 0.0
        return min(coasting, max(cruise, braked))
    trac = traction_force_max(speed, q[Q_TRAC_F], q[Q_TRAC_P], q[Q_TRAC_VMAX])
    sq = speed * speed + 2.0 * dx * (trac / q[Q_MEFF] - coast)
    return min(cruise, math.sqrt(sq) if sq > 0.0 else 0.0)


@njit(cache=True)
def _forward(
    q: np.ndarray,
    line_w: np.ndarray,
    ceiling: np.ndarray,
    envelope: np.ndarray,
    v1: float,
    dx: float,
) -> np.ndarray:
    """Full traction up to the cruise speed ``min(v1, C)``; where the line alone takes the
    train above it (a descent), regeneration instead; bounded by the envelope (module
    docstring)."""
    n = envelope.shape[0]
    v = np.empty(n)
    v[0] = envelope[0]
    for i in range(n - 1):
        v[i + 1] = _forward_next(q, line_w, ceiling, envelope, v1, dx, i, v[i])
    return v


@njit(cache=True)
def _forward_time(
    q: np.ndarray,
    line_w: np.ndarray,
    ceiling: np.ndarray,
    envelope: np.ndarray,
    v1: float,
    dx: float,
) -> float:
    """The running time [s] of :func:`_forward`'s profile, as :func:`_evaluate` gives it,
    to the bit, without the profile or its energy: the search for ``v1`` asks only for
    the time, dozens of times a plan."""
    time = 0.0
    speed = envelope[0]
    for i in range(envelope.shape[0] - 1):
        nxt = _forward_next(q, line_w, ceiling, envelope, v1, dx, i, speed)
        mean = 0.5 * (speed + nxt)
        speed = nxt
        if mean <= 0.0:
            continue  # as _evaluate: a stop inside the grid
        time += dx / mean
    return time


@njit(cache=True)
def _evaluate(
    q: np.ndarray, line_w: np.ndarray, v: np.ndarray, dx: float
) -> tuple[float, float, float, float]:
    """Running time [s], traction energy drawn, regenerated energy returned [J], and the
    energy at the wheel [J] of following the profile ``v`` on the grid."""
    time = 0.0
    drawn = 0.0
    returned = 0.0
    wheel = 0.0
    for i in range(v.shape[0] - 1):
        v0 = v[i]
        v1 = v[i + 1]
        mean = 0.5 * (v0 + v1)
        if mean <= 0.0:
            continue  # a stop inside the grid: not passable, time is infinite
        time += dx / mean
        accel = (v1 * v1 - v0 * v0) / (2.0 * dx)
        w = 0.5 * (line_w[i] + line_w[i + 1])
        force = q[Q_MEFF] * (accel + _coast_decel(q, mean, w))
        if force > 0.0:
            drawn += force * dx / q[Q_ETA_T]
            wheel += force * dx
        else:
            regen = min(-force, regen_force_max(mean, q[Q_REGEN_F], q[Q_REGEN_P], q[Q_REGEN_FADE]))
            returned += regen * dx * q[Q_ETA_R]
    return time, drawn, returned, wheel


@dataclass(frozen=True)
class SpeedPlan:
    """A planned speed profile over a section and what following it costs.

    Attributes
    ----------
    s_m
        Distance from the departure stop [m] of each grid point.
    speed_mps
        The planned speed [m/s] there.
    running_time_s
        Time to run it [s].
    energy_traction_kwh, energy_regenerated_kwh
        Drawn from and returned to the catenary [kWh].
    v1_mps, vf_mps
        MARECO's cap and coast-to-brake speed [m/s] (None for a baseline).
    requested_time_s
        The running time asked for [s]; ``met``: within the search tolerance.
    strategy
        "fastest", "mareco" (the search found it) or "uniform" (the linear margin was
        cheaper and is returned instead).
    """

    s_m: np.ndarray
    speed_mps: np.ndarray
    running_time_s: float
    energy_traction_kwh: float
    energy_regenerated_kwh: float
    v1_mps: float | None
    vf_mps: float | None
    requested_time_s: float | None
    met: bool
    strategy: str = "mareco"

    @property
    def energy_net_kwh(self) -> float:
        """Traction drawn minus regeneration returned [kWh]."""
        return self.energy_traction_kwh - self.energy_regenerated_kwh

    @cached_property
    def elapsed_s(self) -> np.ndarray:
        """Time [s] the plan takes from its start to each grid point (trapezoidal in
        ``1 / v`` between grid points, the planner's own rule; a stretch at rest takes
        none). Computed once: an onboard asks where it stands on its plan every second."""
        s, v = self.s_m, self.speed_mps
        mean = 0.5 * (v[1:] + v[:-1])
        dt = np.where(mean > 0, np.diff(s) / np.where(mean > 0, mean, 1.0), 0.0)
        elapsed = np.concatenate([[0.0], np.cumsum(dt)])
        elapsed.flags.writeable = False
        return elapsed


@dataclass(frozen=True)
class SectionGrid:
    """A section to plan: the grid, the ceiling and the line resistance on it.

    Build with :func:`section`.
    """

    s_m: np.ndarray
    ceiling_mps: np.ndarray
    line_w: np.ndarray
    dx_m: float


def section(
    length_m: float,
    ceiling: tuple[np.ndarray, np.ndarray],
    table: ResistanceTable,
    *,
    start_m: float = 0.0,
    direction: float = FORWARD,
    train_length_m: float = 0.0,
    step_m: float = DEFAULT_STEP_M,
    initial_speed_mps: float = 0.0,
) -> SectionGrid:
    """The planner's grid from the departure stop at ``start_m`` [m] over ``length_m`` [m].

    ``ceiling``: ``(edges_m, speeds_mps)`` of the most restrictive speed profile in the
    train's own coordinate (distance from the departure stop), for the whole train;
    ``table`` the line's resistance for ``direction`` (length-averaged over
    ``train_length_m``). The ceiling is 0 at the end (the stop) and, for a train at rest,
    at the start; a train re-planned on the move starts at ``initial_speed_mps`` [m/s].
    """
    if not (math.isfinite(initial_speed_mps) and initial_speed_mps >= 0):
        raise ConfigError("initial_speed_mps", initial_speed_mps, "a speed >= 0 [m/s]")
    if not (math.isfinite(length_m) and length_m > 2 * step_m):
        raise ConfigError("length_m", length_m, f"a section longer than {2 * step_m:g} m")
    if not (math.isfinite(step_m) and 0 < step_m <= 100):
        raise ConfigError("step_m", step_m, "a grid step in (0, 100] m")
    n = math.ceil(length_m / step_m) + 1
    dx = length_m / (n - 1)
    s = np.linspace(0.0, length_m, n)
    edges, speeds = (np.asarray(a, dtype=float) for a in ceiling)
    if edges.ndim != 1 or speeds.shape != (edges.size - 1,) or np.any(np.diff(edges) <= 0):
        raise ConfigError("ceiling", ceiling, "(edges ascending, one speed per interval)")
    if np.any(~np.isfinite(speeds) | (speeds < 0)):
        raise ConfigError("ceiling", speeds, "finite speeds >= 0 [m/s]")
    idx = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, speeds.size - 1)
    # at an edge the lower side governs
    at_edge = np.isin(s, edges[1:-1])
    lower = np.minimum(speeds[idx], speeds[np.clip(idx - 1, 0, speeds.size - 1)])
    c = np.where(at_edge, lower, speeds[idx])
    c[0] = initial_speed_mps
    c[-1] = 0.0
    x = start_m + direction * s
    w = length_averaged_resistance(table, x, train_length_m, 1.0 if direction >= 0 else -1.0)
    return SectionGrid(s, c, np.asarray(w, dtype=float), dx)


def _result(
    train: DrivingTrain,
    sec: SectionGrid,
    v: np.ndarray,
    v1: float | None,
    vf: float | None,
    requested: float | None,
) -> SpeedPlan:
    time, drawn, returned, _ = _evaluate(train.params(), sec.line_w, v, sec.dx_m)
    met = requested is None or abs(time - requested) <= TIME_TOLERANCE_S
    return SpeedPlan(
        sec.s_m,
        v,
        time,
        drawn / 3.6e6,
        returned / 3.6e6,
        v1,
        vf,
        requested,
        bool(met),
    )


def target_stop_net(train: DrivingTrain) -> float:
    """The least net deceleration [m/s^2] a plan brakes to a target stop with (a red
    signal ahead, not the station): ``TARGET_STOP_NET_SHARE`` of the planning brake."""
    return TARGET_STOP_NET_SHARE * train.brake_mps2


def braking_envelope(
    train: DrivingTrain, sec: SectionGrid, ceiling: np.ndarray, stop_net_mps2: float = 0.0
) -> np.ndarray:
    """The backward braking curves [m/s] to every lower ``ceiling`` and to the stop, with
    the planning brake and no coasting: the fastest run's envelope (``stop_net_mps2`` as
    :func:`fastest`'s)."""
    q = train.params()
    return _envelope(q, sec.line_w, ceiling, np.inf, np.inf, sec.dx_m, stop_net_mps2)


def fastest(train: DrivingTrain, sec: SectionGrid, stop_net_mps2: float = 0.0) -> SpeedPlan:
    """The fastest profile: full traction, the ceiling, the planning brake (to a stop at
    the end, at least ``stop_net_mps2`` [m/s^2] net: a target stop, ``target_stop_net``)."""
    if not (math.isfinite(stop_net_mps2) and stop_net_mps2 >= 0.0):
        raise ConfigError("stop_net_mps2", stop_net_mps2, "a deceleration >= 0 [m/s^2]")
    top = float(sec.ceiling_mps.max())
    # the fastest run does not coast: vf above every speed makes the envelope all braking
    env = braking_envelope(train, sec, sec.ceiling_mps, stop_net_mps2)
    v = _forward(train.params(), sec.line_w, sec.ceiling_mps, env, top, sec.dx_m)
    return replace(_result(train, sec, v, None, None, None), strategy="fastest")


def plan(
    train: DrivingTrain, sec: SectionGrid, running_time_s: float, stop_net_mps2: float = 0.0
) -> SpeedPlan:
    """The MARECO profile that runs the section in ``running_time_s`` [s] (docstring);
    ``stop_net_mps2`` as :func:`fastest`'s.

    Bisection on ``v1`` until the running time is within ``TIME_TOLERANCE_S``. A time
    shorter than the fastest run's gives the fastest run, ``met`` False.
    """
    if not (math.isfinite(running_time_s) and running_time_s > 0):
        raise ConfigError("running_time_s", running_time_s, "a running time > 0 [s]")
    quickest = fastest(train, sec, stop_net_mps2)
    if running_time_s <= quickest.running_time_s + TIME_TOLERANCE_S:
        met = abs(quickest.running_time_s - running_time_s) <= TIME_TOLERANCE_S
        return replace(quickest, requested_time_s=running_time_s, met=met)
    q = train.params()
    top = float(sec.ceiling_mps.max())
    best: SpeedPlan | None = None
    for share in REGEN_BRAKING_SHARES:
        candidate = _search_v1(train, q, sec, running_time_s, share * top, stop_net_mps2)
        if candidate is None:
            continue
        if best is None or candidate.energy_net_kwh < best.energy_net_kwh:
            best = candidate
    # never worse than spreading the margin uniformly: on steep descents the family above
    # can lose to it (docs/onboard.md, "Planned curve": measured), so the baseline is a
    # candidate too
    uniform = _uniform(train, sec, quickest, running_time_s)
    if best is None or uniform.energy_net_kwh < best.energy_net_kwh:
        return uniform
    return best


def _search_v1(
    train: DrivingTrain,
    q: np.ndarray,
    sec: SectionGrid,
    running_time_s: float,
    vb: float,
    stop_net: float,
) -> SpeedPlan | None:
    """Bisection on ``v1`` for one ``vb``; None if this family cannot run that fast."""
    # v1 may exceed the ceiling: the cap then binds nowhere and only vf(v1) < top speed
    # makes the train coast; the search starts where vf reaches the top (no coasting)
    top = float(sec.ceiling_mps.max())
    lo, hi = 0.5, top
    while train.coast_to_brake_speed_mps(hi) < top and hi < 1e3:
        hi *= 1.25
    # this family's fastest: if even that is too slow, it cannot meet the time
    env = _envelope(
        q, sec.line_w, sec.ceiling_mps, train.coast_to_brake_speed_mps(hi), vb, sec.dx_m, stop_net
    )
    if _forward_time(q, sec.line_w, sec.ceiling_mps, env, hi, sec.dx_m) > (
        running_time_s + TIME_TOLERANCE_S
    ):
        return None
    for _ in range(60):
        v1 = 0.5 * (lo + hi)
        vf = train.coast_to_brake_speed_mps(v1)
        env = _envelope(q, sec.line_w, sec.ceiling_mps, vf, vb, sec.dx_m, stop_net)
        time = _forward_time(q, sec.line_w, sec.ceiling_mps, env, v1, sec.dx_m)
        if abs(time - running_time_s) <= TIME_TOLERANCE_S:
            v = _forward(q, sec.line_w, sec.ceiling_mps, env, v1, sec.dx_m)
            return _result(train, sec, v, v1, vf, running_time_s)
        if time > running_time_s:
            lo = v1  # too slow: a higher cap
        else:
            hi = v1
        if hi - lo < 1e-9:
            break
    return None


def linear_margin(train: DrivingTrain, sec: SectionGrid, running_time_s: float) -> SpeedPlan:
    """The baseline: the fastest profile with every speed scaled by one factor.

    ``v(s) = k v_fast(s)`` with ``k = T_fast / T``: the same running time spread uniformly
    (OSRD's linear allowance).
    """
    return _uniform(train, sec, fastest(train, sec), running_time_s)


def _uniform(
    train: DrivingTrain, sec: SectionGrid, quickest: SpeedPlan, running_time_s: float
) -> SpeedPlan:
    k = min(1.0, quickest.running_time_s / running_time_s)
    curve = _result(train, sec, quickest.speed_mps * k, None, None, running_time_s)
    return replace(curve, strategy="uniform")
