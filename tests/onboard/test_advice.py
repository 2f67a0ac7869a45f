"""Driving advice and the driver model (railpilot.onboard.advice)."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.errors import ConfigError
from railpilot.onboard.advice import Advice, DriverModel, advise
from railpilot.onboard.drive import heavy_haul_loaded
from railpilot.onboard.planner import SpeedPlan
from railpilot.units import G_MPS2

PRESET = heavy_haul_loaded()
DRIVE = PRESET.driving
TRAIN = PRESET.train


def cruise_plan(speed=20.0, length=10_000.0):
    s = np.linspace(0.0, length, 1001)
    v = np.full(s.shape, speed)
    return SpeedPlan(s, v, length / speed, 0.0, 0.0, None, None, None, True)


def resistance_n(v):
    kmh = v * 3.6
    return (TRAIN.davis_a0 + TRAIN.davis_a1 * kmh + TRAIN.davis_a2 * kmh**2) * (
        TRAIN.mass_kg * G_MPS2 / 1000.0
    )


def test_cruising_on_the_level_is_traction_against_the_resistance():
    plan = cruise_plan()
    advice = advise(DRIVE, plan, np.zeros(1001), 5_000.0, 20.0, 250.0, 0.5)
    expected = resistance_n(20.0) / float(DRIVE.locomotive.traction.max_force(20.0))
    assert advice.mode == "traction"
    assert_allclose(advice.level, expected, rtol=1e-12)
    assert advice.deviation_s == pytest.approx(0.0, abs=1e-9)


def test_holding_speed_down_12_per_mille_needs_regeneration_and_air():
    plan = cruise_plan()
    w = np.full(1001, -12.0)
    advice = advise(DRIVE, plan, w, 5_000.0, 20.0, 250.0, 0.5)
    braking = TRAIN.mass_kg * G_MPS2 * 12 / 1000 - resistance_n(20.0)
    regen = float(DRIVE.locomotive.regen.max_force(20.0))
    assert advice.mode == "air"
    assert_allclose(advice.level, (braking - regen) / (0.5 * TRAIN.effective_mass_kg), rtol=1e-12)


def test_a_mild_descent_is_regeneration_alone():
    advice = advise(DRIVE, cruise_plan(), np.full(1001, -4.0), 5_000.0, 20.0, 250.0, 0.5)
    assert advice.mode == "regen" and 0.0 < advice.level < 1.0


def test_late_and_early_are_the_difference_to_the_plan():
    plan = cruise_plan()  # 500 s; at 5 km the plan has run 250 s
    late = advise(DRIVE, plan, np.zeros(1001), 5_000.0, 20.0, 262.0, 0.5)
    assert late.deviation_s == pytest.approx(12.0)
    assert late.expected_arrival_s == pytest.approx(512.0)
    assert "12 s late" in late.text()
    early = advise(DRIVE, plan, np.zeros(1001), 5_000.0, 20.0, 240.0, 0.5)
    assert early.deviation_s == pytest.approx(-10.0)


def test_a_train_below_the_plan_is_told_to_pull_harder():
    plan = cruise_plan()
    on = advise(DRIVE, plan, np.zeros(1001), 5_000.0, 20.0, 250.0, 0.5)
    slow = advise(DRIVE, plan, np.zeros(1001), 5_000.0, 18.0, 250.0, 0.5)
    assert slow.mode == "traction" and slow.level > on.level


def test_driver_sets_notches():
    driver = DriverModel(max_accel_mps2=0.08, max_decel_mps2=0.4, notches=8)
    assert driver.notch(0.031) == pytest.approx(0.03)
    assert driver.notch(-0.12) == pytest.approx(-0.1)
    assert driver.notch(5.0) == pytest.approx(0.08)
    assert driver.notch(-5.0) == pytest.approx(-0.4)


def test_driver_acts_after_the_reaction_time():
    from railpilot.control.user import Measurement, Reference

    driver = DriverModel(max_accel_mps2=0.08, max_decel_mps2=0.4, reaction_s=1.5)
    driver.reset()
    dt = 0.1
    # the plan asks to brake from t = 0: the driver's command changes 1.5 s later
    out = [driver.update(Reference(0.0, 10.0, -0.2), Measurement(0.0, 10.0), dt) for _ in range(30)]
    first = int(np.argmax(np.array(out) < 0))
    assert first * dt == pytest.approx(1.5, abs=1e-9)
    assert out[first] == pytest.approx(-0.2)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"max_accel_mps2": 0.0}, "driver.max_accel_mps2"),
        ({"reaction_s": math.nan}, "driver.reaction_s"),
        ({"notches": 0}, "driver.notches"),
    ],
)
def test_bad_driver_parameters_name_the_field(kwargs, field):
    args = {"max_accel_mps2": 0.08, "max_decel_mps2": 0.4} | kwargs
    with pytest.raises(ConfigError) as err:
        DriverModel(**args)
    assert err.value.field == field


def test_advice_is_a_frozen_value():
    advice = Advice("coast", 0.0, 20.0, 500.0, 0.0)
    with pytest.raises(AttributeError):
        advice.level = 1.0  # type: ignore[misc]
