"""SMARC (railpilot.control.smarc) alone, and in closed loop on a written-out plant."""

import numpy as np
import pytest

from railpilot.control.smarc import SMARC

DT = 0.01


def quiet(**kwargs):
    """A SMARC with every term off except those given (and no adaptation)."""
    base = {"c": 0.0, "ks": 0.0, "alpha": 0.0, "eta": 0.0, "phi": 0.05, "gamma": (0.0, 0.0)}
    base.update(kwargs)
    return SMARC(**base)


def test_on_the_surface_with_true_estimates_output_is_equivalent_control():
    # theta = (1.2, -0.05); e1 = 2, e2 = -c e1 = -0.8 -> s = 0
    # u_eq = theta1 (ad - c e2) - theta2 = 1.2 (-0.5 + 0.32) + 0.05 = -0.166
    ctrl = SMARC(c=0.4, ks=1.0, alpha=1.0, eta=0.1, phi=0.05, theta0=(1.2, -0.05))
    u = ctrl.update((100.0, 10.0, -0.5), (102.0, 9.2), DT)
    assert u == pytest.approx(1.2 * (-0.5 - 0.4 * -0.8) + 0.05, abs=1e-12)
    assert ctrl.components["s"] == pytest.approx(0.0, abs=1e-12)
    assert ctrl.components["u_reaching"] == pytest.approx(0.0, abs=1e-12)
    assert ctrl.components["u_robust"] == pytest.approx(0.0, abs=1e-10)


def test_reaching_law_is_ks_one_plus_alpha_abs_s_times_s():
    # s = 0.5: u_reach = -2 (1 + 3 * 0.5) 0.5 = -2.5
    ctrl = quiet(ks=2.0, alpha=3.0, theta0=(0.0, 0.0), theta_bounds=((0.0, 1.5), (-0.3, 0.3)))
    assert ctrl.update((0.0, 10.0, 0.0), (0.0, 10.5), DT) == pytest.approx(-2.5)


@pytest.mark.parametrize(("s", "expected"), [(0.02, -0.4), (0.05, -1.0), (0.7, -1.0), (-3.0, 1.0)])
def test_robust_term_saturates_outside_boundary_layer(s, expected):
    # eta = 1, phi = 0.05: u_rob = -sat(s / phi)
    ctrl = quiet(eta=1.0, phi=0.05, theta0=(0.0, 0.0), theta_bounds=((0.0, 1.5), (-0.3, 0.3)))
    ctrl.update((0.0, 10.0, 0.0), (0.0, 10.0 + s), DT)
    assert ctrl.components["u_robust"] == pytest.approx(expected)


def test_zero_boundary_layer_is_sign():
    ctrl = quiet(eta=0.3, phi=0.0)
    ctrl.update((0.0, 10.0, 0.0), (0.0, 10.001), DT)
    assert ctrl.components["u_robust"] == -0.3


def test_output_respects_limits():
    ctrl = SMARC(ks=5.0, output_limits=(-1.0, 0.0))
    assert ctrl.update((0.0, 10.0, 0.0), (0.0, 13.0), DT) == -1.0


def test_adaptation_signs():
    # too fast (s > 0) while braking (ad < 0, regressor ad - c e2 < 0):
    # d theta1 = -gamma1 s (ad - c e2) > 0 and d theta2 = gamma2 s > 0
    ctrl = SMARC(c=0.4, gamma=(0.5, 0.5))
    ctrl.update((0.0, 10.0, -0.5), (0.0, 10.2), DT)
    s, reg = 0.2, -0.5 - 0.4 * 0.2
    assert ctrl.components["theta1_hat"] == pytest.approx(1.0 - 0.5 * s * reg * DT)
    assert ctrl.components["theta2_hat"] == pytest.approx(0.5 * s * DT)


