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
from railpilot.sim.disturbance import spread_held_values
from railpilot.sim.drive_profile import DriveProfile, PlannedProfile
from railpilot.sim.layout import (
    A_A0,
    A_A1,
    A_A2,
    A_GRADE_FF,
    A_MASS,
    A_MEFF_LW,
    A_PREVIEW,
    A_STOP_M,
    A_UMAX,
    A_UMIN,
    A_UPOWER,
    A_V_CO,
    D_CONST_N,
    N_ATO,
    N_DIST,
    R_ADHESION,
    R_WHEEL_SCALE,
    T_A0,
    T_A1,
    T_A2,
    T_BRAKE_GAIN,
    T_MASS,
    T_MEFF,
    T_V0,
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
from railpilot.units import kmh_to_mps, tonne_to_kg
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
    ref: BrakingCurve | DriveProfile | PlannedProfile, t: np.ndarray, lead_s: float
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


def distance_table(
    ref: BrakingCurve | DriveProfile | PlannedProfile, dt: float, lead_s: float
) -> np.ndarray:
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
    p[A_PREVIEW] = ato.preview_s
    power = getattr(scenario.brake, "max_traction_power_accel_w_per_kg", None)
    p[A_UPOWER] = np.inf if power is None else float(power(train))
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


# --- a Monte Carlo chunk at once ------------------------------------------------------------

#: sampled parameters :func:`batch_inputs` applies to whole arrays (sim/sweep.py lists all)
VECTORISED = frozenset(
    {
        "train.mass_t",
        "train.davis_scale",
        "brake.delay_s",
        "brake.lag_s",
        "brake.air_lag_s",
        "brake.electric_lag_s",
        "brake.gain",
        "disturbance.constant_kn",
        "initial_speed_kmh",
        "realism.wheel_scale_error",
        "realism.adhesion",
    }
)


def _rows(row: np.ndarray, runs: int) -> np.ndarray:
    """``runs`` writable copies of ``row``, one per line."""
    return np.repeat(row[None, :], runs, axis=0)


def random_series_many(
    scenario: Scenario,
    target_accel_mps2: np.ndarray,
    effective_mass_kg: np.ndarray,
    seeds: np.ndarray,
) -> np.ndarray:
    """:meth:`~railpilot.sim.disturbance.Disturbance.random_series` of many runs at once.

    Row ``i`` is exactly ``random_series(n_steps, dt, target, effective_mass_kg[i],
    seed=seeds[i])``: each run's generator draws the same numbers in the same order (one
    call per run: a seeded generator cannot be shared), then the held values are spread
    over the steps and scaled for all runs together, with the same arithmetic.
    """
    disturbance = scenario.disturbance
    sim = scenario.sim
    runs = seeds.shape[0]
    n_steps = sim.n_steps
    if disturbance.random_std_n == 0.0 and disturbance.target_fraction == 0.0:
        return np.zeros((runs, 0))
    hold = max(round(disturbance.random_hold_s / sim.dt_s), 1)
    if disturbance.target_fraction > 0.0 and len(target_accel_mps2) < n_steps:
        raise ValueError(
            f"target_accel_mps2 has {len(target_accel_mps2)} values: expected one per "
            f"step, {n_steps}"
        )
    n_values = n_steps // hold + 1
    normal = np.zeros((runs, n_values))
    factor = np.zeros((runs, n_values))
    for i in range(runs):
        rng = np.random.default_rng(int(seeds[i]))
        if disturbance.random_std_n > 0.0:
            normal[i] = rng.normal(0.0, disturbance.random_std_n, n_values)
        if disturbance.target_fraction > 0.0:
            factor[i] = rng.uniform(
                -disturbance.target_fraction, disturbance.target_fraction, n_values
            )
    force = np.empty((runs, n_steps))
    spread_held_values(
        normal,
        factor,
        hold,
        disturbance.random_std_n > 0.0,
        disturbance.target_fraction > 0.0,
        np.ascontiguousarray(target_accel_mps2[:n_steps], dtype=float),
        np.ascontiguousarray(effective_mass_kg, dtype=float),
        force,
    )
    return force


def batch_inputs(
    nominal: Scenario,
    binding: Binding,
    values: dict[str, np.ndarray],
    seeds: np.ndarray,
    reference: ReferenceIn | None = None,
    line: LineIn | None = None,
) -> RunInputs | None:
    """The batch of runs of a sweep, built for all runs at once: no scenario per run.

    ``nominal``: the sweep's scenario with the ATO frozen (sim/batch.freeze_ato);
    ``values``: sampled parameter (sim/sweep.py's keys) -> one value per run; ``seeds``:
    each run's seed. Every part is exactly what :func:`run_inputs` gives the run's own
    scenario (sim/batch._variant), stacked (sim/layout.stack_runs) -- the same
    arithmetic on whole columns (tests/sim/test_batch_inputs.py compares them array by
    array). None when this cannot be done for all runs at once (an actuator with traction,
    whose ATO limit depends on the sampled train; a brake without ``pack_many`` whose
    packing a sampled value changes; a value its brake refuses): the caller then builds
    run by run.
    """
    runs = int(seeds.shape[0])
    if set(values) - VECTORISED or runs == 0:
        return None
    brake = nominal.brake
    if getattr(brake, "max_traction_accel_mps2", None) is not None:
        return None
    ref = reference_inputs(nominal) if reference is None else reference
    train = nominal.train
    # --- the plant train
    train_p = _rows(train_inputs(nominal).p, runs)
    mass = None
    if "train.mass_t" in values:
        mass = tonne_to_kg(values["train.mass_t"])
        train_p[:, T_MASS] = mass
        train_p[:, T_MEFF] = mass * (1.0 + train.rotating_mass_factor)
    if "train.davis_scale" in values:
        scale = values["train.davis_scale"]
        train_p[:, T_A0] = train.davis_a0 * scale
        train_p[:, T_A1] = train.davis_a1 * scale
        train_p[:, T_A2] = train.davis_a2 * scale
    if "initial_speed_kmh" in values:
        train_p[:, T_V0] = kmh_to_mps(values["initial_speed_kmh"])
    if "brake.gain" in values:
        train_p[:, T_BRAKE_GAIN] = values["brake.gain"]
    # --- the ATO: its load weighing follows the true mass
    nominal_ato = ato_inputs(nominal)
    ato_p = _rows(nominal_ato.p, runs)
    if mass is not None and nominal.ato.mass_kg is None:
        ato_p[:, A_MASS] = mass
        ato_p[:, A_MEFF_LW] = mass * (1 + train.rotating_mass_factor)
    # --- the brake
    changes = {
        key.removeprefix("brake."): value
        for key, value in values.items()
        if key.startswith("brake.") and key != "brake.gain"
    }
    if not changes and mass is None:
        nominal_brake = brake_inputs(nominal, nominal_ato)
        brake_in = BrakeIn(_rows(nominal_brake.p, runs), _rows(nominal_brake.sizes, runs))
    else:
        pack_many = getattr(brake, "pack_many", None)
        if pack_many is None:
            return None
        context = PackContext(nominal.sim.dt_s, float(nominal_ato.p[A_MEFF_LW]), train)
        packed = pack_many(context, changes, runs, load_weighed_eff_mass_kg=ato_p[:, A_MEFF_LW])
        if packed is None:
            return None
        brake_in = BrakeIn(*packed)
    # --- realism: the speed noise is seeded by each run's seed + 1
    realism = nominal.realism
    real_p = _rows(realism.pack(), runs)
    if "realism.wheel_scale_error" in values:
        real_p[:, R_WHEEL_SCALE] = values["realism.wheel_scale_error"]
    if "realism.adhesion" in values:
        real_p[:, R_ADHESION] = values["realism.adhesion"]
    sim = nominal.sim
    n_updates = (sim.n_steps + sim.control_every - 1) // sim.control_every
    if realism.speed_noise_std_mps == 0.0:
        noise = np.zeros((runs, 0))
    else:
        noise = np.stack([realism.speed_noise(n_updates, seed=int(s) + 1) for s in seeds])
    # --- disturbance: the random force is seeded by each run's seed
    dist_p = np.zeros((runs, N_DIST))
    dist_p[:, D_CONST_N] = nominal.disturbance.constant_n
    if "disturbance.constant_kn" in values:
        dist_p[:, D_CONST_N] = values["disturbance.constant_kn"] * 1e3
    start, end, force = nominal.disturbance.region_arrays()
    random_n = random_series_many(nominal, ref.a, train_p[:, T_MEFF], seeds)
    return RunInputs(
        sim=sim_inputs(nominal),
        train=TrainIn(train_p),
        line=line_inputs(nominal) if line is None else line,
        brake=brake_in,
        controller=controller_inputs(binding),
        ato=AtoIn(ato_p),
        realism=RealismIn(real_p, noise, realism.balises()),
        disturbance=DisturbanceIn(dist_p, start, end, force, random_n),
        reference=ref,
    )
