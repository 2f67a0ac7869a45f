"""Driving advice from the planned curve, and a driver who follows it.

Paper 001's onboard gives the driver advice from an expert knowledge base; ours is the
planned curve read at the train's position, with a correction for the speed error, turned
into what a driver sets: a traction level, coasting, a regenerative level or the air brake,
with the expected arrival and the deviation from the plan (:func:`advise`). No I/O, time
passed in.

:class:`DriverModel` closes the loop in simulation: a controller (the simulator's Python
controller interface, control/user.py) that acts on the advice as a driver would, in
notches and after a reaction time.

Advice (``s`` the distance from the departure stop, ``v`` the speed)::

    a_plan  = (v_p(s + h)^2 - v_p(s)^2) / (2 h)            the plan's acceleration ahead
    a_want  = a_plan + (v_p(s) - v) / tau                  closing the speed error in tau
    F       = m_eff (a_want + w_coast(v, s))               the force it takes
    F > 0:  traction at F / F_T(v);  F < 0: regeneration at -F / F_E(v), the air brake for
    what regeneration cannot give; |F| below a dead band: coast.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from railpilot.errors import ConfigError
from railpilot.onboard.planner import DrivingTrain, SpeedPlan
from railpilot.onboard.report import remaining_time_s
from railpilot.units import KMH_PER_MPS

Mode = Literal["traction", "coast", "regen", "air"]

#: look-ahead of the plan's acceleration [m]
LOOKAHEAD_M = 50.0
#: the speed error is closed in this time [s]
CORRECTION_S = 30.0
#: below this share of the available force, coast [-]
DEAD_BAND = 0.05


@dataclass(frozen=True)
class Advice:
    """What the driver is told at one moment.

    Attributes
    ----------
    mode
        "traction", "coast", "regen" or "air" (air: regeneration is not enough).
    level
        Share of the available traction or regenerative force, 0 to 1; for "air" the
        share of the air brake's full service the rest needs.
    target_speed_mps
        The plan's speed here [m/s].
    expected_arrival_s
        Time [s] from the departure at which the train will arrive, at the plan's pace from
        here.
    deviation_s
        ``expected_arrival_s`` minus the planned running time [s]: + late, - early.
    """

    mode: Mode
    level: float
    target_speed_mps: float
    expected_arrival_s: float
    deviation_s: float

    def text(self) -> str:
        """One line for a driver's display."""
        speed = self.target_speed_mps * KMH_PER_MPS
        late = f"{abs(self.deviation_s):.0f} s {'late' if self.deviation_s > 0 else 'early'}"
        what = "coast" if self.mode == "coast" else f"{self.mode} {100 * self.level:.0f} %"
        return f"{what}, target {speed:.0f} km/h, {late}"


def advise(
    train: DrivingTrain,
    plan: SpeedPlan,
    line_w: np.ndarray,
    s_m: float,
    v_mps: float,
    elapsed_s: float,
    air_decel_mps2: float,
) -> Advice:
    """The advice at ``s_m`` [m from the departure stop], ``v_mps`` [m/s], ``elapsed_s`` [s].

    ``line_w`` the section's line resistance [N/kN] on the plan's grid
    (``planner.SectionGrid.line_w``); ``air_decel_mps2`` the air brake's full service.
    """
    if not (math.isfinite(v_mps) and v_mps >= 0):
        raise ConfigError("v_mps", v_mps, "a finite speed >= 0 [m/s]")
    s_grid, v_grid = plan.s_m, plan.speed_mps
    v_here = float(np.sqrt(np.interp(s_m, s_grid, v_grid**2)))
    v_ahead = float(np.sqrt(np.interp(s_m + LOOKAHEAD_M, s_grid, v_grid**2)))
    a_plan = (v_ahead**2 - v_here**2) / (2.0 * LOOKAHEAD_M)
    a_want = a_plan + (v_here - v_mps) / CORRECTION_S
    w = float(np.interp(s_m, s_grid, line_w))
    m_eff = train.train.effective_mass_kg
    force = m_eff * (a_want + train.coast_decel_mps2(v_mps, w))
    loco = train.locomotive
    remaining = remaining_time_s(plan, s_m)
    arrival = elapsed_s + remaining
    deviation = arrival - plan.running_time_s
    if force >= 0.0:
        available = float(loco.traction.max_force(v_mps))
        share = force / available if available > 0 else 1.0
        mode: Mode = "traction" if share > DEAD_BAND else "coast"
        return Advice(mode, min(share, 1.0) if mode != "coast" else 0.0, v_here, arrival, deviation)
    braking = -force
    regen = float(loco.regen.max_force(v_mps))
    if regen > 0 and braking <= regen:
        share = braking / regen
        mode = "regen" if share > DEAD_BAND else "coast"
        return Advice(mode, share if mode != "coast" else 0.0, v_here, arrival, deviation)
    rest = braking - regen
    share = min(rest / (air_decel_mps2 * m_eff), 1.0)
    return Advice("air", share, v_here, arrival, deviation)


