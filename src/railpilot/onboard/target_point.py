"""Target point safety distance (paper 001, section 2.4).

The ground sends the position of a signal held at red (a train ahead, a lost switch
indication, a section fault); the onboard sets its target stop point a safety distance
before it. The paper lists what the distance depends on: the speed, the braking
characteristics, the gradient, the communication delay and the driver's reaction time. It
gives no formula; this is ours (docs/onboard.md, "Target point safety distance"), each term
a documented parameter::

    d_safe(v, i) = d_0                                       fixed margin (overlap)
                 + v (t_comm + t_driver)                     travelled before anything acts
                 + (v + dv)^2 / (2 k a(i)) - v^2 / (2 a(i))  braking-distance uncertainty
    a(i)         = a_brake + g i / (1000 (1 + gamma))         gradient i [per mille, + up]

with ``v`` the speed [m/s], ``dv`` the speed-measurement margin [m/s], ``a_brake`` the
train's guaranteed full-service deceleration on the level [m/s^2], ``k`` in (0, 1] the share
of it that is guaranteed (the rest is dispersion of the brake), ``gamma`` the rotating mass
factor. The braking term is what the train may run beyond its nominal braking curve: the
curve is computed at the measured speed with the nominal deceleration, the real train may
be ``dv`` faster and brake with only ``k a``. A descent (``i < 0``) lowers ``a(i)`` and so
lengthens the distance; if ``a(i) <= 0`` the train cannot stop on that gradient at all and
the distance is an error, not a number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.units import G_MPS2, Num


@dataclass(frozen=True)
class SafetyDistanceParameters:
    """Every term of the target point safety distance (module docstring).

    Attributes
    ----------
    fixed_margin_m
        ``d_0`` [m]: overlap beyond the stop point kept free in any case (50 m).
    comm_delay_s
        ``t_comm`` [s]: from the signal turning red to the target point reaching the
        onboard (ground processing, radio, the link's resend; 2 s).
    driver_reaction_s
        ``t_driver`` [s]: from the advice to the driver's action (3 s; 0 for an ATO).
    speed_margin_mps
        ``dv`` [m/s]: the speed-measurement margin (ETCS uses about 2 % of the speed plus
        a constant; 0.6 m/s here, about 2 km/h).
    brake_guarantee
        ``k`` (0, 1]: the guaranteed share of the nominal deceleration (0.85).
    """

    fixed_margin_m: float = 50.0
    comm_delay_s: float = 2.0
    driver_reaction_s: float = 3.0
    speed_margin_mps: float = 0.6
    brake_guarantee: float = 0.85

    def __post_init__(self) -> None:
        for name in ("fixed_margin_m", "comm_delay_s", "driver_reaction_s", "speed_margin_mps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (
                isinstance(value, int | float) and math.isfinite(value) and value >= 0
            ):
                raise ConfigError(f"safety.{name}", value, "a finite number >= 0")
        k = self.brake_guarantee
        if isinstance(k, bool) or not (isinstance(k, int | float) and 0 < k <= 1):
            raise ConfigError("safety.brake_guarantee", k, "a number in (0, 1]")


def gradient_deceleration_mps2(
    brake_decel_mps2: float,
    gradient_permille: float | np.ndarray,
    rotating_mass_factor: float = 0.06,
) -> np.ndarray:
    """``a(i) = a_brake + g i / (1000 (1 + gamma))`` [m/s^2]: braking on gradient ``i``.

    ``gradient_permille`` [per mille], positive uphill (helps), negative downhill.
    """
    i = np.asarray(gradient_permille, dtype=float)
    return brake_decel_mps2 + G_MPS2 * i / (1000.0 * (1.0 + rotating_mass_factor))


def safety_distance_m(
    speed_mps: Num,
    brake_decel_mps2: float,
    gradient_permille: float | np.ndarray = 0.0,
    params: SafetyDistanceParameters | None = None,
    *,
    rotating_mass_factor: float = 0.06,
) -> np.ndarray:
    """``d_safe`` [m] before a red signal at speed ``speed_mps`` [m/s] (module docstring).

    ``brake_decel_mps2`` [m/s^2] the guaranteed full-service deceleration on the level;
    ``gradient_permille`` the (length-averaged, worst) gradient over the braking distance,
    positive uphill. Vectorised over speed and gradient.
    """
    p = params or SafetyDistanceParameters()
    if not (math.isfinite(brake_decel_mps2) and brake_decel_mps2 > 0):
        raise ConfigError("brake_decel_mps2", brake_decel_mps2, "a deceleration > 0 [m/s^2]")
    v = np.asarray(speed_mps, dtype=float)
    if not np.all(np.isfinite(v) & (v >= 0)):
        raise ConfigError("speed_mps", speed_mps, "finite speeds >= 0 [m/s]")
    a = gradient_deceleration_mps2(brake_decel_mps2, gradient_permille, rotating_mass_factor)
    if np.any(a <= 0):
        raise ConfigError(
            "gradient_permille",
            gradient_permille,
            f"a gradient on which {brake_decel_mps2:g} m/s^2 of braking still stops the train",
        )
    reaction = v * (p.comm_delay_s + p.driver_reaction_s)
    braking = (v + p.speed_margin_mps) ** 2 / (2.0 * p.brake_guarantee * a) - v**2 / (2.0 * a)
    return np.asarray(p.fixed_margin_m + reaction + braking)


def target_stop_point_m(
    signal_m: float,
    direction: float,
    speed_mps: float,
    brake_decel_mps2: float,
    gradient_permille: float = 0.0,
    params: SafetyDistanceParameters | None = None,
    *,
    rotating_mass_factor: float = 0.06,
) -> float:
    """The target stop point [m]: ``signal_m`` moved back by the safety distance.

    ``direction`` +1 (towards increasing positions) or -1; the point is on the approach
    side of the signal.
    """
    d = float(
        safety_distance_m(
            speed_mps,
            brake_decel_mps2,
            gradient_permille,
            params,
            rotating_mass_factor=rotating_mass_factor,
        )
    )
    return signal_m - d if direction >= 0 else signal_m + d
