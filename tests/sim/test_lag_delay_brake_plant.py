"""Paper 002's brake (railpilot.brakes.lag_delay_brake) as the engine's plant.

The controller is taken out of the loop as in tests/sim/test_engine_physics.py: a
SMARC with every gain 0 and no adaptation outputs ``theta1 * a_ff``. With the ATO's
lead 0 and no resistance model, ``a_ff`` is the reference's -0.65 m/s^2 from t = 0
(a constant-deceleration reference without coasting), so the brake sees a step of
``uc = 0.65 / a_max`` at t = 0 and delivers (paper 002 eq. 1)

    decel(t) = 0.65 (1 - exp(-(t - sigma) / tau))   for t >= sigma, else 0.

The recorder holds, at row k (time k dt), the brake force of the step from k dt to
(k + 1) dt, i.e. the brake's output at the end of that step, (k + 1) dt.
"""

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.control.smarc import SMARC
from railpilot.errors import ConfigError
from railpilot.scenario.model import ATOModel, Scenario, SimSettings
from railpilot.sim.reference import constant_deceleration
from railpilot.sim.run import simulate
from railpilot.vehicle.train import Train

DT = 0.01
DECEL = 0.65
TAU = 0.5
MASS = 300e3


def open_loop():
    return SMARC(
        c=0.0,
        ks=0.0,
        alpha=0.0,
        eta=0.0,
        phi=0.05,
        gamma=(0.0, 0.0),
        theta_bounds=((0.0, 1.5), (-0.3, 0.3)),
        theta0=(1.0, 0.0),
    )


def step_scenario(delay_s, lag_s=TAU, max_decel=1.3, gain=1.0):
    train = Train(
        mass_kg=MASS,
        rotating_mass_factor=0.0,
        davis_a0=0.0,
        davis_a1=0.0,
        davis_a2=0.0,
        max_service_decel_mps2=1.0,
    )
    return Scenario(
        train=train,
        brake=LagDelayBrake(lag_s=lag_s, delay_s=delay_s, max_decel_mps2=max_decel),
        reference=constant_deceleration(19.8, DECEL, 0.0),
        ato=ATOModel(davis=(0.0, 0.0, 0.0), brake_delay_s=0.0, brake_lag_s=0.0),
        sim=SimSettings(dt_s=DT, duration_s=10.0),
        brake_gain=gain,
    )


def delivered(scenario):
    result = simulate(scenario, open_loop())
    return result, result["air_n"] / scenario.train.effective_mass_kg


def analytic(t, delay_s, lag_s=TAU):
    shifted = t - delay_s
    if lag_s == 0.0:
        return np.where(shifted >= -1e-12, DECEL, 0.0)
    return np.where(shifted >= 0.0, DECEL * (1.0 - np.exp(-shifted / lag_s)), 0.0)


def test_open_loop_command_is_the_constant_reference_deceleration():
    result, _ = delivered(step_scenario(1.2))
    assert np.all(result["command_mps2"] == -DECEL)


@pytest.mark.parametrize("delay_s", [1.05, 1.2, 1.35])
def test_delivered_deceleration_is_the_lag_delay_step_response(delay_s):
    result, decel = delivered(step_scenario(delay_s))
    t_end = result["time_s"] + DT
    assert_allclose(decel, analytic(t_end, delay_s), atol=1e-12)


@pytest.mark.parametrize("delay_s", [1.205, 1.2345, 0.013])
def test_fractional_delay_is_exact_between_the_steps(delay_s):
    # the delay is not a whole number of steps: the step response still holds at
    # every step end (the delayed step arrives part-way through a step)
    result, decel = delivered(step_scenario(delay_s))
    t_end = result["time_s"] + DT
    assert_allclose(decel, analytic(t_end, delay_s), atol=1e-12)
    # and it differs from the neighbouring whole-step delays
    below = analytic(t_end, np.floor(delay_s / DT) * DT)
    assert np.max(np.abs(decel - below)) > 1e-3


def test_pure_delay_without_lag_is_a_shifted_step():
    # tau = 0: the step arrives whole, in the step that starts sigma after the command
    result, decel = delivered(step_scenario(0.5, lag_s=0.0))
    assert_allclose(decel, analytic(result["time_s"], 0.5, lag_s=0.0), atol=1e-12)
    assert np.flatnonzero(decel)[0] == 50


def test_map_and_its_inverse_cancel_for_any_max_deceleration():
    # uc = 0.65 / a_max goes through F(uc) = -a_max uc: the same delivered deceleration
    _, a = delivered(step_scenario(1.2, max_decel=1.0))
    _, b = delivered(step_scenario(1.2, max_decel=2.0))
    assert_allclose(a, b, atol=1e-12)


def test_brake_gain_scales_the_delivered_deceleration():
    _, nominal = delivered(step_scenario(1.2))
    _, strong = delivered(step_scenario(1.2, gain=1.1))
    assert_allclose(strong, 1.1 * nominal, atol=1e-12)


def test_train_decelerates_at_the_delivered_rate():
    # no resistance, no disturbance: a = -brake / m_eff at every step before the stop
    result, decel = delivered(step_scenario(1.2))
    assert_allclose(result["accel_mps2"], -decel, atol=1e-12)


def test_command_beyond_the_map_saturates_at_full_brake():
    # the controller asks for 0.65 m/s^2 but the brake only has 0.5: uc clips at 1
    result, decel = delivered(step_scenario(0.0, lag_s=0.0, max_decel=0.5))
    assert np.max(decel) == pytest.approx(0.5, abs=1e-12)
    assert np.all(result["demand_n"] <= 0.5 * MASS + 1e-6)


# --- bad parameters -------------------------------------------------------------------


@pytest.mark.parametrize("delay_s", [0.001, 0.005, 0.0099])
def test_delay_shorter_than_one_step_is_refused(delay_s):
    # a delay the step cannot resolve (0 < sigma < dt): the step is too long for it
    with pytest.raises(ConfigError, match="at least one simulation step") as info:
        LagDelayBrake(delay_s=delay_s).pack_arrays(DT)
    assert info.value.field == "brake.delay_s"
    assert info.value.value == delay_s


def test_delay_shorter_than_one_step_is_refused_before_simulating():
    with pytest.raises(ConfigError) as info:
        simulate(step_scenario(0.005), open_loop())
    assert info.value.field == "brake.delay_s"


def test_zero_delay_and_one_step_delay_are_accepted():
    assert LagDelayBrake(delay_s=0.0).pack_arrays(DT).shape == (6,)
    assert LagDelayBrake(delay_s=DT).pack_arrays(DT).shape == (6,)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"delay_s": -0.1}, "brake.delay_s"),
        ({"lag_s": -0.5}, "brake.lag_s"),
        ({"lag_s": float("inf")}, "brake.lag_s"),
        ({"max_decel_mps2": 0.0}, "brake.max_decel_mps2"),
        ({"max_decel_mps2": -1.0}, "brake.max_decel_mps2"),
    ],
)
def test_bad_parameter_raises_config_error_naming_it(kwargs, field):
    with pytest.raises(ConfigError) as info:
        LagDelayBrake(**kwargs)
    assert info.value.field == field


def test_scenario_lead_is_the_brake_delay_plus_lag():
    scenario = dataclasses.replace(step_scenario(1.25), ato=ATOModel())
    assert scenario.brake_lead_s == (1.25, TAU)