@dataclass
class DriverModel:
    """A driver following the planned curve in notches, after a reaction time.

    The simulator's Python controller (control/user.py): ``update(reference, measurement,
    dt)`` returns the commanded acceleration [m/s^2]; the simulator adds the ATO's
    resistance feed-forward on top (as for every controller), so the notches are the
    driver's correction around it. The driver wants ``a_ref + (v_ref - v) / correction_s``
    (the advice's rule, with the simulator's distance-based reference standing for the
    plan), sets the nearest of ``notches`` levels on each side of 0 (traction up to
    ``max_accel_mps2``, braking down to ``-max_decel_mps2``), and what he sets acts
    ``reaction_s`` later.

    Attributes
    ----------
    reaction_s
        Between seeing and acting [s] (1.5 s).
    notches
        Levels on each side of coasting (8).
    max_accel_mps2, max_decel_mps2
        The commands of the top traction and brake notch [m/s^2].
    correction_s
        The speed error is closed in this time [s] (``CORRECTION_S``).
    """

    max_accel_mps2: float
    max_decel_mps2: float
    reaction_s: float = 1.5
    notches: int = 8
    correction_s: float = CORRECTION_S
    name: str = "driver"
    _queue: deque[tuple[float, float]] = field(default_factory=deque, init=False, repr=False)
    _t: float = field(default=0.0, init=False, repr=False)
    _acting: float = field(default=0.0, init=False, repr=False)

    def __post_init__(self) -> None:
        for key in ("max_accel_mps2", "max_decel_mps2", "correction_s"):
            value = getattr(self, key)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ConfigError(f"driver.{key}", value, "a number > 0")
        if not (math.isfinite(self.reaction_s) and self.reaction_s >= 0):
            raise ConfigError("driver.reaction_s", self.reaction_s, "a number >= 0 [s]")
        if not (isinstance(self.notches, int) and 1 <= self.notches <= 100):
            raise ConfigError("driver.notches", self.notches, "an integer in [1, 100]")

    def reset(self) -> None:
        self._queue.clear()
        self._t = 0.0
        self._acting = 0.0

    def notch(self, wanted_mps2: float) -> float:
        """The nearest notch [m/s^2] to ``wanted_mps2``."""
        if wanted_mps2 >= 0:
            step = self.max_accel_mps2 / self.notches
            return min(round(wanted_mps2 / step), self.notches) * step
        step = self.max_decel_mps2 / self.notches
        return -min(round(-wanted_mps2 / step), self.notches) * step

    def update(self, reference, measurement, dt: float) -> float:  # type: ignore[no-untyped-def]
        wanted = reference.a_mps2 + (reference.v_mps - measurement.v_mps) / self.correction_s
        self._queue.append((self._t + self.reaction_s, self.notch(wanted)))
        while self._queue and self._queue[0][0] <= self._t + 1e-9:
            self._acting = self._queue.popleft()[1]
        self._t += dt
        return self._acting
