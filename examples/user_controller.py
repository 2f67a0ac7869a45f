"""Your own controller in railpilot's simulator: two ways (docs/architecture.md).

Run it::

    railpilot simulate examples/paper000_smarc_ep.toml \
        --controller examples/user_controller.py:SpeedPositionTracker --json
    railpilot simulate examples/paper000_smarc_ep.toml \
        --controller examples/user_controller.py:CompiledTracker --json
    railpilot montecarlo examples/paper000_montecarlo.toml --runs 200 \
        --controller examples/user_controller.py:CompiledTracker --json

Both implement the same law: feed the reference acceleration forward and correct the
speed and position errors, ``u = a_ref - k_v (v - v_ref) - k_x (x - x_ref)`` [m/s^2]. The
ATO adds its resistance model and clamps the result to the train's service brake, as for
every built-in controller.

* :class:`SpeedPositionTracker` is plain Python (``reset`` and ``update``): anything goes
  inside ``update``; the simulator calls it at every control update (slower; a Monte
  Carlo runs it one run after another).
* :class:`CompiledTracker` brings a Numba ``step`` (the signature in
  railpilot/control/base.py): it runs in the compiled loop and in parallel Monte Carlo.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from railpilot.control.user import CompiledController

#: gains: speed error [1/s], position error [1/s^2] (a well-damped pair for a brake that
#: answers in about a second)
K_V = 0.8
K_X = 0.15


class SpeedPositionTracker:
    """A Python controller: ``update(reference, measurement, dt) -> command``."""

    name = "speed-position-tracker"

    def __init__(self, k_v: float = K_V, k_x: float = K_X) -> None:
        self.k_v = k_v
        self.k_x = k_x
        self.updates = 0

    def reset(self) -> None:
        self.updates = 0

    def update(self, reference, measurement, dt):  # type: ignore[no-untyped-def]
        x_ref, v_ref, a_ref = reference
        x, v = measurement
        self.updates += 1
        return a_ref - self.k_v * (v - v_ref) - self.k_x * (x - x_ref)


@njit(cache=True)
def tracker_step(params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, u_min, u_max, dt):  # type: ignore[no-untyped-def]
    """The same law as a compiled step (control/base.py); ``state[0]`` counts updates."""
    state[0] += 1.0
    return ref_a - params[0] * (v - ref_v) - params[1] * (x - ref_x) + resist_mps2


class CompiledTracker(CompiledController):
    """A compiled controller: ``step``, ``params``, ``state``."""

    name = "compiled-tracker"
    step = tracker_step

    def __init__(self, k_v: float = K_V, k_x: float = K_X) -> None:
        super().__init__(params=np.array([k_v, k_x]), state=np.zeros(1))
