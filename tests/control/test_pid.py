"""PID (railpilot.control.pid) alone, and against simple-pid where features overlap."""

import numpy as np
import pytest
import simple_pid
from numpy.testing import assert_allclose

from railpilot.control.pid import PID, TrackingPID

DT = 0.05


def random_inputs(seed, n=400):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 1.0, n).cumsum() * 0.1, rng.uniform(-2.0, 2.0, n)


@pytest.mark.parametrize(
    ("gains", "limits", "seed"),
    [
        ((1.3, 0.4, 0.05), (None, None), 1),  # unlimited: plain parallel PID
        ((2.0, 1.5, 0.1), (-1.0, 1.0), 2),  # saturating: clamp anti-windup active
        ((0.8, 3.0, 0.0), (-0.5, 2.0), 3),  # asymmetric limits, PI only
    ],
)
def test_matches_simple_pid_on_random_sequence(gains, limits, seed):
    # overlap: no derivative filter, derivative on measurement, integral clamped into
    # the output limits, output clamped; a set-point that moves every sample
    measurements, setpoints = random_inputs(seed)
    ours = PID(*gains, output_limits=limits, anti_windup="clamp")
    peer = simple_pid.PID(
        *gains, output_limits=limits, sample_time=None, differential_on_measurement=True
    )
    out_ours, out_peer = [], []
    for y, r in zip(measurements, setpoints, strict=True):
        out_ours.append(ours.update(r, y, DT))
        peer.setpoint = r
        out_peer.append(peer(y, dt=DT))
    assert_allclose(out_ours, out_peer, rtol=0, atol=1e-12)


def test_components_match_simple_pid_terms():
    measurements, _ = random_inputs(4, 50)
    ours = PID(1.0, 0.5, 0.2, output_limits=(-1.0, 1.0))
    peer = simple_pid.PID(1.0, 0.5, 0.2, setpoint=0.3, output_limits=(-1.0, 1.0), sample_time=None)
    for y in measurements:
        ours.update(0.3, y, DT)
        peer(y, dt=DT)
    assert_allclose(list(ours.components.values()), peer.components, atol=1e-12)


def test_proportional_only_output_is_kp_times_error():
    assert PID(2.5).update(1.0, 0.2, DT) == pytest.approx(2.0)


def test_integral_accumulates_ki_error_dt():
    pid = PID(0.0, 2.0)
    for _ in range(10):
        out = pid.update(1.0, 0.0, DT)
    assert out == pytest.approx(10 * 2.0 * 1.0 * DT)


def test_no_derivative_kick_on_setpoint_step_by_default():
    pid = PID(0.0, 0.0, 1.0)
    pid.update(0.0, 0.0, DT)
    assert pid.update(5.0, 0.0, DT) == 0.0


def test_derivative_on_error_kicks_on_setpoint_step():
    pid = PID(0.0, 0.0, 1.0, derivative_on="error")
    pid.update(0.0, 0.0, DT)
    assert pid.update(5.0, 0.0, DT) == pytest.approx(5.0 / DT)


def test_output_respects_limits():
    pid = PID(10.0, 5.0, output_limits=(-1.0, 0.5))
    outs = [pid.update(r, 0.0, DT) for r in (1.0, 2.0, -3.0, -10.0)]
    assert max(outs) == 0.5
    assert min(outs) == -1.0


def test_derivative_filter_response_to_ramp_is_first_order():
    # measurement ramp y = k dt: raw derivative 0 at sample 0, -kd from sample 1 on; the
    # backward-Euler filter gives D_k = -kd (1 - q^k), q = tf / (tf + dt)
    kd, tf = 0.7, 0.2
    pid = PID(0.0, 0.0, kd, derivative_filter_s=tf)
    d = []
    for k in range(30):
        pid.update(0.0, k * DT, DT)
        d.append(pid.components["d"])
    q = tf / (tf + DT)
    assert_allclose(d, -kd * (1.0 - q ** np.arange(30)), rtol=1e-12)


def test_derivative_filter_attenuates_measurement_noise():
    noise = np.random.default_rng(11).normal(0.0, 0.01, 500)
    terms = {}
    for tf in (0.0, 0.5):
        pid = PID(0.0, 0.0, 1.0, derivative_filter_s=tf)
        terms[tf] = [pid.update(0.0, y, DT) for y in noise]
    assert np.std(terms[0.5]) < 0.2 * np.std(terms[0.0])


def closed_loop_overshoot(backcalc_gain):
    """Integrator plant dy/dt = u, |u| <= 1, set-point step 0 -> 10; peak overshoot."""
    pid = PID(
        1.0, 1.0, output_limits=(-1.0, 1.0), anti_windup="backcalc", backcalc_gain=backcalc_gain
    )
    y, peak = 0.0, 0.0
    for _ in range(int(60 / DT)):
        y += pid.update(10.0, y, DT) * DT
        peak = max(peak, y)
    return peak - 10.0


def test_backcalculation_recovers_from_saturation_faster_than_windup():
    # backcalc_gain = 0 is no anti-windup: the integrator winds up while saturated
    assert closed_loop_overshoot(backcalc_gain=1.0) < 0.5 * closed_loop_overshoot(0.0)


def test_clamp_keeps_integral_inside_limits():
    pid = PID(0.0, 10.0, output_limits=(-1.0, 1.0))
    for _ in range(100):
        pid.update(1.0, 0.0, DT)
    assert pid.components["i"] == 1.0


def test_reset_forgets_history():
    pid = PID(1.0, 2.0, 0.3, derivative_filter_s=0.1)
    first = [pid.update(1.0, y, DT) for y in (0.0, 0.2, 0.5)]
    pid.reset()
    assert [pid.update(1.0, y, DT) for y in (0.0, 0.2, 0.5)] == first


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"kp": np.nan}, "kp"),
        ({"kp": 1.0, "ki": np.inf}, "ki"),
        ({"kp": 1.0, "kd": np.nan}, "kd"),
        ({"kp": 1.0, "derivative_filter_s": -0.1}, "derivative_filter_s"),
        ({"kp": 1.0, "output_limits": (1.0, -1.0)}, "output_limits"),
        ({"kp": 1.0, "anti_windup": "none"}, "anti_windup"),
        ({"kp": 1.0, "derivative_on": "setpoint"}, "derivative_on"),
    ],
)
def test_bad_parameter_raises_value_error_naming_it(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} = "):
        PID(**kwargs)


@pytest.mark.parametrize("dt", [0.0, -0.01, np.nan])
def test_bad_dt_raises_value_error(dt):
    with pytest.raises(ValueError, match="dt = "):
        PID(1.0).update(0.0, 0.0, dt)


def test_tracking_pid_setpoint_is_corrected_by_position_error():
    # v_set = v_ref - k_x (x - x_ref) = 10 - 0.5 * (103 - 100) = 8.5; P-only, kp = 1
    pid = TrackingPID(1.0, position_gain=0.5)
    assert pid.update((100.0, 10.0), (103.0, 9.0), DT) == pytest.approx(8.5 - 9.0)


def test_tracking_pid_without_position_gain_is_a_speed_pid():
    tracking = TrackingPID(1.2, 0.3, 0.1)
    plain = PID(1.2, 0.3, 0.1)
    for x, v in ((0.0, 10.0), (0.5, 9.8), (1.0, 9.7)):
        assert tracking.update((x + 4.0, 10.0), (x, v), DT) == plain.update(10.0, v, DT)


def test_tracking_pid_rejects_negative_position_gain():
    with pytest.raises(ValueError, match=r"^position_gain = "):
        TrackingPID(1.0, position_gain=-0.1)
