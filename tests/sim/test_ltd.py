"""Longitudinal train dynamics (railpilot.sim.ltd) against closed-form results.

Cases: the force law and its NumPy twin; a coupling's static load on a uniform grade (the
weight component and resistance of the vehicles behind it); the two-mass oscillator's
frequency; energy conservation without friction; the friction gear's energy loss against
its hysteresis loop; a very stiff train against a point mass over a grade change; the
integrator's stability bound; static friction; lumping.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp

from railpilot.errors import ConfigError
from railpilot.sim.ltd import (
    GearArrays,
    coupler_force_n,
    coupling_force,
    draft_gear_force_n,
    gear_arrays,
    initial_state,
    ltd_step,
    ltd_substeps,
    lump_forces,
    lump_vehicles,
    pack_ltd,
    positions_m,
    speeds_mps,
    stable_step_s,
)
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import ResistanceTable, elevation_table, length_averaged_resistance

NO_DAVIS = (0.0, 0.0, 0.0)
#: Davis coefficients of the heavy-haul tests (docs/heavy-haul-vehicle.md) [N/kN]
DAVIS = (0.92, 0.0048, 0.000125)


def uniform_grade(w_n_per_kn: float) -> ResistanceTable:
    """A line of one gradient ``w`` [N/kN] everywhere the tests go."""
    edges = np.array([-1.0e7, 1.0e7])
    return ResistanceTable(edges, np.array([0.0, w_n_per_kn * 2.0e7]), np.array([w_n_per_kn]))


def linear_gear(k_n_per_m: float, damping: float = 0.0) -> DraftGear:
    """A coupling that is the linear spring ``k`` [N/m] up to 1 m either way: no slack,
    no preload, no hysteresis, its stop as stiff as its gear."""
    return DraftGear(
        name="linear",
        slack_m=0.0,
        travel_m=1.0,
        preload_n=0.0,
        force_at_travel_n=k_n_per_m * 1.0,
        unloading_ratio=1.0,
        stop_stiffness_n_per_m=k_n_per_m,
        damping_n_s_per_m=damping,
    )


#: A heavy-haul coupling: two MT-2-like gears in series (83 mm each, 2.27 MN at solid),
#: the rest assumed (docs/longitudinal-dynamics.md)
HEAVY = DraftGear(
    name="MT-2 pair",
    slack_m=0.02,
    travel_m=0.166,
    preload_n=2.0e5,
    force_at_travel_n=2.27e6,
    unloading_ratio=0.2,
    stop_stiffness_n_per_m=1.0e8,
    damping_n_s_per_m=1.0e5,
)


def train(
    masses: list[float] | np.ndarray,
    gear: DraftGear,
    table: ResistanceTable,
    *,
    gamma: float = 0.0,
    length_m: float = 12.0,
    davis: tuple[float, float, float] = NO_DAVIS,
    **kwargs: float,
):
    n = len(masses)
    return pack_ltd(
        np.asarray(masses, dtype=float),
        np.full(n, gamma),
        np.full(n, length_m),
        np.tile(davis, (n, 1)),
        [gear] * (n - 1),
        table,
        **kwargs,
    )


def relative_displacement(inp, state: np.ndarray) -> np.ndarray:
    n = inp.mass_kg.shape[0]
    x = positions_m(state, n)
    return (x[:-1] - inp.length_m[:-1]) - x[1:]


# --- the force law

gear_params = st.builds(
    DraftGear,
    name=st.just("g"),
    slack_m=st.floats(0.0, 0.05),
    travel_m=st.floats(0.01, 0.2),
    preload_n=st.floats(0.0, 5e5),
    force_at_travel_n=st.floats(5e5, 3e6),
    unloading_ratio=st.floats(0.05, 1.0),
    stop_stiffness_n_per_m=st.floats(1e7, 1e9),
    damping_n_s_per_m=st.floats(0.0, 1e6),
    switching_speed_mps=st.floats(0.001, 0.1),
)


@settings(max_examples=300, deadline=None)
@given(gear_params, st.floats(-0.4, 0.4), st.floats(-2.0, 2.0))
def test_numpy_twin_is_the_kernel_law_and_symmetric(gear, d, rate):
    f_kernel, slope = coupling_force(
        gear.slack_m / 2,
        gear.travel_m,
        gear.preload_n,
        gear.gear_stiffness_n_per_m,
        gear.unloading_ratio,
        gear.stop_stiffness_n_per_m,
        gear.damping_n_s_per_m,
        gear.switching_speed_mps,
        d,
        rate,
    )
    assert_allclose(draft_gear_force_n(gear, d, rate), f_kernel, rtol=1e-12, atol=1e-9)
    # draft and buff alike; a side never changes sign; the slope with rate is >= 0
    assert_allclose(draft_gear_force_n(gear, -d, -rate), -f_kernel, rtol=1e-12, atol=1e-9)
    assert f_kernel * d >= 0.0
    assert slope >= 0.0
    if abs(d) <= gear.slack_m / 2:
        assert f_kernel == 0.0


def test_loading_and_unloading_curves_are_the_gear_data():
    # far from the switching band: loading = P + (F_T - P) g / T, unloading = rho times it
    gear = DraftGear("g", 0.02, 0.1, 2e5, 2e6, 0.25, 1e9, 0.0, 0.01)
    g = np.linspace(0.01, 0.1, 10)
    d = 0.01 + g
    loading = 2e5 + (2e6 - 2e5) * g / 0.1
    assert_allclose(draft_gear_force_n(gear, d, 1.0), loading, rtol=1e-12)
    assert_allclose(draft_gear_force_n(gear, d, -1.0), 0.25 * loading, rtol=1e-12)
    assert_allclose(draft_gear_force_n(gear, -d, -1.0), -loading, rtol=1e-12)
    # within the slack nothing; beyond solid the stop
    assert np.all(draft_gear_force_n(gear, np.linspace(-0.01, 0.01, 5), 0.3) == 0.0)
    assert_allclose(draft_gear_force_n(gear, 0.01 + 0.1 + 1e-3, 1.0), 2e6 + 1e9 * 1e-3)


# --- statics


@settings(max_examples=12, deadline=None)
@given(
    n=st.integers(2, 8),
    grade=st.floats(-8.0, 8.0),
    speed=st.floats(5.0, 20.0),
    seed=st.integers(0, 2**31 - 1),
)
def test_steady_coupler_force_is_the_load_of_the_vehicles_behind(n, grade, speed, seed):
    """At constant speed on a uniform grade each coupling carries exactly the gradient and
    Davis resistance of the vehicles behind it: ``f_j = sum_{i > j} (w + w_davis(v)) m_i g /
    1000``; the drive on the head balances the whole train's."""
    rng = np.random.default_rng(seed)
    masses = rng.uniform(20e3, 200e3, n)
    inp = train(masses, HEAVY, uniform_grade(grade), davis=DAVIS, gamma=0.06)
    w_davis = DAVIS[0] + DAVIS[1] * speed * KMH_PER_MPS + DAVIS[2] * (speed * KMH_PER_MPS) ** 2
    per_vehicle = (grade + w_davis) * masses * G_MPS2 / 1000.0
    drive = np.zeros(n)
    drive[0] = per_vehicle.sum()
    state = initial_state(inp, 1000.0, speed, stretched=grade > 0)
    for _ in range(4000):
        ltd_step(inp, state, drive, np.zeros(n), 0.1)
    v = speeds_mps(state, n)
    assert_allclose(v, speed, rtol=1e-6)  # Davis' slope pulls the speed back to v0, slowly
    assert_allclose(v, v[0], rtol=1e-9)  # but every vehicle at the same speed
    w_davis = DAVIS[0] + DAVIS[1] * v[0] * KMH_PER_MPS + DAVIS[2] * (v[0] * KMH_PER_MPS) ** 2
    behind = np.cumsum(((grade + w_davis) * masses * G_MPS2 / 1000.0)[::-1])[::-1][1:]
    # atol: positions of ~1 km in float64 (1e-13 m) times the stop stiffness (1e8 N/m)
    assert_allclose(coupler_force_n(state, n), behind, rtol=1e-9, atol=0.01)


