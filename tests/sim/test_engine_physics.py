"""The simulator's train integration (railpilot.sim.engine via sim.run) against physics.

Constant-force stop distance against v0^2 / (2 a) and coast-down
with Davis resistance against scipy's solve_ivp, within 0.5 %.

How the controller is taken out of the loop through the public API: a SMARC with
every gain 0 and no adaptation outputs ``theta1_hat a_ff - theta2_hat``. With
``theta0 = (1, 0)`` that is the reference acceleration (feed-forward only); with
``theta0 = (0, 0)`` it is 0 and the engine's clamp ``u <= 0`` (no traction) removes
the ATO's resistance feed-forward, so the train coasts with no brake at all.
"""

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import solve_ivp

from railpilot.brakes.ep_blend import EPBrake
from railpilot.control.smarc import SMARC
from railpilot.scenario.model import ATOModel, Scenario, SimSettings
from railpilot.sim.disturbance import Disturbance
from railpilot.sim.reference import constant_deceleration
from railpilot.sim.run import simulate
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.train import ElectricBrakeCurve, Train

G = 9.8
MASS, GAMMA = 536e3, 0.06  # paper 000 Table 1
M_EFF = MASS * (1 + GAMMA)


def open_loop_smarc(theta1):
    return SMARC(
        c=0.0,
        ks=0.0,
        alpha=0.0,
        eta=0.0,
        phi=0.05,
        gamma=(0.0, 0.0),
        theta_bounds=((0.0, 1.5), (-0.3, 0.3)),
        theta0=(theta1, 0.0),
    )


# an ideal brake: no delay, no lags, no jerk limit to speak of, no changeover fade
IDEAL_BRAKE = EPBrake(
    delay_s=0.0,
    air_lag_s=0.0,
    electric_lag_s=0.0,
    jerk_limit_mps3=1e6,
    changeover_kmh=0.0,
    prenotice_s=0.0,
)


def constant_force_scenario(by):
    """19.8 m/s at 1000 m; the ATO thinks the train is 20 % heavier than it is.

    The ATO demands 0.65 m/s^2 times its (wrong) effective mass, so the train
    really decelerates at a = 0.65 * 1.2 = 0.78 m/s^2 (not the reference's 0.65) and
    stops before the reference ends: the check is on the plant, not the feed-forward.
    ``by = "electric"``: an unlimited electric brake; ``"air"``: no electric brake and
    a shoe with constant friction (beta1 = 0 -> g(v) = 1).
    """
    if by == "electric":
        curve = ElectricBrakeCurve(max_force_n=1e9, max_power_w=1e12)
        brake = IDEAL_BRAKE
    else:
        curve = ElectricBrakeCurve(max_force_n=0.0, max_power_w=0.0)
        brake = dataclasses.replace(IDEAL_BRAKE, beta1=0.0)
    train = Train(
        mass_kg=MASS,
        rotating_mass_factor=GAMMA,
        davis_a0=0.0,
        davis_a1=0.0,
        davis_a2=0.0,
        max_service_decel_mps2=5.0,
        electric_brake=curve,
    )
    return Scenario(
        train=train,
        line=Line(),
        brake=brake,
        reference=constant_deceleration(19.8, 0.65, start_m=1000.0),
        disturbance=Disturbance(),
        ato=ATOModel(mass_kg=1.2 * MASS, brake_delay_s=0.0, brake_lag_s=0.0),
        sim=SimSettings(dt_s=0.01, duration_s=40.0, control_period_s=0.01),
    )


A_TRUE = 0.65 * 1.2  # = brake force (0.65 * 1.2 M_EFF) / M_EFF


def stop_run(by):
    return simulate(constant_force_scenario(by), open_loop_smarc(1.0))


@pytest.mark.parametrize("by", ["electric", "air"])
def test_constant_force_stop_distance_is_v0_squared_over_2a(by):
    # 19.8^2 / (2 * 0.78) = 251.3077 m past the braking point at 1000 m
    result = stop_run(by)
    assert result.meta["stopped"]
    stop_m = result.meta["stop_point_m"] + result.metrics["stop_error_m"]
    assert_allclose(stop_m - 1000.0, 19.8**2 / (2 * A_TRUE), rtol=1e-9)
    assert_allclose(result["position_m"][-1], stop_m, rtol=1e-12)


@pytest.mark.parametrize("by", ["electric", "air"])
def test_constant_force_stop_time_is_v0_over_a(by):
    # 19.8 / 0.78 = 25.3846 s (not a whole number of 10 ms steps: the stop is mid-step)
    assert_allclose(stop_run(by).metrics["stop_time_s"], 19.8 / A_TRUE, rtol=1e-9)


def test_constant_force_max_deceleration_metric():
    assert_allclose(stop_run("electric").metrics["max_decel_mps2"], A_TRUE, rtol=1e-12)


