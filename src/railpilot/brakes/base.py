"""The interface every brake model of the simulator implements.

A brake model is a frozen dataclass of its parameters (its configuration) with:

* ``pack(context) -> params``: its parameters as one float64 array for the compiled
  loop, for the simulation step and train in ``context``;
* ``sizes(params) -> (n_state, n_buffer)``: the floats of state and of command history
  (its delay line) it needs;
* ``lead_s -> (delay_s, lag_s)``: its response, for the ATO's tuning and feed-forward;
* ``changeover_kmh``: electric/air changeover speed [km/h] (0 for a brake without one);

optionally ``FILE_KEYS`` (scenario-file key -> (field, conversion to SI, conversion
back for error messages), for keys the file writes in other units, e.g.
``fade_rate_kn_per_s``) and ``FILE_LISTS`` (a list key -> the fields it fills): the
scenario loader reads every other field under its own name, and a field that is itself a
config dataclass from a sub-table; and one compiled step with this signature (the *step*
of its registry entry, brakes/registry.py)::

    step(params, state, buffer, u, v, t, dt, m_eff_lw, m_eff) -> (electric_n, air_n, demand_n)

``u``: the ATO's commanded acceleration [m/s^2] (negative brakes); ``v`` speed [m/s];
``t`` time [s]; ``dt`` step [s]; ``m_eff_lw``: the load-weighed effective mass the brake
manager computes forces with [kg]; ``m_eff``: the true effective mass [kg]. It returns
the electric and the air (friction) brake force at the rail [N, positive retarding] and
the force the ATO demanded [N], and advances ``state`` and ``buffer``. The simulator then
scales the air force by the scenario's brake gain (friction error) and limits the total
by adhesion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.vehicle.train import Train


@dataclass(frozen=True)
class PackContext:
    """What a brake model may need to pack itself for one run."""

    dt_s: float
    #: the load-weighed effective mass the brake manager computes forces with [kg]
    load_weighed_eff_mass_kg: float
    train: Train

    def __post_init__(self) -> None:
        # the simulation's step: a brake packed for it names sim.dt_s too
        check_number("sim.dt_s", self.dt_s, positive=True, unit="s", error=ConfigError)
        check_number(
            "load_weighed_eff_mass_kg",
            self.load_weighed_eff_mass_kg,
            positive=True,
            unit="kg",
            error=ConfigError,
        )
        if not isinstance(self.train, Train):
            raise ConfigError("train", self.train, "a railpilot.vehicle.train.Train")


class BrakeModel(Protocol):
    """What the simulator needs of a brake model's configuration object."""

    name: ClassVar[str]

    def pack(self, context: PackContext) -> np.ndarray: ...

    def sizes(self, params: np.ndarray) -> tuple[int, int]: ...

    @property
    def lead_s(self) -> tuple[float, float]: ...

    @property
    def changeover_kmh(self) -> float: ...


#: the type of a brake model's compiled step (a Numba dispatcher)
BrakeStep = Any
