"""Heavy-haul brake-pipe brake (railpilot.brakes.brake_pipe), issue 9 item 6.

Each test drives the compiled step ``brake_pipe_ato_step`` through ``BrakePipeBrake.pack``
with a held or scripted command, so only the brake is under test (no train motion, no
controller). Cross-checks: the kernel against the closed-form step responses of the same
model (exact to rounding), and the train's build-up time against the published ETCS
conversion model (ERA SUBSET-026-3, appendix A.3.8-A.3.9).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from railpilot.brakes import brake_pipe as bp
from railpilot.brakes.base import BrakeModel, PackContext
from railpilot.brakes.brake_pipe import (
    BrakePipeBrake,
    application_lag_s,
    brake_pipe_ato_step,
    build_up_time_s,
    equivalent_build_up_time_s,
    etcs_build_up_time_s,
    etcs_full_force_time_s,
    segment_positions_m,
    segment_pressure_fraction,
    train_force_fraction,
)
from railpilot.errors import ConfigError
from railpilot.vehicle.train import Train

DT = 0.01
A_MAX = 0.5
TRAIN = Train(mass_kg=10_000e3, length_m=1600.0, max_service_decel_mps2=A_MAX)
M_EFF = TRAIN.effective_mass_kg
CONTEXT = PackContext(dt_s=DT, load_weighed_eff_mass_kg=M_EFF, train=TRAIN)
#: "to one step" (the kernel reports at the end of each step), with room for rounding
ONE_STEP = DT * (1.0 + 1e-9)


def run(brake, commands, dt=DT, length_m=1600.0, state=None):
    """Step the brake over ``commands`` [m/s^2]; return (air force / full, fractions, state).

    The force is returned as a fraction of the full-service force ``a_max m_eff``; the
    fractions are each group's cylinder fraction at the end of each step.
    """
    p = brake.pack_arrays(dt, length_m)
    if state is None:
        n_state, n_buffer = brake.sizes(p)
        state = (np.zeros(n_state), np.zeros(n_buffer))
    s, buf = state
    n = len(commands)
    force = np.zeros(n)
    fractions = np.zeros((n, brake.n_segments))
    for k, u in enumerate(commands):
        electric, air, _ = brake_pipe_ato_step(p, s, buf, u, 20.0, k * dt, dt, M_EFF, M_EFF)
        assert electric == 0.0
        force[k] = air / (brake.max_decel_mps2 * M_EFF)
        fractions[k] = s[bp.ST_Y0 :]
    return force, fractions, (s, buf)


def end_of_steps(n, dt=DT):
    """Times [s] at the end of each of ``n`` steps (where the kernel reports)."""
    return np.arange(1, n + 1) * dt


def first_step_above(series, level, dt=DT):
    """End time [s] of the first step whose value exceeds ``level``."""
    return (np.argmax(series > level) + 1) * dt


# --- the brake-model interface --------------------------------------------------------------


def test_is_a_brake_model_of_the_interface():
    brake: BrakeModel = BrakePipeBrake()
    assert brake.name == "brake-pipe"
    assert brake.changeover_kmh == 0.0
    p = brake.pack(CONTEXT)
    n_state, n_buffer = brake.sizes(p)
    assert n_state == 1 + 40
    # the slowest wave (release, 150 m/s) takes 1600 / 150 = 10.67 s = 1066.7 steps
    assert n_buffer == 1066 + 2


def test_pack_takes_the_train_length_from_the_context():
    brake = BrakePipeBrake()
    assert_allclose(brake.pack(CONTEXT), brake.pack_arrays(DT, 1600.0), rtol=0, atol=0)


def test_lead_is_the_front_and_the_train_lead_sums_to_the_equivalent_time():
    brake = BrakePipeBrake(reaction_s=0.7)
    assert brake.lead_s == (0.7, pytest.approx(24.0 / np.log(20.0)))
    delay, lag = brake.train_lead_s(1600.0)
    assert delay == pytest.approx(0.7 + 1600.0 / 500.0)
    assert delay + lag == pytest.approx(
        float(equivalent_build_up_time_s(1600.0, reaction_s=0.7)), rel=1e-12
    )


def test_position_p_uses_the_middle_of_the_uic_p_ranges():
    brake = BrakePipeBrake(position="P")
    assert (brake.application_s, brake.release_s) == (4.0, 17.5)
    brake = BrakePipeBrake(position="P", application_time_s=3.0)
    assert brake.application_s == 3.0


# --- the kernel against the closed-form model ----------------------------------------------


def test_held_full_command_reproduces_the_analytic_fraction_of_every_group():
    # 1600 m, 40 groups: wave delays j * 41.03 m / 250 m/s are mostly not whole steps
    brake = BrakePipeBrake()
    n = 6000
    _, fractions, _ = run(brake, np.full(n, -A_MAX))
    x = segment_positions_m(1600.0, brake.n_segments)
    t = end_of_steps(n)
    for when in (0.5, 3.0, 6.4, 10.0, 24.0, 40.0, 60.0):
        k = round(when / DT) - 1
        expected = segment_pressure_fraction(t[k], x)
        assert_allclose(fractions[k], expected, rtol=0, atol=1e-12)


def test_held_full_command_reproduces_the_analytic_train_force():
    brake = BrakePipeBrake()
    n = 6000
    force, _, _ = run(brake, np.full(n, -A_MAX))
    assert_allclose(force, train_force_fraction(end_of_steps(n), 1600.0), rtol=0, atol=1e-12)


def test_release_reproduces_the_analytic_fraction_of_every_group():
    brake = BrakePipeBrake()
    _, _, state = run(brake, np.full(30_000, -A_MAX))  # 300 s: every cylinder full
    n = 12_000
    _, fractions, _ = run(brake, np.zeros(n), state=state)
    x = segment_positions_m(1600.0, brake.n_segments)
    expected = segment_pressure_fraction(
        end_of_steps(n)[:, None], x, to_fraction=0.0, from_fraction=1.0
    )
    assert_allclose(fractions, expected, rtol=0, atol=1e-9)


def test_release_wave_faster_than_application_wave_is_exact_too():
    # the received target is then the min of the two delayed commands
    brake = BrakePipeBrake(application_wave_mps=120.0, release_wave_mps=330.0, n_segments=7)
    x = segment_positions_m(1600.0, 7)
    speeds = {"application_wave_mps": 120.0, "release_wave_mps": 330.0}
    _, fractions, state = run(brake, np.full(20_000, -A_MAX))
    t = end_of_steps(20_000)
    assert_allclose(fractions, segment_pressure_fraction(t[:, None], x, **speeds), atol=1e-12)
    _, fractions, _ = run(brake, np.zeros(8000), state=state)
    expected = segment_pressure_fraction(
        end_of_steps(8000)[:, None], x, to_fraction=0.0, from_fraction=1.0, **speeds
    )
    assert_allclose(fractions, expected, rtol=0, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(
    length_m=st.floats(50.0, 2000.0),
    n_segments=st.integers(2, 30),
    wave_mps=st.floats(50.0, 400.0),
    application_s=st.floats(0.5, 30.0),
    reaction_s=st.floats(0.0, 3.0),
    dt=st.sampled_from([0.01, 0.02, 0.05, 0.1]),
    increments=st.lists(st.floats(0.0, 0.3), min_size=1, max_size=6),
    gaps=st.lists(st.integers(1, 300), min_size=6, max_size=6),
)
def test_any_rising_command_is_the_superposition_of_analytic_steps(
    length_m, n_segments, wave_mps, application_s, reaction_s, dt, increments, gaps
):
    # a command that never falls keeps every group applying: the model is then linear,
    # and the response is the sum of the delayed first-order steps of its increments
    brake = BrakePipeBrake(
        n_segments=n_segments,
        application_wave_mps=wave_mps,
        application_time_s=application_s,
        reaction_s=reaction_s,
        max_decel_mps2=A_MAX,
    )
    starts = np.cumsum([0, *gaps[: len(increments) - 1]])
    n = int(starts[-1]) + 400
    uc = np.zeros(n)
    for start, du in zip(starts, increments, strict=False):
        uc[start:] += du
    uc = np.minimum(uc, 1.0)
    force, fractions, _ = run(brake, -A_MAX * uc, dt=dt, length_m=length_m)
    steps = np.diff(np.concatenate([[0.0], uc]))
    t = end_of_steps(n, dt)
    x = segment_positions_m(length_m, n_segments)
    expected = np.zeros((n, n_segments))
    for i in np.flatnonzero(steps):
        expected += segment_pressure_fraction(
            t[:, None] - i * dt,
            x,
            to_fraction=steps[i],
            application_time_s=application_s,
            application_wave_mps=wave_mps,
            reaction_s=reaction_s,
        )
    assert_allclose(fractions, expected, rtol=0, atol=1e-9)
    assert_allclose(force, expected.mean(axis=1), rtol=0, atol=1e-9)


def test_continuous_limit_is_the_limit_of_many_groups():
    t = np.linspace(0.0, 80.0, 801)
    continuous = train_force_fraction(t, 1600.0, n_segments=None)
    many = train_force_fraction(t, 1600.0, n_segments=2001)
    assert_allclose(many, continuous, rtol=0, atol=2e-4)


def test_equivalent_time_is_the_integral_of_the_missing_force():
    # T_e = integral (1 - F) dt, checked by quadrature for groups and the continuous limit
    t = np.linspace(0.0, 400.0, 400_001)
    for n_segments in (2, 40, None):
        missing = 1.0 - train_force_fraction(t, 1600.0, n_segments=n_segments)
        assert_allclose(np.trapezoid(missing, t), equivalent_build_up_time_s(1600.0), rtol=1e-6)


# --- front versus rear of a 1,600 m train --------------------------------------------------


def test_rear_of_a_1600_m_train_starts_braking_6_4_s_after_the_front():
    brake = BrakePipeBrake()
    _, fractions, _ = run(brake, np.full(6000, -A_MAX))
    front_start = first_step_above(fractions[:, 0], 0.0)
    rear_start = first_step_above(fractions[:, -1], 0.0)
    assert front_start == pytest.approx(DT)  # the locomotive's group starts at once
    assert rear_start - front_start == pytest.approx(1600.0 / 250.0, abs=ONE_STEP)


def test_rear_of_a_1600_m_train_reaches_95_percent_6_4_s_after_the_front():
    brake = BrakePipeBrake()
    _, fractions, _ = run(brake, np.full(6000, -A_MAX))
    front = first_step_above(fractions[:, 0], 0.95)
    rear = first_step_above(fractions[:, -1], 0.95)
    assert front == pytest.approx(24.0, abs=ONE_STEP)  # brake position G: 24 s
    assert rear - front == pytest.approx(6.4, abs=ONE_STEP)


def test_train_force_reaches_95_percent_at_the_build_up_time():
    brake = BrakePipeBrake()
    force, _, _ = run(brake, np.full(6000, -A_MAX))
    assert first_step_above(force, 0.95) == pytest.approx(
        float(build_up_time_s(1600.0)), abs=ONE_STEP
    )


# --- release, partial and zero commands -----------------------------------------------------


@pytest.mark.parametrize("position", ["G", "P"])
def test_release_is_slower_than_application(position):
    brake = BrakePipeBrake(position=position)
    applying, fractions_on, state = run(brake, np.full(30_000, -A_MAX))
    releasing, fractions_off, _ = run(brake, np.zeros(30_000), state=state)
    # the train: 95 % of the change takes longer off than on
    assert first_step_above(1.0 - releasing, 0.95) > first_step_above(applying, 0.95)
    # every group, and the rear by the slower release wave too
    on = [first_step_above(fractions_on[:, j], 0.95) for j in range(brake.n_segments)]
    off = [first_step_above(1.0 - fractions_off[:, j], 0.95) for j in range(brake.n_segments)]
    assert np.all(np.array(off) > np.array(on))
    # group 0 vents 3.8 -> 0.4 bar in the release time (the UIC test's end points)
    assert first_step_above(1.0 - fractions_off[:, 0], 1.0 - 0.4 / 3.8) == pytest.approx(
        brake.release_s, abs=ONE_STEP
    )


def test_a_short_release_overtaken_by_reapplication_never_reaches_the_rear():
    # release for 2 s, then full again: the application wave (6.4 s to the rear) catches
    # the release wave (10.7 s) before the rear, which so stays fully applied
    brake = BrakePipeBrake()
    _, _, state = run(brake, np.full(30_000, -A_MAX))
    script = np.concatenate([np.zeros(200), np.full(3000, -A_MAX)])
    _, fractions, _ = run(brake, script, state=state)
    assert fractions[:, 0].min() < 0.99  # the front did release for a while
    assert_allclose(fractions[:, -1], 1.0, rtol=0, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(uc=st.floats(0.0, 1.0))
def test_partial_command_gives_a_proportional_force(uc):
    brake = BrakePipeBrake(n_segments=10)
    full, _, _ = run(brake, np.full(4000, -A_MAX))
    part, _, _ = run(brake, np.full(4000, -A_MAX * uc))
    assert_allclose(part, uc * full, rtol=0, atol=1e-12)


def test_demand_and_steady_force_are_the_full_service_force_times_the_command():
    brake = BrakePipeBrake()
    p = brake.pack(CONTEXT)
    n_state, n_buffer = brake.sizes(p)
    s, buf = np.zeros(n_state), np.zeros(n_buffer)
    for k in range(20_000):
        _, air, demand = brake_pipe_ato_step(p, s, buf, -0.3, 20.0, k * DT, DT, M_EFF, M_EFF)
    assert demand == pytest.approx(0.3 * M_EFF, rel=1e-12)
    assert air == pytest.approx(0.3 * M_EFF, rel=1e-9)
    # a command beyond full service is clipped to full service
    for k in range(20_000):
        _, air, demand = brake_pipe_ato_step(p, s, buf, -5.0, 20.0, k * DT, DT, M_EFF, M_EFF)
    assert demand == pytest.approx(A_MAX * M_EFF, rel=1e-12)
    assert air == pytest.approx(A_MAX * M_EFF, rel=1e-9)


@pytest.mark.parametrize("u", [0.0, 0.4])  # coasting, traction
def test_zero_or_positive_command_gives_zero_force(u):
    brake = BrakePipeBrake()
    p = brake.pack(CONTEXT)
    n_state, n_buffer = brake.sizes(p)
    s, buf = np.zeros(n_state), np.zeros(n_buffer)
    for k in range(3000):
        electric, air, demand = brake_pipe_ato_step(p, s, buf, u, 20.0, k * DT, DT, M_EFF, M_EFF)
        assert (electric, air, demand) == (0.0, 0.0, 0.0)


# --- validation against the published build-up time (ETCS conversion model) ----------------

#: the tolerance stated before measuring: the UIC application-time window of a brake
#: position (G 18-30 s) is +-25 % about its middle, the spread the model's own calibration
#: admits
TOLERANCE = 0.25
LENGTHS_M = [400.0, 600.0, 800.0, 1000.0, 1200.0, 1500.0]
#: T_e / T_brake_service_cm0 as measured (docs/heavy-haul-brake.md): none within 25 %
MEASURED_SERVICE_RATIO = {
    "G": [0.63, 0.47, 0.38, 0.32, 0.26, 0.20],
    "P": [0.15, 0.13, 0.12, 0.11, 0.09, 0.08],
}


def test_etcs_formula_reference_values():
    # hand evaluation of SUBSET-026-3 A.3.8.2-3 and A.3.9.2-3 (a + b L/100 + c (L/100)^2)
    assert_allclose(etcs_build_up_time_s(400.0, "G"), 3.00 + 2.77 * 4, rtol=1e-12)
    assert_allclose(etcs_build_up_time_s(200.0, "G"), 3.00 + 2.77 * 4, rtol=1e-12)  # L >= 400
    assert_allclose(etcs_build_up_time_s(200.0, "P"), 3.00 + 2.77 * 2, rtol=1e-12)
    assert_allclose(etcs_build_up_time_s(1500.0, "G"), 10.50 + 0.32 * 15 + 0.18 * 225)
    assert_allclose(etcs_build_up_time_s(600.0, "G", "emergency"), 12.00 + 0.05 * 36)
    assert_allclose(etcs_build_up_time_s(1200.0, "G", "emergency"), -0.40 + 1.60 * 12 + 0.03 * 144)
    assert_allclose(etcs_build_up_time_s(300.0, "P", "emergency"), 2.30 + 0.17 * 16)
    # t2 = 2 T_build_up - T_react (A.3.12.2.1), T_brake_service_react = 5.70 s in G
    assert_allclose(etcs_full_force_time_s(400.0, "G"), 2 * 14.08 - 5.70, rtol=1e-12)


def cases_within_tolerance():
    for position in ("G", "P"):
        for length, ratio in zip(LENGTHS_M, MEASURED_SERVICE_RATIO[position], strict=True):
            mark = pytest.mark.xfail(
                strict=True,
                reason=f"measured T_e / T_brake_service_cm0 = {ratio:.2f}, outside +-25 %: "
                "see the validation table in docs/heavy-haul-brake.md",
            )
            yield pytest.param(position, length, marks=mark, id=f"{position}-{length:g}m")


@pytest.mark.parametrize(("position", "length_m"), list(cases_within_tolerance()))
def test_equivalent_build_up_time_within_25_percent_of_etcs_service(position, length_m):
    """Our equivalent build-up time against the ETCS conversion model's, freight trains.

    Published: ERA SUBSET-026-3 (ETCS SRS chapter 3, appendix A.3.9.2 in P, A.3.9.3 in G),
    basic full-service build-up time of a freight train, used as ``T_brake_service_cm0``
    for a target at zero speed (A.3.9.4)::

        T_brake_basic_sb = a + b (L/100) + c (L/100)^2            [s], L in m
        L <= 900 m:        a = 3.00,  b = 2.77, c = 0.00
        900 < L <= 1500 m: a = 10.50, b = 0.32, c = 0.18
        (in G with L = max(400 m, train length))

    It is an *equivalent* time, ``T_brake_build_up = T_brake_react + T_brake_increase / 2``
    (3.13.2.2.3.2.4): a dead time after which full force gives the same speed loss. Ours is
    the same quantity of the model's response ``F`` to a full-service step,
    ``T_e = integral (1 - F) dt = L / (2 c_a) + T_a`` (exact for a ramp, as theirs is).

    Measured (docs/heavy-haul-brake.md): ``T_e`` is 20-63 % of the formula in G and
    8-15 % in P, falling with length; so these cases are expected failures, strict, and
    the tolerance is the one stated before measuring.
    """
    brake = BrakePipeBrake(position=position)
    ours = equivalent_build_up_time_s(length_m, application_time_s=brake.application_s)
    published = etcs_build_up_time_s(length_m, position, "service")
    assert abs(float(ours / published) - 1.0) <= TOLERANCE


@pytest.mark.parametrize("position", ["G", "P"])
@pytest.mark.parametrize("length_m", LENGTHS_M)
def test_equivalent_build_up_time_is_within_the_etcs_service_maximum(position, length_m):
    """SUBSET-026-3 A.3.9.6: the service build-up times "shall be considered as maximum
    ones"; a brake system may justify shorter ones. Ours is shorter at every length."""
    brake = BrakePipeBrake(position=position)
    ours = equivalent_build_up_time_s(length_m, application_time_s=brake.application_s)
    assert ours <= etcs_build_up_time_s(length_m, position, "service")


