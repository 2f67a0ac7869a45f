"""The effects of a real train (railpilot.sim.realism) as the engine applies them.

Each effect alone, on paper 002's stop (railpilot.reproduce.qsmc_stop.paper_scenario:
lag-delay brake, no running resistance, flat line, rotating mass factor 0) without
its disturbance region, so the only outside influence is the effect under test.
The idealised run stops within a millimetre of the stop point; the train starts
coasting at ``reference.start_m`` = -59.4 m (3 s at 19.8 m/s before the braking point).
"""

import dataclasses

import numpy as np
import pytest

from railpilot.errors import ConfigError
from railpilot.reproduce.qsmc_stop import paper_scenario
from railpilot.sim.disturbance import Disturbance
from railpilot.sim.realism import Realism
from railpilot.sim.run import simulate

G = 9.8  # the engine's g [m/s^2] (paper 000's value)
DT = 0.01
BASE = dataclasses.replace(paper_scenario(), disturbance=Disturbance())
START_M = BASE.reference.start_m


def run(controller="qsmc", scenario=BASE, **realism):
    return simulate(dataclasses.replace(scenario, realism=Realism(**realism)), controller)


def same_metrics(a, b):
    """Bit-for-bit equal metrics, nan equal to nan (no changeover on this brake)."""
    names = sorted(a.metrics)
    return names == sorted(b.metrics) and np.array_equal(
        [a.metrics[n] for n in names], [b.metrics[n] for n in names], equal_nan=True
    )


@pytest.fixture(scope="module")
def ideal():
    return run()


def stop_position(result):
    return result.metrics["stop_error_m"] + result.meta["stop_point_m"]


def test_idealised_run_has_no_odometry_error_and_no_slide(ideal):
    assert ideal.metrics["odometry_error_at_stop_m"] == 0.0
    assert ideal.metrics["slide_time_s"] == 0.0
    assert abs(ideal.metrics["stop_error_m"]) < 0.01


# --- speed measurement ----------------------------------------------------------------


def test_speed_noise_changes_the_run(ideal):
    noisy = run(speed_noise_std_mps=0.05, seed=4)
    assert noisy.metrics["stop_error_m"] != ideal.metrics["stop_error_m"]
    assert not np.array_equal(noisy["command_mps2"], ideal["command_mps2"])


def test_speed_noise_is_reproducible_by_seed():
    first = run(speed_noise_std_mps=0.05, seed=4)
    second = run(speed_noise_std_mps=0.05, seed=4)
    other = run(speed_noise_std_mps=0.05, seed=5)
    assert same_metrics(first, second)
    assert np.array_equal(first["command_mps2"], second["command_mps2"])
    assert other.metrics["stop_error_m"] != first.metrics["stop_error_m"]


def test_speed_noise_is_one_normal_draw_per_controller_update():
    realism = Realism(speed_noise_std_mps=0.05, seed=9)
    noise = realism.speed_noise(20_000)
    assert noise.shape == (20_000,)
    assert abs(np.mean(noise)) < 4 * 0.05 / np.sqrt(20_000)
    assert np.std(noise) == pytest.approx(0.05, rel=0.03)
    assert Realism().speed_noise(100).size == 0  # off: nothing drawn


def test_speed_quantisation_changes_the_run(ideal):
    coarse = run(speed_resolution_mps=0.1)
    assert not np.array_equal(coarse["command_mps2"], ideal["command_mps2"])


# --- odometry -------------------------------------------------------------------------


@pytest.mark.parametrize("error", [0.01, -0.01, 0.03])
def test_wheel_scale_error_makes_odometry_off_by_error_times_distance(error):
    # without balises the odometer counts from the start: x_odo - x = e (x - x_start)
    result = run(wheel_scale_error=error)
    distance = stop_position(result) - START_M
    assert result.metrics["odometry_error_at_stop_m"] == pytest.approx(error * distance, rel=1e-9)


def test_wheel_scale_error_reading_long_makes_the_train_stop_short(ideal):
    # an odometer that reads 1 % long believes it is further on: it stops about 1 % of
    # the ~360 m travelled short of the stop point
    result = run(wheel_scale_error=0.01)
    assert result.metrics["stop_error_m"] == pytest.approx(-0.01 * 361.0 / 1.01, abs=0.2)


@pytest.mark.parametrize("error", [0.01, -0.01])
def test_balise_resets_odometry_to_error_times_distance_since_it(error):
    # balise 10 m before the stop point: the odometer is exact there and then drifts by
    # e per metre again; it is reset in the step it is passed, so up to one step
    # (v dt <= 0.06 m at that speed) of drift is missing
    balise = BASE.reference.stop_m - 10.0
    result = run(wheel_scale_error=error, balises_m=(balise,))
    since = stop_position(result) - balise
    assert since > 0
    assert result.metrics["odometry_error_at_stop_m"] == pytest.approx(
        error * since, abs=abs(error) * 0.06
    )


def test_balise_just_before_the_stop_makes_the_odometry_error_small():
    # without a balise the odometer is off by 1 % of the ~360 m run; a balise 10 m
    # before the stop point leaves 1 % of the last few metres (the stop itself is still
    # short: the train braked on the wrong position until the balise)
    balise = BASE.reference.stop_m - 10.0
    without = run(wheel_scale_error=0.01)
    with_balise = run(wheel_scale_error=0.01, balises_m=(balise,))
    assert without.metrics["odometry_error_at_stop_m"] > 3.0
    assert 0.0 < with_balise.metrics["odometry_error_at_stop_m"] < 0.1


