"""Braking prediction and the paper's TSR check (railpilot.onboard.braking).

The compiled Runge-Kutta loop against analytic solutions (constant deceleration, Davis only)
and against an independent integration of the same model with SciPy (``solve_ivp`` with
events, the vectorised envelope and resistance functions and the brake pipe's closed-form
build-up), including the TSR check's decision and its air-brake point: the table in
docs/onboard.md is reproduced within 2 %.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from railpilot.brakes.brake_pipe import BrakePipeBrake, train_force_fraction
from railpilot.errors import ConfigError
from railpilot.onboard.braking import BrakingTrain, predict_braking, tsr_check
from railpilot.onboard.drive import heavy_haul_loaded
from railpilot.units import G_MPS2, kmh_to_mps
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import BACKWARD, FORWARD, elevation_table, length_averaged_resistance
from railpilot.vehicle.resistance import davis_resistance_n
from railpilot.vehicle.train import Train

#: the heavy-haul train of examples/heavy_haul_run.toml (``railpilot drive``'s preset)
TRAIN = heavy_haul_loaded().train
HEAVY = heavy_haul_loaded().braking
#: the cases of the table: gradient [per mille] x limit [km/h], 80 km/h, TSR 3 km ahead
GRADES = [0.0, -4.0, -12.0]
LIMITS_KMH = [60.0, 45.0]
DISTANCE_M = 3000.0


def level_table(grade_permille=0.0):
    return elevation_table(Line(gradients=(Segment(-20_000.0, 200_000.0, grade_permille),)))


# --- analytic solutions ---------------------------------------------------------------------


def test_constant_deceleration_matches_the_kinematics():
    # no resistance, no regen, air at once with no build-up (ideal pipe, 1 ms cylinders) on a
    # train whose service limit is the air's 0.5 m/s^2: s = v^2 / (2 a)
    train = Train(
        mass_kg=1e6,
        length_m=1.0,
        davis_a0=0.0,
        davis_a1=0.0,
        davis_a2=0.0,
        max_service_decel_mps2=0.5,
    )
    air = BrakePipeBrake(
        max_decel_mps2=0.5,
        application_time_s=0.001 * math.log(20.0),
        n_segments=2,
        valve_flow_mps=math.inf,
        pipe_diffusivity_m2ps=math.inf,
    )
    run = predict_braking(
        BrakingTrain(train, None, air), level_table(), 0.0, 20.0, air_from_s=0.0, dt_s=0.01
    )
    assert run.reached_speed
    assert_allclose(run.x_m[-1], 20.0**2 / (2 * 0.5), rtol=1e-3)
    assert_allclose(run.t_s[-1], 20.0 / 0.5, rtol=1e-3)


def test_davis_coasting_with_only_a0_matches_the_kinematics():
    # a0 only: constant deceleration a0 g / 1000 / (1 + gamma); no brake at all
    train = Train(mass_kg=1e6, length_m=1.0, davis_a0=2.0, davis_a1=0.0, davis_a2=0.0)
    air = BrakePipeBrake()
    run = predict_braking(
        BrakingTrain(train, None, air), level_table(), 0.0, 10.0, until_speed_mps=5.0
    )
    decel = 2.0 * G_MPS2 / 1000.0 / 1.06
    assert_allclose(run.t_s[-1], 5.0 / decel, rtol=1e-9)
    # the last step's crossing is interpolated linearly: exact in v, O(h^2) in x
    assert_allclose(run.x_m[-1], (10.0**2 - 5.0**2) / (2 * decel), rtol=1e-8)


def test_backward_travel_mirrors_forward_travel():
    # a descent of 12 per mille towards increasing x is an ascent the other way
    down_fwd = level_table(-12.0)
    up_bwd = elevation_table(Line(gradients=(Segment(-20_000.0, 200_000.0, -12.0),)), BACKWARD)
    fwd = predict_braking(HEAVY, down_fwd, 0.0, 20.0, air_from_s=0.0, until_speed_mps=10.0)
    bwd = predict_braking(
        HEAVY, up_bwd, 0.0, 20.0, direction=BACKWARD, air_from_s=0.0, until_speed_mps=10.0
    )
    # backwards on a line that falls towards +x, the train climbs: it stops sooner
    assert bwd.x_m[-1] < 0.0
    assert -bwd.x_m[-1] < fwd.x_m[-1]
    mirrored = elevation_table(Line(gradients=(Segment(-200_000.0, 20_000.0, 12.0),)), BACKWARD)
    again = predict_braking(
        HEAVY, mirrored, 0.0, 20.0, direction=BACKWARD, air_from_s=0.0, until_speed_mps=10.0
    )
    assert_allclose(-again.x_m[-1], fwd.x_m[-1], rtol=1e-12)


# --- an independent integration (SciPy) -----------------------------------------------------


def scipy_run(braking, table, v0, air_from_s, until_speed, until_x):
    """solve_ivp (RK45, tight tolerances) of the module docstring's model, vectorised
    helpers, events at the target speed and at the end position. Returns (t, x, v)."""
    train, loco, air = braking.train, braking.locomotive, braking.air
    m_eff = train.effective_mass_kg

    def rate(t, y):
        x, v = y
        speed = max(v, 0.0)
        brake = float(loco.regen.max_force(speed))
        if t >= air_from_s:
            phi = float(train_force_fraction(air, t - air_from_s, train.length_m))
            brake = min(
                train.max_service_decel_mps2 * m_eff, brake + air.max_decel_mps2 * m_eff * phi
            )
        resist = float(
            davis_resistance_n(speed, train.mass_kg, train.davis_a0, train.davis_a1, train.davis_a2)
        )
        w_line = float(length_averaged_resistance(table, x, train.length_m, FORWARD))
        resist += w_line * train.mass_kg * G_MPS2 / 1000.0
        return [v, -(brake + resist) / m_eff]

    def slow(t, y):
        return y[1] - until_speed

    slow.terminal = True
    slow.direction = -1

    def there(t, y):
        return y[0] - until_x

    there.terminal = True
    there.direction = 1

    def runaway(t, y):
        return y[1] - (v0 + 30.0)

    runaway.terminal = True
    sol = solve_ivp(
        rate,
        (0.0, 3600.0),
        [0.0, v0],
        events=[slow, there, runaway],
        rtol=1e-9,
        atol=1e-9,
        max_step=1.0,
    )
    return sol


def scipy_tsr(braking, table, v0, distance, limit):
    """The TSR check by SciPy: regen distance, and the latest air time by brentq."""
    regen = scipy_run(braking, table, v0, math.inf, limit, math.inf)
    regen_distance = regen.y_events[0][0][0] if len(regen.t_events[0]) else math.inf
    if regen_distance <= distance:
        return regen_distance, None

    def excess(air_from_s):
        sol = scipy_run(braking, table, v0, air_from_s, limit, distance)
        if len(sol.t_events[0]):  # reached the limit before the restriction
            return distance - sol.y_events[0][0][0]  # > 0: margin left
        return -(sol.y_events[1][0][1] - limit) * 100.0  # < 0: too fast there

    hi = distance / limit
    t_air = brentq(excess, 0.0, hi, xtol=1e-4)
    # the head's position when the air goes on: regen only until then
    before = scipy_run(braking, table, v0, math.inf, 0.0, math.inf)
    x_air = float(np.interp(t_air, before.t, before.y[0]))
    return regen_distance, x_air


@pytest.mark.parametrize("limit_kmh", LIMITS_KMH)
@pytest.mark.parametrize("grade", GRADES)
@pytest.mark.slow
def test_tsr_check_reproduces_an_independent_integration_within_2_percent(grade, limit_kmh):
    table = level_table(grade)
    v0, limit = kmh_to_mps(80.0), kmh_to_mps(limit_kmh)
    ours = tsr_check(HEAVY, table, 0.0, v0, DISTANCE_M, limit)
    regen_distance, x_air = scipy_tsr(HEAVY, table, v0, DISTANCE_M, limit)
    if math.isinf(regen_distance):
        assert math.isinf(ours.regen_distance_m)
    else:
        assert_allclose(ours.regen_distance_m, regen_distance, rtol=0.02)
    assert ours.regen_sufficient == (regen_distance <= DISTANCE_M)
    if x_air is None:
        assert ours.air_brake_from_m is None
    else:
        # the distance left before the restriction when the air goes on, within 2 %
        assert_allclose(DISTANCE_M - ours.air_brake_from_m, DISTANCE_M - x_air, rtol=0.02)
    assert ours.feasible


def test_regen_alone_cannot_hold_the_train_on_12_per_mille():
    check = tsr_check(HEAVY, level_table(-12.0), 0.0, kmh_to_mps(80.0), 3000.0, kmh_to_mps(60.0))
    assert math.isinf(check.regen_distance_m) and not check.regen_sufficient
    assert 0.0 < check.air_brake_from_m < 3000.0


def test_applying_air_at_the_reported_point_just_makes_it_and_later_does_not():
    table = level_table(-4.0)
    v0, limit = kmh_to_mps(80.0), kmh_to_mps(45.0)
    check = tsr_check(HEAVY, table, 0.0, v0, DISTANCE_M, limit, tolerance_m=0.5)
    regen_only = predict_braking(HEAVY, table, 0.0, v0, until_speed_mps=0.0, horizon_s=600.0)
    t_air = float(np.interp(check.air_brake_from_m, regen_only.x_m, regen_only.t_s))
    on_time = predict_braking(
        HEAVY, table, 0.0, v0, air_from_s=t_air, until_speed_mps=limit, until_position_m=DISTANCE_M
    )
    assert on_time.reached_speed
    late = predict_braking(
        HEAVY,
        table,
        0.0,
        v0,
        air_from_s=t_air + 2.0,
        until_speed_mps=limit,
        until_position_m=DISTANCE_M,
    )
    assert late.reached_position and late.v_mps[-1] > limit


def test_infeasible_restriction_says_so_and_brakes_at_once():
    check = tsr_check(HEAVY, level_table(-12.0), 0.0, kmh_to_mps(80.0), 200.0, kmh_to_mps(45.0))
    assert not check.feasible and check.air_brake_from_m == 0.0
    assert check.speed_at_restriction_mps > kmh_to_mps(45.0)


def test_already_under_the_limit_needs_nothing():
    check = tsr_check(HEAVY, level_table(), 0.0, kmh_to_mps(40.0), 500.0, kmh_to_mps(45.0))
    assert check.regen_sufficient and check.air_brake_from_m is None


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"restriction_start_m": -10.0}, "restriction_start_m"),
        ({"limit_mps": float("nan")}, "limit_mps"),
        ({"limit_mps": -1.0}, "limit_mps"),
    ],
)
def test_bad_inputs_name_the_field(kwargs, field):
    args = {"restriction_start_m": 1000.0, "limit_mps": 10.0} | kwargs
    with pytest.raises(ConfigError) as err:
        tsr_check(HEAVY, level_table(), 0.0, 20.0, **args)
    assert err.value.field == field


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        # before, 1e-12 s asked for 3.6e15 steps of trace (a MemoryError)
        ({"dt_s": 1e-12}, "dt_s"),
        ({"dt_s": 0.0}, "dt_s"),
        ({"horizon_s": math.inf}, "horizon_s"),  # before: OverflowError from ceil
        ({"horizon_s": -1.0}, "horizon_s"),  # before: ValueError from np.empty
        ({"horizon_s": 1e9}, "horizon_s"),
    ],
)
def test_a_prediction_refuses_a_step_or_horizon_it_cannot_hold(kwargs, field):
    with pytest.raises(ConfigError) as err:
        predict_braking(HEAVY, level_table(), 0.0, 20.0, **kwargs)
    assert err.value.field == field


def test_a_prediction_at_the_finest_step_and_longest_horizon_runs():
    run = predict_braking(HEAVY, level_table(), 0.0, 20.0, dt_s=1e-3, horizon_s=3600.0)
    assert run.reached_speed
