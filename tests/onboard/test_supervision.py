"""Supervision curves (railpilot.onboard.supervision).

The deceleration curve against the kinematics of a constant deceleration, the intervention
point against a pure dead-time brake (exact: the dead time's distance) and against the
braking prediction with the real build-up along a 1,600 m train, the indication point's
reaction distance, and the regenerative curve's end on a descent.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.errors import ConfigError
from railpilot.onboard.braking import BrakingTrain, predict_braking
from railpilot.onboard.supervision import SupervisionParameters, supervision_curve
from railpilot.units import kmh_to_mps
from railpilot.vehicle.train import Train

from .test_braking import HEAVY, level_table

NO_MARGIN = SupervisionParameters(driver_reaction_s=4.0, speed_margin_mps=0.0)


def ideal_train(dead_time_s=0.0):
    """No resistance, no regeneration, 0.5 m/s^2 of air after a pure dead time."""
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
        application_time_s=1e-4 * math.log(20.0),  # a 0.1 ms lag: a step
        n_segments=2,
        reaction_s=dead_time_s,
        valve_flow_mps=math.inf,
        pipe_diffusivity_m2ps=math.inf,
    )
    return BrakingTrain(train, None, air)


def test_curve_is_the_constant_deceleration_parabola():
    curve = supervision_curve(ideal_train(), level_table(), 5000.0, 5.0, params=NO_MARGIN)
    v = np.array([5.0, 10.0, 20.0, 30.0])
    # exact at the 2 m integration points; linear interpolation between them: millimetres
    assert_allclose(curve.curve_distance_m(v), (v**2 - 25.0) / (2 * 0.5), rtol=0, atol=0.01)
    assert curve.complete


def test_intervention_of_a_dead_time_brake_is_the_curve_plus_the_dead_time_distance():
    curve = supervision_curve(ideal_train(3.0), level_table(), 5000.0, 0.0, params=NO_MARGIN)
    v = curve.intervention_speed_mps[1:]  # the grid, where it was predicted
    assert_allclose(curve.intervention_distance_m(v), v**2 / 1.0 + 3.0 * v, rtol=0, atol=0.6)


@pytest.mark.parametrize("grade", [0.0, -4.0, -12.0])
@pytest.mark.parametrize("speed_kmh", [30.0, 47.0, 63.0, 80.0])
def test_braking_from_the_intervention_point_stops_at_the_target(grade, speed_kmh):
    # the heavy-haul train, full service with the air brake building up along 1,600 m:
    # from the intervention point it stops within 3 m short of the target, never beyond
    table = level_table(grade)
    curve = supervision_curve(HEAVY, table, 10_000.0, 0.0, params=NO_MARGIN)
    v = kmh_to_mps(speed_kmh)
    start = float(curve.intervention_m(v))
    run = predict_braking(HEAVY, table, start, v, air_from_s=0.0)
    assert run.reached_speed
    assert -3.0 <= run.x_m[-1] - 10_000.0 <= 0.5


def test_a_decrease_to_a_lower_speed_is_supervised_too():
    table = level_table(-4.0)
    curve = supervision_curve(HEAVY, table, 10_000.0, kmh_to_mps(45.0), params=NO_MARGIN)
    v = kmh_to_mps(80.0)
    run = predict_braking(
        HEAVY,
        table,
        float(curve.intervention_m(v)),
        v,
        air_from_s=0.0,
        until_speed_mps=kmh_to_mps(45.0),
    )
    assert -3.0 <= run.x_m[-1] - 10_000.0 <= 0.5


def test_the_build_up_moves_the_intervention_far_ahead_of_the_curve():
    curve = supervision_curve(HEAVY, level_table(), 10_000.0, 0.0, params=NO_MARGIN)
    v = kmh_to_mps(80.0)
    assert curve.intervention_distance_m(v) > 2.0 * curve.curve_distance_m(v)


def test_indication_is_the_driver_reaction_ahead_of_the_intervention():
    params = SupervisionParameters(driver_reaction_s=4.0, speed_margin_mps=0.6)
    curve = supervision_curve(HEAVY, level_table(), 10_000.0, 0.0, params=params)
    v = np.array([10.0, 15.0, 20.0])
    assert_allclose(
        curve.indication_distance_m(v) - curve.intervention_distance_m(v), (v + 0.6) * 4.0
    )
    # the speed margin looks the intervention up at v + dv
    assert_allclose(
        curve.intervention_distance_m(v),
        supervision_curve(
            HEAVY, level_table(), 10_000.0, 0.0, params=NO_MARGIN
        ).intervention_distance_m(v + 0.6),
    )


def test_positions_mirror_for_the_other_direction():
    from railpilot.vehicle.line import Line, Segment
    from railpilot.vehicle.profile import BACKWARD, elevation_table

    fwd = supervision_curve(HEAVY, level_table(), 10_000.0, 0.0, params=NO_MARGIN)
    table = elevation_table(Line(gradients=(Segment(-20_000.0, 200_000.0, 0.0),)), BACKWARD)
    bwd = supervision_curve(HEAVY, table, 10_000.0, 0.0, direction=-1.0, params=NO_MARGIN)
    v = kmh_to_mps(60.0)
    assert float(fwd.intervention_m(v)) < 10_000.0 < float(bwd.intervention_m(v))
    assert_allclose(10_000.0 - fwd.intervention_m(v), bwd.intervention_m(v) - 10_000.0, rtol=1e-9)


def test_regeneration_alone_cannot_stop_the_train_on_a_descent():
    curve = supervision_curve(HEAVY, level_table(-12.0), 10_000.0, 0.0, mode="regen")
    assert not curve.complete
    assert math.isinf(float(curve.intervention_distance_m(kmh_to_mps(60.0))))
    # on the level it can (slowly: about 2.8 km from 80 km/h)
    level = supervision_curve(HEAVY, level_table(), 10_000.0, kmh_to_mps(45.0), mode="regen")
    assert level.complete


def test_permitted_speed_falls_towards_the_target():
    curve = supervision_curve(HEAVY, level_table(), 10_000.0, 0.0)
    x = np.linspace(8_000.0, 10_000.0, 41)
    permitted = curve.permitted_speed_mps(x)
    assert np.all(np.diff(permitted) <= 1e-12)
    assert permitted[-1] == 0.0
    # consistent with the intervention point: at x_I(v) the permitted speed is v
    v = kmh_to_mps(50.0)
    assert_allclose(curve.permitted_speed_mps(curve.intervention_m(v)), v, rtol=1e-3)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"mode": "emergency"}, "mode"),
        ({"target_speed_mps": -1.0}, "target_speed_mps"),
        ({"step_m": 0.0}, "step_m"),
    ],
)
def test_bad_inputs_name_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        supervision_curve(HEAVY, level_table(), 1000.0, **kwargs)
    assert err.value.field == field


def test_bad_parameters_name_the_field():
    with pytest.raises(ConfigError) as err:
        SupervisionParameters(driver_reaction_s=-1.0)
    assert err.value.field == "supervision.driver_reaction_s"
