"""PredictiveStop (railpilot.control.pstop): its stop prediction against analytic
stops, the stop command, the brake split, validation, and the closed loop."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from railpilot.control.pstop import (
    N_STATE,
    P_SIGMA,
    P_STOP,
    P_TAU,
    S_U_STOP,
    PredictiveStop,
    _split,
    _stop_command,
    fast_path_limit,
    predicted_stop_m,
    pstop_step,
)
from railpilot.control.registry import CONTROLLERS
from railpilot.reproduce.precise_stop import heavy_haul_scenario
from railpilot.reproduce.qsmc_stop import realistic_scenario
from railpilot.sim.run import make_controller, simulate

AT_REST = np.zeros(4)  # the brake model released: (a_fast, z_fast, a_slow, z_slow)


def steady_slow(u):
    """The brake model's state after holding braking ``u`` long (all of it slow)."""
    return np.array([0.0, 0.0, u, u])


def lag_response(v0, u, a0, terms):
    """Speed and position of ``dv/dt = a(t)``, ``a(t) = u + sum c e^{-k t}``, in closed form.

    ``terms``: ``(c, k)`` pairs; ``a(0) = u + sum c`` must be ``a0`` (checked).
    Returns ``(v(t), x(t))`` as functions (``x(0) = 0``).
    """
    assert u + sum(c for c, _ in terms) == pytest.approx(a0, abs=1e-12)

    def v(t):
        return v0 + u * t + sum(c / k * (1.0 - math.exp(-k * t)) for c, k in terms)

    def x(t):
        return (
            v0 * t
            + u * t * t / 2.0
            + sum(c / k * (t - (1.0 - math.exp(-k * t)) / k) for c, k in terms)
        )

    return v, x


def pade_lag_terms(u, a0, sigma, tau):
    """``a(t) - u`` of the Pade delay ``(lam - s)/(lam + s)``, ``lam = 2/sigma``, and the lag
    ``1/(tau s + 1)`` after a step of the command from steady ``a0`` to ``u``.

    The Pade's output is ``u - 2 (u - a0) e^{-lam t}`` (it first moves the wrong way);
    the lag's forced response to that term is ``-2 (u - a0) / (1 - lam tau) e^{-lam t}``,
    the free one makes ``a(0) = a0``. ``sigma = 0``: the lag alone.
    """
    if sigma == 0.0:
        return [(a0 - u, 1.0 / tau)]
    lam = 2.0 / sigma
    c_pade = -2.0 * (u - a0) / (1.0 - lam * tau)
    return [(c_pade, lam), (a0 - u - c_pade, 1.0 / tau)]


def analytic_stop(v0, u, a0, terms):
    """Where ``dv/dt = u + sum c e^{-k t}`` from ``v0`` (at 0 m) comes to rest."""
    v, x = lag_response(v0, u, a0, terms)
    t_end = 10.0 * (v0 / -u + sum(1.0 / k for _, k in terms))
    return x(brentq(v, 1e-9, t_end, xtol=1e-13))


# --- the prediction -------------------------------------------------------------------


@pytest.mark.parametrize(("v", "u"), [(20.0, -0.65), (16.7, -0.2), (3.0, -1.1), (0.4, -0.05)])
@pytest.mark.parametrize("x", [0.0, 123.4])
def test_instant_brake_stops_at_v_squared_over_two_u(x, v, u):
    # sigma = tau = 0 and the model already braking at u: the deceleration is constant,
    # each trapezoid step and the last step's v^2 / (2 a) are exact (rounding only)
    params = PredictiveStop(0.0, 0.0).params
    stop = predicted_stop_m(params, x, v, steady_slow(u), u, 0.0, 0.1)
    assert_allclose(stop, x + v * v / (2.0 * -u), rtol=1e-12)


def test_instant_brake_net_acceleration_adds_to_the_command():
    # net = d_hat - r acts on top of the brake: -0.5 braked, 0.1 resistance -> 0.6
    params = PredictiveStop(0.0, 0.0).params
    stop = predicted_stop_m(params, 10.0, 12.0, steady_slow(-0.5), -0.5, -0.1, 0.1)
    assert_allclose(stop, 10.0 + 144.0 / 1.2, rtol=1e-12)


