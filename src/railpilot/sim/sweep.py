"""The ``[montecarlo]`` table: how many runs, the master seed, what varies and how.

Parameters a sweep can vary (values in the scenario file's units)::

    train.mass_t              true mass [t] (the ATO's load weighing follows it)
    train.davis_scale         factor on all three Davis coefficients [-], at most 10
    brake.delay_s             brake delay [s] (EP brake: rounded to whole steps)
    brake.lag_s               lag-delay brake's time constant tau [s]
    brake.air_lag_s           EP brake cylinder time constant [s]
    brake.electric_lag_s      EP electric brake time constant [s]
    brake.gain                true brake effort / assumed (friction error) [-], at most 10
    disturbance.constant_kn   constant outside force [kN], + pushes the train on
    initial_speed_kmh         the train's speed at the start [km/h]
    realism.wheel_scale_error odometer circumference error [-]
    realism.adhesion          peak wheel-rail adhesion [-], at most 1
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.sim.realism import MAX_ADHESION

#: Largest factor on the train's Davis coefficients [-]: they are measured for the train
#: (the examples vary them by 20 %); ten times its resistance is another train, not an
#: uncertainty. (A maximum of 1e308 passed: the resistance overflowed and every run
#: stopped at once, hundreds of metres short.)
MAX_DAVIS_SCALE = 10.0
#: Largest true brake effort over what the brake manager assumes [-]: shoe friction
#: varies by some tens of percent with speed, heat and wet (the examples: 5-10 %); ten
#: times the service brake is far beyond what adhesion (at most ``MAX_ADHESION`` g) can
#: pass to the rail. (A maximum of 1e308 passed and ran, to a stop hundreds of metres
#: short.)
MAX_BRAKE_GAIN = 10.0

#: key -> lowest value allowed
VARIABLE_PARAMETERS: dict[str, float] = {
    "train.mass_t": 1e-3,
    "train.davis_scale": 0.0,
    "brake.delay_s": 0.0,
    "brake.lag_s": 0.0,
    "brake.air_lag_s": 0.0,
    "brake.electric_lag_s": 0.0,
    "brake.gain": 0.0,
    "disturbance.constant_kn": -np.inf,
    "initial_speed_kmh": 0.0,
    "realism.wheel_scale_error": -0.2,
    "realism.adhesion": 0.0,
}
#: key -> highest value allowed, where the parameter's own check has no upper bound (the
#: others are checked by what they build: the brake's ranges, the train's, ...)
VARIABLE_MAXIMA: dict[str, float] = {
    "train.davis_scale": MAX_DAVIS_SCALE,
    "brake.gain": MAX_BRAKE_GAIN,
    "realism.adhesion": MAX_ADHESION,
}


@dataclass(frozen=True)
class Distribution:
    """A sampled parameter: ``uniform`` on ``[low, high]`` or ``normal(mean, std)``
    truncated to ``[low, high]`` (resampled, not clipped, so no mass piles on a bound).
    Values are in the scenario file's units (t, s, km/h, kN, factors)."""

    key: str
    kind: str
    low: float
    high: float
    mean: float = 0.0
    std: float = 0.0

    def __post_init__(self) -> None:
        where = f"montecarlo.vary.{self.key}"
        if self.key not in VARIABLE_PARAMETERS:
            raise ConfigError(where, self.key, f"one of {', '.join(sorted(VARIABLE_PARAMETERS))}")
        if self.kind not in ("uniform", "normal"):
            raise ConfigError(f"{where}.dist", self.kind, "'uniform' or 'normal'")
        finite_needed = self.kind == "uniform"
        if (
            np.isnan(self.low)
            or np.isnan(self.high)
            or self.low > self.high
            or (finite_needed and not (np.isfinite(self.low) and np.isfinite(self.high)))
        ):
            raise ConfigError(
                f"{where}.min",
                (self.low, self.high),
                "min <= max (both finite for a uniform distribution)",
            )
        lowest = VARIABLE_PARAMETERS[self.key]
        if self.low < lowest:
            raise ConfigError(f"{where}.min", self.low, f"a value >= {lowest:g}")
        highest = VARIABLE_MAXIMA.get(self.key, np.inf)
        if self.high > highest:
            raise ConfigError(
                f"{where}.max",
                self.high,
                f"a value <= {highest:g}"
                + ("" if np.isfinite(self.high) else " (a normal distribution needs a max)"),
            )
        if self.kind == "normal" and not (
            np.isfinite(self.std) and self.std > 0 and np.isfinite(self.mean)
        ):
            raise ConfigError(f"{where}.std", self.std, "a finite standard deviation > 0")

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self.kind == "uniform" or self.low == self.high:
            return rng.uniform(self.low, self.high, n)
        from scipy.stats import truncnorm

        a = (self.low - self.mean) / self.std
        b = (self.high - self.mean) / self.std
        return np.asarray(
            truncnorm.rvs(a, b, loc=self.mean, scale=self.std, size=n, random_state=rng)
        )


@dataclass(frozen=True)
class MonteCarloSpec:
    """How many runs, the master seed, what varies, and the chunk size."""

    runs: int = 1000
    seed: int = 0
    vary: tuple[Distribution, ...] = ()
    chunk: int = 500

    def __post_init__(self) -> None:
        if not (isinstance(self.runs, int) and 1 <= self.runs <= 2_000_000):
            raise ConfigError(
                "montecarlo.runs",
                self.runs,
                "an integer in [1, 2000000] (each run keeps 160 bytes of metrics)",
            )
        if not (isinstance(self.seed, int) and self.seed >= 0):
            raise ConfigError("montecarlo.seed", self.seed, "an integer >= 0")
        if not (isinstance(self.chunk, int) and self.chunk >= 1):
            raise ConfigError("montecarlo.chunk", self.chunk, "an integer >= 1")

    def samples(self) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Every run's sampled values and seed, from the master seed alone.

        Each parameter draws from its own stream (keyed by its name), so run ``i``'s
        values depend on the master seed and ``i`` only: not on the number of runs,
        nor on which other parameters vary or in what order.
        """
        values = {
            d.key: d.sample(
                np.random.default_rng([self.seed, 2, zlib.crc32(d.key.encode())]), self.runs
            )
            for d in self.vary
        }
        seeds = np.random.default_rng([self.seed, 1]).integers(0, 2**62, self.runs)
        return values, seeds