def test_an_effective_wave_of_18_mps_reproduces_etcs_service_up_to_900_m():
    # the formula is linear up to 900 m, T = 3.00 + 2.77 L / 100: our T_e = L / (2 c) + T_a
    # matches it with c = 100 / (2 * 2.77) = 18.05 m/s and T_a = 3.00 s (t_app = 8.99 s).
    # Not a signal speed: the rate at which the pipe's full-service reduction reaches the
    # rear, which the wave model leaves out (docs/heavy-haul-brake.md)
    lengths = np.linspace(400.0, 900.0, 11)
    ours = equivalent_build_up_time_s(
        lengths, application_time_s=3.0 * np.log(20.0), wave_speed_mps=100.0 / (2 * 2.77)
    )
    assert_allclose(ours, etcs_build_up_time_s(lengths, "G"), rtol=1e-12)
    assert_allclose(ours, etcs_build_up_time_s(lengths, "P"), rtol=1e-12)


def test_single_group_matches_the_uic_application_time():
    # the locomotive's group has no wave delay: 95 % in the position's application time
    for position, t_app in (("G", 24.0), ("P", 4.0)):
        y = segment_pressure_fraction(t_app, 0.0, application_time_s=t_app)
        assert_allclose(y, 0.95, rtol=1e-12)
        assert application_lag_s(t_app) == pytest.approx(t_app / np.log(20.0))
        assert bp.UIC_TIMES_S[position][0][0] <= t_app <= bp.UIC_TIMES_S[position][0][1]