def test_a_balise_beyond_the_stop_does_nothing():
    far = run(wheel_scale_error=0.01, balises_m=(BASE.reference.stop_m + 100.0,))
    assert same_metrics(far, run(wheel_scale_error=0.01))


def test_recorded_odometer_jumps_to_the_true_position_at_the_balise():
    balise = 150.0
    result = run(wheel_scale_error=0.02, balises_m=(balise,))
    x, odo = result["position_m"], result["odometer_m"]
    before = x < balise
    assert odo[before][-1] - x[before][-1] == pytest.approx(
        0.02 * (x[before][-1] - START_M), rel=1e-9
    )
    # the first sample after the balise step: only one step of drift since the reset
    k = np.argmax(~before) + 1
    assert abs(odo[k] - x[k]) < 0.02 * 20.0 * DT * 2


# --- brake notches --------------------------------------------------------------------


@pytest.mark.parametrize("notches", [4, 7])
def test_notches_quantise_the_command_to_the_notch_grid(notches):
    result = run(notches=notches)
    step = BASE.train.max_service_decel_mps2 / notches
    grid = result["command_mps2"] / step
    np.testing.assert_allclose(grid, np.round(grid), atol=1e-9)
    assert len(np.unique(np.round(grid))) >= 3  # several notches in use, not one


def test_stepless_commands_are_off_the_notch_grid(ideal):
    grid = ideal["command_mps2"] / (BASE.train.max_service_decel_mps2 / 7)
    assert np.max(np.abs(grid - np.round(grid))) > 0.25


# --- adhesion and slide ---------------------------------------------------------------

# 0.07 g = 0.686 m/s^2 of adhesion: above the reference's 0.65 m/s^2 but below what the
# controller demands while it makes up for the brake's 1.2 s delay
ADHESION = 0.07


@pytest.fixture(scope="module")
def sliding():
    return run(adhesion=ADHESION)


def test_low_adhesion_makes_the_wheels_slide(sliding):
    assert sliding.metrics["slide_time_s"] > 1.0


def test_slide_makes_the_stop_longer(ideal, sliding):
    assert sliding.metrics["stop_time_s"] > ideal.metrics["stop_time_s"] + 1.0
    assert sliding.metrics["stop_error_m"] > 1.0  # overshoot


def test_deceleration_while_sliding_is_slide_ratio_times_adhesion_times_g(sliding):
    # no resistance, no outside force: a sliding step decelerates at exactly
    # slide_ratio * adhesion * g (m_eff = m here); the steps at that deceleration
    # add up to the slide time the engine counted
    slide_decel = 0.8 * ADHESION * G
    at_slide = np.abs(sliding["accel_mps2"] + slide_decel) < 1e-9
    assert at_slide.sum() * DT == pytest.approx(sliding.metrics["slide_time_s"], abs=DT / 2)
    # and no step ever brakes harder than the adhesion itself
    assert sliding.metrics["max_decel_mps2"] <= ADHESION * G + 1e-12


def test_adhesion_above_every_demand_changes_nothing(ideal):
    dry = run(adhesion=0.2)  # 1.96 m/s^2 > the brake's 1 m/s^2
    assert same_metrics(dry, ideal)


def test_slide_slip_fools_the_odometer_while_sliding():
    # a sliding wheel turns slower than the train: the odometer falls behind
    result = run(adhesion=ADHESION, slide_slip=0.1)
    assert result.metrics["odometry_error_at_stop_m"] < -0.5


# --- ATO control cycle ----------------------------------------------------------------


def test_control_period_holds_the_command_between_updates():
    slow = dataclasses.replace(BASE, sim=dataclasses.replace(BASE.sim, control_period_s=0.2))
    command = simulate(slow, "qsmc")["command_mps2"]
    changes = np.flatnonzero(np.diff(command)) + 1
    assert changes.size > 10
    assert np.all(changes % 20 == 0)


def test_control_every_step_changes_the_command_between_those_steps(ideal):
    changes = np.flatnonzero(np.diff(ideal["command_mps2"])) + 1
    assert np.any(changes % 20 != 0)


# --- validation -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"speed_noise_std_mps": -0.1}, "realism.speed_noise_std_mps"),
        ({"speed_resolution_mps": float("nan")}, "realism.speed_resolution_mps"),
        ({"adhesion": -0.01}, "realism.adhesion"),
        ({"wheel_scale_error": 0.2}, "realism.wheel_scale_error"),
        ({"slide_slip": 1.5}, "realism.slide_slip"),
        ({"slide_ratio": -0.1}, "realism.slide_ratio"),
        ({"notches": -1}, "realism.notches"),
        ({"notches": 2.5}, "realism.notches"),
        ({"seed": -3}, "realism.seed"),
        ({"balises_m": (100.0, float("inf"))}, "realism.balises_km"),
    ],
)
def test_bad_realism_raises_config_error_naming_the_field(kwargs, field):
    with pytest.raises(ConfigError) as info:
        Realism(**kwargs)
    assert info.value.field == field
