"""Step-response metrics of a torque run, like paper 003 Table 4.

Definitions (``Md`` the demanded torque, the response starts from 0 at ``t = 0``):

rise_time_s
    Time from the first sample with ``M >= 0.1 Md`` to the first with ``M >= 0.9 Md``.
peak_time_s, overshoot_nm
    Time and excess ``max(M) - Md`` (floored at 0) of the largest torque of the whole
    run -- the paper's Table 4 overshoot of fuzzy adaptive PI equals its steady maximum
    minus the demand, so it too is a whole-run maximum that includes chopper ripple.
settling_time_s
    First time after which ``|M - Md| <= settling_band * Md`` (default 2 %) holds until
    the end of the steady window; ``nan`` if the torque is outside the band then.
steady_mean_nm, steady_max_nm, steady_min_nm, steady_variance_nm2
    Mean, maximum, minimum and (population) variance of ``M`` over the steady window
    ``[steady_start_s, t_end]`` where ``t_end`` is when the speed first drops to
    ``steady_end_speed_kmh`` (the end of the run if it never does).
hold_from_speed_kmh, hold_until_speed_kmh
    Speeds at the start and end of the longest stretch of samples with
    ``|M - Md| <= hold_band * Md`` (default 1 %): the speed range over which the brake
    holds the demand; ``nan`` if it never does.

All functions take plain arrays; the metrics are as fine as the sampling
(``record_every=1`` in :func:`railpilot.eddy.simulate.simulate_eddy` sees every ripple).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from railpilot.errors import ConfigError


@dataclass(frozen=True)
class StepMetrics:
    """Table-4 style metrics of one run (see the module docstring for definitions)."""

    rise_time_s: float
    settling_time_s: float
    peak_time_s: float
    overshoot_nm: float
    steady_mean_nm: float
    steady_max_nm: float
    steady_min_nm: float
    steady_variance_nm2: float
    hold_from_speed_kmh: float
    hold_until_speed_kmh: float
    steady_window_s: tuple[float, float]

    def to_dict(self) -> dict[str, float | list[float] | None]:
        """JSON-ready: ``nan`` becomes ``None``."""
        out: dict[str, float | list[float] | None] = {}
        for key, value in asdict(self).items():
            if isinstance(value, tuple):
                out[key] = [float(v) for v in value]
            else:
                out[key] = None if math.isnan(value) else float(value)
        return out


def rise_time_s(time_s: np.ndarray, torque_nm: np.ndarray, demand_nm: float) -> float:
    """10-90 % rise time [s]; ``nan`` if the torque never reaches 90 % of the demand."""
    above10 = np.flatnonzero(torque_nm >= 0.1 * demand_nm)
    above90 = np.flatnonzero(torque_nm >= 0.9 * demand_nm)
    if above10.size == 0 or above90.size == 0:
        return math.nan
    return float(time_s[above90[0]] - time_s[above10[0]])


def settling_time_s(
    time_s: np.ndarray, torque_nm: np.ndarray, demand_nm: float, band: float, t_end_s: float
) -> float:
    """First time after which the torque stays within ``band * demand`` up to ``t_end_s``."""
    upto = time_s <= t_end_s
    outside = np.flatnonzero((np.abs(torque_nm - demand_nm) > band * demand_nm) & upto)
    last = int(np.flatnonzero(upto)[-1])
    if outside.size == 0:
        return float(time_s[0])
    if outside[-1] >= last:
        return math.nan
    return float(time_s[outside[-1] + 1])


def hold_speeds_kmh(
    speed_kmh: np.ndarray, torque_nm: np.ndarray, demand_nm: float, band: float
) -> tuple[float, float]:
    """Speeds [km/h] at the start and end of the longest in-band stretch."""
    inside = np.abs(torque_nm - demand_nm) <= band * demand_nm
    if not inside.any():
        return math.nan, math.nan
    padded = np.concatenate([[False], inside, [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2]  # stretch k is [starts[k], stops[k])
    k = int(np.argmax(stops - starts))
    return float(speed_kmh[starts[k]]), float(speed_kmh[stops[k] - 1])


def step_metrics(
    time_s: np.ndarray,
    torque_nm: np.ndarray,
    speed_kmh: np.ndarray,
    demand_nm: float,
    *,
    settling_band: float = 0.02,
    hold_band: float = 0.01,
    steady_start_s: float = 5.0,
    steady_end_speed_kmh: float = 30.0,
) -> StepMetrics:
    """All Table-4 metrics of one run (definitions in the module docstring)."""
    time_s = np.asarray(time_s, dtype=float)
    torque_nm = np.asarray(torque_nm, dtype=float)
    speed_kmh = np.asarray(speed_kmh, dtype=float)
    if not (time_s.shape == torque_nm.shape == speed_kmh.shape) or time_s.size < 2:
        raise ConfigError(
            "metrics.series",
            f"shapes {time_s.shape}, {torque_nm.shape}, {speed_kmh.shape}",
            "three equally long one-dimensional series with at least 2 samples",
        )
    if not demand_nm > 0:
        raise ConfigError("metrics.demand_nm", demand_nm, "a number > 0")
    below = np.flatnonzero(speed_kmh <= steady_end_speed_kmh)
    t_end = float(time_s[below[0]]) if below.size else float(time_s[-1])
    window = (time_s >= steady_start_s) & (time_s <= t_end)
    if window.any():
        steady = torque_nm[window]
        s_mean, s_max = float(steady.mean()), float(steady.max())
        s_min, s_var = float(steady.min()), float(steady.var())
    else:
        s_mean = s_max = s_min = s_var = math.nan
    i_peak = int(np.argmax(torque_nm))
    hold_from, hold_until = hold_speeds_kmh(speed_kmh, torque_nm, demand_nm, hold_band)
    return StepMetrics(
        rise_time_s=rise_time_s(time_s, torque_nm, demand_nm),
        settling_time_s=settling_time_s(time_s, torque_nm, demand_nm, settling_band, t_end),
        peak_time_s=float(time_s[i_peak]),
        overshoot_nm=max(float(torque_nm[i_peak]) - demand_nm, 0.0),
        steady_mean_nm=s_mean,
        steady_max_nm=s_max,
        steady_min_nm=s_min,
        steady_variance_nm2=s_var,
        hold_from_speed_kmh=hold_from,
        hold_until_speed_kmh=hold_until,
        steady_window_s=(float(steady_start_s), t_end),
    )