# --- dynamics without friction


def test_two_masses_oscillate_at_the_linear_frequency():
    """``omega = sqrt(k (1/M1 + 1/M2))`` (M effective masses); the step is 1/400 of a
    period, so symplectic Euler's frequency error ``(h omega)^2 / 24`` is below 1e-5."""
    k = 5e7
    m1, m2, gamma = 100e3, 60e3, 0.05
    inp = train([m1, m2], linear_gear(k), uniform_grade(0.0), gamma=gamma)
    omega = math.sqrt(k * (1 / (m1 * (1 + gamma)) + 1 / (m2 * (1 + gamma))))
    period = 2 * math.pi / omega
    h = period / 400
    state = initial_state(inp, 0.0, 10.0)
    state[2] = 10.2  # rear vehicle faster: the coupling starts in buff
    d = []
    for _ in range(400 * 50):
        ltd_substeps(inp, state, np.zeros(2), np.zeros(2), h, 1)
        d.append(relative_displacement(inp, state)[0])
    d = np.asarray(d)
    t = h * np.arange(1, d.size + 1)
    up = np.nonzero((d[:-1] < 0) & (d[1:] >= 0))[0]
    crossing = t[up] + h * (-d[up]) / (d[up + 1] - d[up])
    measured = 2 * math.pi / np.mean(np.diff(crossing))
    assert_allclose(measured, omega, rtol=1e-4)


