"""The planned-curve report to the ground (paper 001 section 2.3).

The onboard tells the ground how it stands on the current station pair: the time already
run and the time its plan still needs (link message ``PlannedCurve``), so the ground can
compare with the timetable and re-time. The times change every second while the train
runs; what matters to the ground is the predicted running time ``elapsed + remaining``. So
a report goes out when the station pair changes, when that prediction has moved by at least
``threshold_s`` since the last report, and otherwise every ``refresh_s`` (a lost report is
repaired without waiting for a change). No I/O: the caller sends what :meth:`update`
returns (``OnboardEndpoint.send``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from railpilot.errors import ConfigError
from railpilot.interp import interp_at
from railpilot.jit import njit
from railpilot.link.messages import PlannedCurve
from railpilot.onboard.planner import SpeedPlan


def remaining_time_s(plan: SpeedPlan, position_s_m: float) -> float:
    """Time [s] the plan still needs from ``position_s_m`` [m from the departure stop].

    The plan's running time minus its time to reach that point (trapezoidal in ``1 / v``
    between grid points, the planner's own rule); 0 at or beyond the end.
    """
    elapsed_plan = plan.elapsed_s
    return _remaining_s(float(position_s_m), plan.s_m, elapsed_plan)


@njit(cache=True)
def _remaining_s(position_s_m: float, s_m: np.ndarray, elapsed: np.ndarray) -> float:
    # Compiled: every train asks once or twice a second, and np.interp called from Python
    # on one point costs microseconds (benchmarks/line_speed.py); interp_at gives NumPy's
    # results to the bit (tests/onboard/test_report.py, tests/test_interp.py).
    return max(0.0, elapsed[-1] - interp_at(position_s_m, s_m, elapsed))


@dataclass
class PlannedCurveReporter:
    """Decides when the onboard reports its planned curve (module docstring).

    Attributes
    ----------
    threshold_s
        Report when the predicted running time has moved by this much [s] (1 s).
    refresh_s
        Report at least this often [s] while running (60 s).
    """

    threshold_s: float = 1.0
    refresh_s: float = 60.0
    _last: tuple[int, int, float, float] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("threshold_s", "refresh_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ConfigError(f"report.{name}", value, "a number > 0 [s]")

    def update(
        self,
        from_station_id: int,
        to_station_id: int,
        elapsed_s: float,
        remaining_s: float,
        now_s: float,
    ) -> PlannedCurve | None:
        """The message to send now, or None. ``now_s`` the onboard's clock [s]."""
        total = elapsed_s + remaining_s
        last = self._last
        due = (
            last is None
            or (last[0], last[1]) != (from_station_id, to_station_id)
            or abs(total - last[2]) >= self.threshold_s
            or now_s - last[3] >= self.refresh_s
        )
        if not due:
            return None
        message = PlannedCurve(
            from_station_id, to_station_id, max(0.0, elapsed_s), max(0.0, remaining_s)
        )
        self._last = (from_station_id, to_station_id, total, now_s)
        return message
