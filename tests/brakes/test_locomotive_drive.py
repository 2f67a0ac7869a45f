"""Locomotive drive of a heavy-haul train (railpilot.brakes.locomotive_drive).

Each test drives the compiled step ``locomotive_drive_ato_step`` through
``LocomotiveDrive.pack`` with a held or scripted command at a held speed, so only the
actuator is under test (no train motion, no controller). Cross-checks: the electric force
against the closed-form first-order response (the kernel is exact at the end of each
step), the envelopes against the HXD1's published numbers, and the air part against the
brake pipe's own closed form (brakes/brake_pipe.py, ``train_force_fraction``).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from railpilot.brakes import locomotive_drive as ld
from railpilot.brakes.base import BrakeModel, PackContext
from railpilot.brakes.brake_pipe import BrakePipeBrake, train_force_fraction
from railpilot.brakes.locomotive_drive import (
    LocomotiveDrive,
    electric_step_response_n,
    locomotive_drive_ato_step,
)
from railpilot.errors import ConfigError
from railpilot.units import kmh_to_mps
from railpilot.vehicle.traction import (
    HXD1_MAX_REGEN_FORCE_N,
    HXD1_MAX_TRACTIVE_FORCE_N,
    HXD1_POWER_W,
    HXD1_REGEN_POWER_W,
    hxd1_locomotive,
    traction_force_max,
)
from railpilot.vehicle.train import Train

DT = 0.01
LAG = 1.0
# 10,000 t of wagons and the 200 t HXD1
TRAIN = Train(mass_kg=10_000e3 + 200e3, length_m=1600.0, rotating_mass_factor=0.06)
M_EFF = TRAIN.effective_mass_kg
CONTEXT = PackContext(dt_s=DT, load_weighed_eff_mass_kg=M_EFF, train=TRAIN)
DRIVE = LocomotiveDrive(traction_lag_s=LAG)
#: steps to the air brake's steady state: 2,500 s, the rear group (dead time 26 s, lag
#: 58 s with the pipe) within exp(-2474 / 58) = 3e-19 of its target
STEADY = 250_000


def run(drive, commands, speed_mps, m_eff_lw=M_EFF, state=None, context=CONTEXT):
    """Step the drive over ``commands`` [m/s^2] at a held speed.

    Returns (electric [N], air [N], demand [N], (state, buffer)), each force at the end of
    each step.
    """
    p = drive.pack(context)
    if state is None:
        n_state, n_buffer = drive.sizes(p)
        state = (np.zeros(n_state), np.zeros(n_buffer))
    s, buf = state
    n = len(commands)
    out = np.zeros((n, 3))
    speeds = np.broadcast_to(np.asarray(speed_mps, dtype=float), (n,))
    for k in range(n):
        out[k] = locomotive_drive_ato_step(
            p, s, buf, commands[k], speeds[k], k * context.dt_s, context.dt_s, m_eff_lw, M_EFF
        )
    return out[:, 0], out[:, 1], out[:, 2], (s, buf)


def end_of_steps(n, dt=DT):
    """Times [s] at the end of each of ``n`` steps (where the kernel reports)."""
    return np.arange(1, n + 1) * dt


# --- the brake-model interface --------------------------------------------------------------


def test_is_a_brake_model_of_the_interface():
    drive: BrakeModel = LocomotiveDrive()
    assert drive.name == "locomotive-drive"
    assert drive.changeover_kmh == 0.0
    p = drive.pack(CONTEXT)
    air = BrakePipeBrake()
    n_state, n_buffer = drive.sizes(p)
    air_state, air_buffer = air.sizes(air.pack(CONTEXT))
    assert (n_state, n_buffer) == (1 + air_state, air_buffer)
    assert n_state == 1 + 1 + 40


def test_params_are_own_floats_then_the_air_brakes_packed_with_the_same_context():
    drive = LocomotiveDrive(traction_lag_s=0.8)
    p = drive.pack(CONTEXT)
    assert_allclose(p[ld.P_AIR0 :], BrakePipeBrake().pack(CONTEXT), rtol=0, atol=0)
    assert p[ld.P_ALPHA] == pytest.approx(np.exp(-DT / 0.8), rel=1e-15)
    assert p[ld.P_T_F0] == HXD1_MAX_TRACTIVE_FORCE_N == 760e3
    assert p[ld.P_T_POWER] == HXD1_POWER_W
    assert p[ld.P_T_VMAX] == pytest.approx(120.0 / 3.6)
    assert p[ld.P_R_F0] == HXD1_MAX_REGEN_FORCE_N == 461e3
    assert p[ld.P_R_POWER] == HXD1_REGEN_POWER_W
    assert p[ld.P_R_FADE] == pytest.approx(10.0 / 3.6)
    assert p[ld.P_REGEN_ON] == 1.0


def test_lead_is_the_air_brakes_the_slow_path():
    air = BrakePipeBrake(reaction_s=0.5)
    drive = LocomotiveDrive(air=air)
    assert drive.lead_s == air.lead_s
    assert drive.train_lead_s(1600.0) == air.train_lead_s(1600.0)
    assert drive.lead_s[1] > 5 * drive.traction_lag_s


def test_max_traction_accel_is_starting_effort_over_effective_mass():
    # 760 kN / (10,200 t * 1.06) = 0.07029 m/s^2
    assert DRIVE.max_traction_accel_mps2(TRAIN) == pytest.approx(760e3 / (10_200e3 * 1.06))
    assert DRIVE.max_traction_accel_mps2(TRAIN) == pytest.approx(0.0702923, abs=1e-7)


def test_default_locomotive_is_the_hxd1():
    assert LocomotiveDrive().locomotive == hxd1_locomotive()
    assert LocomotiveDrive().traction_lag_s == ld.TRACTION_LAG_S == 1.0


# --- traction -------------------------------------------------------------------------------


def test_held_traction_below_the_envelope_follows_the_first_order_lag_negative():
    # at 10 m/s the envelope is min(760 kN, 9.6 MW / 10 m/s) = 760 kN; 0.03 m/s^2 asks
    # 0.03 * 10,812 t = 324.36 kN, below it
    n = 1000
    u = 0.03
    demand = u * M_EFF
    assert demand < float(traction_force_max(10.0, 760e3, 9.6e6, 120 / 3.6))
    electric, air, reported, _ = run(DRIVE, np.full(n, u), 10.0)
    t = end_of_steps(n)
    assert_allclose(electric, -demand * (1.0 - np.exp(-t / LAG)), rtol=1e-12, atol=1e-6)
    assert_allclose(electric, electric_step_response_n(t, -demand, LAG), rtol=1e-12, atol=1e-6)
    assert np.all(electric < 0.0)  # propulsive
    assert np.all(air == 0.0)
    assert_allclose(reported, -demand, rtol=1e-15)


def test_held_traction_above_the_envelope_tends_to_the_envelope():
    # at 20 m/s the envelope is 9.6 MW / 20 m/s = 480 kN; 0.06 m/s^2 asks 648.7 kN
    v = 20.0
    envelope = float(traction_force_max(v, 760e3, 9.6e6, 120 / 3.6))
    assert envelope == pytest.approx(480e3)
    u = 0.06
    assert u * M_EFF > envelope
    n = 3000
    electric, air, _, _ = run(DRIVE, np.full(n, u), v)
    assert_allclose(electric, -envelope * (1.0 - np.exp(-end_of_steps(n) / LAG)), rtol=1e-12)
    assert electric[-1] == pytest.approx(-envelope, rel=1e-12)
    assert np.all(-electric <= envelope)
    assert np.all(air == 0.0)


def test_traction_is_cut_above_the_maximum_speed():
    electric, _, _, _ = run(DRIVE, np.full(100, 0.05), kmh_to_mps(121.0))
    assert np.all(electric == 0.0)


def test_traction_relaxes_to_zero_with_its_lag_at_a_zero_command():
    n = 2000
    electric, _, _, state = run(DRIVE, np.full(n, 0.03), 10.0)
    e0 = electric[-1]
    electric, air, reported, _ = run(DRIVE, np.zeros(n), 10.0, state=state)
    assert_allclose(electric, e0 * np.exp(-end_of_steps(n) / LAG), rtol=1e-12, atol=1e-9)
    assert np.all(air == 0.0)
    assert np.all(reported == 0.0)


# --- braking --------------------------------------------------------------------------------


def test_braking_within_the_regen_envelope_is_all_regeneration():
    # at 20 m/s the regen envelope is min(461 kN, 9.6 MW / 20 m/s) = 461 kN; 0.03 m/s^2
    # brakes with 324.36 kN, within it
    n = 3000
    u = -0.03
    braking = -u * M_EFF
    assert braking < 461e3
    electric, air, reported, (s, buf) = run(DRIVE, np.full(n, u), 20.0)
    t = end_of_steps(n)
    assert_allclose(electric, braking * (1.0 - np.exp(-t / LAG)), rtol=1e-12)
    # the brake pipe was commanded 0 throughout: no history, no cylinder
    assert np.all(air == 0.0)
    assert np.all(buf == 0.0)
    assert np.all(s[ld.ST_AIR0 + 1 :] == 0.0)
    assert_allclose(reported, braking, rtol=1e-15)


@pytest.mark.slow
def test_braking_above_the_regen_envelope_blends_in_the_air_brake():
    # 0.1 m/s^2 brakes with 1,081.2 kN; regen gives its 461 kN, the brake pipe the other
    # 620.2 kN (a command of 0.0574 m/s^2 of its 0.5 m/s^2), building up along the train
    n = STEADY
    u = -0.1
    braking = -u * M_EFF
    electric, air, reported, _ = run(DRIVE, np.full(n, u), 20.0)
    t = end_of_steps(n)
    rest = braking - 461e3
    assert_allclose(electric, 461e3 * (1.0 - np.exp(-t / LAG)), rtol=1e-12)
    # the brake pipe is linear in its command: the rest times its unit step response
    expected_air = rest * train_force_fraction(BrakePipeBrake(), t, 1600.0)
    assert_allclose(air, expected_air, rtol=1e-9, atol=1e-6)
    # steady state
    assert electric[-1] == pytest.approx(461e3, rel=1e-12)
    assert air[-1] == pytest.approx(rest, rel=1e-8)
    assert electric[-1] + air[-1] == pytest.approx(braking, rel=1e-8)
    assert_allclose(reported, braking, rtol=1e-15)
    e_ss, a_ss = DRIVE.steady_forces_n(u, 20.0, M_EFF, M_EFF)
    assert (float(e_ss), float(a_ss)) == (pytest.approx(461e3), pytest.approx(rest))


def test_air_part_carries_the_load_weighing_error():
    # the brake manager weighs 5 % light: the ATO's demand and the brake-pipe command are
    # computed with m_eff,lw, the brake pipe acts on the true mass
    m_lw = 0.95 * M_EFF
    n = STEADY
    u = -0.1
    electric, air, reported, _ = run(DRIVE, np.full(n, u), 20.0, m_eff_lw=m_lw)
    braking = -u * m_lw
    assert reported[-1] == pytest.approx(braking)
    assert electric[-1] == pytest.approx(461e3, rel=1e-12)
    assert air[-1] == pytest.approx((braking - 461e3) * M_EFF / m_lw, rel=1e-8)
    e_ss, a_ss = DRIVE.steady_forces_n(u, 20.0, m_lw, M_EFF)
    assert float(e_ss) == pytest.approx(461e3)
    assert float(a_ss) == pytest.approx(air[-1], rel=1e-8)


def test_air_saturates_at_full_service():
    # 1.0 m/s^2 asks 10.8 MN: regen 461 kN, air at most 0.5 m/s^2 * 10,812 t = 5.41 MN
    e_ss, a_ss = DRIVE.steady_forces_n(-1.0, 20.0, M_EFF, M_EFF)
    assert float(a_ss) == pytest.approx(0.5 * M_EFF)
    electric, air, _, _ = run(DRIVE, np.full(STEADY, -1.0), 20.0)
    assert air[-1] == pytest.approx(0.5 * M_EFF, rel=1e-8)
    assert electric[-1] == pytest.approx(float(e_ss), rel=1e-12)


def test_regen_fades_below_its_fade_speed():
    # at 5 km/h with the HXD1's 10 km/h fade: half of 461 kN
    n = 3000
    u = -0.1
    electric, _, _, _ = run(DRIVE, np.full(n, u), kmh_to_mps(5.0))
    assert electric[-1] == pytest.approx(461e3 / 2.0, rel=1e-12)
    assert np.all(electric <= 461e3 / 2.0)
    e_ss, a_ss = DRIVE.steady_forces_n(u, kmh_to_mps(5.0), M_EFF, M_EFF)
    assert float(e_ss) == pytest.approx(230.5e3)
    assert float(a_ss) == pytest.approx(-u * M_EFF - 230.5e3)
    # and at standstill nothing: the air brake holds the train
    electric, _, _, _ = run(DRIVE, np.full(100, u), 0.0)
    assert np.all(electric == 0.0)


def test_without_regeneration_the_air_brake_takes_every_demand():
    drive = LocomotiveDrive(regen_enabled=False)
    assert drive.pack(CONTEXT)[ld.P_REGEN_ON] == 0.0
    n = 12_000
    electric, air, _, _ = run(drive, np.full(n, -0.03), 20.0)
    assert np.all(electric == 0.0)
    expected = 0.03 * M_EFF * train_force_fraction(BrakePipeBrake(), end_of_steps(n), 1600.0)
    assert_allclose(air, expected, rtol=1e-9, atol=1e-6)


def test_falling_envelope_clips_the_delivered_force():
    # regenerating 400 kN at 20 m/s, then at 5 km/h the envelope is 230.5 kN: the force is
    # clipped at once, never above the envelope at the current speed
    n = 2000
    _, _, _, state = run(DRIVE, np.full(n, -0.1), 20.0)
    electric, _, _, _ = run(DRIVE, np.full(10, -0.1), kmh_to_mps(5.0), state=state)
    assert_allclose(electric, 230.5e3, rtol=1e-12)


# --- switching ------------------------------------------------------------------------------


def test_switching_from_traction_to_braking_has_no_jump_in_the_electric_force():
    # 10 s of 0.04 m/s^2 traction, then 10 s of 0.03 m/s^2 braking, at 15 m/s
    v = 15.0
    n = 1000
    commands = np.concatenate((np.full(n, 0.04), np.full(n, -0.03)))
    electric, _, _, _ = run(DRIVE, commands, v)
    e_switch = electric[n - 1]
    assert e_switch == pytest.approx(-0.04 * M_EFF * (1.0 - np.exp(-10.0)), rel=1e-12)
    # after the switch: the same lag from where the force was, through zero
    target = 0.03 * M_EFF
    expected = electric_step_response_n(end_of_steps(n), target, LAG, e_switch)
    assert_allclose(electric[n:], expected, rtol=1e-12, atol=1e-6)
    # continuous: each step moves by at most (1 - exp(-dt/T)) of the distance to the target
    steps = np.abs(np.diff(np.concatenate(([0.0], electric))))
    bound = (1.0 - np.exp(-DT / LAG)) * (0.04 * M_EFF + target)
    assert steps.max() <= bound * (1.0 + 1e-12)
    # the first braking step: from where traction was, not from zero or from the target
    assert steps[n] == pytest.approx((1.0 - np.exp(-DT / LAG)) * (target - e_switch), rel=1e-9)
    # one force: traction, then regeneration, changing sign once
    assert np.count_nonzero(np.diff(np.sign(electric)) != 0) == 1


@settings(max_examples=40, deadline=None)
@given(
    commands=st.lists(st.floats(-0.6, 0.1), min_size=1, max_size=60),
    speeds=st.lists(st.floats(0.0, 40.0), min_size=1, max_size=60),
)
def test_electric_force_never_exceeds_the_envelope_at_the_current_speed(commands, speeds):
    loco = hxd1_locomotive()
    n = min(len(commands), len(speeds))
    # each command held 2 s, with its own speed
    u = np.repeat(commands[:n], 200)
    v = np.repeat(speeds[:n], 200)
    electric, air, _, _ = run(DRIVE, u, v)
    traction = loco.traction.max_force(v)
    regen = loco.regen.max_force(v)
    assert np.all(electric >= -traction)
    assert np.all(electric <= regen)
    assert np.all(air >= 0.0)


# --- validation -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"traction_lag_s": -1.0}, "brake.traction_lag_s"),
        ({"traction_lag_s": float("nan")}, "brake.traction_lag_s"),
        ({"traction_lag_s": 61.0}, "brake.traction_lag_s"),
        ({"traction_lag_s": True}, "brake.traction_lag_s"),
        ({"locomotive": "HXD1"}, "brake.locomotive"),
        ({"air": "brake-pipe"}, "brake.air"),
        ({"regen_enabled": "yes"}, "brake.regen_enabled"),
    ],
)
def test_bad_configuration_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        LocomotiveDrive(**kwargs)
    assert err.value.field == field


def test_zero_lag_is_immediate():
    drive = LocomotiveDrive(traction_lag_s=0.0)
    electric, _, _, _ = run(drive, np.full(5, 0.03), 10.0)
    assert_allclose(electric, -0.03 * M_EFF, rtol=1e-15)


def test_pack_rejects_a_bad_step_and_a_train_lighter_than_its_locomotive():
    with pytest.raises(ConfigError) as err:
        DRIVE.pack(PackContext(dt_s=0.0, load_weighed_eff_mass_kg=M_EFF, train=TRAIN))
    assert err.value.field == "sim.dt_s"
    light = Train(mass_kg=150e3, length_m=1600.0)
    with pytest.raises(ConfigError) as err:
        DRIVE.pack(PackContext(dt_s=DT, load_weighed_eff_mass_kg=M_EFF, train=light))
    assert err.value.field == "train.mass_kg"


def test_sizes_rejects_params_that_are_not_a_drives():
    p = DRIVE.pack(CONTEXT)
    with pytest.raises(ConfigError) as err:
        DRIVE.sizes(p[: ld.P_AIR0])
    assert err.value.field == "brake.params"
    with pytest.raises(ConfigError) as err:
        DRIVE.sizes(np.zeros((2, 20)))
    assert err.value.field == "brake.params"
    bad = p.copy()
    bad[ld.P_ALPHA] = 1.5
    with pytest.raises(ConfigError) as err:
        DRIVE.sizes(bad)
    assert err.value.field == "brake.params"
    with pytest.raises(ConfigError) as err:
        DRIVE.sizes(p[:-3])  # the air brake's part cut short
    assert err.value.field == "brake.air.params"


# --- the brake manager's handover from regeneration to air ---------------------------------


def test_handover_share_falls_linearly_from_the_handover_to_the_fade_speed():
    from railpilot.brakes.locomotive_drive import handover_share

    fade, handover = kmh_to_mps(10.0), kmh_to_mps(50.0)
    v = kmh_to_mps(np.array([0.0, 5.0, 10.0, 20.0, 30.0, 50.0, 80.0]))
    assert_allclose(handover_share(v, handover, fade), [0, 0, 0, 0.25, 0.5, 1, 1], atol=1e-12)
    # no handover (0, or not above the fade speed): always the whole share
    assert_allclose(handover_share(v, 0.0, fade), 1.0)


def test_with_a_handover_the_air_brake_takes_regeneration_s_share_early():
    # at 30 km/h, halfway from the 50 km/h handover to the 10 km/h fade, regeneration
    # gives half its envelope and the air brake the rest; above 50 km/h nothing changes
    drive = LocomotiveDrive(traction_lag_s=LAG, handover_kmh=50.0)
    u = -0.1
    v = kmh_to_mps(30.0)
    e_ss, a_ss = drive.steady_forces_n(u, v, M_EFF, M_EFF)
    envelope = float(drive.locomotive.regen.max_force(v))
    assert float(e_ss) == pytest.approx(0.5 * envelope)
    assert float(a_ss) == pytest.approx(-u * M_EFF - 0.5 * envelope)
    electric, air, _, _ = run(drive, np.full(STEADY, u), v)
    assert electric[-1] == pytest.approx(0.5 * envelope, rel=1e-12)
    assert air[-1] == pytest.approx(float(a_ss), rel=1e-8)
    fast = kmh_to_mps(60.0)
    assert drive.steady_forces_n(u, fast, M_EFF, M_EFF)[0] == pytest.approx(
        DRIVE.steady_forces_n(u, fast, M_EFF, M_EFF)[0]
    )


def test_bad_handover_names_the_field():
    with pytest.raises(ConfigError) as err:
        LocomotiveDrive(handover_kmh=-5.0)
    assert err.value.field == "brake.handover_kmh"