@pytest.mark.parametrize("u", [-1.2, -0.6, -0.3, -0.1, 0.0, 0.2])
@pytest.mark.parametrize("beyond", [50.0, 400.0, 3_000.0])
def test_a_prediction_asked_only_whether_it_passes_a_point_says_so_as_the_whole_one(u, beyond):
    # the stop law's questions (stop beyond the point, or not) are answered when the model
    # train passes the point: the answer is the whole prediction's, and a prediction that
    # does not pass it is the whole prediction, to the bit
    params = PredictiveStop(4.0, 6.0).params
    model = steady_slow(-0.2)
    whole = predicted_stop_m(params, 0.0, 18.0, model, u, 0.02, 0.5)
    cut = predicted_stop_m(params, 0.0, 18.0, model, u, 0.02, 0.5, beyond)
    assert (cut > beyond) == (whole > beyond)
    assert (cut >= beyond) == (whole >= beyond)
    if whole <= beyond:
        assert cut == whole
    else:
        assert beyond < cut <= whole


def test_standing_train_is_already_stopped():
    params = PredictiveStop(2.0, 3.0).params
    assert predicted_stop_m(params, 42.0, 0.0, AT_REST, -0.3, 0.0, 0.1) == 42.0


def test_no_braking_never_stops():
    # coasting with nothing slowing the train: the prediction gives up at _FAR
    params = PredictiveStop(0.0, 1.0).params
    assert predicted_stop_m(params, 0.0, 5.0, AT_REST, 0.0, 0.0, 0.5) >= 1e12


@pytest.mark.parametrize(
    ("v0", "u", "tau"), [(12.0, -0.6, 3.0), (16.7, -0.4, 6.0), (5.0, -0.8, 0.5)]
)
def test_first_order_lag_from_rest_matches_the_analytic_stop(v0, u, tau):
    # a(t) = u (1 - exp(-t/tau)): v(t) = v0 + u (t - tau (1 - exp(-t/tau))), x in closed
    # form, the stop time by brentq. The prediction advances the lag exactly and
    # integrates with trapezoids: second order in the step, ~1e-5 m at 0.01 s here
    params = PredictiveStop(0.0, tau).params
    expected = analytic_stop(v0, u, 0.0, pade_lag_terms(u, 0.0, 0.0, tau))
    stop = predicted_stop_m(params, 0.0, v0, AT_REST, u, 0.0, 0.01)
    assert_allclose(stop, expected, atol=1e-3)


def test_prediction_error_is_second_order_in_the_step():
    # halving the step quarters the error (trapezoids on exact actuator samples)
    v0, u, tau = 12.0, -0.6, 3.0
    params = PredictiveStop(0.0, tau).params
    expected = analytic_stop(v0, u, 0.0, pade_lag_terms(u, 0.0, 0.0, tau))
    errors = [
        abs(predicted_stop_m(params, 0.0, v0, AT_REST, u, 0.0, h) - expected) for h in (0.08, 0.04)
    ]
    assert 3.0 < errors[0] / errors[1] < 5.0


@pytest.mark.parametrize(("sigma", "tau"), [(4.0, 6.0), (1.2, 0.5)])
def test_pade_delay_and_lag_match_the_analytic_stop(sigma, tau):
    # the slow path is the Pade delay and the lag; a(t) from pade_lag_terms (about 50 s of
    # braking: 5,000 prediction steps, within the prediction's 6,000)
    u, v0 = -0.3, 12.0
    params = PredictiveStop(sigma, tau).params
    expected = analytic_stop(v0, u, 0.0, pade_lag_terms(u, 0.0, sigma, tau))
    stop = predicted_stop_m(params, 0.0, v0, AT_REST, u, 0.0, 0.01)
    assert_allclose(stop, expected, atol=2e-3)


def test_release_uses_the_release_lag():
    # the model braking at -0.8 is told -0.3: the slow path releases with tau_release
    # (8 s), not tau (1 s): a(t) = -0.3 - 0.5 exp(-t / 8)
    u, a0, v0 = -0.3, -0.8, 10.0
    params = PredictiveStop(0.0, 1.0, tau_release=8.0).params
    stop = predicted_stop_m(params, 0.0, v0, steady_slow(a0), u, 0.0, 0.01)
    assert_allclose(stop, analytic_stop(v0, u, a0, [(a0 - u, 1.0 / 8.0)]), atol=1e-3)
    # with the brake's own lag it would release six times faster and run further
    fast = analytic_stop(v0, u, a0, [(a0 - u, 1.0)])
    assert fast > stop + 5.0


