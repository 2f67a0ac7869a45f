"""Train braking module of paper 003 section 2.2 (eq. 25-29).

One axle with its disc brake: ``-(Fb + Ff) = m0 dv/dt`` (eq. 25) with the brake force at
the wheel rim ``Fb = 2 M / Dw`` (eq. 26) and the basic resistance ``Ff = w0 m0 g``
(eq. 27, ``w0`` in N/kN so ``Ff = w0 m0 g / 1000`` N) where ``w0 = A + B v + C v^2``,
``v`` in km/h (eq. 28). Straight level track, so no additional resistance; as in the
paper there is no rotating-mass factor. The train stops at ``v = 0`` (the brake and the
resistance cannot drive it backwards).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from railpilot.checks import check_number
from railpilot.eddy.torque_model import WHEEL_DIAMETER_M
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle.resistance import davis_specific_resistance

T_MASS, T_DW, T_A, T_B, T_C = range(5)
N_TRAIN = 5


@dataclass(frozen=True)
class TrainParams:
    """Axle braked by one eddy-current disc.

    Attributes
    ----------
    axle_mass_kg
        Axle load ``m0`` [kg] (our choice 16 t: a 160 km/h single-deck coach).
    wheel_diameter_m
        ``Dw`` [m] (paper: 0.845 m).
    resistance_a, resistance_b, resistance_c
        ``A`` [N/kN], ``B`` [N/kN per km/h], ``C`` [N/kN per (km/h)^2] of eq. 28
        (paper: 1.61, 0.0040, 0.000187).
    """

    axle_mass_kg: float = 16_000.0
    wheel_diameter_m: float = WHEEL_DIAMETER_M
    resistance_a: float = 1.61
    resistance_b: float = 0.0040
    resistance_c: float = 0.000187

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            positive = name in ("axle_mass_kg", "wheel_diameter_m")
            check_number(
                f"train.{name}",
                value,
                minimum=0.0,
                positive=positive,
                error=ConfigError,
            )

    def packed(self) -> np.ndarray:
        out = np.zeros(N_TRAIN)
        out[T_MASS] = self.axle_mass_kg
        out[T_DW] = self.wheel_diameter_m
        out[T_A] = self.resistance_a
        out[T_B] = self.resistance_b
        out[T_C] = self.resistance_c
        return out

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@njit(cache=True)
def train_step(speed_mps: float, torque_nm: float, train: np.ndarray, dt: float) -> float:
    """Speed [m/s] one explicit-Euler step later; stops at zero (eq. 29).

    ``-dv/dt = (Fb + Ff) / m0`` with the rim force ``Fb = 2 M / Dw`` (eq. 26) and the
    basic resistance ``Ff = (A + B v + C v^2) m0 g / 1000`` (eq. 27-28, v in km/h).
    """
    if speed_mps <= 0.0:
        return 0.0
    v_kmh = speed_mps * KMH_PER_MPS
    w0 = davis_specific_resistance(v_kmh, train[T_A], train[T_B], train[T_C])
    mass = train[T_MASS]
    force = 2.0 * torque_nm / train[T_DW] + w0 * mass * G_MPS2 / 1000.0
    nxt = speed_mps - force / mass * dt
    if nxt < 0.0:
        return 0.0
    return nxt
