"""Paper 002's brake: static map ``F``, first-order lag ``tau``, transport delay ``sigma``.

``ac(s) / at(s) = exp(-sigma s) / (tau s + 1)``, ``at = F(uc)`` (paper 002 eq. 1, 5).
The map is linear, ``F(uc) = -a_max uc`` for a command ``uc`` in ``[0, 1]``; a notched
(stepped) map is the same line sampled at ``notches`` steps, which the ATO's command
quantisation (railpilot.sim.realism) provides for every brake model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from railpilot.brakes.base import PackContext
from railpilot.brakes.lag_delay import (
    E_LEN,
    MAX_DELAY_STEPS,
    LagDelay,
    exact_params,
    lag_delay_exact_step,
)
from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit

#: longest lag or delay a brake model accepts [s]
MAX_TIME_S = 60.0
#: index of ``a_max`` [m/s^2] in the packed params (after LagDelay's five)
LD_A_MAX = 5


@dataclass(frozen=True)
class LagDelayBrake:
    """Parameters of paper 002's brake model.

    Attributes
    ----------
    lag_s
        Response time constant ``tau`` [s].
    delay_s
        Transmission delay ``sigma`` [s] (paper: 1.05 to 1.35 s).
    max_decel_mps2
        ``a_max`` [m/s^2]: ``F(1) = -a_max`` (paper: 1.0).
    """

    lag_s: float = 0.5
    delay_s: float = 1.2
    max_decel_mps2: float = 1.0

    def __post_init__(self) -> None:
        for name in ("lag_s", "delay_s"):
            # a brake slower than a minute is a configuration error, not a brake
            check_number(
                f"brake.{name}",
                getattr(self, name),
                minimum=0.0,
                maximum=MAX_TIME_S,
                allowed=f"a number in [0, {MAX_TIME_S:g}] s",
                error=ConfigError,
            )
        check_number(
            "brake.max_decel_mps2",
            self.max_decel_mps2,
            positive=True,
            error=ConfigError,
        )

    name: ClassVar[str] = "lag-delay"
    #: no electric brake, so no changeover
    changeover_kmh: ClassVar[float] = 0.0

    @property
    def lead_s(self) -> tuple[float, float]:
        """``(delay, lag)`` [s] (what the ATO must lead)."""
        return self.delay_s, self.lag_s

    def sizes(self, params: np.ndarray) -> tuple[int, int]:
        """Floats of state (output, step index) and of delay line (brakes/base.py)."""
        return 2, int(params[E_LEN])

    def pack(self, context: PackContext) -> np.ndarray:
        """The kernel's params for the context's step (brakes/base.py)."""
        return self.pack_arrays(context.dt_s)

    def pack_arrays(self, dt: float) -> np.ndarray:
        """The kernel's params: LagDelay's exact-method params, then ``a_max``."""
        if self.delay_s > 0 and self.delay_s < dt:
            raise ConfigError(
                "brake.delay_s", self.delay_s, f"0 or at least one simulation step (dt = {dt} s)"
            )
        params = LagDelay(self.lag_s, self.delay_s, dt).params
        return np.append(params, self.max_decel_mps2)

    def pack_many(
        self,
        context: PackContext,
        changes: dict[str, np.ndarray],
        runs: int,
        load_weighed_eff_mass_kg: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Params and sizes of ``runs`` copies of this brake with sampled fields, at once.

        ``changes``: field name -> one value per run (a Monte Carlo's sampled brakes;
        sim/inputs.batch_inputs); ``load_weighed_eff_mass_kg``: each run's (this brake
        does not use it). Row ``i`` is exactly what :meth:`pack` and :meth:`sizes`
        give the brake with run ``i``'s values; None if a value is one :meth:`pack` would
        refuse (the caller then builds run by run, to raise the error that names it).
        """
        if set(changes) - {"lag_s", "delay_s"}:
            return None
        dt = context.dt_s
        lag = np.broadcast_to(np.asarray(changes.get("lag_s", self.lag_s), dtype=float), (runs,))
        delay = np.broadcast_to(
            np.asarray(changes.get("delay_s", self.delay_s), dtype=float), (runs,)
        )
        for value in (lag, delay):
            if not (np.all(np.isfinite(value)) and np.all((value >= 0) & (value <= MAX_TIME_S))):
                return None
        if np.any((delay > 0) & (delay < dt)) or np.any(delay / dt > MAX_DELAY_STEPS):
            return None
        params = np.empty((runs, LD_A_MAX + 1))
        params[:, :LD_A_MAX] = exact_params(lag, delay, dt)
        params[:, LD_A_MAX] = self.max_decel_mps2
        sizes = np.empty((runs, 2), dtype=np.int64)
        sizes[:, 0] = 2
        sizes[:, 1] = params[:, E_LEN].astype(np.int64)
        return params, sizes


@njit(cache=True)
def lag_delay_ato_step(
    p: np.ndarray,
    state: np.ndarray,
    buffer: np.ndarray,
    u: float,
    speed_mps: float,
    t: float,
    dt: float,
    m_eff_lw: float,
    m_eff: float,
) -> tuple[float, float, float]:
    """Paper 002's brake in the simulator (the step of brakes/base.py).

    The ATO's command becomes ``uc = F^-1(u)`` in [0, 1] through the linear map; the
    delivered deceleration acts on the true effective mass. No electric brake.
    """
    uc = min(max(-u / p[LD_A_MAX], 0.0), 1.0)
    demand = uc * p[LD_A_MAX] * m_eff
    ac = lag_delay_exact_step(p, state, buffer, -p[LD_A_MAX] * uc)
    return 0.0, -ac * m_eff, demand
