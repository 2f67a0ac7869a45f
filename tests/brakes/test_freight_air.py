"""Freight air brake along the train (railpilot.brakes.freight_air).

Each test drives the compiled step ``freight_air_step`` with held driver's-valve commands
and checks it against a closed form of the model: the front's arrival ``distance / speed``
(nearest valve), the AR/BC mass balance (``C = C0 + rho (A0 - A)``, equalization
``rho A / (1 + rho)``, emergency ``(rho A + e E + C) / (rho + e + 1)``), and, with quick
service off, the equivalent build-up time of the point model of brakes/brake_pipe.py
(calibrated against the ETCS conversion model).
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit
from numpy.testing import assert_allclose

from railpilot.brakes import freight_air as fa
from railpilot.brakes.brake_pipe import (
    BrakePipeBrake,
    application_lag_s,
    equivalent_build_up_time_s,
    release_lag_s,
)
from railpilot.brakes.freight_air import (
    FreightAirBrake,
    arrival_time_s,
    emergency_bc_kpa,
    equalization_bc_kpa,
    pack_freight_air,
    recharge_time_s,
    service_bc_kpa,
    simulate,
)
from railpilot.errors import ConfigError

DT = 0.05
BRAKE = FreightAirBrake()
P0 = BRAKE.charged_kpa
FULL_ER = P0 - BRAKE.full_service_reduction_kpa()


def train(n_wagons, loco_m=22.0, wagon_m=12.0):
    """Positions [m]: a locomotive at 0 and ``n_wagons`` wagons behind it."""
    return np.concatenate(([0.0], loco_m + wagon_m * np.arange(n_wagons)))


def packed(x, valves=(0,), brake=BRAKE, direct=None, loco_braked=False):
    """(params, state) for positions ``x``; the locomotive unbraked unless asked."""
    n = x.size
    braked = np.ones(n, dtype=bool)
    braked[0] = loco_braked
    direct = np.ones(n, dtype=bool) if direct is None else direct
    return pack_freight_air(brake, x, np.asarray(valves, dtype=np.int64), direct, braked)


def first_change_s(trace_bp, times, p0=P0):
    """End time [s] of the first step after which each vehicle's pipe is below ``p0``."""
    changed = trace_bp < p0 - 1e-9
    assert changed.any(axis=0).all(), "the change never reached some vehicle"
    return times[np.argmax(changed, axis=0)]


# --- propagation -------------------------------------------------------------------------


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    speed=st.floats(120.0, 350.0),
    dt=st.sampled_from([0.005, 0.02, 0.05]),
)
def test_a_reduction_reaches_each_vehicle_at_distance_over_speed(seed, speed, dt):
    """The pipe at each vehicle first changes in the step in which the front arrives:
    ``x / c`` after the valve's reduction (random spacing, speed and step)."""
    rng = np.random.default_rng(seed)
    x = np.concatenate(([0.0], np.cumsum(rng.uniform(10.0, 25.0, 30))))
    brake = FreightAirBrake(service_wave_mps=speed)
    params, state = packed(x, brake=brake)
    out = simulate(params, state, np.array([FULL_ER]), np.zeros(1), x[-1] / speed + 1.0, dt)
    expected = arrival_time_s(x, np.array([0]), speed)
    measured = first_change_s(out["bp"], out["t"])
    # the step reports at its end: the change shows in the step that contains the arrival
    assert np.all(measured >= expected - 1e-9)
    assert np.all(measured <= expected + dt + 1e-9)
    # and each charged distributor's application starts exactly at the arrival
    assert_allclose(fa.application_start_s(params, state)[1:], expected[1:], atol=1e-9)


def test_emergency_travels_faster_than_a_service_reduction():
    x = train(110)
    service = simulate(*packed(x), np.array([FULL_ER]), np.zeros(1), 7.0, DT)
    emergency = simulate(*packed(x), np.array([P0]), np.ones(1), 7.0, DT)
    t_service = first_change_s(service["bp"], service["t"])
    t_emergency = first_change_s(emergency["bp"], emergency["t"])
    for measured, speed in ((t_service, 250.0), (t_emergency, 280.0)):
        expected = x / speed
        assert np.all((measured >= expected - 1e-9) & (measured <= expected + DT + 1e-9))
    # the rear: 1,330 m at 280 m/s (4.75 s) against 250 m/s (5.32 s)
    assert t_emergency[-1] < t_service[-1] - 0.5


