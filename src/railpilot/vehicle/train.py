"""The train: mass, rotating mass, length, resistance, brake capability."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from railpilot.checks import check_count, check_number
from railpilot.errors import ConfigError
from railpilot.units import Num, kmh_to_mps

#: Fastest speed any scenario may give [km/h] (a reference, a limit, a start speed):
#: above the fastest trains that run (maglev ~600 km/h); far beyond it the kinematics
#: (``v**2``, ``v / a``) overflow floats mid-run
MAX_SPEED_KMH = 600.0
MAX_SPEED_MPS = float(kmh_to_mps(MAX_SPEED_KMH))
#: Longest train [m]: as the ground side and the train-ground link allow
#: (ground/occupancy.py, link/messages.py); the brake pipe's moments grow as ``L**4``
MAX_LENGTH_M = 10_000.0


def _positive(name: str, value: object) -> None:
    check_number(name, value, positive=True, error=ConfigError)


def _non_negative(name: str, value: object) -> None:
    check_number(name, value, minimum=0.0, error=ConfigError)


@dataclass(frozen=True)
class ElectricBrakeCurve:
    """Maximum electric (regenerative/rheostatic) brake force of the whole train.

    Constant force ``max_force_n`` [N] up to the base speed, then constant power
    ``max_power_w`` [W]: ``F_max(v) = min(max_force_n, max_power_w / v)``, the usual
    tractive-effort envelope of an inverter-fed drive in braking.
    """

    max_force_n: float = 380e3
    max_power_w: float = 4.8e6

    def __post_init__(self) -> None:
        _non_negative("train.electric_brake.max_force_n", self.max_force_n)
        _non_negative("train.electric_brake.max_power_w", self.max_power_w)

    def max_force(self, speed_mps: Num) -> Num:
        """Available electric brake force [N] at ``speed_mps`` [m/s]."""
        speed = np.maximum(np.abs(speed_mps), 1e-9)
        return np.minimum(self.max_force_n, self.max_power_w / speed)


@dataclass(frozen=True)
class Train:
    """A train as a point mass with Davis resistance.

    Attributes
    ----------
    mass_kg
        Total (loaded) mass [kg]. Paper 000 Table 1: 536 t.
    rotating_mass_factor
        ``gamma`` [-], effective mass ``m (1 + gamma)``. Paper 000: 0.06.
    length_m
        Train length [m] (used by the link to extend TSRs and for gradients).
    davis_a0, davis_a1, davis_a2
        Basic resistance ``w = a0 + a1 v + a2 v^2`` [N/kN], v in km/h.
        Paper 000: 0.42, 0.0016, 0.000132.
    max_service_decel_mps2
        Maximum service deceleration [m/s^2] (positive number). Paper 000: 1.0.
    electric_brake
        Electric brake envelope; ``motor_cars`` is how many cars share it.
    """

    mass_kg: float = 536e3
    rotating_mass_factor: float = 0.06
    length_m: float = 140.0
    davis_a0: float = 0.42
    davis_a1: float = 0.0016
    davis_a2: float = 0.000132
    max_service_decel_mps2: float = 1.0
    electric_brake: ElectricBrakeCurve = field(default_factory=ElectricBrakeCurve)
    motor_cars: int = 4

    def __post_init__(self) -> None:
        _positive("train.mass_kg", self.mass_kg)
        _non_negative("train.rotating_mass_factor", self.rotating_mass_factor)
        _positive("train.length_m", self.length_m)
        if self.length_m > MAX_LENGTH_M:
            raise ConfigError(
                "train.length_m", self.length_m, f"a length in (0, {MAX_LENGTH_M:g}] m"
            )
        for name in ("davis_a0", "davis_a1", "davis_a2"):
            _non_negative(f"train.{name}", getattr(self, name))
        _positive("train.max_service_decel_mps2", self.max_service_decel_mps2)
        if not isinstance(self.electric_brake, ElectricBrakeCurve):
            raise ConfigError("train.electric_brake", self.electric_brake, "an ElectricBrakeCurve")
        check_count(
            "train.motor_cars", self.motor_cars, 1, allowed="an integer >= 1", error=ConfigError
        )

    @property
    def effective_mass_kg(self) -> float:
        """Mass including rotating inertia, ``m (1 + gamma)`` [kg]."""
        return self.mass_kg * (1.0 + self.rotating_mass_factor)
