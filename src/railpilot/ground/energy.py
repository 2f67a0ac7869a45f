"""Energy-time curves of a line's sections, from the onboard planner.

The re-timing LP (ground/running_time_lp.py) trades lateness against energy through one convex
curve per section: net energy [kWh] against running time [s]. In the paper's system the
onboard computes its planned curve for the running time the ground sends; here the ground
asks the same planner (onboard/planner.py, through the route construction of
onboard/drive.py: MRSP of the static limits, whole-train ceiling 5 km/h below it) for the
section at a few running times and keeps the lower convex hull of the answers.

Samples: the fastest run ``T_f`` and ``factor x T_f`` for each factor (1.03 to 1.30 by
default), plus any running times asked for (the timetable's, so that the fixed plan's
energy is the planner's own). Energy: traction drawn minus regeneration returned
(``SpeedPlan.energy_net_kwh``), negative where the section descends enough.

The planner's energy is not always monotone or convex in the running time: on steep
descents it moves between its strategies in a sawtooth (docs/onboard.md, "Not met, on
steep descents"). The hull (:meth:`EnergyCurve.from_samples`) lies on or below every
sample and is what the onboard could achieve by mixing two of its plans; where it lies
below a sample, the LP's energy for that running time is optimistic by the gap
(:attr:`SectionEnergy.hull_gap_kwh`). Nothing is cached on disk.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.ground.running_time_lp import EnergyCurve
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.onboard.drive import DEFAULT_MARGIN_KMH, TrainPreset, departure_section
from railpilot.onboard.mrsp import travelled_m
from railpilot.onboard.planner import fastest, plan

#: running times sampled, as multiples of the fastest run
DEFAULT_FACTORS = (1.00, 1.03, 1.06, 1.10, 1.15, 1.20, 1.30)
#: an extra running time this close to a sample [s] is not sampled again
MIN_SAMPLE_SPACING_S = 1.0


@dataclass(frozen=True, eq=False)
class SectionEnergy:
    """One section's samples and its curve.

    Attributes
    ----------
    from_station, to_station
        Station ids.
    length_m
        Stop to stop [m].
    fastest_s
        The planner's fastest run [s]: the section's minimum running time.
    times_s, energy_net_kwh
        The samples: running time [s] the planner met and its net energy [kWh].
    strategies
        The planner's strategy for each sample ("fastest", "mareco", "uniform").
    curve
        The lower convex hull of the samples (up to its minimum).
    """

    from_station: int
    to_station: int
    length_m: float
    fastest_s: float
    times_s: np.ndarray
    energy_net_kwh: np.ndarray
    strategies: tuple[str, ...]
    curve: EnergyCurve

    @property
    def hull_gap_kwh(self) -> float:
        """How far the curve lies below the furthest sample [kWh] (0: the planner's
        energy is convex and non-increasing over the samples)."""
        below = self.energy_net_kwh - self.curve.energy_at(self.times_s)
        return float(np.max(below, initial=0.0))


def section_energy(
    line: RailLine,
    preset: TrainPreset,
    from_station: int,
    to_station: int,
    *,
    factors: Sequence[float] = DEFAULT_FACTORS,
    extra_times_s: Sequence[float] = (),
    margin_kmh: float = DEFAULT_MARGIN_KMH,
) -> SectionEnergy:
    """Sample the planner on one station pair (stop to stop) and build its curve.

    ``factors``: multiples (>= 1) of the fastest run to sample; ``extra_times_s``: running
    times [s] to sample as well (those shorter than the fastest run are skipped). The
    section is the one ``railpilot drive`` plans: no TSRs, no target points.
    """
    if not factors or any(
        isinstance(f, bool) or not isinstance(f, int | float) or not (1.0 <= f <= 3.0)
        for f in factors
    ):
        raise ConfigError("factors", factors, "multiples of the fastest run in [1, 3]")
    for t in extra_times_s:
        if (
            isinstance(t, bool)
            or not isinstance(t, int | float)
            or not (math.isfinite(t) and t > 0)
        ):
            raise ConfigError("extra_times_s", t, "running times > 0 [s]")
    start = line.station(from_station)
    end = line.station(to_station)
    if start.id == end.id:
        raise ConfigError("to_station", to_station, "a station other than from_station")
    direction = UP if end.centre_m > start.centre_m else DOWN
    length = float(travelled_m(end.stop_m(direction), direction, start.stop_m(direction)))
    sec = departure_section(line, preset, from_station, to_station, margin_kmh)
    quickest = fastest(preset.driving, sec)
    t_fast = quickest.running_time_s
    wanted = sorted({f * t_fast for f in factors if f > 1.0} | {t for t in extra_times_s})
    times = [t_fast]
    energies = [quickest.energy_net_kwh]
    strategies = [quickest.strategy]
    for target in wanted:
        if target <= t_fast + MIN_SAMPLE_SPACING_S or any(
            abs(target - t) < MIN_SAMPLE_SPACING_S for t in times
        ):
            continue
        curve = plan(preset.driving, sec, target)
        times.append(curve.running_time_s)
        energies.append(curve.energy_net_kwh)
        strategies.append(curve.strategy)
    t_arr = np.asarray(times)
    e_arr = np.asarray(energies)
    order = np.argsort(t_arr, kind="stable")
    return SectionEnergy(
        start.id,
        end.id,
        length,
        t_fast,
        t_arr[order],
        e_arr[order],
        tuple(strategies[i] for i in order),
        EnergyCurve.from_samples(t_arr, e_arr),
    )


def route_energy(
    line: RailLine,
    preset: TrainPreset,
    stations: Sequence[int],
    *,
    planned_running_s: Mapping[tuple[int, int], float] | None = None,
    factors: Sequence[float] = DEFAULT_FACTORS,
) -> tuple[SectionEnergy, ...]:
    """Curves of every consecutive pair of ``stations`` (ids in running order).

    ``planned_running_s``: the timetable's running time per ``(from, to)``, sampled as
    well so that the curve passes through (or below) the planner's energy there.
    """
    if len(stations) < 2:
        raise ConfigError("stations", stations, "at least two station ids in running order")
    planned = planned_running_s or {}
    return tuple(
        section_energy(
            line,
            preset,
            a,
            b,
            factors=factors,
            extra_times_s=(planned[(a, b)],) if (a, b) in planned else (),
        )
        for a, b in itertools.pairwise(stations)
    )
