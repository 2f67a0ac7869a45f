"""Build the description of a run (sim/layout.py) from a scenario: one function per concern.

Every run, single or in a Monte Carlo, is built here and nowhere else:
:func:`run_inputs` calls one builder per part of :class:`~railpilot.sim.layout.RunInputs`.
The controller's part comes from its :class:`~railpilot.control.user.Binding`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from railpilot.brakes.base import PackContext
from railpilot.control.user import Binding
from railpilot.sim.drive_profile import DriveProfile
from railpilot.sim.layout import (
    A_A0,
    A_A1,
    A_A2,
    A_GRADE_FF,
    A_MASS,
    A_MEFF_LW,
    A_STOP_M,
    A_UMAX,
    A_UMIN,
    A_V_CO,
    D_CONST_N,
    N_ATO,
    N_DIST,
    AtoIn,
    BrakeIn,
    ControllerIn,
    DisturbanceIn,
    LineIn,
    RealismIn,
    ReferenceIn,
    RunInputs,
    SimIn,
    TrainIn,
)
from railpilot.sim.reference import BrakingCurve
from railpilot.units import kmh_to_mps
from railpilot.vehicle.profile import elevation_table

if TYPE_CHECKING:  # the simulator never imports the scenario package at run time
    from railpilot.scenario.model import Scenario


def ato_brake_model(scenario: Scenario) -> tuple[float, float]:
    """The ATO's model of the brake's ``(delay, lag)`` [s].

    ``ato.brake_delay_s`` and ``ato.brake_lag_s``; each one not given is the plant's: the
    whole train's for a brake whose response depends on the train's length (a brake
    pipe's wave takes ``L / c`` to the rear: ``train_lead_s(length)``), else ``lead_s``.
    """
    train_lead = getattr(scenario.brake, "train_lead_s", None)
    if train_lead is not None:
        delay, lag = train_lead(scenario.train.length_m)
    else:
        delay, lag = scenario.brake.lead_s
    ato = scenario.ato
    return (
        delay if ato.brake_delay_s is None else ato.brake_delay_s,
        lag if ato.brake_lag_s is None else ato.brake_lag_s,
    )


def tuning_model(scenario: Scenario) -> tuple[float, float]:
    """The ``(theta, T)`` the tuning rules get: the ATO's brake model plus sampling.

    A controller that updates every ``control_period_s`` adds half a period of
    effective delay (Skogestad 2003, section 3.2: the zero-order hold), so the rules see
    ``theta = brake delay + period / 2``; that also keeps ``theta > 0``, which SIMC needs.
    """
    delay, lag = ato_brake_model(scenario)
    return delay + scenario.sim.control_period_s / 2.0, lag


def feed_forward_acceleration(
    ref: BrakingCurve | DriveProfile, t: np.ndarray, lead_s: float
) -> np.ndarray:
    """Reference acceleration [m/s^2] to command at ``t`` for a brake ``lead_s`` slow.

    ``a_ref(t + lead)``, except over the last ``lead`` before the stop: there the
    reference is at rest at ``t + lead`` only because the train will have stopped, not
    because the brake is to be released, so the deceleration the curve stops with is
    held (a train stops on its brakes).
    """
    _, _, a_ahead = ref.sample(t + lead_s)
    end = ref.duration_s
    _, _, (a_final,) = ref.sample(np.array([end - 1e-9]))
    holding = (t < end) & (t + lead_s >= end)
    return np.where(holding, np.minimum(a_ahead, a_final), a_ahead)


def distance_table(ref: BrakingCurve | DriveProfile, dt: float, lead_s: float) -> np.ndarray:
    """The braking curve by position: ``[x, v(x), fed-forward a(x)]`` rows, x increasing.

    For a distance-based reference the ATO looks these up at the measured position.
    Sampled at the simulation step over the curve's moving part; the fed-forward
    acceleration at a position is the one the time-based ATO would command when the
    reference passes it (``feed_forward_acceleration``), and beyond the stop point the
    last row holds (at rest, braking with the final deceleration).
    """
    t = np.arange(0.0, ref.duration_s + dt, dt)
    x, v, _ = ref.sample(t)
    a_ff = feed_forward_acceleration(ref, t, lead_s)
    keep = np.concatenate(([True], np.diff(x) > 0))  # interp needs increasing positions
    return np.vstack([x[keep], v[keep], a_ff[keep]])


# --- one builder per concern ---------------------------------------------------------------


def sim_inputs(scenario: Scenario) -> SimIn:
    sim = scenario.sim
    return SimIn(sim.n_steps, sim.dt_s, sim.control_every)


def train_inputs(scenario: Scenario) -> TrainIn:
    train = scenario.train
    ref = scenario.reference
    v0 = ref.v0_mps if scenario.initial_speed_mps is None else scenario.initial_speed_mps
    return TrainIn(
        np.array(
            [
                train.effective_mass_kg,
                train.mass_kg,
                train.davis_a0,
                train.davis_a1,
                train.davis_a2,
                ref.start_m,
                v0,
                scenario.brake_gain,
                train.length_m,
            ]
        )
    )


def line_inputs(scenario: Scenario) -> LineIn:
    table = elevation_table(scenario.line)
    return LineIn(table.edges_m, table.values_n_per_kn, table.cumulative)


def ato_inputs(scenario: Scenario) -> AtoIn:
    train = scenario.train
    ato = scenario.ato
    mass_lw = ato.mass_kg if ato.mass_kg is not None else train.mass_kg
    davis = ato.davis if ato.davis is not None else (train.davis_a0, train.davis_a1, train.davis_a2)
    p = np.zeros(N_ATO)
    p[A_MEFF_LW] = mass_lw * (1 + train.rotating_mass_factor)
    p[A_A0], p[A_A1], p[A_A2] = davis
    p[A_MASS] = mass_lw
    p[A_UMIN] = -train.max_service_decel_mps2
    p[A_UMAX] = 0.0
    p[A_STOP_M] = scenario.reference.stop_m
    p[A_V_CO] = kmh_to_mps(scenario.changeover_kmh)
    # an actuator with traction lets the ATO drive, up to its starting effort
    traction = getattr(scenario.brake, "max_traction_accel_mps2", None)
    p[A_UMAX] = 0.0 if traction is None else float(traction(train))
    p[A_GRADE_FF] = 1.0 if ato.gradient_feedforward else 0.0
    return AtoIn(p)


def brake_inputs(scenario: Scenario, ato: AtoIn) -> BrakeIn:
    """The brake packed for the step, the train and the ATO's load-weighed mass."""
    context = PackContext(scenario.sim.dt_s, float(ato.p[A_MEFF_LW]), scenario.train)
    params = scenario.brake.pack(context)
    return BrakeIn(params, np.array(scenario.brake.sizes(params), dtype=np.int64))


def realism_inputs(scenario: Scenario) -> RealismIn:
    realism = scenario.realism
    sim = scenario.sim
    n_updates = (sim.n_steps + sim.control_every - 1) // sim.control_every
    # seeded by the realism's own seed
    return RealismIn(realism.pack(), realism.speed_noise(n_updates), realism.balises())


def disturbance_inputs(scenario: Scenario, reference: ReferenceIn) -> DisturbanceIn:
    disturbance = scenario.disturbance
    sim = scenario.sim
    p = np.zeros(N_DIST)
    p[D_CONST_N] = disturbance.constant_n
    start, end, force = disturbance.region_arrays()
    random_n = disturbance.random_series(
        sim.n_steps, sim.dt_s, reference.a, scenario.train.effective_mass_kg
    )
    return DisturbanceIn(p, start, end, force, random_n)


def reference_inputs(scenario: Scenario) -> ReferenceIn:
    """The braking curve sampled at every step, fed forward by the ATO's brake lead."""
    sim = scenario.sim
    ref = scenario.reference
    t = np.arange(sim.n_steps + 1) * sim.dt_s
    x, v, a = ref.sample(t)
    delay, lag = ato_brake_model(scenario)
    a_ff = feed_forward_acceleration(ref, t, delay + lag)
    by_distance = (
        distance_table(ref, sim.dt_s, delay + lag)
        if scenario.ato.reference == "distance"
        else np.zeros((3, 0))
    )
    return ReferenceIn(x, v, a, a_ff, by_distance)


def controller_inputs(binding: Binding) -> ControllerIn:
    return ControllerIn(binding.params.copy(), binding.state.copy())


def run_inputs(
    scenario: Scenario,
    binding: Binding,
    reference: ReferenceIn | None = None,
    line: LineIn | None = None,
) -> RunInputs:
    """The description of one run of ``scenario`` with the bound controller.

    ``reference`` and ``line``: the sampled reference and the line table of a scenario with
    the same curve, sim settings, ATO model and line, reused (a Monte Carlo's runs share
    them: a sweep varies neither).
    """
    ref = reference_inputs(scenario) if reference is None else reference
    ato = ato_inputs(scenario)
    return RunInputs(
        sim=sim_inputs(scenario),
        train=train_inputs(scenario),
        line=line_inputs(scenario) if line is None else line,
        brake=brake_inputs(scenario, ato),
        controller=controller_inputs(binding),
        ato=ato,
        realism=realism_inputs(scenario),
        disturbance=disturbance_inputs(scenario, ref),
        reference=ref,
    )
