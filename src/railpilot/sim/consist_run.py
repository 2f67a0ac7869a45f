"""A consist driven along a line: its locomotives under distributed power, the freight air
brake along the train, and the longitudinal dynamics of every vehicle.

One compiled loop (:func:`consist_kernel`) steps, every ``dt``:

1. the driver on the lead locomotive (:class:`ConsistDriver`): a script of commands, each
   from a time, a head position or a speed on (effort as a fraction of the locomotives'
   envelopes, a speed to hold, a brake-pipe reduction, a release, an emergency), or a
   speed-by-distance profile to follow with regeneration and traction and, where they
   are not enough, braking cycles of the air brake;
2. distributed power: every remote unit receives the lead's effort, its brake-valve
   pressure and its emergency after the consist's radio delay (a ring buffer of the
   lead's commands);
3. each locomotive's electric force: its effort times its own envelope at its own speed,
   through the drive's first-order lag;
4. the freight air brake (brakes/freight_air.py): every driver's brake valve holds its
   pipe at its equalizing-reservoir pressure; each braked vehicle's friction force is its
   full-service force scaled by its brake-cylinder pressure;
5. the longitudinal dynamics (sim/ltd.py): one mass per vehicle (or per lump), couplings
   with slack and friction draft gears.

The run's metrics (coupler forces, brake applications, recharge margins, energy) are
gathered in the loop; the fields along the train (coupler force, brake-pipe, auxiliary
reservoir and brake-cylinder pressures) are recorded every ``record_every_s``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from railpilot.brakes import freight_air
from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.interp import interp_at
from railpilot.jit import njit
from railpilot.sim import ltd
from railpilot.units import G_MPS2, KMH_PER_MPS, kmh_to_mps
from railpilot.vehicle.consist import Consist
from railpilot.vehicle.line import Line
from railpilot.vehicle.profile import (
    ResistanceTable,
    elevation_table,
    mean_specific_resistance,
)
from railpilot.vehicle.traction import regen_force_max, traction_force_max

#: the default limit of coupler force [N]: Chinese heavy-haul practice (docs/consist-run.md)
DEFAULT_COUPLER_LIMIT_N = 2_250e3
#: an auxiliary reservoir within this of the charged pipe pressure counts as recharged [kPa]
RECHARGED_WITHIN_KPA = 10.0
#: the electric drive's lag [s], as brakes/locomotive_drive.py's default (assumed there)
ELECTRIC_LAG_S = 1.0
#: where the driver reads the plan ahead of the head [m]
LOOK_AHEAD_M = np.array([250.0, 500.0, 1_000.0, 2_000.0, 4_000.0])
#: no braking cycle within this many times the distance the stop's application needs
APPROACH_FACTOR = 1.5
#: the time over which the driver reads the train's acceleration [s]
ACCEL_SMOOTHING_S = 2.0
#: the least net deceleration [m/s^2] the stop is planned with (a steep descent)
MIN_STOP_DECEL = 0.02
#: a mass slower than this is at rest [m/s]: a distributed-power remote's residual drive
#: force, balanced against its brake at a stand, leaves it creeping at round-off speeds
#: (2.5e-10 m/s measured on the 20,000 t train), and the run would never end
AT_REST_MPS = 1e-6
#: the least speed the driver aims at on a profile before its stop [m/s]
MIN_GOAL_MPS = 1.0
#: the most traction [share of the envelope] the driver pulls against the stop's air
#: brake when it would stop the train short (stretch braking: the brake cannot be eased)
STOP_STRETCH_EFFORT = 0.3
#: the distance [m] over which the driver reads the plan's acceleration (its feedforward)
FEEDFORWARD_DX_M = 10.0
#: the share of regeneration's force the driver's stop counts on before it deepens the
#: reduction
STOP_REGEN_SHARE = 0.5
#: the time step [s] of the driver's prediction of where its stop application stops
STOP_PREDICTION_STEP_S = 0.25
#: the driver predicts its stop once the head is within this many times the distance
#: the stop's air brake needs at its fill time and built-up deceleration (on a descent
#: the line speeds the train up while the cylinders fill: the prediction is longer)
STOP_WATCH_FACTOR = 3.0
#: the reduction [kPa] the brake cylinders' fill time is measured with (air_fill_time_s)
FILL_PROBE_KPA = 70.0
#: the longest the fill is followed for [s]
FILL_PROBE_S = 300.0
#: the points along the way to the stop (shares of it) whose line the stop is planned on
STOP_LINE_SAMPLES = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
#: most brake releases a run keeps the air state of (for the recharge margins)
MAX_RELEASES = 256

# command table columns: conditions (nan: none) and actions
(
    CMD_AT_S,
    CMD_AT_M,
    CMD_BELOW_MPS,
    CMD_ABOVE_MPS,
    CMD_MODE,
    CMD_VALUE,
    CMD_REDUCTION_KPA,
    CMD_EMERGENCY,
) = range(8)
N_CMD = 8
#: effort modes: a fixed fraction of the envelopes, a speed to hold, the profile to follow
MODE_KEEP, MODE_EFFORT, MODE_HOLD, MODE_PROFILE = range(4)

# the driver's parameters
(
    DP_KP,
    DP_KI,
    DP_LAG_S,
    DP_APPLY_ABOVE_MPS,
    DP_RELEASE_BELOW_MPS,
    DP_MIN_RELEASE_MPS,
    DP_CYCLE_REDUCTION_KPA,
    DP_STOP_M,
    DP_LIMIT_N,
    DP_RADIO_DELAY_S,
    DP_REMOTES_FOLLOW,
    DP_END_AT_REST,
    DP_STOP_REDUCTION_KPA,
    DP_STOP_LEAD_S,
    DP_RELEASE_WAIT_S,
    DP_LENGTH_M,
    DP_EFFECTIVE_MASS_KG,
    DP_KPA_PER_MPS2,
    DP_FULL_REDUCTION_KPA,
    DP_STOP_NET_MPS2,
    DP_AIR_FILL_S,
    DP_DAVIS_A0,
    DP_DAVIS_A1,
    DP_DAVIS_A2,
    DP_WEIGHT_SHARE,
    DP_FINAL_BRAKING_M,
) = range(26)
N_DRIVER = 26

# the run's metrics, then the loop-carried scalars (a run can stop at a step and go on)
(
    M_MAX_TENSION_N,
    M_MAX_TENSION_AT,
    M_MAX_TENSION_T,
    M_MAX_COMPRESSION_N,
    M_MAX_COMPRESSION_AT,
    M_MAX_COMPRESSION_T,
    M_OVER_LIMIT_S,
    M_APPLICATIONS,
    M_RELEASES,
    M_E_TRACTION_J,
    M_E_REGEN_J,
    M_E_AIR_J,
    M_E_TRAC_AIR_J,
    M_MAX_SPEED_MPS,
    M_STOP_T,
    M_STEPS,
    M_EMERGENCY_T,
    M_EMERGENCY_V,
    M_EMERGENCY_X,
    M_FINAL_X,
    C_NEXT_CMD,
    C_MODE,
    C_VALUE,
    C_REDUCTION,
    C_EMERGENCY,
    C_INTEGRAL,
    C_APPLIED,
    C_STOPPING,
    C_N_EVENTS,
    C_N_REC,
    C_HAS_MOVED,
    C_ENDED,
    C_RELEASED_AT,
    C_ACCEL,
    C_STOP_SINCE,
) = range(35)
N_METRICS = 35


@dataclass(frozen=True)
class DriverCommand:
    """One command of a driving script: what the driver sets once its conditions hold.

    A command waits for the one before it; then it acts at the first step where every
    condition it has holds: ``at_s`` [s] reached, the head at ``at_m`` [m] or beyond,
    the lead's speed below ``below_kmh`` or above ``above_kmh``. Its actions: ``effort``
    (a fraction of the locomotives' envelopes in [-1, 1]: + traction, - regeneration),
    ``hold_kmh`` (hold this speed with traction and regeneration), ``follow`` (the
    driver's profile), ``reduction_kpa`` (the brake pipe that far below its charged
    pressure; 0 releases), ``emergency``. An action not given leaves what was set.
    """

    at_s: float | None = None
    at_m: float | None = None
    below_kmh: float | None = None
    above_kmh: float | None = None
    effort: float | None = None
    hold_kmh: float | None = None
    follow: bool = False
    reduction_kpa: float | None = None
    emergency: bool = False

    def __post_init__(self) -> None:
        for name in ("at_s", "at_m"):
            value = getattr(self, name)
            if value is not None:
                check_number(f"command.{name}", value, minimum=0.0, error=ConfigError)
        for name in ("below_kmh", "above_kmh", "hold_kmh"):
            value = getattr(self, name)
            if value is not None:
                check_number(
                    f"command.{name}", value, minimum=0.0, maximum=200.0, error=ConfigError
                )
        if self.effort is not None:
            check_number(
                "command.effort", self.effort, minimum=-1.0, maximum=1.0, error=ConfigError
            )
        if self.reduction_kpa is not None:
            check_number(
                "command.reduction_kpa",
                self.reduction_kpa,
                minimum=0.0,
                maximum=300.0,
                error=ConfigError,
            )
        modes = sum(x is not None for x in (self.effort, self.hold_kmh)) + int(self.follow)
        if modes > 1:
            raise ConfigError(
                "command", "effort, hold_kmh and follow together", "at most one of them"
            )

    def row(self) -> np.ndarray:
        """This command as a row of the kernel's command table."""
        nan = math.nan
        mode, value = MODE_KEEP, 0.0
        if self.effort is not None:
            mode, value = MODE_EFFORT, float(self.effort)
        elif self.hold_kmh is not None:
            mode, value = MODE_HOLD, float(kmh_to_mps(self.hold_kmh))
        elif self.follow:
            mode = MODE_PROFILE
        return np.array(
            [
                nan if self.at_s is None else self.at_s,
                nan if self.at_m is None else self.at_m,
                nan if self.below_kmh is None else float(kmh_to_mps(self.below_kmh)),
                nan if self.above_kmh is None else float(kmh_to_mps(self.above_kmh)),
                float(mode),
                value,
                nan if self.reduction_kpa is None else self.reduction_kpa,
                1.0 if self.emergency else 0.0,
            ]
        )


@dataclass(frozen=True)
class ConsistDriver:
    """The driver on the lead locomotive: a script, and how a held speed or a profile is
    driven (docs/consist-run.md, "`railpilot drive` on the consist").

    ``profile_m``, ``profile_mps``: a speed [m/s] by head position [m] that the mode
    ``follow`` tracks. Speed holding is a PI law on the lead's speed error giving the
    effort fraction (``kp`` per m/s, ``ki`` per m); in ``follow``, on top of it, the
    effort the profile's acceleration takes against the running resistance and the line
    (:func:`_plan_effort`). In ``follow`` the driver reads the profile ahead
    (LOOK_AHEAD_M, past the distance the air brake builds up in, ``stop_lead_s``) and
    applies the air brake for what regeneration at its limit and the line do not give
    towards a lower speed there, as a reduction of that depth (at least
    ``cycle_reduction_kpa``, at most full service; deepened, never eased); where the
    profile holds a speed that regeneration at its limit cannot, an application of
    ``cycle_reduction_kpa`` once the train, at its present acceleration, would be
    ``apply_above_kmh`` over it after ``stop_lead_s``. It releases in full when the
    train has fallen ``release_below_kmh`` under the profile, never below
    ``min_release_kmh`` (and always at a stand short of the stop), and draws no traction
    while applied nor for ``release_wait_s`` after a release (the brakes release along
    the train meanwhile). ``stop_m``: where a profile's stop is. The stop's application
    is ``stop_reduction_kpa``, or with ``stop_net_mps2`` > 0 the one that brakes the train
    at that deceleration net of the line (:func:`_stop_reduction_kpa`); the driver makes
    it where its prediction of the stop (:func:`_stop_distance_m`) reaches ``stop_m``, and
    then trims to the stop point (:func:`_stop_trim`). Within APPROACH_FACTOR times the
    stop's distance, the profile's braking to the stop is the stop's application's, not
    a cycle's. ``end_at_rest``: the run ends when the script is done (or the profile's
    stop reached) and the train stands.
    """

    commands: tuple[DriverCommand, ...] = ()
    profile_m: tuple[float, ...] = ()
    profile_mps: tuple[float, ...] = ()
    kp: float = 1.0
    ki: float = 0.002
    apply_above_kmh: float = 1.0
    release_below_kmh: float = 5.0
    min_release_kmh: float = 30.0
    cycle_reduction_kpa: float = 50.0
    stop_m: float = math.inf
    stop_reduction_kpa: float = 70.0
    stop_net_mps2: float = 0.0
    stop_lead_s: float = 18.0
    release_wait_s: float = 150.0
    end_at_rest: bool = True

    def __post_init__(self) -> None:
        if len(self.profile_m) != len(self.profile_mps):
            raise ConfigError(
                "driver.profile", len(self.profile_mps), "as many speeds as positions"
            )
        if self.profile_m and np.any(np.diff(self.profile_m) <= 0.0):
            raise ConfigError("driver.profile_m", "not increasing", "increasing positions")
        for name in ("kp", "ki", "apply_above_kmh", "release_below_kmh", "min_release_kmh"):
            check_number(f"driver.{name}", getattr(self, name), minimum=0.0, error=ConfigError)
        check_number(
            "driver.cycle_reduction_kpa",
            self.cycle_reduction_kpa,
            positive=True,
            error=ConfigError,
        )


@dataclass(frozen=True)
class ConsistRunSettings:
    """How a consist run is stepped and what it keeps.

    ``dt_s``: the outer step (driver, drive, air brake; the dynamics substep at their
    own stable step); ``duration_s``: the longest run; ``record_every_s``: the spacing of
    the recorded fields; ``distributed_power``: the remote units follow the lead by
    radio (False: they stand idle and their brake valves are cut out, as in a train
    without a radio link); ``coupler_limit_kn``: the limit whose exceedance is timed;
    ``lump``: wagons per mass (1: one mass per vehicle); ``start_m``, ``start_kmh``:
    where the head starts and how fast; ``compare_without_distributed_power``: run the
    scenario a second time with ``distributed_power`` off (the command line reports both).
    """

    dt_s: float = 0.05
    duration_s: float = 3_600.0
    record_every_s: float = 1.0
    distributed_power: bool = True
    coupler_limit_kn: float = DEFAULT_COUPLER_LIMIT_N / 1e3
    lump: int = 1
    start_m: float = 0.0
    start_kmh: float = 0.0
    compare_without_distributed_power: bool = False

    def __post_init__(self) -> None:
        check_number("sim.dt_s", self.dt_s, positive=True, maximum=0.2, error=ConfigError)
        check_number(
            "sim.duration_s",
            self.duration_s,
            positive=True,
            maximum=7 * 86_400.0,
            error=ConfigError,
        )
        check_number("sim.record_every_s", self.record_every_s, positive=True, error=ConfigError)
        check_number(
            "sim.coupler_limit_kn", self.coupler_limit_kn, positive=True, error=ConfigError
        )
        check_number("sim.start_kmh", self.start_kmh, minimum=0.0, maximum=200.0, error=ConfigError)
        if not isinstance(self.lump, int) or isinstance(self.lump, bool) or self.lump < 1:
            raise ConfigError("sim.lump", self.lump, "an integer >= 1")


@dataclass(frozen=True)
class ConsistScenario:
    """Everything one consist run needs."""

    name: str
    consist: Consist
    line: Line
    driver: ConsistDriver = field(default_factory=ConsistDriver)
    air: FreightAirBrake = field(default_factory=FreightAirBrake)
    sim: ConsistRunSettings = field(default_factory=ConsistRunSettings)

    def __post_init__(self) -> None:
        # a reduction is the driver's at the brake valve: none below the minimum (the
        # distributors would not all apply), none beyond full service (nothing more)
        low = self.air_brake.min_reduction_kpa
        high = self.air_brake.full_service_reduction_kpa()
        allowed = f"0 (a release) or a reduction in [{low:g}, {high:.4g}] kPa"
        for i, command in enumerate(self.driver.commands):
            r = command.reduction_kpa
            if r is not None and r != 0.0 and not low <= r <= high:
                raise ConfigError(f"driver.commands[{i}].reduction_kpa", r, allowed)
        for name in ("cycle_reduction_kpa", "stop_reduction_kpa"):
            r = getattr(self.driver, name)
            if not low <= r <= high:
                raise ConfigError(f"driver.{name}", r, allowed[allowed.index("a reduction") :])

    @property
    def air_brake(self) -> FreightAirBrake:
        """The air brake as charged on this consist (its ``brake_pipe_kpa``)."""
        return dataclasses.replace(self.air, charged_kpa=self.consist.brake_pipe_kpa)


@dataclass
class ConsistResult:
    """One consist run: time series of the train, fields along it, metrics, metadata.

    ``series``: 1-D arrays by name (time, head position and speed, forces); ``fields``:
    2-D arrays (recorded sample x coupling or vehicle): ``coupler_force_n`` (+ tension),
    ``brake_pipe_kpa``, ``aux_reservoir_kpa``, ``brake_cylinder_kpa``, ``speed_mps``;
    ``metrics``: the run's figures (docs/consist-run.md); ``events``: the driver's
    brake applications and releases.
    """

    series: dict[str, np.ndarray]
    fields: dict[str, np.ndarray]
    metrics: dict[str, float | int | None]
    events: dict[str, list[Any]]
    meta: dict[str, Any]

    def summary(self) -> dict[str, Any]:
        return dict(self.metrics)


class ConsistInputs(NamedTuple):
    """The compiled loop's inputs (arrays only)."""

    driver: np.ndarray  # N_DRIVER
    commands: np.ndarray  # (k, N_CMD)
    profile_m: np.ndarray
    profile_v2: np.ndarray  # the profile's speeds squared [m^2/s^2]
    loco: np.ndarray  # (n_loco, 7): vehicle, T0, PT, vmax, E0, PE, fade
    remote: np.ndarray  # (n_loco,) 1.0 for a remote unit
    valve_of_loco: np.ndarray  # (n_loco,) index into the valves, -1: no valve
    brake_force_n: np.ndarray  # (n_vehicles,) full-service friction force of each vehicle
    mass_of_vehicle: np.ndarray  # (n_vehicles,) the mass a vehicle belongs to
    charged_kpa: float
    full_service_bc_kpa: float


@njit(cache=True, inline="always")
def _profile_speed(x: float, xs: np.ndarray, v2: np.ndarray) -> float:
    """The profile's speed [m/s] at ``x`` [m]: ``v^2`` [m^2/s^2] linear between knots
    (uniform acceleration, as the planner's passes compute it), held beyond the ends."""
    return math.sqrt(interp_at(x, xs, v2)) if xs.shape[0] > 0 else 0.0


#: within this of the charged pressure (pipe, reservoirs) and of 0 (cylinders) the air
#: brake counts as charged and released [kPa]
QUIET_KPA = 0.5


@njit(cache=True)
def _charged_and_released(air_p: np.ndarray, air_s: np.ndarray, charged_kpa: float) -> bool:
    """Whether the air brake is charged and released everywhere (within QUIET_KPA)."""
    bp = freight_air.bp_kpa(air_p, air_s)
    ar = freight_air.ar_kpa(air_p, air_s)
    bc = freight_air.bc_kpa(air_p, air_s)
    for i in range(bp.shape[0]):
        if abs(bp[i] - charged_kpa) > QUIET_KPA or bc[i] > QUIET_KPA:
            return False
        if abs(ar[i] - charged_kpa) > QUIET_KPA:
            return False
    return True


@njit(cache=True)
def _plan_effort(
    inp: ConsistInputs, drv: np.ndarray, head_m: float, v_mps: float, line: float
) -> float:
    """The effort (a share of the locomotives' envelopes at ``v_mps``, in [-1, 1]) that
    gives the plan's acceleration at the head's position against the train's running
    resistance and the line under it (``line``: its gradient and curve resistance
    [N/kN]): the speed law's feedforward, so that the train
    keeps to the plan where it accelerates at full traction (from a stand above all,
    where a speed error alone starts it slowly) and holds its speed on a grade."""
    v2_here = interp_at(head_m, inp.profile_m, inp.profile_v2)
    v2_ahead = interp_at(head_m + FEEDFORWARD_DX_M, inp.profile_m, inp.profile_v2)
    accel = (v2_ahead - v2_here) / (2.0 * FEEDFORWARD_DX_M)
    kmh = v_mps * KMH_PER_MPS
    davis = drv[DP_DAVIS_A0] + drv[DP_DAVIS_A1] * kmh + drv[DP_DAVIS_A2] * kmh * kmh
    resist = (line + davis) * drv[DP_WEIGHT_SHARE] * G_MPS2 / 1000.0
    force = drv[DP_EFFECTIVE_MASS_KG] * (accel + resist)
    envelope = 0.0
    for j in range(inp.loco.shape[0]):
        loco = inp.loco[j]
        if force >= 0.0:
            envelope += traction_force_max(v_mps, loco[1], loco[2], loco[3])
        else:
            envelope += regen_force_max(v_mps, loco[4], loco[5], loco[6])
    if envelope <= 0.0:
        return 0.0
    return min(max(force / envelope, -1.0), 1.0)


@njit(cache=True)
def _line_decel_ahead(
    dyn: Any, drv: np.ndarray, head_m: float, to_go_m: float, length_m: float
) -> float:
    """The line's deceleration [m/s^2] (gradients and curves; negative on a descent) on
    the train's way to its stop ``to_go_m`` [m] ahead: the mean over STOP_LINE_SAMPLES."""
    total = 0.0
    for share in STOP_LINE_SAMPLES:
        total += mean_specific_resistance(
            dyn.edges_m,
            dyn.cumulative,
            dyn.values_n_per_kn,
            head_m + share * to_go_m,
            length_m,
            1.0,
        )
    mean_n_per_kn = total / STOP_LINE_SAMPLES.shape[0]
    return mean_n_per_kn * drv[DP_WEIGHT_SHARE] * G_MPS2 / 1000.0


@njit(cache=True)
def _stop_reduction_kpa(drv: np.ndarray, line_mps2: float) -> float:
    """The reduction [kPa] the stop is made with: ``stop_reduction_kpa``, or with a
    ``stop_net_mps2`` the one that slows the train at that deceleration net of the line
    (on a descent the air adds what the line takes away; on a climb the line's help is
    not counted on), at least ``cycle_reduction_kpa`` and at most full service."""
    if drv[DP_STOP_NET_MPS2] <= 0.0:
        return drv[DP_STOP_REDUCTION_KPA]
    air_mps2 = drv[DP_STOP_NET_MPS2] + max(-line_mps2, 0.0)
    wanted = air_mps2 * drv[DP_KPA_PER_MPS2]
    return min(max(wanted, drv[DP_CYCLE_REDUCTION_KPA]), drv[DP_FULL_REDUCTION_KPA])


@njit(cache=True)
def _stop_distance_m(
    drv: np.ndarray, v_mps: float, line_mps2: float, air_now_mps2: float, air_built_mps2: float
) -> float:
    """Where [m ahead] the train stops from ``v_mps``: the line's deceleration, the
    train's running resistance and the air brake's, going from ``air_now_mps2`` to
    ``air_built_mps2`` as the cylinders fill (a first-order approach of the train's fill
    time: air_fill_time_s); inf where it would not stop."""
    fill_s = drv[DP_AIR_FILL_S]
    per_n_per_kn = drv[DP_WEIGHT_SHARE] * G_MPS2 / 1000.0
    x = 0.0
    v = v_mps
    t = 0.0
    h = STOP_PREDICTION_STEP_S
    while v > 0.0:
        kmh = v * KMH_PER_MPS
        davis = drv[DP_DAVIS_A0] + drv[DP_DAVIS_A1] * kmh + drv[DP_DAVIS_A2] * kmh * kmh
        # the air brake at the middle of the step (second order in the step)
        fill = math.exp(-(t + 0.5 * h) / fill_s)
        a = line_mps2 + davis * per_n_per_kn + air_built_mps2
        a += (air_now_mps2 - air_built_mps2) * fill
        if a <= 0.0 and line_mps2 + air_built_mps2 <= 0.0 and t > 5.0 * fill_s:
            return math.inf
        step = h
        if a > 0.0 and a * h > v:
            step = v / a
        x += v * step - 0.5 * a * step * step
        v -= a * step
        t += step
    return x


@njit(cache=True)
def _air_decel_mps2(inp: ConsistInputs, bc: np.ndarray, mass_kg: float) -> float:
    """The deceleration [m/s^2] the brake cylinders give now."""
    force = 0.0
    for i in range(bc.shape[0]):
        force += inp.brake_force_n[i] * bc[i] / inp.full_service_bc_kpa
    return force / mass_kg


@njit(cache=True)
def _air_built_mps2(
    inp: ConsistInputs, air_p: np.ndarray, air_s: np.ndarray, mass_kg: float, reduction: float
) -> float:
    """The deceleration [m/s^2] the brake cylinders give once settled at ``reduction``
    [kPa]: each distributor's auxiliary reservoir, as charged as it is now, gives its
    cylinder air until it laps at the pipe or equalizes with the cylinder (the mass
    balance of freight_air.service_bc_kpa); a reservoir not recharged since the last
    application gives less."""
    rho = air_p[freight_air.P_RHO]
    pipe = inp.charged_kpa - reduction
    ar = freight_air.ar_kpa(air_p, air_s)
    bc = freight_air.bc_kpa(air_p, air_s)
    force = 0.0
    for i in range(bc.shape[0]):
        a0 = ar[i]
        c0 = bc[i]
        a_eq = a0 - max(a0 - c0, 0.0) / (1.0 + rho)
        a_end = min(max(pipe, a_eq), a0)
        force += inp.brake_force_n[i] * (c0 + rho * (a0 - a_end)) / inp.full_service_bc_kpa
    return force / mass_kg


@njit(cache=True)
def _stop_trim(
    inp: ConsistInputs,
    drv: np.ndarray,
    air_p: np.ndarray,
    air_s: np.ndarray,
    v_lead: float,
    to_go: float,
    line_mps2: float,
    reduction: float,
) -> tuple[float, float]:
    """The driver's effort and reduction [kPa] on the stop's application: it predicts
    where the application stops the train (what the cylinders give now, going to what the
    reduction gives once they have filled) and makes up the difference to the stop
    ``to_go`` [m] ahead with regeneration, then by deepening the reduction (deepened,
    never eased: a direct-release brake releases only in full); where the application
    would stop the train short, with a bounded traction against it (STOP_STRETCH_EFFORT:
    stretch braking)."""
    mass = drv[DP_EFFECTIVE_MASS_KG]
    v = max(v_lead, 0.0)
    if to_go <= 0.0 or v <= 0.0:
        return -1.0, reduction
    air_now = _air_decel_mps2(inp, freight_air.bc_kpa(air_p, air_s), mass)
    air_built = _air_built_mps2(inp, air_p, air_s, mass, reduction)
    predicted = _stop_distance_m(drv, v, line_mps2, air_now, max(air_built, air_now))
    # the deceleration the stop needs over the one the application gives
    short_mps2 = v * v / (2.0 * to_go) - v * v / (2.0 * predicted)
    regen_n = 0.0
    traction_n = 0.0
    for j in range(inp.loco.shape[0]):
        loco = inp.loco[j]
        regen_n += regen_force_max(v, loco[4], loco[5], loco[6])
        traction_n += traction_force_max(v, loco[1], loco[2], loco[3])
    if short_mps2 >= 0.0:
        effort = -min(short_mps2 * mass / regen_n, 1.0) if regen_n > 0.0 else 0.0
        # the air brake deepened for what half of regeneration's reach does not give:
        # regeneration, fast, keeps the other half to trim with as the cylinders fill
        beyond_mps2 = short_mps2 - STOP_REGEN_SHARE * regen_n / mass
        if beyond_mps2 > 0.0:
            wanted = reduction + beyond_mps2 * drv[DP_KPA_PER_MPS2]
            reduction = min(wanted, drv[DP_FULL_REDUCTION_KPA])
        return effort, reduction
    effort = 0.0
    if traction_n > 0.0:
        effort = min(-short_mps2 * mass / traction_n, STOP_STRETCH_EFFORT)
    return effort, reduction


@njit(cache=True)
def consist_kernel(
    inp: ConsistInputs,
    dyn: Any,
    dyn_state: np.ndarray,
    air_p: np.ndarray,
    air_s: np.ndarray,
    electric: np.ndarray,
    ring: np.ndarray,
    dt: float,
    k_stop: int,
    record_every: int,
    rec_scalar: np.ndarray,
    rec_coupler: np.ndarray,
    rec_bp: np.ndarray,
    rec_ar: np.ndarray,
    rec_bc: np.ndarray,
    metrics: np.ndarray,
    events: np.ndarray,
    release_air: np.ndarray,
) -> None:
    """Run the consist from step ``metrics[M_STEPS]`` up to step ``k_stop`` (or until it
    ends at rest); everything it carries from one call to the next is in its arguments.

    ``electric``: each locomotive's electric force [N, + forward]; ``ring``: the lead's
    commands on their way to the remote units (one row a step of the radio delay);
    ``events[i] = (time, kind, head_m)`` (kind 1: application, 2: release, 3:
    emergency); ``release_air[r]``: the air brake's state at release ``r`` (for its
    recharge time). The ``rec_*`` arrays get a row every ``record_every`` steps.
    """
    drv = inp.driver
    cmds = inp.commands
    n_cmd = cmds.shape[0]
    n_loco = inp.loco.shape[0]
    n_valves = 0
    for j in range(n_loco):
        if inp.valve_of_loco[j] >= 0:
            n_valves += 1
    n_mass = dyn.mass_kg.shape[0]
    positions = ltd.positions_m(dyn_state, n_mass)
    speeds = ltd.speeds_mps(dyn_state, n_mass)
    forces = ltd.coupler_force_n(dyn_state, n_mass)
    bc = freight_air.bc_kpa(air_p, air_s)
    drive_n = np.zeros(n_mass)
    brake_n = np.zeros(n_mass)
    er = np.full(n_valves, inp.charged_kpa)
    emerg = np.zeros(n_valves)
    delay_steps = ring.shape[0] - 1
    lag = math.exp(-dt / drv[DP_LAG_S]) if drv[DP_LAG_S] > 0.0 else 0.0
    limit = drv[DP_LIMIT_N]
    next_cmd = int(metrics[C_NEXT_CMD])
    mode = int(metrics[C_MODE])
    value = metrics[C_VALUE]
    reduction = metrics[C_REDUCTION]
    emergency = metrics[C_EMERGENCY] > 0.5
    integral = metrics[C_INTEGRAL]
    applied = metrics[C_APPLIED] > 0.5
    stopping = metrics[C_STOPPING] > 0.5
    stop_since = metrics[C_STOP_SINCE]
    n_events = int(metrics[C_N_EVENTS])
    n_rec = int(metrics[C_N_REC])
    has_moved = metrics[C_HAS_MOVED] > 0.5
    released_at = metrics[C_RELEASED_AT]
    accel = metrics[C_ACCEL]
    n_rec_max = rec_scalar.shape[0]
    length_m = drv[DP_LENGTH_M]
    k = int(metrics[M_STEPS])
    # a brake charged and released, with every valve at the charged pressure, stays so:
    # its step is skipped (on a long run most of the time)
    quiet = _charged_and_released(air_p, air_s, inp.charged_kpa)
    effort = 0.0
    while k < k_stop and metrics[C_ENDED] < 0.5:
        t = k * dt
        head_m = positions[0]
        v_lead = speeds[0]
        # --- the script
        while next_cmd < n_cmd:
            row = cmds[next_cmd]
            ready = True
            if row[CMD_AT_S] == row[CMD_AT_S] and t < row[CMD_AT_S]:
                ready = False
            if row[CMD_AT_M] == row[CMD_AT_M] and head_m < row[CMD_AT_M]:
                ready = False
            if row[CMD_BELOW_MPS] == row[CMD_BELOW_MPS] and v_lead >= row[CMD_BELOW_MPS]:
                ready = False
            if row[CMD_ABOVE_MPS] == row[CMD_ABOVE_MPS] and v_lead <= row[CMD_ABOVE_MPS]:
                ready = False
            if not ready:
                break
            if row[CMD_MODE] != MODE_KEEP:
                mode = int(row[CMD_MODE])
                value = row[CMD_VALUE]
                integral = 0.0
            if row[CMD_REDUCTION_KPA] == row[CMD_REDUCTION_KPA]:
                reduction = row[CMD_REDUCTION_KPA]
            if row[CMD_EMERGENCY] > 0.5:
                emergency = True
            next_cmd += 1
        # --- the lead's effort
        effort = 0.0
        if mode == MODE_EFFORT:
            effort = value
        elif mode in (MODE_HOLD, MODE_PROFILE):
            goal = value
            if mode == MODE_PROFILE:
                # a floor, so that a profile from rest starts the train
                goal = max(_profile_speed(head_m, inp.profile_m, inp.profile_v2), MIN_GOAL_MPS)
            err = goal - v_lead
            raw = drv[DP_KP] * err + drv[DP_KI] * integral
            w_line = 0.0
            if mode == MODE_PROFILE:
                # the line under the train: the feedforward's, the stop's and the cycles'
                w_line = mean_specific_resistance(
                    dyn.edges_m, dyn.cumulative, dyn.values_n_per_kn, head_m, length_m, 1.0
                )
                raw += _plan_effort(inp, drv, head_m, v_lead, w_line)
            if -1.0 < raw < 1.0 or raw * err < 0.0:
                integral += err * dt  # conditional integration: no wind-up at a limit
            effort = min(max(raw, -1.0), 1.0)
            if mode == MODE_PROFILE and not emergency:
                # the stop: its application where the driver's prediction of where it
                # stops the train reaches the stop point; then the trim to the point
                to_go = drv[DP_STOP_M] - head_m
                # the stop's air brake, with the line's gradients and curves on the way to
                # the stop helping or against it (a descent lengthens the stop)
                line_stop = _line_decel_ahead(dyn, drv, head_m, max(to_go, 0.0), length_m)
                stop_kpa = _stop_reduction_kpa(drv, line_stop)
                air_stop = stop_kpa / drv[DP_KPA_PER_MPS2]
                decel = max(air_stop + line_stop, MIN_STOP_DECEL)
                needed = v_lead * drv[DP_AIR_FILL_S] + v_lead * v_lead / (2.0 * decel)
                # where the application, building up along the train, stops it
                if (
                    to_go <= STOP_WATCH_FACTOR * needed
                    and not stopping
                    and to_go
                    <= _stop_distance_m(
                        drv,
                        v_lead,
                        line_stop,
                        _air_decel_mps2(inp, bc, drv[DP_EFFECTIVE_MASS_KG]),
                        _air_built_mps2(
                            inp, air_p, air_s, drv[DP_EFFECTIVE_MASS_KG], max(reduction, stop_kpa)
                        ),
                    )
                ):
                    stopping = True
                    stop_since = t
                    reduction = max(reduction, stop_kpa)
                if stopping:
                    law = effort
                    effort, reduction = _stop_trim(
                        inp, drv, air_p, air_s, v_lead, to_go, line_stop, reduction
                    )
                    if head_m < drv[DP_FINAL_BRAKING_M]:
                        # a lower planned speed before the plan's own braking to the stop
                        # (a lower limit short of the station): the speed law keeps the
                        # train to it whatever the stop's application would allow
                        effort = min(effort, law)
                else:
                    # the air the plan ahead asks for: the deepest deceleration to any
                    # of its speeds ahead (the air's build-up run first), less what the
                    # line and full regeneration give, as a reduction (linear in the
                    # deceleration up to full service); deepened, never eased (a
                    # direct-release brake releases only in full)
                    lead = drv[DP_STOP_LEAD_S]
                    kinematic = 0.0
                    approach_m = drv[DP_STOP_M] - APPROACH_FACTOR * needed
                    # from the plan's speed here: a train a little over it is the speed
                    # law's to bring back (or a braking cycle's, below), not a reason
                    # for an application towards a speed just ahead
                    v_plan = min(v_lead, goal)
                    for look in LOOK_AHEAD_M:
                        ahead_m = look - v_lead * lead
                        # the plan's own stop is the stop's application's to brake for;
                        # a speed so near that the air would spend most of the way to it
                        # building up is the speed law's (regeneration) to reach
                        if ahead_m >= 0.5 * look and head_m + look < approach_m:
                            g_ahead = _profile_speed(head_m + look, inp.profile_m, inp.profile_v2)
                            if v_plan > g_ahead:
                                kinematic = max(
                                    kinematic, (v_plan**2 - g_ahead**2) / (2.0 * ahead_m)
                                )
                    regen_mps2 = 0.0
                    for j in range(n_loco):
                        loco = inp.loco[j]
                        regen_mps2 += regen_force_max(v_lead, loco[4], loco[5], loco[6])
                    regen_mps2 /= drv[DP_EFFECTIVE_MASS_KG]
                    line_mps2 = w_line * G_MPS2 / 1000.0
                    # regeneration, which acts within its lag, follows the plan's own
                    # braking curves (the speed law above); the air brake, which takes a
                    # build-up along the train, is applied ahead of them for what
                    # regeneration at its limit and the line do not give
                    air_mps2 = kinematic - line_mps2 - regen_mps2
                    wanted = 0.0
                    # worth an application: at least half what the least one gives
                    least = 0.5 * drv[DP_CYCLE_REDUCTION_KPA] / drv[DP_KPA_PER_MPS2]
                    # on the approach, the plan's braking to the stop is the stop's
                    # application's (its prediction times it), not a cycle's
                    approach = to_go <= APPROACH_FACTOR * needed
                    if kinematic > 0.0 and air_mps2 > least and not approach:
                        wanted = min(
                            max(air_mps2 * drv[DP_KPA_PER_MPS2], drv[DP_CYCLE_REDUCTION_KPA]),
                            drv[DP_FULL_REDUCTION_KPA],
                        )
                    # braking cycles where the plan holds its speed: apply when the train,
                    # at its present acceleration, will be over it once the air has built
                    # up with regeneration already at its limit (on the approach too, for
                    # a lower limit short of the station)
                    speeding = v_lead + max(accel, 0.0) * lead
                    # on the approach, once the plan brakes to the stop, its application
                    # is the stop's (a cycle's here cannot be eased before it)
                    to_stop = approach and head_m >= drv[DP_FINAL_BRAKING_M]
                    if effort <= -1.0 and speeding > goal + drv[DP_APPLY_ABOVE_MPS] and not to_stop:
                        wanted = max(wanted, drv[DP_CYCLE_REDUCTION_KPA])
                    if v_lead <= 0.0 and has_moved:
                        # at a stand short of the stop: release, go on once released
                        reduction = 0.0
                    elif wanted > reduction:
                        reduction = wanted
                    elif (
                        reduction > 0.0
                        and wanted == 0.0
                        and v_lead < goal - drv[DP_RELEASE_BELOW_MPS]
                        and v_lead > drv[DP_MIN_RELEASE_MPS]
                    ):
                        reduction = 0.0
                if not stopping and (reduction > 0.0 or t < released_at + drv[DP_RELEASE_WAIT_S]):
                    # no traction against the air brake, nor while it releases (the stop's
                    # stretch braking apart: _stop_trim)
                    effort = min(effort, 0.0)
        if emergency:
            effort = 0.0
        er_lead = inp.charged_kpa - reduction
        if emergency:
            er_lead = 0.0
        # the driver's brake actions, counted at the lead's valve
        now_applied = emergency or reduction > 0.0
        if now_applied != applied and n_events < events.shape[0]:
            kind = 1.0 if now_applied else 2.0
            if emergency:
                kind = 3.0
            events[n_events, 0] = t
            events[n_events, 1] = kind
            events[n_events, 2] = head_m
            n_events += 1
            if kind == 2.0:
                released_at = t
                r = int(metrics[M_RELEASES])
                if r < release_air.shape[0]:
                    release_air[r, :] = air_s
                metrics[M_RELEASES] += 1.0
            else:
                metrics[M_APPLICATIONS] += 1.0
            if kind == 3.0:
                metrics[M_EMERGENCY_T] = t
                metrics[M_EMERGENCY_V] = v_lead
                metrics[M_EMERGENCY_X] = head_m
        applied = now_applied
        # --- distributed power: the remote units act on the lead's command of a radio
        # delay ago (the ring's oldest row; the row written ``delay_steps`` steps ago)
        slot = k % (delay_steps + 1)
        ring[slot, 0] = effort
        ring[slot, 1] = er_lead
        ring[slot, 2] = 1.0 if emergency else 0.0
        if k >= delay_steps:
            old = (k + 1) % (delay_steps + 1)
            late_effort, late_er, late_em = ring[old, 0], ring[old, 1], ring[old, 2]
        else:
            # nothing has reached the remote units yet: they hold what they had
            late_effort, late_er, late_em = 0.0, inp.charged_kpa, 0.0
        valve = 0
        for j in range(n_loco):
            loco = inp.loco[j]
            v_j = speeds[int(inp.mass_of_vehicle[int(loco[0])])]
            is_remote = inp.remote[j] > 0.5
            e_j = effort
            if is_remote:
                e_j = late_effort if drv[DP_REMOTES_FOLLOW] > 0.5 else 0.0
            t_max = traction_force_max(v_j, loco[1], loco[2], loco[3])
            r_max = regen_force_max(v_j, loco[4], loco[5], loco[6])
            target = e_j * t_max if e_j >= 0.0 else e_j * r_max
            # the drive's lag, then never beyond the envelope at this speed
            f = target + (electric[j] - target) * lag
            electric[j] = min(max(f, -r_max), t_max)
            if inp.valve_of_loco[j] >= 0:
                if is_remote:
                    er[valve] = late_er
                    emerg[valve] = late_em
                else:
                    er[valve] = er_lead
                    emerg[valve] = 1.0 if emergency else 0.0
                valve += 1
        # --- the air brake, then each mass's forces, then the dynamics
        if not (quiet and reduction == 0.0 and not emergency and late_er == inp.charged_kpa):
            freight_air.freight_air_step(air_p, air_s, er, emerg, dt)
            quiet = _charged_and_released(air_p, air_s, inp.charged_kpa)
        drive_n[:] = 0.0
        for j in range(n_loco):
            drive_n[int(inp.mass_of_vehicle[int(inp.loco[j, 0])])] += electric[j]
        brake_n[:] = 0.0
        for i in range(bc.shape[0]):
            brake_n[int(inp.mass_of_vehicle[i])] += (
                inp.brake_force_n[i] * bc[i] / inp.full_service_bc_kpa
            )
        ltd.ltd_step(dyn, dyn_state, drive_n, brake_n, dt)
        # the lead's acceleration, smoothed over ACCEL_SMOOTHING_S (what a driver reads)
        accel += ((speeds[0] - v_lead) / dt - accel) * min(dt / ACCEL_SMOOTHING_S, 1.0)
        # --- metrics: the forces' work over the step at each mass's speed
        trac = 0.0
        regen = 0.0
        air = 0.0
        for i in range(n_mass):
            work = drive_n[i] * speeds[i] * dt
            if work > 0.0:
                trac += work
            else:
                regen -= work
            air += brake_n[i] * speeds[i] * dt
        metrics[M_E_TRACTION_J] += trac
        metrics[M_E_REGEN_J] += regen
        metrics[M_E_AIR_J] += air
        # traction pulling against the air brake: the smaller of the two (sim/engine.py)
        metrics[M_E_TRAC_AIR_J] += min(trac, air)
        over = False
        for i in range(forces.shape[0]):
            f = forces[i]
            if f > metrics[M_MAX_TENSION_N]:
                metrics[M_MAX_TENSION_N] = f
                metrics[M_MAX_TENSION_AT] = i
                metrics[M_MAX_TENSION_T] = t + dt
            if -f > metrics[M_MAX_COMPRESSION_N]:
                metrics[M_MAX_COMPRESSION_N] = -f
                metrics[M_MAX_COMPRESSION_AT] = i
                metrics[M_MAX_COMPRESSION_T] = t + dt
            if abs(f) > limit:
                over = True
        if over:
            metrics[M_OVER_LIMIT_S] += dt
        moving = False
        for i in range(n_mass):
            if speeds[i] > AT_REST_MPS:
                moving = True
            if speeds[i] > metrics[M_MAX_SPEED_MPS]:
                metrics[M_MAX_SPEED_MPS] = speeds[i]
        if moving:
            has_moved = True
        if k % record_every == 0 and n_rec < n_rec_max:
            rec_scalar[n_rec, 0] = t + dt
            rec_scalar[n_rec, 1] = positions[0]
            rec_scalar[n_rec, 2] = speeds[0]
            pull = 0.0
            hold = 0.0
            for j in range(n_loco):
                if electric[j] > 0.0:
                    pull += electric[j]
                else:
                    hold -= electric[j]
            rec_scalar[n_rec, 3] = pull
            rec_scalar[n_rec, 4] = hold
            rec_scalar[n_rec, 5] = np.sum(brake_n)
            rec_scalar[n_rec, 6] = effort
            rec_scalar[n_rec, 7] = er_lead
            rec_coupler[n_rec, :] = forces
            rec_bp[n_rec, :] = freight_air.bp_kpa(air_p, air_s)
            rec_ar[n_rec, :] = freight_air.ar_kpa(air_p, air_s)
            rec_bc[n_rec, :] = bc
            n_rec += 1
        k += 1
        done = next_cmd >= n_cmd and (mode != MODE_PROFILE or stopping)
        if drv[DP_END_AT_REST] > 0.5 and has_moved and not moving and done:
            metrics[M_STOP_T] = t + dt
            metrics[C_ENDED] = 1.0
    metrics[M_STEPS] = k
    metrics[M_FINAL_X] = positions[0]
    metrics[C_NEXT_CMD] = next_cmd
    metrics[C_MODE] = mode
    metrics[C_VALUE] = value
    metrics[C_REDUCTION] = reduction
    metrics[C_EMERGENCY] = 1.0 if emergency else 0.0
    metrics[C_INTEGRAL] = integral
    metrics[C_APPLIED] = 1.0 if applied else 0.0
    metrics[C_STOPPING] = 1.0 if stopping else 0.0
    metrics[C_STOP_SINCE] = stop_since
    metrics[C_N_EVENTS] = n_events
    metrics[C_N_REC] = n_rec
    metrics[C_HAS_MOVED] = 1.0 if has_moved else 0.0
    metrics[C_RELEASED_AT] = released_at
    metrics[C_ACCEL] = accel


def final_braking_m(profile_m: Any, profile_mps: Any) -> float:
    """Where [m] a profile's last braking begins: going back from its end, the last
    point from which its speed only falls (-inf for an empty profile)."""
    speeds = np.asarray(profile_mps, dtype=float)
    if speeds.shape[0] == 0:
        return -math.inf
    j = speeds.shape[0] - 1
    while j > 0 and speeds[j - 1] > speeds[j]:
        j -= 1
    return float(np.asarray(profile_m, dtype=float)[j])


def air_fill_time_s(air_p: np.ndarray, air_s: np.ndarray, n_valves: int, dt: float) -> float:
    """How long [s] the brake cylinders of this train take to fill to 63 % of what a
    FILL_PROBE_KPA reduction gives them (mean over the train), from charged and released:
    the time constant the driver's stop is predicted with. Run on a copy of the air brake
    (``air_p``, ``air_s``: the stepper's, charged)."""
    state = air_s.copy()
    charged = float(np.max(freight_air.bp_kpa(air_p, state)))
    er = np.full(n_valves, charged - FILL_PROBE_KPA)
    emergency = np.zeros(n_valves)
    steps = math.ceil(FILL_PROBE_S / dt)
    mean_bc = np.empty(steps)
    for k in range(steps):
        freight_air.freight_air_step(air_p, state, er, emergency, dt)
        mean_bc[k] = float(np.mean(freight_air.bc_kpa(air_p, state)))
    filled = np.nonzero(mean_bc >= (1.0 - math.exp(-1.0)) * mean_bc[-1])[0]
    return float((filled[0] + 1) * dt)


def _locomotive_rows(consist: Consist) -> np.ndarray:
    rows = []
    for i in consist.locomotive_indices():
        loco = consist.vehicles[int(i)].locomotive
        assert loco is not None
        vmax = loco.traction.max_speed_mps
        rows.append(
            [
                float(i),
                loco.traction.max_force_n,
                loco.traction.max_power_w,
                math.inf if vmax is None else vmax,
                loco.regen.max_force_n,
                loco.regen.max_power_w,
                loco.regen.fade_below_mps,
            ]
        )
    return np.array(rows, dtype=float)


def dynamics_inputs(
    consist: Consist, table: ResistanceTable, lump: int = 1
) -> tuple[ltd.LtdInputs, np.ndarray]:
    """The dynamics' inputs for ``consist`` on a line (``table``), with ``lump`` wagons to a
    mass (locomotives stay masses of their own), and the mass each vehicle belongs to."""
    masses = consist.masses_kg()
    gammas = consist.rotating_mass_factors()
    lengths = consist.lengths_m()
    davis = consist.davis()
    gears: Any = consist.draft_gears()
    of_vehicle = np.arange(consist.n_vehicles)
    if lump > 1:
        lumped = ltd.lump_vehicles(
            masses,
            gammas,
            lengths,
            davis,
            gears,
            lump,
            alone=[int(i) for i in consist.locomotive_indices()],
        )
        masses, gammas, lengths, davis, gears = (
            lumped.masses_kg,
            lumped.rotating_mass_factors,
            lumped.lengths_m,
            lumped.davis,
            lumped.gears,
        )
        of_vehicle = np.asarray(lumped.lump_of_vehicle)
    return ltd.pack_ltd(masses, gammas, lengths, davis, gears, table), of_vehicle


class ConsistStepper:
    """One consist run that can stop at a time and go on (the onboard re-plans between).

    :meth:`advance_to` runs to a time; :meth:`replace_profile` gives the driver a new
    profile to follow (and where its stop is); :meth:`result` gathers the run so far.
    :func:`run_consist` runs a scenario to its end in one go.
    """

    def __init__(self, scenario: ConsistScenario) -> None:
        self.scenario = scenario
        consist = scenario.consist
        settings = scenario.sim
        driver = scenario.driver
        dt = settings.dt_s
        n = consist.n_vehicles
        table = elevation_table(scenario.line)
        self.dyn, self.mass_of_vehicle = dynamics_inputs(consist, table, settings.lump)
        self.dyn_state = ltd.initial_state(
            self.dyn, settings.start_m, float(kmh_to_mps(settings.start_kmh))
        )
        locos = consist.locomotive_indices()
        remote = np.array([1.0 if consist.vehicles[int(i)].remote else 0.0 for i in locos])
        with_valve = np.ones(len(locos), dtype=bool) if settings.distributed_power else remote < 0.5
        self.n_valves = int(with_valve.sum())
        valve_of_loco = np.full(len(locos), -1.0)
        valve_of_loco[with_valve] = np.arange(self.n_valves)
        centres = consist.front_m() + consist.lengths_m() / 2.0
        air = scenario.air_brake
        self.air_p, self.air_s = freight_air.pack_freight_air(
            air,
            centres,
            np.asarray(locos[with_valve], dtype=np.int64),
            consist.direct_release(),
            consist.has_air_brake(),
        )
        drv = np.zeros(N_DRIVER)
        drv[DP_KP] = driver.kp
        drv[DP_KI] = driver.ki
        drv[DP_LAG_S] = ELECTRIC_LAG_S
        drv[DP_APPLY_ABOVE_MPS] = kmh_to_mps(driver.apply_above_kmh)
        drv[DP_RELEASE_BELOW_MPS] = kmh_to_mps(driver.release_below_kmh)
        drv[DP_MIN_RELEASE_MPS] = kmh_to_mps(driver.min_release_kmh)
        drv[DP_CYCLE_REDUCTION_KPA] = driver.cycle_reduction_kpa
        drv[DP_STOP_M] = driver.stop_m
        drv[DP_LIMIT_N] = settings.coupler_limit_kn * 1e3
        drv[DP_RADIO_DELAY_S] = consist.dp_radio_delay_s
        drv[DP_REMOTES_FOLLOW] = 1.0 if settings.distributed_power else 0.0
        drv[DP_END_AT_REST] = 1.0 if driver.end_at_rest else 0.0
        drv[DP_STOP_REDUCTION_KPA] = driver.stop_reduction_kpa
        drv[DP_STOP_LEAD_S] = driver.stop_lead_s
        drv[DP_STOP_NET_MPS2] = driver.stop_net_mps2
        drv[DP_FINAL_BRAKING_M] = final_braking_m(driver.profile_m, driver.profile_mps)
        drv[DP_AIR_FILL_S] = air_fill_time_s(self.air_p, self.air_s, self.n_valves, dt)
        # the train's running resistance (mass-weighted Davis coefficients) and its weight
        # over its effective mass, for the driver's prediction of its stop
        masses = self.dyn.mass_kg
        drv[DP_DAVIS_A0 : DP_DAVIS_A2 + 1] = masses @ self.dyn.davis / masses.sum()
        drv[DP_WEIGHT_SHARE] = float(masses.sum()) / float(consist.effective_masses_kg().sum())
        drv[DP_RELEASE_WAIT_S] = driver.release_wait_s
        drv[DP_LENGTH_M] = consist.length_m
        effective_kg = float(consist.effective_masses_kg().sum())
        drv[DP_EFFECTIVE_MASS_KG] = effective_kg
        # a full-service reduction gives every brake its full-service force
        full_mps2 = float(consist.service_brake_force_n().sum()) / effective_kg
        drv[DP_FULL_REDUCTION_KPA] = air.full_service_reduction_kpa()
        drv[DP_KPA_PER_MPS2] = air.full_service_reduction_kpa() / full_mps2
        commands = (
            np.array([c.row() for c in driver.commands])
            if driver.commands
            else np.zeros((0, N_CMD))
        )
        self.inputs = ConsistInputs(
            drv,
            commands,
            np.asarray(driver.profile_m, dtype=float),
            np.asarray(driver.profile_mps, dtype=float) ** 2,
            _locomotive_rows(consist),
            remote,
            valve_of_loco,
            consist.service_brake_force_n().astype(float),
            self.mass_of_vehicle.astype(float),
            float(consist.brake_pipe_kpa),
            float(air.full_service_bc_kpa()),
        )
        self.electric = np.zeros(len(locos))
        delay_steps = max(round(consist.dp_radio_delay_s / dt), 0)
        self.ring = np.zeros((delay_steps + 1, 3))
        self.n_steps = math.ceil(settings.duration_s / dt)
        self.record_every = max(round(settings.record_every_s / dt), 1)
        rows = self.n_steps // self.record_every + 1
        n_mass = self.dyn.mass_kg.shape[0]
        self.rec_scalar = np.zeros((rows, 8))
        self.rec_coupler = np.zeros((rows, max(n_mass - 1, 0)))
        self.rec_bp = np.zeros((rows, n))
        self.rec_ar = np.zeros((rows, n))
        self.rec_bc = np.zeros((rows, n))
        self.metrics = np.zeros(N_METRICS)
        self.metrics[[M_STOP_T, M_EMERGENCY_T, M_EMERGENCY_V, M_EMERGENCY_X]] = math.nan
        self.metrics[C_MODE] = MODE_EFFORT
        self.metrics[C_RELEASED_AT] = -math.inf
        self.events = np.zeros((4 * MAX_RELEASES, 3))
        self.release_air = np.zeros((MAX_RELEASES, self.air_s.shape[0]))

    @property
    def time_s(self) -> float:
        return float(self.metrics[M_STEPS]) * self.scenario.sim.dt_s

    @property
    def ended(self) -> bool:
        """The run is over: at rest with its script done, or at its duration."""
        return bool(self.metrics[C_ENDED] > 0.5) or self.metrics[M_STEPS] >= self.n_steps

    @property
    def position_m(self) -> float:
        return float(ltd.positions_m(self.dyn_state, self.dyn.mass_kg.shape[0])[0])

    @property
    def speed_mps(self) -> float:
        return float(ltd.speeds_mps(self.dyn_state, self.dyn.mass_kg.shape[0])[0])

    def advance_to(self, time_s: float) -> None:
        """Run up to ``time_s`` [s] (or to the run's end)."""
        k_stop = min(math.ceil(time_s / self.scenario.sim.dt_s - 1e-9), self.n_steps)
        consist_kernel(
            self.inputs,
            self.dyn,
            self.dyn_state,
            self.air_p,
            self.air_s,
            self.electric,
            self.ring,
            self.scenario.sim.dt_s,
            k_stop,
            self.record_every,
            self.rec_scalar,
            self.rec_coupler,
            self.rec_bp,
            self.rec_ar,
            self.rec_bc,
            self.metrics,
            self.events,
            self.release_air,
        )

    def run_to_end(self) -> None:
        self.advance_to(self.n_steps * self.scenario.sim.dt_s)

    def replace_profile(
        self, profile_m: np.ndarray, profile_mps: np.ndarray, stop_m: float
    ) -> None:
        """Follow a new speed profile [m/s by m] to a stop at ``stop_m`` [m] from now on."""
        driver = self.inputs.driver.copy()
        driver[DP_STOP_M] = stop_m
        driver[DP_FINAL_BRAKING_M] = final_braking_m(profile_m, profile_mps)
        self.inputs = self.inputs._replace(
            driver=driver,
            profile_m=np.asarray(profile_m, dtype=float),
            profile_v2=np.asarray(profile_mps, dtype=float) ** 2,
        )
        self.metrics[C_STOPPING] = 0.0
        self.metrics[C_ENDED] = 0.0

    def result(self) -> ConsistResult:
        return _result(
            self.scenario,
            self.metrics,
            self.events,
            self.release_air,
            self.air_p,
            self.n_valves,
            int(self.metrics[C_N_REC]),
            self.rec_scalar,
            self.rec_coupler,
            self.rec_bp,
            self.rec_ar,
            self.rec_bc,
            self.mass_of_vehicle,
        )


def run_consist(scenario: ConsistScenario) -> ConsistResult:
    """Run ``scenario``: the consist along its line under its driver, to its end."""
    stepper = ConsistStepper(scenario)
    stepper.run_to_end()
    return stepper.result()


@njit(cache=True)
def _recharge_time_s(
    air_p: np.ndarray,
    state: np.ndarray,
    n_valves: int,
    charged_kpa: float,
    within_kpa: float,
    braked: np.ndarray,
    dt: float,
    cap_s: float,
) -> float:
    """Time [s] for every braked vehicle's auxiliary reservoir to come within
    ``within_kpa`` of the charged pressure, the valves held at it from ``state`` on
    (``state`` is advanced; inf if not by ``cap_s``)."""
    er = np.full(n_valves, charged_kpa)
    em = np.zeros(n_valves)
    ar = freight_air.ar_kpa(air_p, state)
    t = 0.0
    while t < cap_s:
        low = charged_kpa
        for i in range(ar.shape[0]):
            if braked[i] and ar[i] < low:
                low = ar[i]
        if low >= charged_kpa - within_kpa:
            return t
        freight_air.freight_air_step(air_p, state, er, em, dt)
        t += dt
    return math.inf


def recharge_margins_s(
    events: np.ndarray,
    recharge_s: list[float],
) -> list[float]:
    """For each release followed by an application: the time between them less the time
    the train needed to recharge after that release [s] (negative: applied too early)."""
    margins = []
    release = 0
    for i in range(events.shape[0]):
        kind = events[i, 1]
        if kind == 2.0:
            t_rel = events[i, 0]
            for j in range(i + 1, events.shape[0]):
                if events[j, 1] in (1.0, 3.0):
                    margins.append(events[j, 0] - t_rel - recharge_s[release])
                    break
            release += 1
    return margins


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _result(
    scenario: ConsistScenario,
    metrics: np.ndarray,
    events: np.ndarray,
    release_air: np.ndarray,
    air_p: np.ndarray,
    n_valves: int,
    written: int,
    rec_scalar: np.ndarray,
    rec_coupler: np.ndarray,
    rec_bp: np.ndarray,
    rec_ar: np.ndarray,
    rec_bc: np.ndarray,
    mass_of_vehicle: np.ndarray,
) -> ConsistResult:
    consist = scenario.consist
    settings = scenario.sim
    events = events[: int(metrics[C_N_EVENTS])]
    braked = consist.has_air_brake()
    locos = consist.locomotive_indices()
    recharge = []
    for r in range(min(int(metrics[M_RELEASES]), MAX_RELEASES)):
        recharge.append(
            float(
                _recharge_time_s(
                    air_p,
                    release_air[r].copy(),
                    n_valves,
                    float(consist.brake_pipe_kpa),
                    RECHARGED_WITHIN_KPA,
                    braked,
                    settings.dt_s,
                    3_600.0,
                )
            )
        )
    margins = recharge_margins_s(events, recharge)
    lead = consist.vehicles[int(locos[0])].locomotive
    assert lead is not None
    j_to_kwh = 1.0 / 3.6e6
    # the couplings between masses: behind which vehicle, how far from the head
    last_of_mass = np.append(np.flatnonzero(np.diff(mass_of_vehicle)), consist.n_vehicles - 1)
    ends = consist.front_m() + consist.lengths_m()

    def largest(kind: str, force: int, at: int, when: int) -> dict[str, Any]:
        """The largest force of ``kind`` and where and when (None: none in the run)."""
        out: dict[str, Any] = {f"max_coupler_{kind}_kn": metrics[force] / 1e3}
        found = metrics[force] > 0.0 and last_of_mass.size > 1
        v = int(last_of_mass[int(metrics[at])]) if found else -1
        out[f"max_coupler_{kind}_behind"] = consist.vehicles[v].name if found else None
        out[f"max_coupler_{kind}_from_head_m"] = float(ends[v]) if found else None
        out[f"max_coupler_{kind}_time_s"] = float(metrics[when]) if found else None
        return out

    stop_t = metrics[M_STOP_T]
    emergency_t = metrics[M_EMERGENCY_T]
    out: dict[str, Any] = {
        **largest("tension", M_MAX_TENSION_N, M_MAX_TENSION_AT, M_MAX_TENSION_T),
        **largest("compression", M_MAX_COMPRESSION_N, M_MAX_COMPRESSION_AT, M_MAX_COMPRESSION_T),
        "coupler_force_limit_kn": settings.coupler_limit_kn,
        "coupler_force_limit_exceeded_s": metrics[M_OVER_LIMIT_S],
        "air_brake_applications": int(metrics[M_APPLICATIONS]),
        "air_brake_releases": int(metrics[M_RELEASES]),
        "min_recharge_margin_s": min(margins) if margins else None,
        "max_speed_kmh": metrics[M_MAX_SPEED_MPS] * KMH_PER_MPS,
        "running_time_s": _finite(stop_t),
        "final_position_m": metrics[M_FINAL_X],
        "emergency_stopping_distance_m": (
            metrics[M_FINAL_X] - metrics[M_EMERGENCY_X]
            if math.isfinite(emergency_t) and math.isfinite(stop_t)
            else None
        ),
        "emergency_speed_kmh": _finite(metrics[M_EMERGENCY_V] * KMH_PER_MPS),
        "energy_traction_kwh": metrics[M_E_TRACTION_J] / lead.traction_efficiency * j_to_kwh,
        "energy_regenerated_kwh": metrics[M_E_REGEN_J] * lead.regen_efficiency * j_to_kwh,
        "energy_air_brake_kwh": metrics[M_E_AIR_J] * j_to_kwh,
        "energy_traction_against_air_kwh": metrics[M_E_TRAC_AIR_J]
        / lead.traction_efficiency
        * j_to_kwh,
    }
    n = written
    series = {
        "time_s": rec_scalar[:n, 0],
        "position_m": rec_scalar[:n, 1],
        "speed_mps": rec_scalar[:n, 2],
        "traction_n": rec_scalar[:n, 3],
        "regeneration_n": rec_scalar[:n, 4],
        "air_brake_n": rec_scalar[:n, 5],
        "effort": rec_scalar[:n, 6],
        "lead_er_kpa": rec_scalar[:n, 7],
    }
    fields = {
        "coupler_force_n": rec_coupler[:n],
        "brake_pipe_kpa": rec_bp[:n],
        "aux_reservoir_kpa": rec_ar[:n],
        "brake_cylinder_kpa": rec_bc[:n],
    }
    kinds = {1.0: "application", 2.0: "release", 3.0: "emergency"}
    return ConsistResult(
        series,
        fields,
        out,
        {
            "time_s": [float(e[0]) for e in events],
            "kind": [kinds[float(e[1])] for e in events],
            "head_m": [float(e[2]) for e in events],
            "recharge_needed_s": recharge,
        },
        {
            "name": scenario.name,
            "consist": consist.name,
            "vehicles": consist.n_vehicles,
            "masses": int(mass_of_vehicle.max()) + 1,
            "steps": int(metrics[M_STEPS]),
            "coupling_from_head_m": [float(ends[v]) for v in last_of_mass[:-1]],
            "vehicle_centre_m": (consist.front_m() + consist.lengths_m() / 2.0).tolist(),
        },
    )
