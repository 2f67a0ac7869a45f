"""Outside disturbances acting on the train: constant, by region, random (seeded).

All are forces [N], positive in the direction of travel (a positive disturbance
pushes the train on, as a tail wind or an unmodelled down-grade would; a negative
one holds it back).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.jit import njit


@dataclass(frozen=True)
class Region:
    """A force [N] acting while the train's head is in ``[start_m, end_m)``."""

    start_m: float
    end_m: float
    force_n: float


@dataclass(frozen=True)
class Disturbance:
    """Disturbance forces.

    Attributes
    ----------
    constant_n
        Force acting all the time [N].
    regions
        Forces acting over stretches of line.
    random_std_n
        Standard deviation of a random force [N]: a new normal value every
        ``random_hold_s`` seconds, held in between (piecewise constant).
    random_hold_s
        How long each random value holds [s] (also for ``target_fraction``).
    target_fraction
        Amplitude of a random disturbance acceleration proportional to the target
        acceleration (paper 002: 0.023 for -2.3 % to +2.3 %): a new uniform factor in
        ``[-target_fraction, target_fraction]`` every ``random_hold_s`` seconds.
    seed
        Seed of the random force; the same seed gives the same numbers.
    """

    constant_n: float = 0.0
    regions: tuple[Region, ...] = ()
    random_std_n: float = 0.0
    random_hold_s: float = 1.0
    target_fraction: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not np.isfinite(self.constant_n):
            raise ConfigError("disturbance.constant_n", self.constant_n, "a finite number")
        for i, r in enumerate(self.regions):
            if not (np.isfinite(r.start_m) and np.isfinite(r.end_m) and r.end_m > r.start_m):
                raise ConfigError(
                    f"disturbance.regions[{i}]", (r.start_m, r.end_m), "finite start_m < end_m"
                )
            if not np.isfinite(r.force_n):
                raise ConfigError(f"disturbance.regions[{i}].force_n", r.force_n, "a finite number")
        if not (np.isfinite(self.random_std_n) and self.random_std_n >= 0):
            raise ConfigError("disturbance.random_std_n", self.random_std_n, "a number >= 0")
        if not (np.isfinite(self.target_fraction) and 0 <= self.target_fraction < 1):
            raise ConfigError(
                "disturbance.target_fraction", self.target_fraction, "a fraction in [0, 1)"
            )
        if not (isinstance(self.seed, int | np.integer) and self.seed >= 0):
            raise ConfigError("disturbance.seed", self.seed, "an integer >= 0")
        # up to the longest run (sim.duration_s): the hold is rounded to whole steps
        if not (np.isfinite(self.random_hold_s) and 0 < self.random_hold_s <= 86_400):
            raise ConfigError(
                "disturbance.random_hold_s", self.random_hold_s, "a time in (0, 86400] s"
            )

    def region_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(starts, ends, forces)`` for the kernel."""
        if not self.regions:
            return np.zeros(0), np.zeros(0), np.zeros(0)
        return (
            np.array([r.start_m for r in self.regions]),
            np.array([r.end_m for r in self.regions]),
            np.array([r.force_n for r in self.regions]),
        )

    def random_series(
        self,
        n_steps: int,
        dt: float,
        target_accel_mps2: np.ndarray,
        effective_mass_kg: float,
        seed: int | None = None,
    ) -> np.ndarray:
        """The random force [N] at each of ``n_steps`` steps (empty if there is none).

        ``target_accel_mps2`` (the reference acceleration per step) scales the
        ``target_fraction`` part; ``seed`` overrides the scenario's (Monte Carlo runs).
        """
        if self.random_std_n == 0.0 and self.target_fraction == 0.0:
            return np.zeros(0)
        hold = max(round(self.random_hold_s / dt), 1)
        if self.target_fraction > 0.0 and len(target_accel_mps2) < n_steps:
            raise ValueError(
                f"target_accel_mps2 has {len(target_accel_mps2)} values: expected one per "
                f"step, {n_steps}"
            )
        rng = np.random.default_rng(self.seed if seed is None else seed)
        n_values = n_steps // hold + 1
        normal = np.zeros((1, n_values))
        factor = np.zeros((1, n_values))
        if self.random_std_n > 0.0:
            normal[0] = rng.normal(0.0, self.random_std_n, n_values)
        if self.target_fraction > 0.0:
            factor[0] = rng.uniform(-self.target_fraction, self.target_fraction, n_values)
        force = np.empty((1, n_steps))
        spread_held_values(
            normal,
            factor,
            hold,
            self.random_std_n > 0.0,
            self.target_fraction > 0.0,
            np.ascontiguousarray(target_accel_mps2[:n_steps], dtype=float),
            np.array([float(effective_mass_kg)]),
            force,
        )
        return force[0]


@njit(cache=True)
def spread_held_values(
    normal: np.ndarray,
    factor: np.ndarray,
    hold: int,
    use_normal: bool,
    use_factor: bool,
    target: np.ndarray,
    mass: np.ndarray,
    out: np.ndarray,
) -> None:
    """``out[i, k] = 0 + normal[i, k // hold] + factor[i, k // hold] * target[k] * mass[i]``
    (each term only if used): the random force of run ``i``, its held values spread over the
    steps. One implementation for a single run (:meth:`Disturbance.random_series`) and a
    Monte Carlo chunk (sim/inputs.py ``random_series_many``); a loop instead of NumPy's
    repeat and products, whose temporaries of a chunk's size cost more than the arithmetic."""
    for i in range(out.shape[0]):
        m = mass[i]
        for k in range(out.shape[1]):
            j = k // hold
            f = 0.0
            if use_normal:
                f += normal[i, j]
            if use_factor:
                f += factor[i, j] * target[k] * m
            out[i, k] = f