# --- configuration errors name the field -----------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"position": "R"}, "brake.position"),
        ({"n_segments": 1}, "brake.n_segments"),
        ({"n_segments": 201}, "brake.n_segments"),
        ({"n_segments": 2.5}, "brake.n_segments"),
        ({"n_segments": True}, "brake.n_segments"),
        ({"application_wave_mps": 0.0}, "brake.application_wave_mps"),
        ({"application_wave_mps": 500.0}, "brake.application_wave_mps"),
        ({"release_wave_mps": float("nan")}, "brake.release_wave_mps"),
        ({"application_time_s": 0.0}, "brake.application_time_s"),
        ({"release_time_s": 200.0}, "brake.release_time_s"),
        ({"max_decel_mps2": 0.0}, "brake.max_decel_mps2"),
        ({"reaction_s": -1.0}, "brake.reaction_s"),
    ],
)
def test_bad_configuration_names_the_field(kwargs, field):
    with pytest.raises(ConfigError) as err:
        BrakePipeBrake(**kwargs)
    assert err.value.field == field


def test_pack_rejects_a_bad_step_naming_the_field():
    brake = BrakePipeBrake()
    with pytest.raises(ConfigError) as err:
        brake.pack(PackContext(dt_s=0.0, load_weighed_eff_mass_kg=M_EFF, train=TRAIN))
    assert err.value.field == "sim.dt_s"
    # 10.7 s of release wave at 1 us steps is more than the 10,000,000-step delay line
    with pytest.raises(ConfigError) as err:
        brake.pack(PackContext(dt_s=1e-6, load_weighed_eff_mass_kg=M_EFF, train=TRAIN))
    assert err.value.field == "sim.dt_s"


def test_sizes_rejects_an_array_that_is_not_this_models_params():
    brake = BrakePipeBrake()
    short = np.zeros(3)
    wrong_size = brake.pack_arrays(DT, 1600.0)[:-1]  # one float short of 40 groups
    for params in (short, wrong_size):
        with pytest.raises(ConfigError) as err:
            brake.sizes(params)
        assert err.value.field == "brake.params"


def test_etcs_formula_rejects_lengths_beyond_its_validity():
    with pytest.raises(ConfigError) as err:
        etcs_build_up_time_s(1600.0, "G")
    assert err.value.field == "train_length_m"
    assert etcs_build_up_time_s(1600.0, "G", extrapolate=True) > etcs_build_up_time_s(1500.0, "G")