def _energies(inp, state: np.ndarray, k: np.ndarray, h: float) -> tuple[float, float]:
    """(kinetic + spring energy, symplectic Euler's modified energy) of a chain of linear
    couplings ``k``: ``E~ = E - (h/2) sum_j f_j r_j`` (``f_j = k_j d_j``, ``r_j`` the
    coupling's rate) is conserved exactly by v' = v + h a(x), x' = x + h v' for a linear
    system (kick-drift; ``E~ = (v'Mv + x'Kx - h v'Kx) / 2``)."""
    n = inp.mass_kg.shape[0]
    v = speeds_mps(state, n)
    d = relative_displacement(inp, state)
    f = k * d
    e = 0.5 * float(np.sum(inp.effective_mass_kg * v * v) + np.sum(f * d))
    return e, e - 0.5 * h * float(np.sum(f * (v[:-1] - v[1:])))


def test_energy_is_conserved_without_damping_or_friction():
    """A free chain of linear couplings, kicked: the modified energy is conserved to
    rounding over thousands of periods of the slowest mode, and the true kinetic + spring
    energy stays within its bounds ``E~ / (1 +- h omega_max / 2)``: no drift."""
    k = np.array([4e7, 8e7, 2e7])
    masses = np.array([120e3, 80e3, 100e3, 60e3])
    inp = pack_ltd(
        masses,
        np.full(4, 0.05),
        np.full(4, 12.0),
        np.zeros((4, 3)),
        [linear_gear(kj) for kj in k],
        uniform_grade(0.0),
    )
    state = initial_state(inp, 0.0, 0.0)
    speeds_mps(state, 4)[:] = [0.3, -0.2, 0.1, 0.0]
    h = stable_step_s(inp, 0.5)  # h omega_max <= 1
    e0, modified0 = _energies(inp, state, k, h)
    assert modified0 == e0  # no spring energy yet
    energies = []
    for _ in range(20000):  # about 1,700 periods of the slowest mode
        ltd_substeps(inp, state, np.zeros(4), np.zeros(4), h, 5)
        e, modified = _energies(inp, state, k, h)
        energies.append(e)
        assert abs(modified / e0 - 1) < 1e-9
    energies = np.asarray(energies)
    assert np.all((energies > e0 / 1.5) & (energies < e0 / 0.5))
    assert_allclose(energies[-2000:].mean(), energies[:2000].mean(), rtol=0.01)


def _integral_of_min(k_stop: float, a: float, b: float, g: float) -> float:
    """``integral_0^g min(k_stop s, a + b s) ds`` (the ramp, then the gear's line)."""
    cross = a / (k_stop - b)
    if g <= cross:
        return k_stop * g * g / 2
    return k_stop * cross * cross / 2 + a * (g - cross) + b * (g * g - cross * cross) / 2


