"""First-order lag plus transport delay (railpilot.brakes.lag_delay).

Cross-checks: the exact method against the analytic step response
``1 - exp(-(t - delay) / lag)``; the Pade option against python-control
(``control.pade`` and ``control.step_response`` of the same transfer function).
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

import control
from railpilot.brakes.lag_delay import (
    LagDelay,
    pade_coefficients,
    pade_difference,
    step_response_analytic,
)
from railpilot.errors import ConfigError

DT = 0.01
N = 400
T_END = np.arange(1, N + 1) * DT  # each output is at the end of its step


@pytest.mark.parametrize(
    ("lag_s", "delay_s"),
    [
        (0.65, 0.3),  # paper 000 brake cylinder: whole number of steps (30)
        (0.65, 0.305),  # fractional delay: 30.5 steps
        (0.5, 0.0043),  # delay shorter than one step
        (0.4, 0.0),  # pure lag
    ],
)
def test_exact_step_response_matches_analytic(lag_s, delay_s):
    y = LagDelay(lag_s, delay_s, DT).response(np.ones(N))
    assert_allclose(y, step_response_analytic(T_END, lag_s, delay_s), atol=1e-9)


def test_exact_pure_delay_shifts_by_whole_steps():
    u = np.random.default_rng(7).normal(size=50)
    y = LagDelay(0.0, 0.05, DT).response(u)  # 5 steps
    assert_allclose(y[5:], u[:-5], atol=0.0)
    assert_allclose(y[:5], 0.0, atol=0.0)


def test_exact_response_of_arbitrary_input_matches_convolution_of_held_steps():
    # a held sequence is a sum of shifted steps; linearity makes the response the same sum
    lag, delay = 0.3, 0.137
    u = np.random.default_rng(3).uniform(-1.0, 1.0, size=120)
    y = LagDelay(lag, delay, DT).response(u)
    du = np.diff(np.concatenate([[0.0], u]))
    t = np.arange(1, len(u) + 1) * DT
    expected = sum(d * step_response_analytic(t - i * DT, lag, delay) for i, d in enumerate(du))
    assert_allclose(y, expected, atol=1e-9)


def test_initial_value_is_a_steady_state():
    ld = LagDelay(0.65, 0.3, DT, initial=2.5)
    assert_allclose(ld.response(np.full(100, 2.5)), 2.5, rtol=1e-14)


def test_pade_initial_value_is_a_steady_state():
    ld = LagDelay(0.65, 0.3, DT, method="pade", pade_order=3, initial=2.5)
    assert_allclose(ld.response(np.full(100, 2.5)), 2.5, rtol=1e-12)


def test_reset_restores_the_initial_response():
    ld = LagDelay(0.65, 0.3, DT)
    first = ld.response(np.ones(80))
    ld.reset()
    assert_allclose(ld.response(np.ones(80)), first, atol=0.0)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_pade_coefficients_match_python_control(order):
    num, den = pade_coefficients(0.3, order)
    num_ref, den_ref = control.pade(0.3, order)
    assert_allclose(num, num_ref, rtol=1e-12)
    assert_allclose(den, den_ref, rtol=1e-12)


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_pade_step_response_matches_python_control(order):
    # G(s) = pade_n(exp(-0.3 s)) / (0.65 s + 1); our ZOH discretisation of a held
    # step is exact, so it equals python-control's continuous step response sampled
    lag, delay = 0.65, 0.3
    sys = control.tf(*control.pade(delay, order)) * control.tf([1.0], [lag, 1.0])
    _, y_ref = control.step_response(sys, T=np.concatenate([[0.0], T_END]))
    y = LagDelay(lag, delay, DT, method="pade", pade_order=order).response(np.ones(N))
    assert_allclose(y, y_ref[1:], atol=1e-9)


def test_pade_difference_decreases_with_order():
    diffs = [pade_difference(0.65, 0.3, DT, order) for order in range(1, 6)]
    assert np.all(np.diff(diffs) < 0)


def test_pade_difference_is_zero_without_delay():
    assert pade_difference(0.65, 0.0, DT, 3) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"lag_s": -0.1, "delay_s": 0.3, "dt": DT}, "lag_s"),
        ({"lag_s": 0.65, "delay_s": np.inf, "dt": DT}, "delay_s"),
        ({"lag_s": 0.65, "delay_s": 0.3, "dt": 0.0}, "dt"),
        ({"lag_s": 0.65, "delay_s": 0.3, "dt": DT, "method": "euler"}, "method"),
        (
            {"lag_s": 0.65, "delay_s": 0.3, "dt": DT, "method": "pade", "pade_order": 0},
            "pade_order",
        ),
    ],
)
def test_bad_parameter_raises_config_error_naming_it(kwargs, field):
    with pytest.raises(ConfigError) as info:
        LagDelay(**kwargs)
    assert info.value.field == field
