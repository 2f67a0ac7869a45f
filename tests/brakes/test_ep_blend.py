"""EP blended brake (railpilot.brakes.ep_blend), paper 000 section 1.1.

Each test drives the kernel ``ep_brake_step`` through ``EPBrake.pack`` with a
held demand and speed, so only the brake is under test (no train, no controller).
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.brakes import ep_blend
from railpilot.brakes.ep_blend import EPBrake, ep_brake_step
from railpilot.brakes.friction import friction_ratio
from railpilot.errors import ConfigError

DT = 0.01
M_EFF = 536e3 * 1.06  # paper 000 train, effective mass [kg]
F_MAX, P_MAX = 380e3, 4.8e6  # default electric envelope [N], [W]


def run_brake(brake, demand, speed, n, cars=4, f_max=F_MAX, p_max=P_MAX, state=None, t0=0.0):
    """Step the brake ``n`` times; return arrays (electric, air, commanded demand) and state."""
    p = brake.pack_arrays(DT, M_EFF, f_max, p_max, cars)
    if state is None:
        state = (np.zeros(ep_blend.N_STATE), np.zeros(int(p[ep_blend.P_BUF_LEN])))
    s, buf = state
    out = np.zeros((n, 3))
    for k in range(n):
        speed_k = speed(k) if callable(speed) else speed
        demand_k = demand(k) if callable(demand) else demand
        e, a = ep_brake_step(p, s, buf, demand_k, speed_k, t0 + k * DT, DT)
        out[k] = e, a, s[ep_blend.S_FCMD]
    return out[:, 0], out[:, 1], out[:, 2], (s, buf)


def test_small_demand_is_all_electric_in_steady_state():
    # 15 m/s: E_max = min(380 kN, 4.8 MW / 15 m/s = 320 kN) > 200 kN demand
    e, air, _, _ = run_brake(EPBrake(), 200e3, 15.0, 2000)
    assert_allclose(e[-1], 200e3, rtol=1e-9)
    assert_allclose(air[-1], 0.0, atol=1e-6)


def test_large_demand_is_electric_up_to_limit_and_air_the_rest():
    # 500 kN at 15 m/s: electric 320 kN (power limit), air command 180 kN times g(54 km/h)
    e, air, _, _ = run_brake(EPBrake(), 500e3, 15.0, 2000)
    assert_allclose(e[-1], 320e3, rtol=1e-9)
    assert_allclose(air[-1], 180e3 * friction_ratio(54.0), rtol=1e-9)


def test_air_force_is_command_times_friction_ratio_at_low_speed():
    # no electric (0 kN envelope): all 100 kN by air; shoe gives g(v) times the command
    e, air, _, _ = run_brake(EPBrake(), 100e3, 3.0, 2000, f_max=0.0, p_max=0.0)
    assert_allclose(e[-1], 0.0, atol=1e-9)
    assert_allclose(air[-1], 100e3 * friction_ratio(10.8), rtol=1e-9)


def test_air_force_at_standstill_uses_g0():
    _, air, _, _ = run_brake(EPBrake(), 100e3, 0.0, 2000, f_max=0.0, p_max=0.0)
    assert_allclose(air[-1], 100e3 * 0.359 / 0.221, rtol=1e-9)


def test_delay_is_exactly_delay_s():
    # no lags, no jerk limit to speak of: nothing happens for 30 steps, then all at once
    brake = EPBrake(delay_s=0.3, air_lag_s=0.0, electric_lag_s=0.0, jerk_limit_mps3=1e6)
    e, _, _, _ = run_brake(brake, 100e3, 15.0, 40)
    assert np.all(e[:30] == 0.0)
    assert_allclose(e[30:], 100e3, rtol=1e-12)


def test_jerk_limit_bounds_rate_of_demand():
    # 0.75 m/s^3 on M_EFF: the commanded force ramps at 0.75 * M_EFF N/s
    brake = EPBrake(delay_s=0.0, jerk_limit_mps3=0.75)
    _, _, f_cmd, _ = run_brake(brake, 300e3, 15.0, 200)
    rate = np.diff(f_cmd) / DT
    assert rate.max() == pytest.approx(0.75 * M_EFF, rel=1e-9)
    assert_allclose(f_cmd[-1], 300e3)


def test_jerk_limited_ramp_reaches_demand_at_predicted_time():
    # 300 kN at 0.75 * 568.16e3 N/s = 426.12 kN/s -> 0.704 s -> reached in step 70
    brake = EPBrake(delay_s=0.0, jerk_limit_mps3=0.75)
    _, _, f_cmd, _ = run_brake(brake, 300e3, 15.0, 100)
    first = int(np.argmax(f_cmd >= 300e3))
    assert first == int(np.ceil(300e3 / (0.75 * M_EFF * DT))) - 1


def test_cutout_of_one_of_four_cars_removes_a_quarter_of_electric_at_once():
    # demand above the envelope so electric sits at its limit (320 kN at 15 m/s)
    brake = EPBrake(cutout_cars=1, cutout_time_s=10.0)
    e, _, _, _ = run_brake(brake, 600e3, 15.0, 1100)
    k_cut = 1000  # t = 10.0 s
    assert_allclose(e[k_cut - 1], 320e3, rtol=1e-9)
    assert_allclose(e[k_cut], 0.75 * 320e3, rtol=1e-12)


def test_air_takes_over_after_cutout():
    brake = EPBrake(cutout_cars=1, cutout_time_s=10.0)
    e, air, _, _ = run_brake(brake, 300e3, 15.0, 3000)
    # before: all electric; after: electric 240 kN, air 60 kN times g(54 km/h)
    assert_allclose(e[999], 300e3, rtol=1e-9)
    assert_allclose(e[-1], 240e3, rtol=1e-9)
    assert_allclose(air[-1], 60e3 * friction_ratio(54.0), rtol=1e-6)


def test_fade_below_changeover_reduces_electric_at_fade_rate():
    brake = EPBrake()
    # settle all-electric at 3 m/s, then drop below 6 km/h (1.667 m/s) at t = 20 s
    e0, _, _, state = run_brake(brake, 200e3, 3.0, 2000)
    assert_allclose(e0[-1], 200e3, rtol=1e-9)
    e, _, _, _ = run_brake(brake, 200e3, 1.0, 300, state=state, t0=20.0)
    # prenotice 0.65 s: envelope flat for 65 steps, then falls at 300 kN/s
    assert_allclose(e[:65], 200e3, rtol=1e-9)
    slope = np.diff(e[80:120]) / DT
    assert_allclose(slope, -300e3, rtol=1e-6)
    # 200 kN at 300 kN/s: gone 0.667 s after the pre-notice time
    assert_allclose(e[65 + 67 + 1 :], 0.0, atol=1e-6)


def test_air_takes_over_the_whole_demand_after_fade():
    brake = EPBrake()
    _, _, _, state = run_brake(brake, 200e3, 3.0, 2000)
    e, air, _, _ = run_brake(brake, 200e3, 1.0, 2000, state=state, t0=20.0)
    assert e[-1] == 0.0
    assert_allclose(air[-1], 200e3 * friction_ratio(3.6), rtol=1e-6)


def test_air_ramps_in_while_electric_fades():
    brake = EPBrake()
    _, _, _, state = run_brake(brake, 200e3, 3.0, 2000)
    _, air, _, _ = run_brake(brake, 200e3, 1.0, 200, state=state, t0=20.0)
    assert air[0] < air[60] < air[120]


def test_non_integer_delay_raises_config_error():
    with pytest.raises(ConfigError) as info:
        EPBrake(delay_s=0.305).pack_arrays(DT, M_EFF, F_MAX, P_MAX, 4)
    assert info.value.field == "brake.delay_s"


def test_cutout_of_more_cars_than_motor_cars_raises():
    with pytest.raises(ConfigError) as info:
        EPBrake(cutout_cars=5).pack_arrays(DT, M_EFF, F_MAX, P_MAX, 4)
    assert info.value.field == "brake.cutout_cars"


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("air_lag_s", -0.1),
        ("delay_s", np.nan),
        ("jerk_limit_mps3", 0.0),
        ("fade_rate_n_per_s", -1.0),
        ("beta3", 0.0),
        ("cutout_cars", -1),
    ],
)
def test_bad_parameter_raises_config_error_naming_it(name, value):
    with pytest.raises(ConfigError) as info:
        EPBrake(**{name: value})
    assert info.value.field == f"brake.{name}"


# --- speeding back above the changeover speed -------------------------
#
# A train that falls below the changeover speed and then speeds back up (a down-grade)
# must get its electric brake back as a ramp, and the next fall must be a new fade with
# its pre-notice, never a cut: the fade state used to stay set, so the second fall found
# an envelope that had run out long ago and dropped ~200 kN in one 10 ms step.

CO = 6.0 / 3.6  # changeover [m/s]
#: speed [m/s] against time [s] from t0: below changeover, back above, below again
SPEED_BACK_UP = {
    # fully faded before the speed rises again
    "after the fade": [(0.0, 2.5), (4.0, 1.3), (8.0, 2.3), (16.0, 0.0)],
    # rises in the middle of the fade-out
    "during the fade": [(0.0, 2.5), (3.5, 1.5), (5.0, 2.3), (14.0, 0.0)],
    # rises again during the pre-notice, before traction began to fade
    "during the pre-notice": [(0.0, 2.5), (3.0, 1.6), (3.3, 2.0), (12.0, 0.0)],
}


def speed_profile(points):
    times, speeds = zip(*points, strict=True)
    return lambda k: float(np.interp(k * DT, times, speeds))


def settled_all_electric(brake, demand=200e3):
    """The brake state after 20 s all-electric at 2.5 m/s (above changeover)."""
    e, _, _, state = run_brake(brake, demand, 2.5, 2000)
    assert_allclose(e[-1], demand, rtol=1e-9)
    return state


@pytest.mark.parametrize("case", SPEED_BACK_UP)
def test_brake_force_jerk_stays_within_the_jerk_limit_when_speed_returns(case):
    # held demand: whatever the changeover does, |d(E + A g)/dt| / m_eff <= jerk limit
    brake = EPBrake()
    state = settled_all_electric(brake)
    speed = speed_profile(SPEED_BACK_UP[case])
    e, air, _, _ = run_brake(brake, 200e3, speed, 1800, state=state, t0=20.0)
    jerk = np.abs(np.diff(e + air)) / DT / M_EFF
    assert jerk.max() <= brake.jerk_limit_mps3
    # and the electric brake itself never moves faster than the fade rate
    assert np.abs(np.diff(e)).max() / DT <= brake.fade_rate_n_per_s * (1 + 1e-9)
    assert e[-1] == 0.0  # faded out for good at the stop


def test_electric_brake_returns_as_a_ramp_at_the_fade_rate():
    brake = EPBrake()
    state = settled_all_electric(brake)
    speed = speed_profile(SPEED_BACK_UP["after the fade"])
    e, _, _, (s, _) = run_brake(brake, 200e3, speed, 1000, state=state, t0=20.0)
    # below from 2.78 s: pre-notice to 3.43 s, 200 kN at 300 kN/s gone by 4.1 s
    k_up = int(np.argmax([speed(k) > CO for k in range(300, 1000)])) + 300
    assert np.all(e[420:k_up] == 0.0)  # faded out while below
    rise = np.diff(e[k_up:]) / DT
    assert rise.max() <= brake.fade_rate_n_per_s * (1 + 1e-9)
    assert_allclose(e[-1], 200e3, rtol=1e-5)  # all of it back (behind the 0.3 s lag)
    assert s[ep_blend.S_PHASE] == ep_blend.PHASE_NORMAL


def test_second_fall_below_changeover_is_a_new_fade_with_its_prenotice():
    brake = EPBrake()
    state = settled_all_electric(brake)
    points = SPEED_BACK_UP["after the fade"]
    speed = speed_profile(points)
    e, _, _, _ = run_brake(brake, 200e3, speed, 1400, state=state, t0=20.0)
    k_down = int(np.argmax([speed(k) <= CO for k in range(900, 1400)])) + 900
    assert_allclose(e[k_down - 1], 200e3, rtol=1e-6)
    # pre-notice: traction holds the electric brake for 0.65 s ...
    assert_allclose(e[k_down : k_down + 65], e[k_down - 1], rtol=1e-9)
    # ... then fades it at 300 kN/s, never in one step
    slope = np.diff(e[k_down + 70 : k_down + 120]) / DT
    assert_allclose(slope, -brake.fade_rate_n_per_s, rtol=1e-6)


def test_air_is_released_only_as_electric_returns():
    # above changeover again, the air command never drops below demand - electric
    brake = EPBrake(air_lag_s=0.0)  # air = command * g, so the command is visible
    state = settled_all_electric(brake)
    speed = speed_profile(SPEED_BACK_UP["after the fade"])
    e, air, _, _ = run_brake(brake, 200e3, speed, 900, state=state, t0=20.0)
    ratio = np.array([friction_ratio(speed(k) * 3.6) for k in range(900)])
    assert np.all(air / ratio >= 200e3 - e - 1e-6)
