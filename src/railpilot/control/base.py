"""The interface every controller implements.

Habits from simple-pid: ``reset()``, output limits, anti-windup, internal terms
inspectable for tuning, ``dt`` always explicit, no clock and no sleeping.

Fast path
---------
Controllers keep their numbers in two float64 arrays, ``params`` (fixed by the
constructor) and ``state`` (changed by every update), and do their arithmetic in a
Numba ``@njit`` kernel taking ``(params, state, ...)``. The Python object calls
that kernel, and so does the simulator's compiled inner loop, so there is one
implementation of every control law.

The simulator's step
--------------------
The simulator calls one compiled function per controller, with this signature (the
*step* of a registry entry, control/registry.py, or of a user's compiled controller)::

    step(params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, u_min, u_max, dt) -> u

``ref_*``: the reference position [m], speed [m/s] and the acceleration the ATO feeds
forward [m/s^2]; ``x, v``: measured position and speed; ``resist_mps2``: the ATO's model
of the running resistance as a deceleration [m/s^2] (positive), for a feed-forward;
``u_min, u_max``: where the ATO will clamp ``u`` [m/s^2]; ``dt``: control period [s]. It
returns the commanded acceleration ``u`` [m/s^2] (negative brakes) and may change
``state``, and ``params`` (the simulator passes private copies of both).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

# the shared checks live in railpilot.checks (the physical models use them too); these
# names stay importable from here
from railpilot.checks import as_float as _as_float
from railpilot.checks import check_count as check_count
from railpilot.checks import check_flag as check_flag
from railpilot.checks import check_number as check_number
from railpilot.checks import check_pair as check_pair
from railpilot.errors import shown


class Controller(ABC):
    """A discrete-time controller that knows nothing about the plant it drives."""

    #: Short name used on the command line and in reports (``"pid"``, ``"smarc"``).
    name: ClassVar[str]

    params: np.ndarray
    state: np.ndarray

    @abstractmethod
    def reset(self) -> None:
        """Forget all history (integrators, filters, estimates) and start again."""

    @property
    @abstractmethod
    def components(self) -> dict[str, float]:
        """The internal terms of the last update (for tuning and plots)."""


def check_dt(dt: object) -> float:
    """Return ``dt`` [s] as a float, or raise ValueError if it is not > 0 and finite."""
    if type(dt) is float and 0.0 < dt < math.inf:  # the fast path (nan fails both)
        return dt
    return check_number("dt", dt, positive=True, unit="s")


def check_limits(limits: object) -> tuple[float, float]:
    """Turn ``(low, high)`` output limits (None = unbounded) into floats, low < high;
    a ValueError naming ``output_limits`` if they are no such pair."""
    allowed = "(low, high), each a number or None (unbounded)"
    bounds = []
    for i, (entry, unbounded) in enumerate(
        zip(check_pair("output_limits", limits, what=allowed), (-math.inf, math.inf), strict=True)
    ):
        bound = unbounded if entry is None else _as_float(entry)
        if bound is None or math.isnan(bound):
            raise ValueError(
                f"output_limits[{i}] = {shown(entry)} is not allowed: expected a number or "
                "None (unbounded)"
            )
        bounds.append(bound)
    low, high = bounds
    if not low < high:
        raise ValueError(
            f"output_limits = {shown(limits)} is not allowed: expected (low, high) with low < high"
        )
    return low, high
