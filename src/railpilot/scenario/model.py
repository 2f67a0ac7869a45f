"""Typed configuration of one braking scenario (paper 000 style, EP brake)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.control.registry import CONTROLLERS as CONTROLLER_REGISTRY
from railpilot.errors import ConfigError
from railpilot.sim.disturbance import Disturbance
from railpilot.sim.drive_profile import DriveProfile, PlannedProfile, drive_profile
from railpilot.sim.realism import Realism
from railpilot.sim.reference import BrakingCurve, constant_deceleration, smooth_stop
from railpilot.sim.sweep import MAX_BRAKE_GAIN
from railpilot.units import kmh_to_mps
from railpilot.vehicle.line import Line
from railpilot.vehicle.train import MAX_SPEED_KMH, MAX_SPEED_MPS, Train

#: the built-in controllers' names, from their registry (control/registry.py)
CONTROLLERS = tuple(CONTROLLER_REGISTRY)


@dataclass(frozen=True)
class ATOModel:
    """What the ATO (the controllers' side) believes about the train.

    Attributes
    ----------
    mass_kg
        Load-weighed mass [kg] the brake demand is computed with; None = the true mass.
    davis
        The ATO's resistance model ``(a0, a1, a2)`` [N/kN], v in km/h, used as a
        feed-forward; None = the true coefficients.
    brake_delay_s, brake_lag_s
        The ATO's model of the brake's delay and time constant [s] (the air path of an
        EP brake): the tuning rules use them and the reference acceleration is fed
        forward by their sum. None = the plant's true value.
    reference
        ``"time"`` (default, as the papers): the controllers track the curve as a
        function of time since the braking point. ``"distance"``: the ATO looks the curve
        up at the measured position (distance to go), as production ATOs do, so a train
        that falls behind is not chased by a reference running away from it.
    gradient_feedforward
        The ATO adds the line's gradient and curve resistance (averaged over the train's
        length, at the measured position) to its resistance feed-forward, as an ATO that
        knows the line's profile does. Off in the papers' world (they model none).
    preview_s
        Look-ahead [s]: the ATO takes the distance-based curve and the line's gradients
        (with ``gradient_feedforward``) at ``x + v preview_s`` instead of at the measured
        position ``x``, to lead a brake that takes that long to act (a long train's air
        brake). 0 (default): no look-ahead.
    """

    mass_kg: float | None = None
    davis: tuple[float, float, float] | None = None
    brake_delay_s: float | None = None
    brake_lag_s: float | None = None
    reference: str = "time"
    gradient_feedforward: bool = False
    preview_s: float = 0.0

    def __post_init__(self) -> None:
        if self.mass_kg is not None and not (np.isfinite(self.mass_kg) and self.mass_kg > 0):
            raise ConfigError("ato.mass_kg", self.mass_kg, "a finite mass > 0")
        if self.reference not in ("time", "distance"):
            raise ConfigError("ato.reference", self.reference, "'time' or 'distance'")
        for name in ("brake_delay_s", "brake_lag_s"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"ato.{name}", value, "a finite number >= 0 [s]")
        if not (
            isinstance(self.preview_s, int | float)
            and not isinstance(self.preview_s, bool)
            and np.isfinite(self.preview_s)
            and 0 <= self.preview_s <= 600
        ):
            raise ConfigError("ato.preview_s", self.preview_s, "a number in [0, 600] s")
        if self.davis is not None and not all(np.isfinite(c) and c >= 0 for c in self.davis):
            raise ConfigError("ato.davis", self.davis, "three finite numbers >= 0")


@dataclass(frozen=True)
class ControllerSpec:
    """Which controller runs and the parameters of each (constructor keywords)."""

    name: str = "smarc"
    params: dict[str, dict[str, Any]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in CONTROLLERS and ":" not in self.name:
            raise ConfigError(
                "controller.name",
                self.name,
                f"one of {', '.join(CONTROLLERS)} or module:Name (your own controller)",
            )


#: Most solver steps one run may take (``sim.duration_s / sim.dt_s``): the longest run (a
#: day, 86,400 s) at the default 0.01 s step takes 8.64e6; the examples take at most
#: 24,000 (heavy_haul_run.toml: 2,400 s at 0.1 s) and the defaults 7,000. A run samples
#: the reference at every step and, with ``record_every = 1``, records every step's 12
#: channels: about 300 bytes a step measured, some 3 GB at the limit. A finer step is
#: allowed for a shorter run; without a bound ``dt_s = 1e-12`` asked for 1e14 steps
#: (memory error) and 5e-324 for infinitely many (OverflowError).
MAX_STEPS = 10_000_000


@dataclass(frozen=True)
class SimSettings:
    """Solver step [s], duration [s], ATO control period [s], recorder decimation."""

    dt_s: float = 0.01
    duration_s: float = 70.0
    #: None (the default) = every step, ``dt_s``
    control_period_s: float = None  # type: ignore[assignment]
    record_every: int = 1

    def __post_init__(self) -> None:
        if not (np.isfinite(self.dt_s) and 0 < self.dt_s <= 0.1):
            raise ConfigError("sim.dt_s", self.dt_s, "a step in (0, 0.1] s")
        if self.control_period_s is None:
            object.__setattr__(self, "control_period_s", self.dt_s)
        # up to a day: a heavy-haul run over a whole line takes hours
        if not (np.isfinite(self.duration_s) and self.dt_s < self.duration_s <= 86_400):
            raise ConfigError("sim.duration_s", self.duration_s, "a duration in (dt_s, 86400] s")
        steps = self.duration_s / self.dt_s  # inf for a subnormal step
        if not (np.isfinite(steps) and round(steps) <= MAX_STEPS):
            raise ConfigError(
                "sim.dt_s",
                self.dt_s,
                f"a step in [{self.duration_s / MAX_STEPS:g}, 0.1] s: at most {MAX_STEPS:,} "
                f"steps of sim.duration_s = {self.duration_s:g} s",
            )
        # an ATO cycles in well under a second; beyond a minute the controller would
        # hardly act, and a huge period overflows the kernel's step counter (int64)
        if not (np.isfinite(self.control_period_s) and 0 < self.control_period_s <= 60):
            raise ConfigError(
                "sim.control_period_s", self.control_period_s, "a period in (0, 60] s"
            )
        ratio = self.control_period_s / self.dt_s
        if not (np.isfinite(ratio) and ratio >= 1 - 1e-9 and abs(ratio - round(ratio)) < 1e-6):
            raise ConfigError(
                "sim.control_period_s",
                self.control_period_s,
                f"a whole multiple (>= 1) of sim.dt_s = {self.dt_s}",
            )
        # a stride beyond the run's steps records its first step only; one beyond 64 bits
        # made the kernel refuse its arguments mid-run (a Numba TypingError)
        if not (isinstance(self.record_every, int) and 1 <= self.record_every <= MAX_STEPS):
            raise ConfigError(
                "sim.record_every", self.record_every, f"an integer in [1, {MAX_STEPS:,}]"
            )

    @property
    def n_steps(self) -> int:
        return round(self.duration_s / self.dt_s)

    @property
    def control_every(self) -> int:
        return round(self.control_period_s / self.dt_s)


@dataclass(frozen=True)
class SmoothStopSpec:
    """Parameters of :func:`~railpilot.sim.reference.smooth_stop`; the defaults are paper
    000's non-linear target curve from 72 km/h (our shape; see docs), braking at the 20 km
    point after a 2 s coast. ``[reference] shape = "smooth"`` in a file."""

    v0_mps: float = 20.0
    decel_mps2: float = 0.5
    jerk_mps3: float = 0.5
    final_decel_mps2: float = 0.3
    final_phase_speed_mps: float = 2.0
    start_m: float = 20_000.0
    coast_s: float = 2.0
    ease_out: bool = False

    def build(self) -> BrakingCurve:
        return smooth_stop(
            self.v0_mps,
            self.decel_mps2,
            self.jerk_mps3,
            self.final_decel_mps2,
            self.final_phase_speed_mps,
            self.start_m,
            coast_s=self.coast_s,
            ease_out=self.ease_out,
        )


@dataclass(frozen=True)
class ConstantDecelSpec:
    """Parameters of :func:`~railpilot.sim.reference.constant_deceleration` (paper 002):
    ``decel_mps2`` is required. ``[reference] shape = "constant"`` in a file."""

    decel_mps2: float
    v0_mps: float = 20.0
    start_m: float = 0.0
    coast_s: float = 0.0

    def build(self) -> BrakingCurve:
        return constant_deceleration(self.v0_mps, self.decel_mps2, self.start_m, self.coast_s)


@dataclass(frozen=True)
class DriveSpec:
    """A whole run: start (from rest by default), accelerate, cruise, obey the line's speed
    limits (held until the tail has left them), brake to a stop at ``stop_m``
    (:func:`~railpilot.sim.drive_profile.drive_profile`). ``[reference] shape = "drive"``
    in a file; the ATO then tracks it by distance. ``stop_m`` is required."""

    stop_m: float
    start_m: float = 0.0
    cruise_mps: float = kmh_to_mps(80.0)
    accel_mps2: float = 0.05
    decel_mps2: float = 0.1
    v_start_mps: float = 0.0

    def build(self, line: Line, train: Train) -> DriveProfile:
        limits = [
            (seg.start_m, seg.end_m, seg.value)
            for seg in line.speed_limits
            if seg.end_m > self.start_m and seg.start_m < self.stop_m
        ]
        return drive_profile(
            self.start_m,
            self.stop_m,
            self.cruise_mps,
            self.accel_mps2,
            self.decel_mps2,
            limits=limits,
            v_start_mps=self.v_start_mps,
            train_length_m=train.length_m,
        )


def paper000_reference(start_m: float = SmoothStopSpec.start_m) -> BrakingCurve:
    """Paper 000's non-linear target curve from 72 km/h (:class:`SmoothStopSpec`)."""
    return SmoothStopSpec(start_m=start_m).build()