def test_friction_gear_absorbs_its_hysteresis_loop():
    """Two wagons run together through the slack into the gears and part again. The
    relative kinetic energy left is the area under the unloading curve up to the deepest
    travel reached, which the loading curve fixes: ``0.5 mu v0^2 = integral f_L``."""
    gear = DraftGear("g", 0.02, 0.166, 2e5, 2.27e6, 0.2, 1e8, 0.0, 0.01)
    m1, m2 = 100e3, 100e3
    mu = m1 * m2 / (m1 + m2)
    v0 = 1.0  # closing speed [m/s]
    inp = train([m1, m2], gear, uniform_grade(0.0))
    state = initial_state(inp, 0.0, 0.0)
    speeds_mps(state, 2)[:] = [0.0, v0]
    e_in, e_back, loop = _impact(gear, m1, m2, v0)
    assert loop > 0.7 * e_in  # most of it is the loop's
    h = 2e-5
    ltd_substeps(inp, state, np.zeros(2), np.zeros(2), h, int(0.3 / h))
    v = speeds_mps(state, 2)
    assert abs(relative_displacement(inp, state)[0]) < 0.01  # parted: within the slack
    e_out = 0.5 * mu * (v[0] - v[1]) ** 2
    assert_allclose(e_out, e_back, rtol=0.01)
    # momentum is kept by the coupling
    assert_allclose(m1 * v[0] + m2 * v[1], m2 * v0, rtol=1e-12)


def _impact(gear: DraftGear, m1: float, m2: float, v0: float) -> tuple[float, float, float]:
    """(energy in, energy the unloading curve gives back, loop area) [J] of a run-in at
    closing speed ``v0`` that stays within the gears' travel."""
    mu = m1 * m2 / (m1 + m2)
    e_in = 0.5 * mu * v0**2
    k, p, b, rho = (
        gear.stop_stiffness_n_per_m,
        gear.preload_n,
        gear.gear_stiffness_n_per_m,
        gear.unloading_ratio,
    )
    lo, hi = 0.0, gear.travel_m
    for _ in range(200):  # bisection for the deepest travel: the loading curve's work
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _integral_of_min(k, p, b, mid) < e_in else (lo, mid)
    e_back = _integral_of_min(k, rho * p, rho * b, 0.5 * (lo + hi))
    return e_in, e_back, e_in - e_back


@settings(max_examples=40, deadline=None)
@given(
    gear=gear_params,
    v0=st.floats(0.2, 2.0),
    ratio=st.floats(1.0, 3.0),
    reach=st.floats(0.05, 0.8),
)
def test_gear_loss_at_the_default_substep(gear, v0, ratio, reach):
    """As a simulation runs (ltd_step at 0.05 s, the default substep): after a run-in that
    stays within the travel the energy left is the unloading curve's within 10 % of the
    energy brought in plus the preload's work over one substep at the closing speed, and
    energy is never gained beyond that. The preload is reached within a substep, so the
    force jumps onto it up to a substep early or late: first order in the substep. (Stops of
    1e8 N/m or stiffer and 10 times the gear's rate, as real couplings have; the slack wide
    enough to see the parting at 0.05 s.)"""
    gear = DraftGear(
        "g", 0.3, gear.travel_m, gear.preload_n, gear.force_at_travel_n,
        min(gear.unloading_ratio, 0.9),
        max(gear.stop_stiffness_n_per_m, 1e8, 10 * gear.gear_stiffness_n_per_m),
        0.0, gear.switching_speed_mps,
    )  # fmt: skip
    m1, m2 = 100e3, 100e3 * ratio
    capacity = _integral_of_min(
        gear.stop_stiffness_n_per_m, gear.preload_n, gear.gear_stiffness_n_per_m, gear.travel_m
    )
    v0 = min(v0, math.sqrt(2 * reach * capacity * (m1 + m2) / (m1 * m2)))
    # the switch between the curves takes a small part of the run-in (the analytic
    # energies assume a sharp switch)
    gear = dataclasses.replace(gear, switching_speed_mps=min(gear.switching_speed_mps, v0 / 20))
    e_in, e_back, _ = _impact(gear, m1, m2, v0)
    inp = train([m1, m2], gear, uniform_grade(0.0))
    state = initial_state(inp, 0.0, 0.0)
    speeds_mps(state, 2)[:] = [0.0, v0]
    # one impact: the wagons part (the rear now slower than the front) and are back within
    # the slack; a contact may begin and end inside one 0.05 s step
    for _ in range(400):
        ltd_step(inp, state, np.zeros(2), np.zeros(2), 0.05)
        v = speeds_mps(state, 2)
        parted = v[1] < v[0] and abs(relative_displacement(inp, state)[0]) < 0.15
        if parted:
            break
    assert parted
    e_out = 0.5 * m1 * m2 / (m1 + m2) * (v[0] - v[1]) ** 2
    jump = gear.preload_n * v0 * inp.max_substep_s[0]
    assert abs(e_out - e_back) < 0.1 * e_in + jump
    assert e_out < 1.05 * e_in + jump


