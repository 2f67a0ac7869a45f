"""Controllers behind one small interface (:class:`~railpilot.control.base.Controller`).

A controller never sees the plant: it gets a reference, a measurement and an
explicit ``dt`` and returns one command. Each controller's arithmetic is a Numba
kernel ``*_step(params, state, ...)`` so the simulator's compiled loop and the
Python object share one implementation.
"""

from railpilot.control.base import Controller
from railpilot.control.pid import PID
from railpilot.control.qsmc import QSMC

__all__ = ["PID", "QSMC", "Controller"]
