"""The effects of a real train that set stopping accuracy.

All off by default (the papers' idealised world); each is switched on by a value
in the scenario's ``[realism]`` table and is used by every controller and every brake
model:

* speed measurement noise (normal, seeded, one draw per controller update) and
  quantisation (the tachometer's resolution);
* position from odometry: the wheel circumference is off by ``wheel_scale_error``
  (wear, calibration), a sliding wheel turns slower than the train
  (``slide_slip``), and balises at known positions reset the odometer;
* brake commands quantised to ``notches`` steps of the maximum service brake;
* the ATO control cycle (``sim.control_period_s``) slower than the plant step;
* adhesion-limited braking: above ``adhesion * m g`` at the rail the wheels slide and
  deliver only ``slide_ratio`` of it;
* gradients on the approach come from the line (``[line] gradients``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.sim import layout

#: Largest peak adhesion coefficient [-]: wheel on rail gives 0.05-0.1 wet and 0.15-0.3
#: dry in service, hardly 0.6 clean and dry in a laboratory; above 1 a wheel would grip
#: better than steel on steel can. (1e308 passed and silently meant no limit, as 0 does.)
MAX_ADHESION = 1.0


@dataclass(frozen=True)
class Realism:
    """Real-train effects; zeros switch each off.

    Attributes
    ----------
    speed_noise_std_mps
        Standard deviation of the speed measurement noise [m/s].
    speed_resolution_mps
        Quantisation step of the measured speed [m/s].
    wheel_scale_error
        Relative error of the odometer's wheel circumference [-] (+0.01 = reads 1 % long).
    slide_slip
        Fraction of the train speed a sliding wheel loses [-].
    balises_m
        Positions [m] of balises that reset the odometer.
    adhesion
        Peak adhesion coefficient [-] (0 = unlimited; dry rail about 0.15-0.2, wet 0.05-0.1).
    slide_ratio
        Sliding friction as a fraction of the peak adhesion [-].
    notches
        Number of brake notches (0 = stepless).
    seed
        Seed of the speed noise.
    """

    speed_noise_std_mps: float = 0.0
    speed_resolution_mps: float = 0.0
    wheel_scale_error: float = 0.0
    slide_slip: float = 0.0
    balises_m: tuple[float, ...] = ()
    adhesion: float = 0.0
    slide_ratio: float = 0.8
    notches: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("speed_noise_std_mps", "speed_resolution_mps", "adhesion"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"realism.{name}", value, "a finite number >= 0")
        if self.adhesion > MAX_ADHESION:
            raise ConfigError(
                "realism.adhesion",
                self.adhesion,
                f"a coefficient in [0, {MAX_ADHESION:g}] (0 = unlimited)",
            )
        if not (np.isfinite(self.wheel_scale_error) and abs(self.wheel_scale_error) < 0.2):
            raise ConfigError(
                "realism.wheel_scale_error",
                self.wheel_scale_error,
                "a fraction between -0.2 and 0.2",
            )
        for name in ("slide_slip", "slide_ratio"):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= 1):
                raise ConfigError(f"realism.{name}", value, "a fraction in [0, 1]")
        if not (isinstance(self.notches, int) and self.notches >= 0):
            raise ConfigError("realism.notches", self.notches, "an integer >= 0 (0 = stepless)")
        if not (isinstance(self.seed, int | np.integer) and self.seed >= 0):
            raise ConfigError("realism.seed", self.seed, "an integer >= 0")
        if any(not np.isfinite(b) for b in self.balises_m):
            raise ConfigError("realism.balises_km", self.balises_m, "finite positions")

    def pack(self) -> np.ndarray:
        """The kernel's realism params."""
        real = np.zeros(layout.N_REAL)
        real[layout.R_SPEED_RES] = self.speed_resolution_mps
        real[layout.R_WHEEL_SCALE] = self.wheel_scale_error
        real[layout.R_SLIDE_SLIP] = self.slide_slip
        real[layout.R_ADHESION] = self.adhesion
        real[layout.R_SLIDE_RATIO] = self.slide_ratio
        real[layout.R_NOTCHES] = self.notches
        return real

    def balises(self) -> np.ndarray:
        return np.sort(np.asarray(self.balises_m, dtype=float))

    def speed_noise(self, n_updates: int, seed: int | None = None) -> np.ndarray:
        """Noise [m/s] for each controller update (empty if there is none)."""
        if self.speed_noise_std_mps == 0.0:
            return np.zeros(0)
        rng = np.random.default_rng(self.seed if seed is None else seed)
        return rng.normal(0.0, self.speed_noise_std_mps, size=n_updates)