# --- against the point mass


@pytest.mark.parametrize(
    ("substep_s", "speed_tol", "position_tol"), [(None, 3e-4, 0.3), (4e-4, 6e-5, 0.06)]
)
def test_very_stiff_train_moves_as_the_point_mass(substep_s, speed_tol, position_tol):
    """Ten equal vehicles with stiff, slack-free couplings are a point mass with the total
    forces and the length-averaged grade (vehicle/profile.py). Over 600 s from rest with a
    constant drive, across a rise into a 6 per mille climb and a fall to -4 per mille
    (52 km), speed and head position against solve_ivp (rtol 1e-10) of the point mass:
    within the first-order integrator's error at the default substep (1.8 ms here), and
    about 5 times closer at a substep 4.5 times shorter (the error is O(h))."""
    n = 10
    masses = np.full(n, 100e3)
    gamma = 0.06
    line = Line(gradients=(Segment(2000.0, 4000.0, 6.0), Segment(4000.0, 9000.0, -4.0)))
    table = elevation_table(line)
    inp = train(
        masses, linear_gear(2e9, damping=2e7), table, gamma=gamma, davis=DAVIS,
        **({} if substep_s is None else {"max_substep_s": substep_s}),
    )  # fmt: skip
    length = n * 12.0
    drive_total = 4e5
    drive = np.zeros(n)
    drive[0] = drive_total
    head0 = 1500.0
    state = initial_state(inp, head0, 0.0)
    dt = 0.1
    times = np.arange(1, 6001) * dt
    speeds = []
    heads = []
    for _ in times:
        ltd_step(inp, state, drive, np.zeros(n), dt)
        speeds.append(speeds_mps(state, n).mean())
        heads.append(positions_m(state, n)[0])
    m_total = masses.sum()

    def rhs(_t, y):
        x, v = y
        w_line = length_averaged_resistance(table, x, length)
        w_davis = DAVIS[0] + DAVIS[1] * v * KMH_PER_MPS + DAVIS[2] * (v * KMH_PER_MPS) ** 2
        force = drive_total - (w_line + w_davis) * m_total * G_MPS2 / 1000.0
        return [v, force / (m_total * (1 + gamma))]

    ref = solve_ivp(rhs, (0, times[-1]), [head0, 0.0], t_eval=times, rtol=1e-10, atol=1e-9)
    assert ref.y[0, -1] > 5000.0  # the run passed both changes of grade
    assert_allclose(speeds, ref.y[1], rtol=0, atol=speed_tol)
    assert_allclose(heads, ref.y[0], rtol=0, atol=position_tol)


# --- stability


@pytest.mark.parametrize(("fraction", "grows"), [(0.99, False), (1.02, True)])
def test_stable_step_is_the_real_bound(fraction, grows):
    """Two equal masses on a linear coupling: ``omega = sqrt(2 k / M)`` and symplectic
    Euler is stable for ``h < 2 / omega``, which stable_step_s gives with safety 1."""
    k, m = 1e8, 100e3
    inp = train([m, m], linear_gear(k), uniform_grade(0.0))
    assert_allclose(stable_step_s(inp, 1.0), 2 / math.sqrt(2 * k / m), rtol=1e-12)
    h = stable_step_s(inp, fraction)
    state = initial_state(inp, 0.0, 0.0)
    speeds_mps(state, 2)[:] = [0.01, -0.01]
    amplitude = []
    for _ in range(400):
        ltd_substeps(inp, state, np.zeros(2), np.zeros(2), h, 1)
        amplitude.append(abs(relative_displacement(inp, state)[0]))
    early, late = max(amplitude[:50]), max(amplitude[-50:])
    if grows:
        assert late > 1e6 * early  # |lambda| = 1.49 per substep at 1.02 of the bound
    else:
        assert late < 1.05 * early


