"""Step metrics on synthetic signals with known answers."""

import math

import numpy as np
from numpy.testing import assert_allclose

from railpilot.eddy.metrics import hold_speeds_kmh, rise_time_s, settling_time_s, step_metrics


def test_first_order_response():
    t = np.linspace(0, 10, 100_001)
    tau = 0.5
    m = 1000 * (1 - np.exp(-t / tau))
    assert_allclose(rise_time_s(t, m, 1000), tau * np.log(9), atol=2e-4)  # 2.197 tau
    assert_allclose(settling_time_s(t, m, 1000, 0.02, 10.0), tau * np.log(50), atol=2e-4)


def test_overshoot_peak_and_steady_statistics():
    t = np.linspace(0, 20, 20_001)
    m = np.full_like(t, 500.0)
    m[t < 1] = 500 * t[t < 1]
    m[(t >= 1) & (t < 1.5)] = 530.0  # overshoot of 30 N m from 1 s to 1.5 s
    steady = t >= 5
    m[steady] += np.where(np.arange(steady.sum()) % 2 == 0, 2.0, -2.0)  # +-2 square ripple
    speed = np.linspace(100, 0, t.size)
    r = step_metrics(t, m, speed, 500.0, steady_start_s=5.0, steady_end_speed_kmh=0.0)
    assert r.overshoot_nm == 30.0
    assert_allclose(r.peak_time_s, 1.0)
    assert_allclose(r.steady_variance_nm2, 4.0, rtol=1e-3)
    assert r.steady_max_nm == 502.0 and r.steady_min_nm == 498.0
    assert_allclose(r.steady_mean_nm, 500.0, atol=1e-3)
    assert_allclose(r.settling_time_s, 1.5, atol=1e-3)


def test_hold_speed_is_the_end_of_the_longest_in_band_stretch():
    speed = np.linspace(160, 0, 1601)
    m = np.full(speed.size, 3500.0)
    m[:50] = 3000.0  # transient
    m[100:110] = 3600.0  # a brief excursion
    m[speed < 16] = 3000.0
    start, end = hold_speeds_kmh(speed, m, 3500.0, 0.01)
    assert_allclose(end, 16.0, atol=0.11)
    assert_allclose(start, speed[110])


def test_never_reaching_gives_nan():
    t = np.linspace(0, 1, 11)
    m = np.zeros(11)
    r = step_metrics(t, m, np.linspace(10, 9, 11), 100.0, steady_start_s=0.0)
    assert math.isnan(r.rise_time_s) and math.isnan(r.hold_until_speed_kmh)
    assert r.to_dict()["rise_time_s"] is None