def test_blended_brake_fast_part_acts_at_once_the_rest_lags():
    # fast path instant and already giving its 0.2 m/s^2 at every speed (full at 0 m/s);
    # the command -0.5 asks the slow path (lag 4 s, from released) for the other 0.3:
    # a(t) = -0.2 - 0.3 (1 - exp(-t/4)) = -0.5 + 0.3 exp(-t/4)
    params = PredictiveStop(
        0.0, 4.0, sigma_track=0.0, tau_track=0.0, fast_limit=0.2, fast_full_mps=0.0
    ).params
    model = np.array([-0.2, -0.2, 0.0, 0.0])
    stop = predicted_stop_m(params, 0.0, 15.0, model, -0.5, 0.0, 0.01)
    assert_allclose(stop, analytic_stop(15.0, -0.5, -0.2, [(0.3, 0.25)]), atol=1e-3)


# --- the line profile ------------------------------------------------------------------


def test_rising_resistance_ahead_stops_earlier_by_the_v_squared_amount():
    # instant brake at -0.5 from 10 m/s at 0 m: 100 m on a level line. The line's
    # resistance rises linearly from 0 at 20 m to 0.1 m/s^2 at 30 m and stays:
    # d(v^2)/dx = 2 a(x), so v^2(20) = 100 - 2 * 0.5 * 20 = 80,
    # v^2(30) = 80 - 2 * (0.5 * 10 + 0.1 * 10 / 2) = 69, stop = 30 + 69 / (2 * 0.6) = 87.5 m
    flat = PredictiveStop(0.0, 0.0).params
    rising = PredictiveStop(0.0, 0.0, line_profile=([0.0, 20.0, 30.0], [0.0, 0.0, 0.1])).params
    step = 0.005  # 20 s of braking in 4,000 prediction steps
    assert_allclose(predicted_stop_m(flat, 0.0, 10.0, steady_slow(-0.5), -0.5, 0.0, step), 100.0)
    stop = predicted_stop_m(rising, 0.0, 10.0, steady_slow(-0.5), -0.5, 0.0, step)
    assert_allclose(stop, 87.5, atol=1e-3)


def test_line_profile_counts_from_the_resistance_now():
    # the resistance where the train is now is already in net (the ATO's); only its change
    # ahead is added: a constant 0.1 m/s^2 line changes nothing
    level = PredictiveStop(0.0, 0.0, line_profile=([0.0, 500.0], [0.1, 0.1])).params
    stop = predicted_stop_m(level, 0.0, 10.0, steady_slow(-0.5), -0.5, -0.1, 0.01)
    assert_allclose(stop, 100.0 / 1.2, rtol=1e-12)


def test_davis_speed_term_changes_over_the_prediction():
    # with a (level) profile the Davis model enters as its change from now: c1 = 0.02
    # 1/s gives dv/dt = u - c1 (v - v0) = B - c1 v, B = u + c1 v0, so
    # v(t) = B/c1 + (v0 - B/c1) e^{-c1 t}. The resistance is taken at the step's start
    # speed (first order in the step: about c1 |a| h T^2 / 4 < 1 cm here, T = 25.5 s)
    u, v0, c1 = -0.5, 10.0, 0.02
    params = PredictiveStop(
        0.0, 0.0, davis_mps2=(0.3, c1, 0.0), line_profile=([0.0, 1.0], [0.0, 0.0])
    ).params
    b = u + c1 * v0
    t_stop = math.log(1.0 - c1 * v0 / b) / c1
    x_stop = b / c1 * t_stop + (v0 - b / c1) * (1.0 - math.exp(-c1 * t_stop)) / c1
    stop = predicted_stop_m(params, 0.0, v0, steady_slow(u), u, 0.0, 0.005)
    assert_allclose(stop, x_stop, atol=1e-2)
    assert stop > v0 * v0 / (2.0 * -u) + 1.0  # the resistance falls with the speed


# --- the stop command -----------------------------------------------------------------


def lag_stop(v0, u, tau):
    return analytic_stop(v0, u, 0.0, pade_lag_terms(u, 0.0, 0.0, tau))


def test_stop_command_stops_the_model_at_the_stop_point():
    # lag 2 s, 14 m/s from 0 m: the command whose analytic stop is 150 m, by brentq
    v0, tau, stop_m, step = 14.0, 2.0, 150.0, 0.01
    params = PredictiveStop(0.0, tau, stop_m=stop_m).params
    u = _stop_command(params, 0.0, v0, AT_REST, 0.0, step, -1.0, 0.0)
    assert_allclose(predicted_stop_m(params, 0.0, v0, AT_REST, u, 0.0, step), stop_m, atol=1e-3)
    expected_u = brentq(lambda c: lag_stop(v0, c, tau) - stop_m, -1.0, -0.1, xtol=1e-12)
    assert_allclose(u, expected_u, atol=1e-5)