@settings(max_examples=15, deadline=None)
@given(n=st.integers(2, 12), seed=st.integers(0, 2**31 - 1))
def test_a_random_train_stays_bounded_at_the_stable_step(n, seed):
    """Random masses and linear couplings, kicked: at ltd_step's substep (0.9 of the
    Gershgorin bound) the modified energy is conserved and positive definite, so the true
    energy stays below ``E~ / (1 - h omega / 2) <= 10 E0``: the bound holds for uneven
    trains too."""
    rng = np.random.default_rng(seed)
    masses = rng.uniform(20e3, 250e3, n)
    k = rng.uniform(1e7, 5e8, n - 1)
    inp = pack_ltd(
        masses,
        np.zeros(n),
        np.full(n, 12.0),
        np.zeros((n, 3)),
        [linear_gear(kj) for kj in k],
        uniform_grade(0.0),
    )
    state = initial_state(inp, 0.0, 0.0)
    speeds_mps(state, n)[:] = rng.normal(0.0, 0.1, n)
    h = stable_step_s(inp)
    e0, _ = _energies(inp, state, k, h)
    for _ in range(200):
        ltd_substeps(inp, state, np.zeros(n), np.zeros(n), h, 20)
        e, modified = _energies(inp, state, k, h)
        assert abs(modified / e0 - 1) < 1e-9
        assert e < 10.0 * e0


# --- static friction


def test_braked_train_holds_on_a_grade_and_rolls_when_released():
    """Down 10 per mille, each wagon braked with more than its gradient force, stands
    still; released, it rolls off with ``a = (10 - a0) g / 1000 / (1 + gamma)`` (equal
    vehicles: the couplings stay unloaded)."""
    n, grade, gamma = 6, -10.0, 0.05
    masses = np.full(n, 80e3)
    inp = train(masses, HEAVY, uniform_grade(grade), gamma=gamma, davis=DAVIS)
    state = initial_state(inp, 500.0, 0.0)
    x0 = positions_m(state, n).copy()
    brake = 1.2 * (-grade) * masses * G_MPS2 / 1000.0
    for _ in range(1000):
        ltd_step(inp, state, np.zeros(n), brake, 0.1)
    assert np.all(speeds_mps(state, n) == 0.0)
    assert np.array_equal(positions_m(state, n), x0)
    t = 20.0
    for _ in range(int(t / 0.1)):
        ltd_step(inp, state, np.zeros(n), np.zeros(n), 0.1)
    # speeds stay below the Davis a1, a2 terms' effect (< 1 %): check against a0 alone
    a = (-grade - DAVIS[0]) * G_MPS2 / 1000.0 / (1 + gamma)
    assert_allclose(speeds_mps(state, n), a * t, rtol=0.01)
    assert_allclose(coupler_force_n(state, n), 0.0, atol=1.0)


def test_one_braked_vehicle_holds_the_train_through_its_couplings():
    """Down a grade, only the last vehicle braked, enough for all: the train runs out
    against it and the couplings then carry the gradient force of the vehicles ahead
    (tension), friction at rest holding the sum."""
    n, grade = 4, -6.0
    masses = np.full(n, 100e3)
    inp = train(masses, HEAVY, uniform_grade(grade))  # no Davis: only the brake holds
    state = initial_state(inp, 0.0, 0.0, stretched=False)
    brake = np.zeros(n)
    brake[-1] = 2 * n * (-grade) * 100e3 * G_MPS2 / 1000.0
    for _ in range(3000):
        ltd_step(inp, state, np.zeros(n), brake, 0.1)
    assert np.all(np.abs(speeds_mps(state, n)) < 1e-9)  # unbraked: held by the couplings
    push = (-grade) * 100e3 * G_MPS2 / 1000.0
    assert_allclose(coupler_force_n(state, n), push * np.arange(1, n), rtol=1e-6)


# --- states, inputs, lumping


@pytest.mark.parametrize(("stretched", "offset"), [(None, 0.0), (True, 1.0), (False, -1.0)])
def test_initial_state_places_the_slack(stretched, offset):
    inp = train([200e3, 100e3, 100e3], HEAVY, uniform_grade(0.0))
    state = initial_state(inp, 100.0, 3.0, stretched=stretched)
    assert_allclose(relative_displacement(inp, state), offset * HEAVY.slack_m / 2, atol=1e-12)
    assert positions_m(state, 3)[0] == 100.0
    assert np.all(speeds_mps(state, 3) == 3.0)
    ltd_step(inp, state, np.zeros(3), np.zeros(3), 1e-3)
    # at the edge of the slack: zero but for positions' rounding times the stop stiffness
    assert_allclose(coupler_force_n(state, 3), 0.0, atol=1e-3)