def test_a_head_and_mid_train_valve_reach_every_vehicle_no_later_and_the_rear_much_earlier():
    x = train(110)
    mid = 55
    alone = simulate(*packed(x), np.array([FULL_ER]), np.zeros(1), 7.0, DT)
    both = simulate(*packed(x, valves=(0, mid)), np.full(2, FULL_ER), np.zeros(2), 7.0, DT)
    t_alone = first_change_s(alone["bp"], alone["t"])
    t_both = first_change_s(both["bp"], both["t"])
    expected = arrival_time_s(x, np.array([0, mid]), 250.0)
    assert np.all((t_both >= expected - 1e-9) & (t_both <= expected + DT + 1e-9))
    assert np.all(t_both <= t_alone + 1e-9)
    # the rear hears the mid-train valve after (x_rear - x_mid) / c: half the head's time
    assert t_both[-1] < 0.55 * t_alone[-1]


# --- application --------------------------------------------------------------------------


def test_a_change_smaller_than_the_sensitivity_applies_nothing():
    x = train(40)
    params, state = packed(x)
    small = P0 - 0.5 * BRAKE.application_sensitivity_kpa
    out = simulate(params, state, np.array([small]), np.zeros(1), 120.0, DT)
    assert out["bc"].max() == 0.0
    assert out["ar"].min() == P0  # the check valve keeps the AR charged


@pytest.mark.parametrize("reduction_kpa", [12.0, 20.0])
def test_a_small_first_reduction_applies_at_least_the_quick_service_depth(reduction_kpa):
    """A reduction between the application sensitivity and the quick service's depth
    ``q`` applies every distributor as if by ``q`` (the local venting); the settled BC is
    ``rho q``, and the pipe settling back above it releases none of them."""
    x = train(40)
    params, state = packed(x)
    out = simulate(params, state, np.array([P0 - reduction_kpa]), np.zeros(1), 150.0, DT)
    expected = service_bc_kpa(BRAKE, P0, out["bp"][-1])
    assert_allclose(expected[1:], BRAKE.ar_to_bc_ratio * BRAKE.quick_service_kpa)
    assert_allclose(out["bc"][-1, 1:], expected[1:], atol=0.5)


def test_a_minimum_reduction_on_a_train_not_recharged_brakes_weaker_and_holds():
    """Released after a full service and reduced by the minimum again before the AR have
    recharged (the head's recharge first, the rear's last): every distributor brakes less
    than a charged train's minimum application ``rho r_min``, the less the further back
    it is; at the rear, whose reservoirs were charged least, the brakes stay released or
    release again (the pipe there is still drawn down by the reservoirs charging)."""
    x = train(110)  # a 10,000 t train: minutes to recharge
    params, state = packed(x)
    full = np.array([P0 - BRAKE.full_service_reduction_kpa()])
    simulate(params, state, full, np.zeros(1), 200.0, DT)
    simulate(params, state, np.array([P0]), np.zeros(1), 240.0, DT)
    assert np.all(fa.bc_kpa(params, state) < 0.5)  # released
    before = fa.ar_kpa(params, state).copy()
    assert np.all(before[1:] < P0 - BRAKE.application_sensitivity_kpa)  # not recharged
    out = simulate(params, state, np.array([P0 - BRAKE.min_reduction_kpa]), np.zeros(1), 300.0, DT)
    bc, ar = out["bc"][:, 1:], out["ar"][:, 1:]
    charged_min = BRAKE.ar_to_bc_ratio * BRAKE.min_reduction_kpa
    settled = bc[-1]
    applied = settled > 1.0
    assert applied[0] and not applied[-1]
    assert np.all(settled < charged_min - 5.0)
    assert np.all(np.diff(settled) <= 1.0)  # weaker towards the rear
    assert settled.mean() < 0.6 * charged_min
    # the head's applied from the moment the reduction reached it, never released since
    head = bc[:, 0]
    k = int((head > 1.0).argmax())
    assert np.all(head[k:] > 1.0)
    # and holds the air its reservoir gave (the mass balance)
    assert settled[0] == pytest.approx(BRAKE.ar_to_bc_ratio * (before[1] - ar[-1, 0]), abs=1.0)