def test_stop_command_brakes_fully_when_even_that_overruns():
    # 1 cm inside what full braking can reach: nothing in the limits stops there
    v0, tau = 14.0, 2.0
    params = PredictiveStop(0.0, tau, stop_m=lag_stop(v0, -1.0, tau) - 0.01).params
    assert _stop_command(params, 0.0, v0, AT_REST, 0.0, 0.01, -1.0, -0.2) == -1.0


def test_stop_command_releases_when_even_that_stops_short():
    # 1 cm beyond where the least braking (-0.2) stops: the command is the upper limit
    # (72 s of braking: a 0.02 s step keeps it within the prediction's 6,000 steps)
    v0, tau = 14.0, 2.0
    params = PredictiveStop(0.0, tau, stop_m=lag_stop(v0, -0.2, tau) + 0.01).params
    assert _stop_command(params, 0.0, v0, AT_REST, 0.0, 0.02, -1.0, -0.2) == -0.2
    # and 10 cm inside it the command is not clamped
    params = PredictiveStop(0.0, tau, stop_m=lag_stop(v0, -0.2, tau) - 0.1).params
    assert -1.0 < _stop_command(params, 0.0, v0, AT_REST, 0.0, 0.02, -1.0, -0.2) < -0.2


def test_stop_command_coasting_with_resistance_is_hi():
    # hi = 0 with 0.05 m/s^2 resistance stops at v^2 / 0.1 = 160 m; a stop point beyond
    params = PredictiveStop(0.0, 0.0, stop_m=170.0).params
    assert _stop_command(params, 0.0, 4.0, AT_REST, -0.05, 0.1, -1.0, 0.0) == 0.0


