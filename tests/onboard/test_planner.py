"""The energy-efficient planned curve (railpilot.onboard.planner).

Properties: it meets the running time within one control period; its energy is never above
the fastest profile's with a uniform (linear) time margin; energy does not increase as the
running time grows; and on three sections it is within 3 % of a numerical optimum computed
here by an independent method (dynamic programming on a distance grid, the same train
physics, written out again with NumPy).
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.onboard.drive import heavy_haul_loaded
from railpilot.onboard.planner import (
    TIME_TOLERANCE_S,
    DrivingTrain,
    _envelope,
    _evaluate,
    _forward,
    _forward_time,
    fastest,
    linear_margin,
    plan,
    section,
    target_stop_net,
)
from railpilot.units import G_MPS2, kmh_to_mps
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import elevation_table
from railpilot.vehicle.traction import hxd1_locomotive

#: the heavy-haul train of examples/heavy_haul_run.toml (``railpilot drive``'s preset)
TRAIN = heavy_haul_loaded().train
DRIVE = heavy_haul_loaded().driving
V80 = kmh_to_mps(80.0)


def make_section(length_m, gradients=(), limits=None, step_m=10.0):
    table = elevation_table(Line(gradients=tuple(Segment(*g) for g in gradients)))
    edges, speeds = limits or (np.array([0.0, length_m]), np.array([V80]))
    return section(length_m, (edges, speeds), table, train_length_m=1600.0, step_m=step_m)


SECTIONS = {
    "level": make_section(15_000.0),
    "descent": make_section(15_000.0, [(5_000.0, 10_000.0, -12.0)]),
    "ascent-and-restriction": make_section(
        15_000.0,
        [(3_000.0, 7_000.0, 4.0)],
        (np.array([0.0, 9_000.0, 11_000.0, 15_000.0]), np.array([V80, kmh_to_mps(60.0), V80])),
    ),
}
SUPPLEMENTS = [0.0, 0.02, 0.05, 0.10, 0.20, 0.40]


@pytest.mark.parametrize("name", SECTIONS)
@pytest.mark.parametrize("supplement", SUPPLEMENTS)
def test_meets_the_running_time_within_one_control_period(name, supplement):
    sec = SECTIONS[name]
    target = fastest(DRIVE, sec).running_time_s * (1.0 + supplement)
    curve = plan(DRIVE, sec, target)
    assert curve.met
    assert abs(curve.running_time_s - target) <= TIME_TOLERANCE_S


@pytest.mark.parametrize("name", SECTIONS)
@pytest.mark.parametrize("supplement", SUPPLEMENTS)
def test_never_above_the_linear_margin(name, supplement):
    sec = SECTIONS[name]
    target = fastest(DRIVE, sec).running_time_s * (1.0 + supplement)
    ours = plan(DRIVE, sec, target)
    baseline = linear_margin(DRIVE, sec, target)
    assert abs(baseline.running_time_s - target) <= 1e-6 * target
    assert ours.energy_net_kwh <= baseline.energy_net_kwh + 1e-9


@pytest.mark.parametrize("name", ["level", "ascent-and-restriction"])
def test_energy_does_not_increase_as_the_running_time_grows(name):
    # NOT on the 12 per mille descent: there the planner's energy rises and falls as the
    # running time grows (a sawtooth, measured in docs/onboard.md); a known defect
    sec = SECTIONS[name]
    quickest = fastest(DRIVE, sec).running_time_s
    energies = [
        plan(DRIVE, sec, quickest * (1.0 + k)).energy_net_kwh for k in np.linspace(0, 0.5, 26)
    ]
    assert np.all(np.diff(energies) <= 1e-6)


@pytest.mark.parametrize("name", SECTIONS)
def test_never_above_the_ceiling_and_stops_at_both_ends(name):
    sec = SECTIONS[name]
    curve = plan(DRIVE, sec, fastest(DRIVE, sec).running_time_s * 1.1)
    assert np.all(curve.speed_mps <= sec.ceiling_mps + 1e-12)
    assert curve.speed_mps[0] == 0.0 and curve.speed_mps[-1] == 0.0


def test_a_time_faster_than_the_fastest_run_is_not_met():
    sec = SECTIONS["level"]
    curve = plan(DRIVE, sec, 0.5 * fastest(DRIVE, sec).running_time_s)
    assert not curve.met


def test_mareco_coast_to_brake_speed_by_hand():
    # vf = psi v1 / (psi + R v1), psi = v1^2 R'(v1); Davis in N/kN with v in km/h
    v1 = V80
    kmh = 80.0
    a0, a1, a2, mass = TRAIN.davis_a0, TRAIN.davis_a1, TRAIN.davis_a2, TRAIN.mass_kg
    r = (a0 + a1 * kmh + a2 * kmh**2) * mass * G_MPS2 / 1000.0
    r_prime = (a1 + 2 * a2 * kmh) * 3.6 * mass * G_MPS2 / 1000.0
    psi = v1**2 * r_prime
    assert_allclose(DRIVE.coast_to_brake_speed_mps(v1), psi * v1 / (psi + r * v1), rtol=1e-12)


# --- the independent optimum: dynamic programming on a distance grid -----------------------


def dp_optimum(sec_length_m, gradients, limits, weight, dx=50.0, dv2=1.0):
    """Minimum of energy + weight * time over every speed sequence on the grid.

    States: the speed at every ``dx``, on a grid uniform in ``v^2`` (step ``dv2``
    [m^2/s^2], so every acceleration is resolved to ``dv2 / (2 dx)`` = 0.01 m/s^2 at any
    speed; a grid uniform in ``v`` cannot follow the weak power-limited acceleration of a
    heavy train at speed); a transition from ``v_i`` to ``v_j`` over one
    step is allowed if the force it needs is within full traction (at ``v_i``) and the
    planning brake; its energy is the traction drawn (``/ eta_t``) or minus the regeneration
    returned (``x eta_r``, up to the regenerative envelope), its time ``dx / mean speed``.
    Returns (time [s], net energy [kWh], traction drawn [kWh]) of the optimal sequence.
    """
    loco = DRIVE.locomotive
    n = round(sec_length_m / dx) + 1
    s = np.linspace(0.0, sec_length_m, n)
    table = elevation_table(Line(gradients=tuple(Segment(*g) for g in gradients)))
    from railpilot.vehicle.profile import length_averaged_resistance

    line_w = length_averaged_resistance(table, s, 1600.0, 1.0)
    edges, speeds = limits
    ceiling = speeds[np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(speeds) - 1)]
    ceiling_prev = speeds[np.clip(np.searchsorted(edges, s, side="left") - 1, 0, len(speeds) - 1)]
    ceiling = np.minimum(ceiling, ceiling_prev)
    ceiling[0] = ceiling[-1] = 0.0
    v = np.sqrt(np.arange(0.0, V80**2 + 1e-9, dv2))
    m_eff = TRAIN.effective_mass_kg
    weight_n = TRAIN.mass_kg * G_MPS2 / 1000.0
    vi, vj = np.meshgrid(v, v, indexing="ij")
    mean = 0.5 * (vi + vj)
    accel = (vj**2 - vi**2) / (2 * dx)
    kmh = mean * 3.6
    davis = TRAIN.davis_a0 + TRAIN.davis_a1 * kmh + TRAIN.davis_a2 * kmh**2
    trac_max = loco.traction.max_force(vi)
    regen_max = loco.regen.max_force(mean)
    cost = np.full(len(v), np.inf)
    cost[0] = 0.0
    energy = np.zeros(len(v))
    drawn = np.zeros(len(v))
    time = np.zeros(len(v))
    for k in range(n - 1):
        w = 0.5 * (line_w[k] + line_w[k + 1])
        force = m_eff * accel + (davis + w) * weight_n
        ok = (force <= trac_max + 1e-6) & (force >= -DRIVE.brake_mps2 * m_eff - 1e-6)
        ok &= (mean > 0) & (vj <= ceiling[k + 1] + 1e-9) & (vi <= ceiling[k] + 1e-9)
        e_step = np.where(
            force > 0,
            force * dx / loco.traction_efficiency,
            -np.minimum(-force, regen_max) * dx * loco.regen_efficiency,
        )
        t_step = np.where(mean > 0, dx / np.where(mean > 0, mean, 1.0), np.inf)
        total = cost[:, None] + np.where(ok, e_step / 3.6e6 + weight * t_step, np.inf)
        best = np.argmin(total, axis=0)
        cols = np.arange(len(v))
        cost = total[best, cols]
        energy = energy[best] + e_step[best, cols] / 3.6e6
        drawn = drawn[best] + np.maximum(e_step[best, cols], 0.0) / 3.6e6
        time = time[best] + t_step[best, cols]
    return float(time[0]), float(energy[0]), float(drawn[0])


DP_CASES = {
    "level": (15_000.0, [], None),
    "ascent-and-restriction": (
        15_000.0,
        [(3_000.0, 7_000.0, 4.0)],
        (np.array([0.0, 9_000.0, 11_000.0, 15_000.0]), np.array([V80, kmh_to_mps(60.0), V80])),
    ),
    "two-restrictions": (
        15_000.0,
        [(2_000.0, 6_000.0, 2.0)],
        (
            np.array([0.0, 5_000.0, 6_500.0, 10_000.0, 11_000.0, 15_000.0]),
            np.array([V80, kmh_to_mps(45.0), V80, kmh_to_mps(60.0), V80]),
        ),
    ),
}
#: weights on time [kWh/s] that give the DP about a 10 % running-time supplement
DP_WEIGHTS = {"level": 1.4, "ascent-and-restriction": 1.4, "two-restrictions": 1.4}
#: stated before measuring: the planner's net energy within 3 % of the DP optimum's traction
#: energy (net energy is small, even negative, on a descent: a ratio of nets means nothing).
#: On steep descents the planner is further off (docs/onboard.md); they are not among these.
DP_TOLERANCE = 0.03


@pytest.mark.parametrize("name", DP_CASES)
@pytest.mark.slow
def test_within_3_percent_of_a_dynamic_programming_optimum(name):
    length, gradients, limits = DP_CASES[name]
    limits = limits or (np.array([0.0, length]), np.array([V80]))
    sec = make_section(length, gradients, limits)
    t_dp, e_dp, drawn_dp = dp_optimum(length, gradients, limits, DP_WEIGHTS[name])
    # the DP's own running time is the one to plan for
    assert 1.03 < t_dp / fastest(DRIVE, sec).running_time_s < 1.25
    ours = plan(DRIVE, sec, t_dp)
    assert ours.met and ours.strategy == "mareco"
    assert ours.energy_net_kwh <= e_dp + DP_TOLERANCE * drawn_dp


@pytest.mark.parametrize("name", ["level", "ascent-and-restriction"])
@pytest.mark.parametrize("supplement", [0.05, 0.10, 0.20])
def test_the_search_itself_beats_the_linear_margin_where_it_should(name, supplement):
    # plan() falls back to the linear margin if that is cheaper; off steep descents the
    # search's own profile is cheaper, by a clear margin
    sec = SECTIONS[name]
    target = fastest(DRIVE, sec).running_time_s * (1.0 + supplement)
    ours = plan(DRIVE, sec, target)
    assert ours.strategy == "mareco"
    assert ours.energy_net_kwh < 0.97 * linear_margin(DRIVE, sec, target).energy_net_kwh


def test_bad_inputs_name_the_field():
    with pytest.raises(ConfigError) as err:
        plan(DRIVE, SECTIONS["level"], -5.0)
    assert err.value.field == "running_time_s"
    with pytest.raises(ConfigError) as err:
        DrivingTrain(TRAIN, hxd1_locomotive(), brake_mps2=0.9)
    assert err.value.field == "brake_mps2"
    with pytest.raises(ConfigError) as err:
        make_section(15.0)
    assert err.value.field == "length_m"
    with pytest.raises(ConfigError) as err:
        section(
            1000.0,
            (np.array([0.0, 500.0, 400.0]), np.array([10.0, 10.0])),
            elevation_table(Line()),
        )
    assert err.value.field == "ceiling"


def test_a_planning_brake_weaker_than_a_descent_still_gives_a_plan():
    # 0.05 m/s^2 cannot hold a 10,000 t train on 12 per mille (0.09 m/s^2 of gravity net):
    # where it would be needed the plan brakes with the train's full service, and the plan
    # never stands still between the stops
    weak = DrivingTrain(TRAIN, DRIVE.locomotive, brake_mps2=0.05)
    sec = make_section(
        15_000.0,
        [(5_000.0, 12_000.0, -12.0)],
        (np.array([0.0, 11_000.0, 13_000.0, 15_000.0]), np.array([V80, kmh_to_mps(45.0), V80])),
    )
    curve = plan(weak, sec, 1.1 * fastest(weak, sec).running_time_s)
    assert curve.met
    assert np.all(curve.speed_mps[1:-1] > 0.0)
    assert np.all(curve.speed_mps <= sec.ceiling_mps + 1e-12)


@pytest.mark.parametrize("name", SECTIONS)
def test_the_search_times_a_profile_as_evaluating_it_does(name):
    # the search for v1 asks _forward_time for the running time alone; what it finds must
    # be what the whole profile, evaluated, takes, to the bit (else the plans would change)
    sec = SECTIONS[name]
    q = DRIVE.params()
    top = float(sec.ceiling_mps.max())
    for vb in (np.inf, 0.5 * top, 0.0):
        for v1 in np.linspace(0.2, 1.3, 12) * top:
            vf = DRIVE.coast_to_brake_speed_mps(v1)
            env = _envelope(q, sec.line_w, sec.ceiling_mps, vf, vb, sec.dx_m, 0.0)
            profile = _forward(q, sec.line_w, sec.ceiling_mps, env, v1, sec.dx_m)
            time = _forward_time(q, sec.line_w, sec.ceiling_mps, env, v1, sec.dx_m)
            assert time == _evaluate(q, sec.line_w, profile, sec.dx_m)[0]


#: 15 km all 10 per mille down, a stop at each end
DESCENT_10 = make_section(15_000.0, [(0.0, 15_000.0, -10.0)])
#: distance to the stop at the end [m], on its grid
DESCENT_10_TO_GO = DESCENT_10.s_m[-1] - DESCENT_10.s_m


def _stop_braking(curve):  # type: ignore[no-untyped-def]
    """Grid points of the stop at the end's braking: after the last at the curve's peak."""
    peak = curve.speed_mps.max()
    return np.arange(curve.speed_mps.size) > np.flatnonzero(curve.speed_mps >= peak - 1e-9).max()


def _under_20_kmh_m(curve):  # type: ignore[no-untyped-def]
    """How far before the stop at the end the curve falls below 20 km/h [m]."""
    return DESCENT_10_TO_GO[curve.speed_mps >= kmh_to_mps(20.0)].min()


def test_a_target_stop_on_a_long_descent_is_braked_at_half_the_planning_brake_net():
    # 10 per mille down: coasting accelerates the loaded train by 0.07-0.08 m/s^2, so the
    # planning brake (0.1 m/s^2) alone would leave 0.02-0.03 m/s^2 to stop with, a stop
    # planned 5 km long from 80 km/h; a target stop is braked at half the planning brake,
    # net
    sec, to_go = DESCENT_10, DESCENT_10_TO_GO
    net = 0.5 * DRIVE.brake_mps2
    assert target_stop_net(DRIVE) == net
    curve = fastest(DRIVE, sec, net)
    braking = _stop_braking(curve)
    assert to_go[braking].max() == pytest.approx(V80**2 / (2.0 * net), abs=10.0)
    # a constant net deceleration from rest backwards, v = sqrt(2 net d), to rounding
    assert_allclose(curve.speed_mps[braking], np.sqrt(2.0 * net * to_go[braking]), rtol=1e-9)
    # a plan for a longer time brakes its last 20 km/h in less than two thirds of the
    # distance the same plan to the station does (measured: 350-610 m against 920-1,750 m)
    station = fastest(DRIVE, sec)
    for supplement in (0.05, 0.2, 0.4):
        to_target = plan(DRIVE, sec, (1.0 + supplement) * curve.running_time_s, net)
        to_station = plan(DRIVE, sec, (1.0 + supplement) * station.running_time_s)
        assert _under_20_kmh_m(to_target) < 2.0 / 3.0 * _under_20_kmh_m(to_station)


def test_the_station_stop_on_a_long_descent_is_braked_as_before():
    # the planning brake's force, net of the line: 0.02-0.03 m/s^2, a stop kilometres long
    curve = fastest(DRIVE, DESCENT_10)
    peak = curve.speed_mps.max()
    assert DESCENT_10_TO_GO[_stop_braking(curve)].max() > peak**2 / (2.0 * 0.03)
    # and its last 20 km/h take longer than a target stop's (test above)
    assert _under_20_kmh_m(curve) > kmh_to_mps(20.0) ** 2 / (2.0 * 0.03)


@pytest.mark.parametrize("bad", [-0.05, float("nan"), float("inf")])
def test_a_stop_deceleration_that_is_not_one_is_refused_by_name(bad):
    with pytest.raises(ConfigError, match="stop_net_mps2"):
        plan(DRIVE, SECTIONS["level"], 1_000.0, bad)


def test_a_distributed_power_train_is_planned_with_every_unit_s_force() -> None:
    """The 20,000 t train's two HXD1s take the same notch (the remote by radio): the
    drive the planner sees pulls and regenerates with both, the 10,000 t train's with its
    one."""
    from railpilot.onboard.drive import hauling
    from railpilot.scenario.consist_file import consist_preset

    single = consist_preset("heavy-haul-10kt")
    double = consist_preset("heavy-haul-20kt-dp")
    units = [double.vehicles[int(i)].locomotive for i in double.locomotive_indices()]
    assert len(units) == 2 and all(u is not None for u in units)
    one = hauling(single)
    both = hauling(double)
    assert one is single.vehicles[0].locomotive
    assert both.traction.max_force_n == sum(u.traction.max_force_n for u in units if u)
    assert both.traction.max_power_w == sum(u.traction.max_power_w for u in units if u)
    assert both.regen.max_force_n == sum(u.regen.max_force_n for u in units if u)
    assert both.regen.max_power_w == sum(u.regen.max_power_w for u in units if u)
    assert both.traction.max_force_n == 2 * one.traction.max_force_n
