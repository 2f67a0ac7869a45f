"""Coil R-L current, hysteresis band, and the train's deceleration (eq. 29)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.control.open_loop import OpenLoop
from railpilot.eddy.coil import (
    CoilParams,
    coil_current_response_a,
    coil_decay,
    coil_step,
    hysteresis_step,
)
from railpilot.eddy.simulate import simulate_eddy
from railpilot.eddy.table import TorqueTable
from railpilot.eddy.train import TrainParams, train_step
from railpilot.errors import ConfigError

COIL = CoilParams()


def test_coil_current_follows_the_analytic_exponential():
    dt = 1e-4
    packed, decay = COIL.packed(), coil_decay(COIL, dt)
    i, out = 0.0, []
    for _ in range(5000):
        i = coil_step(i, True, packed, decay)
        out.append(i)
    t = dt * np.arange(1, 5001)
    assert_allclose(out, coil_current_response_a(COIL, COIL.supply_voltage_v, 0.0, t), rtol=1e-10)


def test_free_wheel_decays_to_zero_and_never_reverses():
    packed = CoilParams(freewheel_voltage_v=2.0).packed()
    decay = coil_decay(COIL, 1e-3)
    i = 10.0
    for _ in range(20000):
        i = coil_step(i, False, packed, decay)
        assert i >= 0.0
    assert i == 0.0


def test_hysteresis_band_and_current_limit():
    assert hysteresis_step(10.2, 10.0, False, 0.1, 425.0)
    assert not hysteresis_step(9.8, 10.0, True, 0.1, 425.0)
    assert hysteresis_step(10.05, 10.0, True, 0.1, 425.0)  # inside the band: keep
    assert not hysteresis_step(10.05, 10.0, False, 0.1, 425.0)
    assert not hysteresis_step(500.0, 425.0, True, 0.1, 425.0)


def test_closed_current_loop_stays_within_band_plus_one_step():
    table = TorqueTable.from_model(max_current_a=500, current_step_a=50, speed_step_kmh=50)
    res = simulate_eddy(
        OpenLoop(300.0),
        table=table,
        torque_demand_nm=1.0,
        initial_speed_mps=40.0,
        duration_s=3.0,
        record_every=1,
    )
    settled = res.time_s > 1.0
    err = res.current_a[settled] - res.current_ref_a[settled]
    # band 0.1 A plus at most one step of the steepest slope (free-wheel at 300 A)
    one_step = 300.0 / COIL.time_constant_s * 1e-4
    assert np.abs(err).max() <= 0.1 + one_step
    assert np.abs(err).max() > 0.09  # and it does use the band


def test_coil_validation():
    with pytest.raises(ConfigError, match=r"coil.current_limit_a"):
        CoilParams(current_limit_a=600.0)
    with pytest.raises(ConfigError, match=r"coil.inductance_h"):
        CoilParams(inductance_h=-1.0)


def test_train_deceleration_matches_the_closed_form_for_constant_torque():
    # dv/dt = -(F/m + k (A + B c v + C c^2 v^2)), c = 3.6, k = g/1000: a Riccati equation
    train = TrainParams()
    m, dw, g = train.axle_mass_kg, train.wheel_diameter_m, 9.8
    torque = 3000.0
    a = 2 * torque / dw / m + train.resistance_a * g / 1000
    b = train.resistance_b * 3.6 * g / 1000
    c = train.resistance_c * 3.6**2 * g / 1000
    disc = np.sqrt(4 * a * c - b * b)
    v0, dt = 40.0, 1e-4
    t = np.arange(0, 20.0 + dt / 2, dt)
    # closed form: arctan((2 c v + b)/disc) decreases linearly at rate disc/2
    theta = np.arctan((2 * c * v0 + b) / disc) - disc / 2 * t
    exact = (disc * np.tan(theta) - b) / (2 * c)
    packed = train.packed()
    v, sim = v0, [v0]
    for _ in range(t.size - 1):
        v = train_step(v, torque, packed, dt)
        sim.append(v)
    assert_allclose(sim, exact, atol=2e-4)


def test_train_stops_and_stays_stopped():
    packed = TrainParams().packed()
    assert train_step(0.001, 3500.0, packed, 0.1) == 0.0
    assert train_step(0.0, 3500.0, packed, 0.1) == 0.0