def test_graduated_steps_raise_the_bc_monotonically_to_the_mass_balance():
    """ER lowered in 30 kPa steps: every BC rises monotonically, and after each step it is
    the mass balance's ``rho (A0 - p)`` for the pipe it has settled at, up to equalization."""
    x = train(30)
    params, state = packed(x)
    bcs = []
    for er in (550.0, 520.0, 490.0, 460.0, 430.0, 400.0):
        out = simulate(params, state, np.array([er]), np.zeros(1), 90.0, DT)
        bcs.append(out["bc"][:, 1:])
        expected = service_bc_kpa(BRAKE, P0, out["bp"][-1, 1:])
        assert_allclose(out["bc"][-1, 1:], expected, atol=0.5)
    trace = np.concatenate(bcs)
    assert np.all(np.diff(trace, axis=0) >= -1e-9)
    # the last step is beyond full service: AR and BC equalized at rho p0 / (1 + rho)
    assert_allclose(trace[-1], BRAKE.full_service_bc_kpa(), atol=0.5)
    assert_allclose(BRAKE.full_service_bc_kpa(), equalization_bc_kpa(P0, 0.0, 2.5))


@settings(max_examples=8, deadline=None)
@given(r1=st.floats(50.0, 200.0), r2=st.floats(50.0, 200.0))
def test_a_deeper_reduction_never_brakes_less(r1, r2):
    x = train(20)
    low, high = sorted((r1, r2))
    ends = []
    for reduction in (low, high):
        params, state = packed(x)
        out = simulate(params, state, np.array([P0 - reduction]), np.zeros(1), 120.0, DT)
        ends.append(out["bc"][-1, 1:])
        assert_allclose(ends[-1], service_bc_kpa(BRAKE, P0, out["bp"][-1, 1:]), atol=0.5)
    assert np.all(ends[0] <= ends[1] + 1e-6)


# --- release --------------------------------------------------------------------------------


def test_a_small_rise_releases_a_direct_release_brake_fully_and_a_graduated_one_in_part():
    x = train(20)
    graduated = np.arange(x.size) % 2 == 0  # every other wagon a UIC-type distributor
    params, state = packed(x, direct=~graduated)
    simulate(params, state, np.array([430.0]), np.zeros(1), 120.0, DT)
    assert np.all(fa.bc_kpa(params, state)[1:] > 420.0)
    rise = 430.0 + BRAKE.release_sensitivity_kpa + 10.0
    out = simulate(params, state, np.array([rise]), np.zeros(1), 240.0, DT)
    bc = out["bc"][-1]
    wagons = np.arange(x.size) > 0
    assert np.all(bc[wagons & ~graduated] < 1.0)
    # graduated release: the BC follows rho (p_ref - p) down to the new pipe pressure
    expected = BRAKE.ar_to_bc_ratio * (P0 - out["bp"][-1])
    assert_allclose(bc[wagons & graduated], expected[wagons & graduated], atol=1.0)


def test_a_second_application_before_recharge_brakes_weaker_by_the_mass_balance():
    x = train(110)
    params, state = packed(x)
    first = simulate(params, state, np.array([430.0]), np.zeros(1), 180.0, DT)
    gap = simulate(params, state, np.array([P0]), np.zeros(1), 120.0, DT)
    assert np.all(gap["bc"][:, 1:].min(axis=0) < 50.0), "every brake released"
    second = simulate(params, state, np.array([430.0]), np.zeros(1), 240.0, DT)
    # the AR rose while recharging and stopped when the application started; the BC fell
    # while releasing and rose from there
    ar = np.concatenate((gap["ar"], second["ar"]))[:, 1:]
    bc = np.concatenate((gap["bc"], second["bc"]))[:, 1:]
    ar_start = ar.max(axis=0)
    bc_start = bc[np.argmax(ar, axis=0) + 1, np.arange(ar.shape[1])]
    assert np.all(ar_start < P0 - 5.0), "not recharged"
    expected = service_bc_kpa(BRAKE, ar_start, second["bp"][-1, 1:], bc_start)
    assert_allclose(second["bc"][-1, 1:], expected, atol=1.5)
    assert np.all(second["bc"][-1, 1:] < first["bc"][-1, 1:] - 5.0)


# --- emergency ------------------------------------------------------------------------------


