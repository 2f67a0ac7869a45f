"""Longitudinal train dynamics: one mass per vehicle, couplings with slack and friction gears.

A train of ``n`` vehicles, numbered from the head. Vehicle ``i`` has mass ``m_i``,
rotating-mass factor ``gamma_i`` (effective mass ``M_i = m_i (1 + gamma_i)``), length
``l_i`` over couplers, front position ``x_i`` [m] (along the direction of travel, in the
train's own coordinate: the line as seen by a train running towards increasing ``x``) and
speed ``v_i`` [m/s]; it occupies ``[x_i - l_i, x_i]``. Coupling ``j`` joins vehicles ``j``
and ``j + 1``; its relative displacement and rate are

    d_j = (x_j - l_j) - x_{j+1}           [m]   (0: the middle of the free slack)
    r_j = v_j - v_{j+1}                   [m/s] (> 0: stretching)

and it carries the force ``f_j(d_j, r_j)`` [N], tension positive (:func:`coupling_force`).
Each vehicle obeys

    M_i dv_i/dt = f_{i-1} - f_i + D_i - W_i + Q_i,

``D_i`` the caller's drive force (signed: + traction, - regenerative braking), ``W_i =
w_bar_i m_i g / 1000`` its gradient + curve force (``w_bar_i`` [N/kN] the profile averaged
over the vehicle's own span, vehicle/profile.py), and ``Q_i`` friction: the brake force
``B_i >= 0`` plus the Davis resistance ``(a0 + a1 V + a2 V^2) m_i g / 1000`` (V in km/h),
opposing motion and, at rest, holding the vehicle up to that magnitude (Karnopp: a vehicle
at rest stays at rest while the other forces on it are within its friction; a vehicle whose
speed would change sign within a step stops at zero).

The force law of a coupling (symmetric in draft and buff), with ``s`` the free slack,
``g = |d| - s/2`` the gears' travel beyond it, ``T`` their travel to solid, ``P`` the
preload, ``F_T`` the force at ``T``, ``rho`` the unloading ratio, ``k_s`` the stop
stiffness, ``c`` the viscous damping and ``v_sw`` the switching speed:

    f_L(g)   = P + (F_T - P) min(g, T) / T                 loading curve
    sigma    = clip(1/2 + r_out / (2 v_sw), 0, 1),         r_out = sign(d) r
    beta     = rho + (1 - rho) sigma                       (rho unloading .. 1 loading)
    |f|      = min(k_s g, beta f_L(g)) + k_s max(g - T, 0) + c r_out,   clipped at 0
    f        = sign(d) |f|   for g > 0,   0 within the slack.

The ramp ``k_s g`` makes the preloaded gear a stiff stop until the force reaches the
preload (no jump in force where the slack is taken up); beyond solid the coupler and the
underframe act as the spring ``k_s``. This is the loading/unloading-curve model of
C. Cole's "Longitudinal train dynamics" (Handbook of Railway Vehicle Dynamics) with the
switch between the curves spread over a band of relative speed (see
docs/longitudinal-dynamics.md for the sources read and the deviations).

Integrator: semi-implicit (symplectic) Euler, with every velocity-dependent coupling
force (the viscous damping and the friction switch, whose slope ``(1 - rho) f_L / (2
v_sw)`` can reach 10^8 N s/m) taken implicitly, linearised: one tridiagonal solve per
substep (Thomas algorithm, O(n)). Only the stiffness is explicit, so the step is bounded
by the stiffest coupling alone: ``h < 2 / omega_max`` with ``omega_max^2 <= max_i 2 (k_{i-1}
+ k_i) / M_i`` (Gershgorin's bound on ``M^-1 K``; exact for two equal masses) and ``k_j``
the largest slope of coupling ``j``'s force law (:func:`stable_step_s`). :func:`ltd_step`
takes the caller's step ``dt`` and divides it into equal substeps no longer than the
inputs' ``max_substep_s``: by default a quarter of the bound, which accuracy (a run-in
through the slack) rather than stability asks for. The method is first order.

State: one float array (:func:`initial_state`): positions ``[0, n)``, speeds ``[n, 2n)``,
coupling forces ``[2n, 3n - 1)`` (those applied in the last substep, tension positive), the
time advanced ``[3n - 1]`` and the kernel's private work space ``[3n, 10n)``. Read it
through :func:`positions_m`, :func:`speeds_mps`, :func:`coupler_force_n` (views).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from railpilot.checks import check_count, check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle import resistance
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.profile import ResistanceTable

__all__ = [
    "DEFAULT_SAFETY",
    "DEFAULT_STEP_FRACTION",
    "GearArrays",
    "LtdInputs",
    "LumpedTrain",
    "coupler_force_n",
    "coupling_force",
    "draft_gear_force_n",
    "gear_arrays",
    "initial_state",
    "ltd_step",
    "ltd_substeps",
    "lump_forces",
    "lump_vehicles",
    "pack_ltd",
    "positions_m",
    "speeds_mps",
    "stable_step_s",
    "state_size",
]

# Davis' law, inlined into the loop (as sim/engine.py does: the same arithmetic, no call)
_davis_specific_resistance = njit(inline="always")(resistance._davis_specific_resistance)

G = G_MPS2

#: Fraction of the stability bound :func:`stable_step_s` gives by default.
DEFAULT_SAFETY = 0.9
#: Fraction of the stability bound the substeps use by default: accuracy, not stability,
#: sets it (a run-in through the slack into the gears loses its hysteresis loop's energy
#: within 3 % at 0.25, within 20 % at 0.9; docs/longitudinal-dynamics.md)
DEFAULT_STEP_FRACTION = 0.25


class GearArrays(NamedTuple):
    """The couplings' parameters as arrays, one entry per coupling (fields and units as
    :class:`~railpilot.vehicle.coupler.DraftGear`). A lumped train's couplings
    (:func:`lump_vehicles`) may exceed a single DraftGear's limits (its slack and travel
    are those of several couplings in series), so they are carried in this form."""

    slack_m: np.ndarray
    travel_m: np.ndarray
    preload_n: np.ndarray
    force_at_travel_n: np.ndarray
    unloading_ratio: np.ndarray
    stop_stiffness_n_per_m: np.ndarray
    damping_n_s_per_m: np.ndarray
    switching_speed_mps: np.ndarray


class LtdInputs(NamedTuple):
    """Everything :func:`ltd_step` reads (arrays only; built by :func:`pack_ltd`).

    Per vehicle (``n``): ``mass_kg``, ``effective_mass_kg`` ``m (1 + gamma)``,
    ``length_m``, ``weight_kn`` ``m g / 1000`` (the factor of a specific force in N/kN),
    ``davis`` ``(n, 3)`` ``a0, a1, a2`` [N/kN, V in km/h]. Per coupling (``n - 1``):
    ``half_slack_m``, ``travel_m``, ``preload_n``, ``gear_rate_n_per_m`` ``(F_T - P) / T``,
    ``unloading_ratio``, ``stop_stiffness_n_per_m``, ``damping_n_s_per_m``,
    ``switching_speed_mps``. The line: ``edges_m``, ``cumulative``, ``values_n_per_kn`` of
    :class:`~railpilot.vehicle.profile.ResistanceTable` (for the direction of travel).
    ``max_substep_s`` (one element): the longest substep :func:`ltd_step` takes.
    """

    mass_kg: np.ndarray
    effective_mass_kg: np.ndarray
    length_m: np.ndarray
    weight_kn: np.ndarray
    davis: np.ndarray
    half_slack_m: np.ndarray
    travel_m: np.ndarray
    preload_n: np.ndarray
    gear_rate_n_per_m: np.ndarray
    unloading_ratio: np.ndarray
    stop_stiffness_n_per_m: np.ndarray
    damping_n_s_per_m: np.ndarray
    switching_speed_mps: np.ndarray
    edges_m: np.ndarray
    cumulative: np.ndarray
    values_n_per_kn: np.ndarray
    max_substep_s: np.ndarray


class LumpedTrain(NamedTuple):
    """A train with consecutive vehicles lumped (:func:`lump_vehicles`): the arrays
    :func:`pack_ltd` takes, per lump, and ``lump_of_vehicle[i]``, the lump vehicle ``i``
    belongs to."""

    masses_kg: np.ndarray
    rotating_mass_factors: np.ndarray
    lengths_m: np.ndarray
    davis: np.ndarray
    gears: GearArrays
    lump_of_vehicle: np.ndarray


# --- the coupling's force law


def _coupling_force(
    half_slack: float,
    travel: float,
    preload: float,
    gear_rate: float,
    ratio: float,
    k_stop: float,
    damping: float,
    v_switch: float,
    d: float,
    rate: float,
) -> tuple[float, float]:
    """Force [N] of one coupling (tension +) and its slope with the relative rate
    ``df/dr`` [N s/m] (>= 0), at relative displacement ``d`` [m] and rate ``r`` [m/s]."""
    ad = abs(d)
    g = ad - half_slack
    if g <= 0.0:
        return 0.0, 0.0
    sign = 1.0 if d > 0.0 else -1.0
    out_rate = sign * rate  # > 0: the gears close further (loading)
    sigma = 0.5 + 0.5 * out_rate / v_switch
    dsigma = 0.5 / v_switch
    if sigma >= 1.0:
        sigma = 1.0
        dsigma = 0.0
    elif sigma <= 0.0:
        sigma = 0.0
        dsigma = 0.0
    beta = ratio + (1.0 - ratio) * sigma
    curve = preload + gear_rate * (g if g < travel else travel)
    gear = beta * curve
    ramp = k_stop * g
    if ramp < gear:
        mag = ramp  # the gears have not started to move: elastic, no hysteresis
        slope = 0.0
    else:
        mag = gear
        slope = (1.0 - ratio) * dsigma * curve
    if g > travel:
        mag += k_stop * (g - travel)
    mag += damping * out_rate
    slope += damping
    if mag <= 0.0:
        # a coupling side cannot change sign: a gear in buff never pulls
        return 0.0, 0.0
    return sign * mag, slope


#: The force law, compiled (callable from Python; the NumPy twin is draft_gear_force_n)
coupling_force = njit(cache=True)(_coupling_force)
_coupling_force_inline = njit(inline="always")(_coupling_force)


def draft_gear_force_n(
    gear: DraftGear | GearArrays, d_m: npt.ArrayLike, rate_mps: npt.ArrayLike
) -> np.ndarray:
    """Force [N] of a coupling (tension +) at relative displacement ``d_m`` [m] and relative
    speed ``rate_mps`` [m/s] (``v_front - v_rear``), broadcast: the NumPy twin of the
    kernel's law (module docstring; :func:`coupling_force`), for plots and tests.

    ``d_m = 0`` is the middle of the free slack; ``|d_m| <= slack_m / 2`` carries no force.
    ``gear`` is one :class:`~railpilot.vehicle.coupler.DraftGear` or a one-coupling
    :class:`GearArrays`.
    """
    if isinstance(gear, DraftGear):
        gear = gear_arrays([gear])
    half = float(gear.slack_m[0]) / 2.0
    travel = float(gear.travel_m[0])
    preload = float(gear.preload_n[0])
    rate_k = (float(gear.force_at_travel_n[0]) - preload) / travel
    ratio = float(gear.unloading_ratio[0])
    k_stop = float(gear.stop_stiffness_n_per_m[0])
    damping = float(gear.damping_n_s_per_m[0])
    v_sw = float(gear.switching_speed_mps[0])
    d, r = np.broadcast_arrays(np.asarray(d_m, dtype=float), np.asarray(rate_mps, dtype=float))
    g = np.abs(d) - half
    sign = np.where(d > 0.0, 1.0, -1.0)
    out_rate = sign * r
    sigma = np.clip(0.5 + 0.5 * out_rate / v_sw, 0.0, 1.0)
    beta = ratio + (1.0 - ratio) * sigma
    curve = preload + rate_k * np.minimum(g, travel)
    mag = np.minimum(k_stop * g, beta * curve)
    mag = mag + k_stop * np.maximum(g - travel, 0.0) + damping * out_rate
    return np.where((g > 0.0) & (mag > 0.0), sign * mag, 0.0)


# --- building the inputs


def gear_arrays(gears: Sequence[DraftGear]) -> GearArrays:
    """The parameters of ``gears`` (one per coupling) as :class:`GearArrays`."""
    for j, gear in enumerate(gears):
        if not isinstance(gear, DraftGear):
            raise ConfigError(f"gears[{j}]", gear, "a DraftGear")

    def column(name: str) -> np.ndarray:
        return np.array([float(getattr(g, name)) for g in gears], dtype=float)

    return GearArrays(*(column(name) for name in GearArrays._fields))


def _vector(name: str, values: npt.ArrayLike, n: int | None, *, positive: bool) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=float)
    if array.ndim != 1 or array.shape[0] == 0 or (n is not None and array.shape[0] != n):
        size = "a non-empty 1-D array" if n is None else f"a 1-D array of {n} numbers"
        raise ConfigError(name, values, size)
    bad = ~np.isfinite(array) | ((array <= 0.0) if positive else (array < 0.0))
    if np.any(bad):
        i = int(np.argmax(bad))
        raise ConfigError(
            f"{name}[{i}]", array[i], "a finite number " + ("> 0" if positive else ">= 0")
        )
    return array


def _check_gears(gears: GearArrays, n_couplings: int) -> GearArrays:
    checked = []
    for name in GearArrays._fields:
        column = np.ascontiguousarray(getattr(gears, name), dtype=float)
        if column.shape != (n_couplings,):
            raise ConfigError(f"gears.{name}", column, f"{n_couplings} values (one per coupling)")
        positive = name not in ("slack_m", "preload_n", "damping_n_s_per_m")
        if n_couplings:
            _vector(f"gears.{name}", column, None, positive=positive)
        checked.append(column)
    out = GearArrays(*checked)
    if np.any(out.unloading_ratio > 1.0):
        j = int(np.argmax(out.unloading_ratio > 1.0))
        raise ConfigError(f"gears.unloading_ratio[{j}]", out.unloading_ratio[j], "in (0, 1]")
    if np.any(out.force_at_travel_n < out.preload_n):
        j = int(np.argmax(out.force_at_travel_n < out.preload_n))
        raise ConfigError(
            f"gears.force_at_travel_n[{j}]", out.force_at_travel_n[j], "a force >= preload_n"
        )
    return out


def pack_ltd(
    masses_kg: npt.ArrayLike,
    rotating_mass_factors: npt.ArrayLike,
    lengths_m: npt.ArrayLike,
    davis: npt.ArrayLike,
    gears: Sequence[DraftGear] | GearArrays,
    table: ResistanceTable,
    *,
    max_substep_s: float | None = None,
    step_fraction: float = DEFAULT_STEP_FRACTION,
) -> LtdInputs:
    """The inputs of :func:`ltd_step` for a train of ``n`` vehicles (from the head).

    Parameters
    ----------
    masses_kg, rotating_mass_factors, lengths_m
        Per vehicle: mass [kg] > 0, rotating-mass factor ``gamma`` [-] >= 0, length over
        couplers [m] > 0.
    davis
        ``(n, 3)``: each vehicle's Davis coefficients ``a0, a1, a2`` [N/kN] with V in km/h
        (vehicle/resistance.py), >= 0.
    gears
        ``n - 1`` couplings, from the head: DraftGears, or :class:`GearArrays`.
    table
        The line's gradient + curve resistance for the direction of travel
        (:func:`railpilot.vehicle.profile.elevation_table`).
    max_substep_s
        Longest substep [s] (default: no limit but ``step_fraction``'s).
    step_fraction
        The substep as a fraction of the stability bound (:func:`stable_step_s` with
        ``safety=1``), in (0, 1): 0.25 resolves the stiffest coupling's oscillation in
        about 12 substeps.
    """
    mass = _vector("masses_kg", masses_kg, None, positive=True)
    n = mass.shape[0]
    gamma = _vector("rotating_mass_factors", rotating_mass_factors, n, positive=False)
    length = _vector("lengths_m", lengths_m, n, positive=True)
    coefficients = np.ascontiguousarray(davis, dtype=float)
    if coefficients.shape != (n, 3) or not np.all(np.isfinite(coefficients) & (coefficients >= 0)):
        raise ConfigError("davis", davis, f"an ({n}, 3) array of finite a0, a1, a2 >= 0 [N/kN]")
    if not isinstance(gears, GearArrays):
        gears = gear_arrays(list(gears))
    g = _check_gears(gears, n - 1)
    step_fraction = check_number(
        "step_fraction", step_fraction, positive=True, maximum=0.99, error=ConfigError
    )
    edges, cumulative, values = (np.ascontiguousarray(a, dtype=float) for a in table)
    inp = LtdInputs(
        mass_kg=mass,
        effective_mass_kg=mass * (1.0 + gamma),
        length_m=length,
        weight_kn=mass * G / 1000.0,
        davis=coefficients,
        half_slack_m=g.slack_m / 2.0,
        travel_m=g.travel_m,
        preload_n=g.preload_n,
        gear_rate_n_per_m=(g.force_at_travel_n - g.preload_n) / g.travel_m,
        unloading_ratio=g.unloading_ratio,
        stop_stiffness_n_per_m=g.stop_stiffness_n_per_m,
        damping_n_s_per_m=g.damping_n_s_per_m,
        switching_speed_mps=g.switching_speed_mps,
        edges_m=edges,
        cumulative=cumulative,
        values_n_per_kn=values,
        max_substep_s=np.array([math.inf]),
    )
    step = stable_step_s(inp, step_fraction)
    if max_substep_s is not None:
        step = min(step, check_number("max_substep_s", max_substep_s, positive=True, unit="s"))
    inp.max_substep_s[0] = step
    return inp


def stable_step_s(inp: LtdInputs, safety: float = DEFAULT_SAFETY) -> float:
    """``safety`` times the longest stable substep [s] of the integrator for ``inp``.

    ``2 / omega_max`` with ``omega_max^2 = max_i 2 (k_{i-1} + k_i) / M_i`` (Gershgorin's
    circle bound on the eigenvalues of ``M^-1 K``; for two equal masses it is the exact
    ``k (1/M_1 + 1/M_2)``), ``M_i`` the effective masses and ``k_j`` the largest slope of
    coupling ``j``'s force law, ``max(k_stop, (F_T - P) / T)``. The damping terms are
    integrated implicitly and add no bound. ``inf`` for a single vehicle.
    """
    stiffness = np.maximum(inp.stop_stiffness_n_per_m, inp.gear_rate_n_per_m)
    if stiffness.shape[0] == 0:
        return math.inf
    around = np.zeros(inp.mass_kg.shape[0])
    around[:-1] += stiffness
    around[1:] += stiffness
    omega2 = float(np.max(2.0 * around / inp.effective_mass_kg))
    return float(safety) * 2.0 / math.sqrt(omega2)


# --- state


def state_size(n: int) -> int:
    """Length of the state array of a train of ``n`` vehicles (module docstring)."""
    return 10 * n


def initial_state(
    inp: LtdInputs, head_m: float, speed_mps: float, *, stretched: bool | None = None
) -> np.ndarray:
    """A state with the head at ``head_m`` [m] and every vehicle at ``speed_mps`` [m/s].

    ``stretched=None``: every coupling in the middle of its slack; ``True``: the slack
    taken in draft; ``False``: in buff (bunched). No coupling carries a force.
    """
    head_m = check_number("head_m", head_m, unit="m")
    speed_mps = check_number("speed_mps", speed_mps, unit="m/s")
    if stretched is not None and not isinstance(stretched, bool):
        raise ConfigError("stretched", stretched, "None, True or False")
    n = inp.mass_kg.shape[0]
    state = np.zeros(state_size(n))
    offset = 0.0 if stretched is None else (1.0 if stretched else -1.0)
    d = offset * inp.half_slack_m
    x = head_m - np.concatenate(([0.0], np.cumsum(inp.length_m[:-1] + d)))
    state[:n] = x
    state[n : 2 * n] = speed_mps
    # the kernel's guesses of the line segments under each vehicle's tail and head
    state[8 * n : 10 * n : 2] = np.searchsorted(inp.edges_m, x - inp.length_m, side="right") - 1
    state[8 * n + 1 : 10 * n : 2] = np.searchsorted(inp.edges_m, x, side="right") - 1
    return state


@njit(cache=True)
def positions_m(state: np.ndarray, n: int) -> np.ndarray:
    """The vehicles' front positions [m] (a view)."""
    return state[:n]


@njit(cache=True)
def speeds_mps(state: np.ndarray, n: int) -> np.ndarray:
    """The vehicles' speeds [m/s] (a view)."""
    return state[n : 2 * n]


@njit(cache=True)
def coupler_force_n(state: np.ndarray, n: int) -> np.ndarray:
    """The ``n - 1`` coupling forces [N] applied in the last substep, tension + (a view)."""
    return state[2 * n : 3 * n - 1]


# --- the kernel


@njit(inline="always")
def _segment_from(edges: np.ndarray, s: float, i: int) -> int:
    """``searchsorted(edges, s, side="right") - 1`` found by walking from the guess ``i``
    (a vehicle moves less than a segment per substep: O(1) instead of O(log n))."""
    last = edges.shape[0] - 1
    if i > last:
        i = last
    if i < -1:
        i = -1
    while i < last and edges[i + 1] <= s:
        i += 1
    while i >= 0 and edges[i] > s:
        i -= 1
    return i


@njit(inline="always")
def _value_at(values: np.ndarray, i: int) -> float:
    if i < 0 or i >= values.shape[0]:
        return 0.0
    return values[i]


@njit(inline="always")
def _span_mean(
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    a: float,
    b: float,
    ia: int,
    ib: int,
) -> float:
    """Mean of the step profile over ``[a, b]`` with ``a``, ``b`` in segments ``ia``, ``ib``:
    the arithmetic of vehicle/profile.py's mean_specific_resistance, term by term."""
    if ia == ib:
        return _value_at(values, ia)
    tail = _value_at(values, ia) * (edges[ia + 1] - a)
    middle = cumulative[ib] - cumulative[ia + 1]
    head = _value_at(values, ib) * (b - edges[ib])
    return (tail + middle + head) / (b - a)


@njit(cache=True)
def ltd_substeps(
    inp: LtdInputs,
    state: np.ndarray,
    drive_n: np.ndarray,
    brake_n: np.ndarray,
    h: float,
    count: int,
) -> None:
    """Advance ``state`` by ``count`` substeps of ``h`` [s], forces held (no stability
    check: :func:`ltd_step` is the public stepper; this is it with the substep given)."""
    n = inp.mass_kg.shape[0]
    x = state[:n]
    v = state[n : 2 * n]
    force = state[2 * n : 3 * n - 1]
    slope = state[3 * n : 4 * n - 1]
    upper = state[4 * n : 5 * n]
    rhs = state[5 * n : 6 * n]
    heading = state[6 * n : 7 * n]
    window = state[7 * n : 8 * n]
    segment = state[8 * n : 10 * n]  # per vehicle: the segments of its tail and head
    mass_eff = inp.effective_mass_kg
    weight = inp.weight_kn
    davis = inp.davis
    edges = inp.edges_m
    cumulative = inp.cumulative
    values = inp.values_n_per_kn
    for _ in range(count):
        # couplings: force and slope at the start of the substep
        for j in range(n - 1):
            f, c = _coupling_force_inline(
                inp.half_slack_m[j],
                inp.travel_m[j],
                inp.preload_n[j],
                inp.gear_rate_n_per_m[j],
                inp.unloading_ratio[j],
                inp.stop_stiffness_n_per_m[j],
                inp.damping_n_s_per_m[j],
                inp.switching_speed_mps[j],
                (x[j] - inp.length_m[j]) - x[j + 1],
                v[j] - v[j + 1],
            )
            force[j] = f
            slope[j] = c
        # the tridiagonal system for the speed changes dv (forward sweep of Thomas):
        # (M_i + h c_{i-1} + h c_i) dv_i - h c_{i-1} dv_{i-1} - h c_i dv_{i+1} = h F_i,
        # or dv_i = 0 for a vehicle friction holds at rest
        prev_upper = 0.0
        prev_rhs = 0.0
        for i in range(n):
            vi = v[i]
            # the line under the vehicle, [x_i - l_i, x_i] (segments found from last time's)
            tail_x = x[i] - inp.length_m[i]
            ia = _segment_from(edges, tail_x, int(segment[2 * i]))
            ib = _segment_from(edges, x[i], int(segment[2 * i + 1]))
            segment[2 * i] = ia
            segment[2 * i + 1] = ib
            net = (
                drive_n[i] - _span_mean(edges, cumulative, values, tail_x, x[i], ia, ib) * weight[i]
            )
            c_front = 0.0
            c_back = 0.0
            if i > 0:
                net += force[i - 1]
                c_front = h * slope[i - 1]
            if i < n - 1:
                net -= force[i]
                c_back = h * slope[i]
            speed_kmh = abs(vi) * KMH_PER_MPS
            friction = brake_n[i] + weight[i] * _davis_specific_resistance(
                speed_kmh, davis[i, 0], davis[i, 1], davis[i, 2]
            )
            held = False
            # the speed friction alone can take away within the substep (Karnopp's window)
            window[i] = h * friction / mass_eff[i]
            if vi > 0.0:
                net -= friction
                heading[i] = 1.0
            elif vi < 0.0:
                net += friction
                heading[i] = -1.0
            elif abs(net) <= friction:
                held = True
                heading[i] = 0.0
            elif net > 0.0:
                net -= friction
                heading[i] = 1.0
            else:
                net += friction
                heading[i] = -1.0
            if held:
                diag = 1.0
                lower = 0.0
                up = 0.0
                b = 0.0
            else:
                diag = mass_eff[i] + c_front + c_back
                lower = -c_front
                up = -c_back
                b = h * net
            denom = diag - lower * prev_upper
            prev_upper = up / denom
            prev_rhs = (b - lower * prev_rhs) / denom
            upper[i] = prev_upper
            rhs[i] = prev_rhs
        # back substitution; Karnopp's stop; positions with the new speeds
        dv_next = 0.0
        for i in range(n - 1, -1, -1):
            dv = rhs[i] - upper[i] * dv_next
            dv_next = dv
            rhs[i] = dv
            vi = v[i] + dv
            if heading[i] == 0.0 or (vi * heading[i] < 0.0 and abs(vi) <= window[i]):
                # held, or friction would reverse it within the substep: it stops
                vi = 0.0
            v[i] = vi
            x[i] += h * vi
        # the forces applied: with the implicit part of their rate dependence
        for j in range(n - 1):
            force[j] += slope[j] * (rhs[j] - rhs[j + 1])
    state[3 * n - 1] += h * count


@njit(cache=True)
def ltd_step(
    inp: LtdInputs, state: np.ndarray, drive_n: np.ndarray, brake_n: np.ndarray, dt: float
) -> None:
    """Advance ``state`` by ``dt`` [s] in equal substeps no longer than
    ``inp.max_substep_s[0]``, the drive forces ``drive_n`` [N] (signed) and the brake forces
    ``brake_n`` [N] (>= 0) per vehicle held over ``dt``."""
    if dt <= 0.0:
        return
    count = math.ceil(dt / inp.max_substep_s[0] - 1e-9)
    if count < 1:
        count = 1
    ltd_substeps(inp, state, drive_n, brake_n, dt / count, count)


# --- lumping


def lump_vehicles(
    masses_kg: npt.ArrayLike,
    rotating_mass_factors: npt.ArrayLike,
    lengths_m: npt.ArrayLike,
    davis: npt.ArrayLike,
    gears: Sequence[DraftGear] | GearArrays,
    group: int,
    *,
    alone: Sequence[int] = (),
) -> LumpedTrain:
    """Lump runs of ``group`` consecutive vehicles into one mass each.

    Vehicles listed in ``alone`` (e.g. the locomotives, whose drive forces must act where
    they are) stay single; every run of other vehicles between them is cut, from the
    head, into lumps of ``group`` (the last one of a run may be shorter).

    A lump: mass and length the sums; ``gamma`` such that the effective mass is the sum;
    Davis coefficients mass-weighted (the resistance force is the sum). A coupling
    between two lumps stands for the real coupling at the boundary plus half of each
    neighbouring lump's internal couplings (all of them for a lump at an end of the
    train), in series: weights ``w`` (1 or 1/2) give slack, travel and switching speed
    ``sum w x``, stop stiffness and damping ``1 / sum(w / x)``, preload, force at travel
    and unloading ratio their ``w``-weighted mean. For ``group`` identical couplings this
    is the same forces over ``group`` times the slack and travel, and ``k_stop / group``;
    the train's total slack and travel are kept.

    Returns a :class:`LumpedTrain`; its first five fields are :func:`pack_ltd`'s first
    five arguments, ``lump_of_vehicle`` maps vehicles to lumps (:func:`lump_forces`).
    """
    mass = _vector("masses_kg", masses_kg, None, positive=True)
    n = mass.shape[0]
    gamma = _vector("rotating_mass_factors", rotating_mass_factors, n, positive=False)
    length = _vector("lengths_m", lengths_m, n, positive=True)
    coefficients = np.asarray(davis, dtype=float)
    if coefficients.shape != (n, 3):
        raise ConfigError("davis", davis, f"an ({n}, 3) array")
    if not isinstance(gears, GearArrays):
        gears = gear_arrays(list(gears))
    gears = _check_gears(gears, n - 1)
    group = check_count("group", group, 1, error=ConfigError)
    single = set()
    for i in alone:
        single.add(check_count("alone[]", i, 0, n - 1, error=ConfigError))
    lump = np.zeros(n, dtype=np.int64)
    k = -1
    run = 0  # vehicles in the current lump (0: the next vehicle starts a new one)
    for i in range(n):
        if i in single:
            k += 1
            run = 0
        else:
            if run == 0 or run >= group:
                k += 1
                run = 0
            run += 1
        lump[i] = k
    n_lumps = k + 1
    out_mass = np.bincount(lump, weights=mass, minlength=n_lumps)
    out_meff = np.bincount(lump, weights=mass * (1.0 + gamma), minlength=n_lumps)
    out_length = np.bincount(lump, weights=length, minlength=n_lumps)
    out_davis = np.stack(
        [
            np.bincount(lump, weights=mass * coefficients[:, c], minlength=n_lumps) / out_mass
            for c in range(3)
        ],
        axis=1,
    )
    # the weight of each real coupling in each lumped one
    weights = np.zeros((max(n_lumps - 1, 0), max(n - 1, 0)))
    for j in range(n - 1):
        a, b = lump[j], lump[j + 1]
        if a != b:
            weights[a, j] = 1.0
            continue
        # internal to lump a: shared by its front (a - 1) and rear (a) boundaries
        front = a - 1 >= 0
        rear = a < n_lumps - 1
        if front and rear:
            weights[a - 1, j] = 0.5
            weights[a, j] = 0.5
        elif front:
            weights[a - 1, j] = 1.0
        elif rear:
            weights[a, j] = 1.0
    total = weights.sum(axis=1)

    def series_sum(values: np.ndarray) -> np.ndarray:
        return np.asarray(weights @ values, dtype=float)

    def series_stiffness(values: np.ndarray) -> np.ndarray:
        # 1 / sum(w / x); 0 if any element in the series has x = 0 (no damping)
        out = np.zeros(weights.shape[0])
        for row in range(weights.shape[0]):
            used = weights[row] > 0.0
            if np.all(values[used] > 0.0):
                out[row] = 1.0 / float(np.sum(weights[row, used] / values[used]))
        return out

    def mean(values: np.ndarray) -> np.ndarray:
        return series_sum(values) / total

    lumped_gears = GearArrays(
        slack_m=series_sum(gears.slack_m),
        travel_m=series_sum(gears.travel_m),
        preload_n=mean(gears.preload_n),
        force_at_travel_n=mean(gears.force_at_travel_n),
        unloading_ratio=mean(gears.unloading_ratio),
        stop_stiffness_n_per_m=series_stiffness(gears.stop_stiffness_n_per_m),
        damping_n_s_per_m=series_stiffness(gears.damping_n_s_per_m),
        switching_speed_mps=series_sum(gears.switching_speed_mps),
    )
    return LumpedTrain(
        out_mass, out_meff / out_mass - 1.0, out_length, out_davis, lumped_gears, lump
    )


def lump_forces(forces_n: npt.ArrayLike, lump_of_vehicle: np.ndarray) -> np.ndarray:
    """Per-vehicle forces [N] (drive, brake) summed per lump."""
    lump = np.asarray(lump_of_vehicle)
    return np.bincount(lump, weights=np.asarray(forces_n, dtype=float), minlength=lump.max() + 1)