# --- the brake split --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("v", "expected"),
    [(15.0, 0.3), (10.0, 0.3), (8.5, 0.225), (7.0, 0.15), (4.0, 0.0), (1.0, 0.0), (0.0, 0.0)],
)
def test_fast_path_limit_full_then_linear_then_zero(v, expected):
    # 0.3 m/s^2 at and above 10 m/s, 0 at and below 4 m/s, linear between
    params = PredictiveStop(1.0, 1.0, fast_limit=0.3, fast_full_mps=10.0, fast_zero_mps=4.0).params
    assert_allclose(fast_path_limit(params, v), expected, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("v", [0.0, 3.0, 30.0])
def test_no_fast_limit_gives_no_fast_braking(v):
    params = PredictiveStop(1.0, 1.0).params
    assert fast_path_limit(params, v) == 0.0
    assert _split(params, -0.7, v) == (0.0, -0.7)


def test_fast_path_handover_at_one_speed():
    # fast_zero = fast_full: all of it at and above that speed, none below (no 0 / 0)
    params = PredictiveStop(1.0, 1.0, fast_limit=0.3, fast_full_mps=5.0, fast_zero_mps=5.0).params
    assert fast_path_limit(params, 5.0) == 0.3
    assert fast_path_limit(params, 4.999) == 0.0


@pytest.mark.parametrize(
    ("u", "v", "fast", "slow"),
    [
        (0.5, 15.0, 0.5, 0.0),  # traction: all fast
        (0.5, 1.0, 0.5, 0.0),  # at any speed
        (-0.2, 15.0, -0.2, 0.0),  # braking within the limit: all fast
        (-0.5, 15.0, -0.3, -0.2),  # beyond it: the rest slow
        (-0.5, 7.0, -0.15, -0.35),  # the limit falling with speed
        (-0.5, 2.0, 0.0, -0.5),  # below fast_zero: all slow
    ],
)
def test_split_traction_fast_braking_beyond_the_limit_slow(u, v, fast, slow):
    params = PredictiveStop(1.0, 1.0, fast_limit=0.3, fast_full_mps=10.0, fast_zero_mps=4.0).params
    got = _split(params, u, v)
    assert_allclose(got, (fast, slow), atol=1e-15)
    assert got[0] + got[1] == pytest.approx(u, abs=1e-15)


def test_fast_limit_fading_below_fast_zero_makes_the_prediction_longer():
    # the same command, but the instant fast path hands its braking to the lagging slow
    # one as the train slows: the stop is further than with the fast path kept
    blend = {"sigma_track": 0.0, "tau_track": 0.0, "fast_limit": 0.2}
    kept = PredictiveStop(0.0, 4.0, **blend).params
    fading = PredictiveStop(0.0, 4.0, **blend, fast_full_mps=8.0, fast_zero_mps=6.0).params
    model = np.array([-0.2, -0.2, -0.1, -0.1])  # steady at -0.3, 0.2 of it fast
    stops = [predicted_stop_m(p, 0.0, 15.0, model, -0.3, 0.0, 0.01) for p in (kept, fading)]
    assert_allclose(stops[0], 375.0, rtol=1e-12)  # steady -0.3 throughout: v^2 / 0.6
    assert stops[1] > stops[0] + 1.0


# --- the law while tracking, and the observer -----------------------------------------


def test_tracking_law_is_feed_forward_plus_speed_feedback_over_the_horizon():
    # first update (no estimate yet): u = a_r + r + (speed_gain / (sigma + tau)) (v_r - v)
    ctrl = PredictiveStop(1.5, 2.5, speed_gain=0.5)
    u = ctrl.update((0.0, 10.0, -0.1), (0.0, 9.0), 0.2, resist_mps2=0.02)
    assert_allclose(u, -0.1 + 0.02 + 0.5 / 4.0 * 1.0, rtol=1e-12)
    assert ctrl.components["stopping"] == 0.0  # no stop point: tracking only


def test_tracking_horizon_is_the_fast_paths_when_it_brakes():
    # with a fast path (fast_limit > 0) the gain is over sigma_track + tau_track = 0.5 s
    ctrl = PredictiveStop(1.5, 2.5, sigma_track=0.2, tau_track=0.3, fast_limit=0.3)
    u = ctrl.update((0.0, 10.0, 0.0), (0.0, 9.8), 0.1)
    assert_allclose(u, 0.5 / 0.5 * 0.2, rtol=1e-12)


def test_observer_converges_geometrically_on_a_plant_equal_to_its_model():
    # plant = the model (lag 1 s on u, trapezoid on the delivered acceleration, the
    # resistance r the ATO reports) plus a constant d. The observer's innovation is then
    # dt (d - d_hat), so d - d_hat shrinks by T_obs / (T_obs + dt) per update,
    # T_obs = observer_gain * (sigma + tau) = 2 s: d_hat_k = d (1 - rho^k)
    tau, dt, r, d = 1.0, 0.1, 0.03, 0.07
    ctrl = PredictiveStop(0.0, tau, observer_gain=2.0)
    rho = 2.0 / (2.0 + dt)
    decay = math.exp(-dt / tau)
    a, v = 0.0, 9.0
    estimates = []
    for k in range(60):
        u = ctrl.update((10.0 * k * dt, 10.0, 0.0), (0.0, v), dt, resist_mps2=r)
        estimates.append(ctrl.components["d_hat"])
        a_next = u + (a - u) * decay
        v += dt * (0.5 * (a + a_next) - r + d)
        a = a_next
    assert_allclose(estimates, d * (1.0 - rho ** np.arange(60)), rtol=1e-9, atol=1e-15)


# --- validation -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "name"),
    [
        ({"sigma": -1.0}, "sigma"),
        ({"tau": float("nan")}, "tau"),
        ({"sigma_track": -0.1}, "sigma_track"),
        ({"tau_track": float("inf")}, "tau_track"),
        ({"sigma_release": -2.0}, "sigma_release"),
        ({"tau_release": -2.0}, "tau_release"),
        ({"speed_gain": 0.0}, "speed_gain"),
        ({"speed_gain": -0.5}, "speed_gain"),
        ({"observer_gain": 0.0}, "observer_gain"),
        ({"d_max": -0.1}, "d_max"),
        ({"a_on": -0.01}, "a_on"),
        ({"stop_decel": -0.2}, "stop_decel"),
        ({"fast_limit": -0.3}, "fast_limit"),
        ({"fast_zero_mps": 6.0, "fast_full_mps": 5.0}, "fast_zero_mps"),
        ({"stop_m": float("inf")}, "stop_m"),
        ({"davis_mps2": (0.1, 0.0)}, "davis_mps2"),
        ({"davis_mps2": (0.1, float("nan"), 0.0)}, "davis_mps2"),
        ({"line_profile": ([0.0, 10.0, 10.0], [0.0, 0.1, 0.2])}, "line_profile"),
        ({"line_profile": ([0.0, 10.0, 5.0], [0.0, 0.1, 0.2])}, "line_profile"),
        ({"line_profile": ([0.0, 10.0], [0.0, 0.1, 0.2])}, "line_profile"),
        ({"line_profile": ([0.0], [0.1])}, "line_profile"),
        ({"line_profile": ([0.0, 10.0], [0.0, float("nan")])}, "line_profile"),
        ({"output_limits": (0.5, -0.5)}, "output_limits"),
    ],
)
def test_bad_parameters_name_themselves(change, name):
    kwargs = {"sigma": 4.0, "tau": 6.0, **change}
    with pytest.raises(ValueError, match=rf"^{name}\b"):
        PredictiveStop(**kwargs)