@pytest.mark.parametrize("brake", [FreightAirBrake(), FreightAirBrake.aar_abd()])
def test_emergency_settles_at_the_mass_balance_and_builds_up_faster(brake):
    x = train(110)
    p0 = brake.charged_kpa
    full_er = p0 - brake.full_service_reduction_kpa()
    em = simulate(*packed(x, brake=brake), np.array([p0]), np.ones(1), 120.0, DT)
    service = simulate(*packed(x, brake=brake), np.array([full_er]), np.zeros(1), 120.0, DT)
    assert_allclose(em["bc"][-1, 1:], emergency_bc_kpa(brake, p0, p0), atol=0.5)
    assert_allclose(em["bp"][-1], 0.0, atol=1e-3)
    if brake.er_to_bc_ratio > 0.0:
        # AAR: the emergency reservoir adds about 20 % to a full service
        assert_allclose(brake.emergency_bc_kpa() / brake.full_service_bc_kpa(), 1.2, rtol=2e-3)
    else:
        assert_allclose(brake.emergency_bc_kpa(), brake.full_service_bc_kpa())
    # the rear's BC reaches 90 % of full service much sooner in emergency
    level = 0.9 * brake.full_service_bc_kpa()
    t_em = em["t"][np.argmax(em["bc"][:, -1] > level)]
    t_sv = service["t"][np.argmax(service["bc"][:, -1] > level)]
    assert service["bc"][:, -1].max() > level
    assert t_em < 0.5 * t_sv


# --- the pipe against the point model -------------------------------------------------------


@pytest.mark.parametrize("length_m", [400.0, 800.0, 1330.0])
def test_without_quick_service_the_build_up_matches_the_point_model(length_m):
    """The equivalent build-up time ``integral (1 - F) dt`` of a full service, quick service
    off, within 6 % of brakes/brake_pipe.py's (the same pipe constants, wave speed and
    cylinder lag; that model's pipe is a dead time and a lag per group, this one resolves
    the flow cell by cell)."""
    brake = FreightAirBrake(
        min_reduction_kpa=1.0,
        quick_service_kpa=0.5,
        application_sensitivity_kpa=0.5,
        release_sensitivity_kpa=0.5,
        quick_service_max_s=1e-3,
    )
    x = np.linspace(0.0, length_m, int(length_m / 12.0) + 1)
    params, state = packed(x, brake=brake, loco_braked=True)
    er = np.array([P0 - brake.full_service_reduction_kpa()])
    out = simulate(params, state, er, np.zeros(1), 400.0, DT)
    force = out["bc"].mean(axis=1) / brake.full_service_bc_kpa()
    assert force[-1] > 0.999
    ours = float(np.sum(1.0 - force) * DT)
    theirs = float(equivalent_build_up_time_s(BrakePipeBrake(), length_m))
    assert_allclose(ours, theirs, rtol=0.06)


# --- the implicit pipe against a fine explicit solution --------------------------------------