@dataclass(frozen=True)
class Scenario:
    """Everything one braking run needs."""

    name: str = "scenario"
    train: Train = field(default_factory=Train)
    line: Line = field(default_factory=Line)
    brake: EPBrake | LagDelayBrake | BrakePipeBrake | LocomotiveDrive = field(
        default_factory=EPBrake
    )
    reference: BrakingCurve | DriveProfile | PlannedProfile = field(
        default_factory=paper000_reference
    )
    disturbance: Disturbance = field(default_factory=Disturbance)
    ato: ATOModel = field(default_factory=ATOModel)
    controller: ControllerSpec = field(default_factory=ControllerSpec)
    sim: SimSettings = field(default_factory=SimSettings)
    realism: Realism = field(default_factory=Realism)
    #: the train's speed at t = 0 [m/s]; None = the reference's (a Monte Carlo can vary it)
    initial_speed_mps: float | None = None
    #: true brake effort relative to what the brake manager assumes (friction error) [-]
    brake_gain: float = 1.0

    def __post_init__(self) -> None:
        if self.initial_speed_mps is not None and not (
            np.isfinite(self.initial_speed_mps) and 0 <= self.initial_speed_mps <= MAX_SPEED_MPS
        ):
            raise ConfigError(
                "initial_speed_kmh",
                self.initial_speed_mps,
                f"a speed >= 0 and <= {MAX_SPEED_MPS:.4g} m/s ({MAX_SPEED_KMH:g} km/h)",
            )
        if not (np.isfinite(self.brake_gain) and 0 <= self.brake_gain <= MAX_BRAKE_GAIN):
            raise ConfigError("brake.gain", self.brake_gain, f"a factor in [0, {MAX_BRAKE_GAIN:g}]")

    @property
    def changeover_kmh(self) -> float:
        """Electric/air changeover speed [km/h]; 0 for a brake without one."""
        return float(self.brake.changeover_kmh)

    @property
    def brake_lead_s(self) -> tuple[float, float]:
        """The plant brake's ``(delay, lag)`` [s] (the air path for the EP brake)."""
        return self.brake.lead_s