# --- interface --------------------------------------------------------------------------


def run_updates(ctrl):
    """A braking approach to 100 m, 40 updates of 0.2 s, the measurement a little fast."""
    out = []
    for k in range(40):
        t = 0.2 * k
        ref = (10.0 * t - 0.25 * t * t, 10.0 - 0.5 * t, -0.5)
        out.append(ctrl.update(ref, (ref[0] + 0.5, ref[1] + 0.2), 0.2, resist_mps2=0.02))
    return out


def test_reset_repeats_the_same_outputs():
    ctrl = PredictiveStop(2.0, 3.0, stop_m=100.0, output_limits=(-1.0, 1.0))
    first = run_updates(ctrl)
    assert ctrl.components["stopping"] == 1.0  # the run did get to the stop law
    ctrl.reset()
    assert math.isnan(ctrl.state[S_U_STOP])  # not evaluated
    np.testing.assert_array_equal(np.nan_to_num(ctrl.state, nan=0.0), np.zeros(N_STATE))
    assert run_updates(ctrl) == first


def test_update_is_the_kernel():
    ctrl = PredictiveStop(2.0, 3.0, stop_m=100.0, output_limits=(-1.0, 1.0))
    params, state = ctrl.params.copy(), ctrl.state.copy()
    for k in range(30):
        t = 0.2 * k
        args = (10.0 * t - 0.25 * t * t, 10.0 - 0.5 * t, -0.5, 10.0 * t + 0.3, 10.1 - 0.5 * t)
        u_obj = ctrl.update(args[:3], args[3:], 0.2, resist_mps2=0.02)
        assert u_obj == pstop_step(params, state, *args, 0.02, -math.inf, math.inf, 0.2)
    np.testing.assert_array_equal(ctrl.state, state)


def test_components_while_stopping():
    ctrl = PredictiveStop(2.0, 3.0, stop_m=100.0, output_limits=(-1.0, 1.0))
    run_updates(ctrl)
    comp = ctrl.components
    assert set(comp) == {"d_hat", "stopping", "u_track", "u_stop", "predicted_stop_m"}
    assert all(isinstance(value, float) for value in comp.values())
    assert comp["stopping"] == 1.0 and math.isfinite(comp["u_stop"])


def test_output_limits_clamp():
    # far too fast for the stop point 20 m ahead: all the braking the limits allow
    ctrl = PredictiveStop(2.0, 3.0, stop_m=20.0, output_limits=(-0.8, 0.5))
    assert ctrl.update((0.0, 15.0, -0.5), (0.0, 15.0), 0.2) == -0.8
    assert ctrl.output_limits == (-0.8, 0.5)


# --- registry and closed loop -----------------------------------------------------------


def test_registered_as_pstop():
    assert CONTROLLERS["pstop"].cls is PredictiveStop
    assert CONTROLLERS["pstop"].step is pstop_step  # the simulator runs the object's kernel


def test_simulator_tells_it_the_reference_stop_and_the_ato_brake_model():
    scenario = heavy_haul_scenario()
    ctrl = make_controller(scenario, "pstop")
    assert isinstance(ctrl, PredictiveStop)
    assert ctrl.params[P_STOP] == scenario.reference.stop_m
    # the ATO's brake model (4 s, 6 s) with half a 0.2 s control period on the delay
    assert_allclose(ctrl.params[[P_SIGMA, P_TAU]], (4.1, 6.0), rtol=1e-12)


@pytest.mark.slow
def test_heavy_haul_stop_within_2_m():
    # the heavy-haul target: 10,000 t, brake 4 s late with a 6 s lag
    error = simulate(heavy_haul_scenario(), "pstop").metrics["stop_error_m"]
    assert abs(error) <= 2.0


def test_metro_stop_within_0_30_m():
    # paper 002's stop on a real train, with pstop's one gain set
    error = simulate(realistic_scenario(), "pstop").metrics["stop_error_m"]
    assert abs(error) <= 0.30