@njit(cache=True)
def _explicit_pipe(x, ell, k, consts, er_apply, t_release, t_end, h, every):
    """The same pipe, head valve, quick service off, solved explicitly at a step ``h`` far
    below its stability limit: a full-service application launched at 0, a release at
    ``t_release``. Each cell is in the application's phase from ``x / c_app`` until
    ``t_release + x / c_rel``; flow only between cells of one phase; every vehicle braked,
    direct release (applies when the front reaches it charged or its pipe falls ``s_app``
    below its AR, releases when the pipe rises ``s_rel`` above it; while applied its AR
    laps at ``max(min(p, A0 - q), A_eq)`` with lag ``T_a`` and gives its air to the BC;
    while released the AR charges from the pipe through its choke). Returns the pipe and
    BC every ``every`` steps."""
    p0, g, c_app, c_rel, s_app, s_rel, q, rho, a_m, tau_a, tau_r, tau_ch = consts
    n = x.size
    p = np.full(n, p0)
    ar = np.full(n, p0)
    bc = np.zeros(n)
    a0 = np.full(n, p0)
    applied = np.zeros(n, dtype=np.bool_)
    reached = np.zeros(n, dtype=np.bool_)
    phase = np.zeros(n, dtype=np.int64)
    flux = np.zeros(n)
    steps = round(t_end / h)
    out_bp = np.empty((steps // every, n))
    out_bc = np.empty((steps // every, n))
    for step in range(steps):
        t = step * h
        for i in range(n):
            phase[i] = 1 if x[i] / c_app <= t < t_release + x[i] / c_rel else 0
            if phase[i] == 1 and not reached[i]:
                reached[i] = True
                if not applied[i] and ar[i] + s_app >= p[i]:
                    applied[i] = True
                    a0[i] = ar[i]
            if not applied[i] and ar[i] - p[i] > s_app:
                applied[i] = True
                a0[i] = ar[i]
            elif applied[i] and p[i] > ar[i] + s_rel:
                applied[i] = False
        flux[:] = 0.0
        for i in range(n - 1):
            if phase[i] == phase[i + 1]:
                f = k[i] * (p[i] - p[i + 1]) * h
                flux[i] -= f
                flux[i + 1] += f
        er = er_apply if t < t_release else p0
        flux[0] += g * (er - p[0]) * h
        for i in range(n):
            p[i] += flux[i] / ell[i]
            if applied[i]:
                a_eq = ar[i] - max(ar[i] - bc[i], 0.0) / (1.0 + rho)
                target = max(min(p[i], a0[i] - q), a_eq)
                if ar[i] > target:
                    given = (ar[i] - target) * h / tau_a
                    ar[i] -= given
                    bc[i] += rho * given
            else:
                bc[i] -= bc[i] * h / tau_r
                if p[i] > ar[i]:
                    moved = a_m * (p[i] - ar[i]) * h / tau_ch
                    ar[i] += moved / a_m
                    p[i] -= moved / ell[i]
        if (step + 1) % every == 0:
            out_bp[(step + 1) // every - 1] = p
            out_bc[(step + 1) // every - 1] = bc
    return out_bp, out_bc


@pytest.mark.slow
def test_the_implicit_pipe_agrees_with_a_fine_explicit_solution():
    """A full service held 100 s, then a release for 100 s, quick service off, on the
    1,330 m train (every vehicle braked), at dt = 0.05 s, against the same pipe solved
    explicitly at 0.2 ms (6 % of its stability limit), sampled every 0.05 s at every
    vehicle. Stated tolerances: the pipe within 2 kPa everywhere (the largest gaps are
    near the valve in the first tenths of a second after each command), within 0.5 kPa
    from 3 s after each command on; every BC within 0.5 kPa; the equivalent build-up time
    of the application within 0.5 %. (Fixed substeps of 10 ms fail the first: ~5 kPa.)"""
    brake = FreightAirBrake(
        min_reduction_kpa=1.0,
        quick_service_kpa=0.5,
        application_sensitivity_kpa=0.5,
        release_sensitivity_kpa=0.5,
        quick_service_max_s=1e-3,
    )
    x = train(110)
    params, state = packed(x, brake=brake, loco_braked=True)
    er = P0 - brake.full_service_reduction_kpa()
    apply = simulate(params, state, np.array([er]), np.zeros(1), 100.0, DT)
    release = simulate(params, state, np.array([P0]), np.zeros(1), 100.0, DT)
    t = np.concatenate((apply["t"], release["t"]))
    bp = np.concatenate((apply["bp"], release["bp"]))
    bc = np.concatenate((apply["bc"], release["bc"]))
    # the reference: its own cells (each vehicle's share of the pipe, half-way to its
    # neighbours), conductances D / dx and reservoir volume
    gaps = np.diff(x)
    ell = np.concatenate(([gaps[0]], (gaps[:-1] + gaps[1:]) / 2.0, [gaps[-1]]))
    k = np.concatenate((brake.pipe_diffusivity_m2ps / gaps, [0.0]))
    a_m = brake.ar_volume_l * 1e-3 / (np.pi * brake.pipe_bore_m**2 / 4.0)
    consts = (
        P0,
        brake.valve_flow_mps,
        brake.service_wave_mps,
        brake.release_wave_mps,
        brake.application_sensitivity_kpa,
        brake.release_sensitivity_kpa,
        brake.quick_service_kpa,
        brake.ar_to_bc_ratio,
        a_m,
        application_lag_s(brake.application_time_s),
        release_lag_s(brake.release_time_s),
        brake.charge_lag_s,
    )
    h_ref = 2e-4
    ref_bp, ref_bc = _explicit_pipe(x, ell, k, consts, er, 100.0, 200.0, h_ref, round(DT / h_ref))
    assert ref_bp.shape == bp.shape
    assert_allclose(bp, ref_bp, atol=2.0)
    settled = ((t >= 3.0) & (t < 100.0)) | (t >= 103.0)
    assert_allclose(bp[settled], ref_bp[settled], atol=0.5)
    assert_allclose(bc, ref_bc, atol=0.5)
    # the equivalent build-up time integral (1 - F) dt, F = mean BC / full-service BC
    full = brake.full_service_bc_kpa()
    ours = np.sum(1.0 - apply["bc"].mean(axis=1) / full) * DT
    theirs = np.sum(1.0 - ref_bc[: apply["t"].size].mean(axis=1) / full) * DT
    assert_allclose(ours, theirs, rtol=5e-3)


# --- recharge and step size -----------------------------------------------------------------


def test_distributed_power_recharges_a_long_train_much_faster():
    x = train(110)
    head = recharge_time_s(BRAKE, x, np.array([0]), hold_s=150.0)
    both = recharge_time_s(BRAKE, x, np.array([0, 55]), hold_s=150.0)
    assert 60.0 < head < 3600.0
    assert both < 0.5 * head


def test_two_step_sizes_agree_after_200_s():
    """Full service for 100 s, release for 100 s: the state at dt = 0.05 s and 0.01 s
    agrees within 1 kPa for every pipe and AR pressure and 5 kPa for every BC (stated
    tolerances). The BC's is wider: the last few distributors' pipes rise through their
    release threshold ``A + s_rel`` at about 0.01 kPa/s, so the few hundredths of a kPa by
    which the two pipes differ move their releases by a second or two, while their BC
    vents at about 4 kPa/s."""
    x = train(110)
    ends = []
    for dt in (0.05, 0.01):
        params, state = packed(x)
        simulate(params, state, np.array([FULL_ER]), np.zeros(1), 100.0, dt)
        simulate(params, state, np.array([P0]), np.zeros(1), 100.0, dt)
        assert_allclose(fa.time_s(state), 200.0, atol=1e-9)
        ends.append((fa.bp_kpa(params, state), fa.ar_kpa(params, state), fa.bc_kpa(params, state)))
    for coarse, fine, atol in zip(ends[0], ends[1], (1.0, 1.0, 5.0), strict=True):
        assert_allclose(coarse, fine, atol=atol)


# --- interface ------------------------------------------------------------------------------


def test_the_accessors_work_inside_a_compiled_function():
    @njit
    def total_bc(params, state):
        return fa.bc_kpa(params, state).sum() + fa.bp_kpa(params, state)[0] * 0.0

    x = train(5)
    params, state = packed(x)
    simulate(params, state, np.array([430.0]), np.zeros(1), 60.0, DT)
    assert_allclose(total_bc(params, state), fa.bc_kpa(params, state).sum())
    # the accessors are views: writing through them changes the state
    fa.ar_kpa(params, state)[:] = 0.0
    assert np.all(fa.ar_kpa(params, state) == 0.0)


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"charged_kpa": -1.0}, "air.charged_kpa"),
        ({"ar_to_bc_ratio": 0.0}, "air.ar_to_bc_ratio"),
        ({"min_reduction_kpa": 300.0}, "air.min_reduction_kpa"),
        ({"application_sensitivity_kpa": 60.0}, "air.application_sensitivity_kpa"),
        ({"service_wave_mps": 500.0}, "air.service_wave_mps"),
        ({"release_time_s": math.nan}, "air.release_time_s"),
        ({"er_to_bc_ratio": -1.0}, "air.er_to_bc_ratio"),
        ({"pipe_bore_m": 0.5}, "air.pipe_bore_m"),
    ],
)
def test_a_bad_parameter_names_its_field(changes, field):
    with pytest.raises(ConfigError) as info:
        FreightAirBrake(**changes)
    assert info.value.field == field


@pytest.mark.parametrize(
    ("args", "field"),
    [
        ((np.array([0.0, 10.0, 5.0]), np.array([0]), None, None), "air.positions_m"),
        ((np.array([0.0, 10.0]), np.array([2]), None, None), "air.valve_vehicles"),
        ((np.array([0.0, 10.0]), np.array([0.0]), None, None), "air.valve_vehicles"),
        ((np.array([0.0, 10.0]), np.array([0]), np.ones(3, bool), None), "air.direct_release"),
        ((np.array([0.0, 10.0]), np.array([0]), None, np.ones(1, bool)), "air.has_brake"),
    ],
)
def test_a_bad_train_names_its_argument(args, field):
    x, valves, direct, braked = args
    direct = np.ones(x.size, bool) if direct is None else direct
    braked = np.ones(x.size, bool) if braked is None else braked
    with pytest.raises(ConfigError) as info:
        pack_freight_air(BRAKE, x, valves, direct, braked)
    assert info.value.field == field
