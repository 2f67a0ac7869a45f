"""Open-loop "controller": a fixed command, no feedback (paper 003's open-loop case).

It implements the :class:`~railpilot.control.base.Controller` interface so the
simulators can run it like any other controller. In the eddy-brake loop
(:mod:`railpilot.eddy.simulate`) its command is the coil-current reference itself [A]
-- the current that gives the demanded torque at the initial speed -- rather than a
change rate, because an open loop has nothing to integrate.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from railpilot.control.base import Controller, check_dt, check_number
from railpilot.jit import njit

O_LEVEL = 0
N_OPEN_PARAMS = 1
O_OUT = 0
N_OPEN_STATE = 1


@njit(cache=True)
def open_loop_step(
    params: np.ndarray, state: np.ndarray, setpoint: float, measurement: float, dt: float
) -> float:
    """Ignore ``setpoint`` and ``measurement``; return the constant command."""
    out = params[O_LEVEL]
    state[O_OUT] = out
    return out


class OpenLoop(Controller):
    """Constant command ``level`` (e.g. a coil current [A]), no feedback."""

    name: ClassVar[str] = "open_loop"

    def __init__(self, level: float) -> None:
        self.params = np.array([check_number("level", level)])
        self.state = np.zeros(N_OPEN_STATE)

    @property
    def level(self) -> float:
        return float(self.params[O_LEVEL])

    def reset(self) -> None:
        self.state[:] = 0.0

    def update(self, setpoint: float, measurement: float, dt: float) -> float:
        """Return the command for this sample; ``dt`` [s] since the previous one."""
        return float(
            open_loop_step(
                self.params, self.state, float(setpoint), float(measurement), check_dt(dt)
            )
        )

    @property
    def components(self) -> dict[str, float]:
        return {"level": self.level}