def test_projection_keeps_estimates_inside_bounds():
    bounds = ((0.7, 1.5), (-0.3, 0.3))
    ctrl = SMARC(gamma=(1e3, 1e3), theta_bounds=bounds)
    rng = np.random.default_rng(5)
    for _ in range(200):
        ctrl.update((0.0, 10.0, -0.8), (rng.normal(0, 5), 10.0 + rng.normal(0, 3)), DT)
        th1, th2 = ctrl.components["theta1_hat"], ctrl.components["theta2_hat"]
        assert bounds[0][0] <= th1 <= bounds[0][1]
        assert bounds[1][0] <= th2 <= bounds[1][1]


def test_projection_hits_the_bound_it_is_pushed_towards():
    ctrl = SMARC(gamma=(1e3, 1e3))
    for _ in range(20):
        ctrl.update((0.0, 10.0, -0.5), (0.0, 12.0), DT)  # s = 2 > 0 throughout
    assert ctrl.components["theta2_hat"] == 0.3
    assert ctrl.components["theta1_hat"] == 1.5


def test_reset_restores_initial_estimates():
    ctrl = SMARC(gamma=(1.0, 1.0), theta0=(1.1, 0.02))
    for _ in range(10):
        ctrl.update((0.0, 10.0, -0.5), (0.3, 10.4), DT)
    ctrl.reset()
    assert ctrl.components["theta1_hat"] == 1.1
    assert ctrl.components["theta2_hat"] == 0.02


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"c": -0.1}, "c"),
        ({"ks": np.nan}, "ks"),
        ({"eta": -1.0}, "eta"),
        ({"phi": np.inf}, "phi"),
        ({"gamma": (0.1, -0.1)}, "gamma2"),
        ({"theta0": (2.0, 0.0)}, r"theta0\[0\]"),
        ({"output_limits": (0.0, 0.0)}, "output_limits"),
    ],
)
def test_bad_parameter_raises_value_error_naming_it(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} = "):
        SMARC(**kwargs)


# --- closed loop: theta1 dv/dt = u + theta2 (the model SMARC is derived for) ----------
THETA1, THETA2 = 1.2, -0.05  # heavier than nominal, a constant push-back
GAMMA = (0.5, 0.5)


def lyapunov(ctrl):
    """Paper 000 eq. 16: V = theta1 s^2 / 2 + sum (theta_hat - theta)^2 / (2 gamma)."""
    comp = ctrl.components
    return (
        THETA1 * comp["s"] ** 2 / 2
        + (comp["theta1_hat"] - THETA1) ** 2 / (2 * GAMMA[0])
        + (comp["theta2_hat"] - THETA2) ** 2 / (2 * GAMMA[1])
    )


def run_ramp(duration_s=25.0):
    """Track a speed ramp v_d = 15 - 0.5 t starting 0.5 m/s fast (s = 0.5 m/s).

    Returns rows ``(e1, e2, V)`` at each controller update.
    """
    ctrl = SMARC(c=0.5, ks=1.5, alpha=0.5, eta=0.02, phi=0.05, gamma=GAMMA)
    x, v = 0.0, 15.5
    history = []
    for k in range(int(duration_s / DT)):
        t = k * DT
        xd, vd, ad = 15.0 * t - 0.25 * t * t, 15.0 - 0.5 * t, -0.5
        u = ctrl.update((xd, vd, ad), (x, v), DT)
        history.append((x - xd, v - vd, lyapunov(ctrl)))
        acc = (u + THETA2) / THETA1  # exact for u held over the step
        x += v * DT + acc * DT * DT / 2
        v += acc * DT
    return np.array(history)


def test_closed_loop_tracks_a_ramp():
    e1, e2, _ = run_ramp().T
    assert abs(e1[-1]) < 1e-3
    assert abs(e2[-1]) < 1e-3


def test_closed_loop_lyapunov_function_decreases():
    # eq. 16: dV/dt <= 0; V settles where s = 0 leaves the estimates (no excitation)
    v_lyap = run_ramp()[:, 2]
    assert v_lyap[-1] < 0.5 * v_lyap[0]
    assert np.max(np.diff(v_lyap)) < 1e-9