def test_pack_refuses_bad_inputs_by_name():
    table = uniform_grade(0.0)
    with pytest.raises(ConfigError, match="gears"):
        pack_ltd([1e5, 1e5], [0, 0], [12, 12], np.zeros((2, 3)), [], table)
    with pytest.raises(ConfigError, match=r"masses_kg\[1\]"):
        pack_ltd([1e5, -1.0], [0, 0], [12, 12], np.zeros((2, 3)), [HEAVY], table)
    with pytest.raises(ConfigError, match="davis"):
        pack_ltd([1e5, 1e5], [0, 0], [12, 12], np.zeros((2, 2)), [HEAVY], table)


def test_lumping_keeps_totals_and_puts_couplings_in_series():
    n, group = 13, 4  # a locomotive and 12 wagons: lumps of 4, 4, 4
    masses = np.r_[200e3, np.full(12, 100e3)]
    lengths = np.r_[35.0, np.full(12, 12.0)]
    gamma = np.r_[0.1, np.full(12, 0.05)]
    davis = np.tile(DAVIS, (n, 1))
    lumped = lump_vehicles(masses, gamma, lengths, davis, [HEAVY] * (n - 1), group, alone=[0])
    assert lumped.lump_of_vehicle.tolist() == [0] + [1] * 4 + [2] * 4 + [3] * 4
    assert_allclose(lumped.masses_kg, [200e3, 400e3, 400e3, 400e3])
    assert_allclose(lumped.lengths_m, [35.0, 48.0, 48.0, 48.0])
    assert_allclose(lumped.masses_kg * (1 + lumped.rotating_mass_factors), [220e3] + [420e3] * 3)
    g = lumped.gears
    # loco | lump 1: 1 + 3/2 couplings; lump 1 | lump 2: 3/2 + 1 + 3/2; lump 2 | 3: 3/2 + 1 + 3
    count = np.array([2.5, 4.0, 5.5])
    assert_allclose(g.slack_m, count * HEAVY.slack_m)
    assert_allclose(g.travel_m, count * HEAVY.travel_m)
    assert_allclose(g.stop_stiffness_n_per_m, HEAVY.stop_stiffness_n_per_m / count)
    assert_allclose(g.force_at_travel_n, HEAVY.force_at_travel_n)
    assert_allclose(g.slack_m.sum(), (n - 1) * HEAVY.slack_m)
    assert_allclose(
        lump_forces(np.arange(n, dtype=float), lumped.lump_of_vehicle)[1], 1 + 2 + 3 + 4
    )
    assert_allclose(lumped.davis, np.tile(DAVIS, (4, 1)))


def test_a_lumped_train_runs_like_the_full_one():
    """1 locomotive + 40 wagons pulling away on a 4 per mille climb, bunched: lumps of
    2 wagons keep the speed after 300 s within 0.1 % and the peak coupler force within
    10 % (larger lumps: docs/longitudinal-dynamics.md)."""
    n = 41
    masses = np.r_[200e3, np.full(40, 100e3)]
    lengths = np.r_[35.0, np.full(40, 12.0)]
    gamma = np.r_[0.1, np.full(40, 0.05)]
    davis = np.tile(DAVIS, (n, 1))
    table = uniform_grade(4.0)
    drive = np.zeros(n)
    drive[0] = 6e5

    def run(inp, drive_n):
        m = inp.mass_kg.shape[0]
        state = initial_state(inp, 0.0, 0.0, stretched=False)
        peak = 0.0
        for _ in range(3000):
            ltd_step(inp, state, drive_n, np.zeros(m), 0.1)
            peak = max(peak, float(np.max(np.abs(coupler_force_n(state, m)))))
        return speeds_mps(state, m)[0], peak

    full = pack_ltd(masses, gamma, lengths, davis, [HEAVY] * (n - 1), table)
    lumped = lump_vehicles(masses, gamma, lengths, davis, [HEAVY] * (n - 1), 2, alone=[0])
    small = pack_ltd(*lumped[:5], table)
    v_full, peak_full = run(full, drive)
    v_lump, peak_lump = run(small, lump_forces(drive, lumped.lump_of_vehicle))
    assert v_full > 5.0
    assert_allclose(v_lump, v_full, rtol=1e-3)
    assert_allclose(peak_lump, peak_full, rtol=0.1)


def test_gear_arrays_accept_only_draft_gears():
    assert isinstance(gear_arrays([HEAVY]), GearArrays)
    with pytest.raises(ConfigError, match=r"gears\[0\]"):
        gear_arrays(["MT-2"])  # type: ignore[list-item]