def test_constant_force_stop_error_is_against_the_reference_stop_point():
    # reference stops at 1000 + 19.8^2 / 1.3 = 1301.569 m, the train at 1251.308 m
    result = stop_run("electric")
    assert_allclose(result.meta["stop_point_m"], 1000.0 + 19.8**2 / 1.3, rtol=1e-14)
    assert_allclose(
        result.metrics["stop_error_m"], 19.8**2 / (2 * A_TRUE) - 19.8**2 / 1.3, rtol=1e-9
    )


@pytest.mark.parametrize(
    ("by", "metric", "other"),
    [
        ("electric", "energy_electric_j", "energy_friction_j"),
        ("air", "energy_friction_j", "energy_electric_j"),
    ],
)
def test_brake_energy_is_force_times_distance(by, metric, other):
    # W = F d = (0.78 M_EFF) (v0^2 / (2 * 0.78)) = M_EFF v0^2 / 2: all kinetic energy
    result = stop_run(by)
    assert_allclose(result.metrics[metric], M_EFF * 19.8**2 / 2, rtol=1e-9)
    assert result.metrics[other] == 0.0
    # braking alone: no traction pulled against the brake
    assert result.metrics["energy_traction_against_air_j"] == 0.0


# --- coast-down --------------------------------------------------------------------
DAVIS = (0.42, 0.0016, 0.000132)  # paper 000 Table 1 [N/kN], v in km/h


def coast_scenario(line, disturbance):
    train = Train(
        mass_kg=MASS,
        rotating_mass_factor=GAMMA,
        davis_a0=DAVIS[0],
        davis_a1=DAVIS[1],
        davis_a2=DAVIS[2],
    )
    # one step past 60 s so the recorder has a row at t = 60 s
    return Scenario(
        train=train,
        line=line,
        brake=EPBrake(),
        reference=constant_deceleration(25.0, 0.1, start_m=0.0),
        disturbance=disturbance,
        sim=SimSettings(dt_s=0.01, duration_s=60.02, control_period_s=0.01),
    )


def coast_at_60_s(line, dist):
    """(position, speed) the simulator records at t = 60 s, and whether it stopped."""
    result = simulate(coast_scenario(line, dist), open_loop_smarc(0.0))
    row = int(np.flatnonzero(np.isclose(result["time_s"], 60.0))[0])
    return result["position_m"][row], result["speed_mps"][row], result


def coast_ivp(extra_n_per_kn, push_n):
    """solve_ivp of m (1 + gamma) dv/dt = -(w_davis(v) + w_line) m g / 1000 + D."""

    def rhs(_t, y):
        v_kmh = y[1] * 3.6
        w = DAVIS[0] + DAVIS[1] * v_kmh + DAVIS[2] * v_kmh**2 + extra_n_per_kn
        return [y[1], (push_n - w * MASS * G / 1000.0) / M_EFF]

    sol = solve_ivp(rhs, (0.0, 60.0), [0.0, 25.0], method="DOP853", rtol=1e-11, atol=1e-11)
    return sol.y[0, -1], sol.y[1, -1]


COAST_CASES = [
    # (line, disturbance, extra specific resistance [N/kN], push [N])
    pytest.param(Line(), Disturbance(), 0.0, 0.0, id="level"),
    pytest.param(
        Line(gradients=(Segment(-1000.0, 5000.0, 10.0),)),  # under the whole train
        Disturbance(),
        10.0,
        0.0,
        id="10-permille-uphill",
    ),
    pytest.param(
        Line(curves=(Segment(-1000.0, 5000.0, 300.0),)), Disturbance(), 2.0, 0.0, id="300-m-curve"
    ),
    pytest.param(Line(), Disturbance(constant_n=-30e3), 0.0, -30e3, id="head-wind"),
]


@pytest.mark.parametrize(("line", "dist", "extra", "push"), COAST_CASES)
def test_coast_down_speed_after_60_s_matches_solve_ivp(line, dist, extra, push):
    _, v, result = coast_at_60_s(line, dist)
    _, v_ref = coast_ivp(extra, push)
    assert not result.meta["stopped"]
    assert_allclose(v, v_ref, rtol=5e-3)
    # the speed *lost* agrees too (a much stricter check than the speed itself)
    assert_allclose(25.0 - v, 25.0 - v_ref, rtol=5e-3)


@pytest.mark.parametrize(("line", "dist", "extra", "push"), COAST_CASES)
def test_coast_down_distance_after_60_s_matches_solve_ivp(line, dist, extra, push):
    x, _, _ = coast_at_60_s(line, dist)
    x_ref, _ = coast_ivp(extra, push)
    assert_allclose(x, x_ref, rtol=5e-3)


def test_coast_down_uses_no_brake():
    _, _, result = coast_at_60_s(Line(), Disturbance())
    assert result.metrics["energy_electric_j"] == 0.0
    assert result.metrics["energy_friction_j"] == 0.0
    assert np.all(result["electric_n"] == 0.0)
    assert np.all(result["air_n"] == 0.0)
