"""The line: gradients, curves, speed limits and stations by position.

Positions are metres along the line inside (km posts at the edges, see units.py).
The train is treated as a point at its head for gradients and curves; averaging a
gradient over the train length is left to a later refinement (docs/architecture.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.units import curve_specific_resistance, gradient_permille_to_specific
from railpilot.vehicle.train import MAX_SPEED_KMH, MAX_SPEED_MPS


@dataclass(frozen=True)
class Segment:
    """A stretch of line ``[start_m, end_m)`` carrying one value.

    Any three numbers build one; the :class:`Line` holding it refuses a non-finite or
    backwards segment, naming its place (``line.gradients[3]``).
    """

    start_m: float
    end_m: float
    value: float

    def __post_init__(self) -> None:
        if type(self.start_m) is type(self.end_m) is type(self.value) is float:
            return  # any float will do: the usual case, a line of thousands of segments
        for name in ("start_m", "end_m", "value"):
            check_number(
                f"segment.{name}",
                getattr(self, name),
                allow_inf=True,
                allow_nan=True,
                allowed="a number",
                error=ConfigError,
            )

    def check(self, where: str) -> None:
        if not (
            math.isfinite(self.start_m) and math.isfinite(self.end_m) and self.end_m > self.start_m
        ):
            raise ConfigError(
                where, (self.start_m, self.end_m), "a segment with finite start_m < end_m"
            )
        if not math.isfinite(self.value):
            raise ConfigError(where, self.value, "a finite number")


@dataclass(frozen=True)
class StopPoint:
    """A station and the stop point [m] the train's head must stop at."""

    name: str
    stop_m: float

    def __post_init__(self) -> None:
        # stop_m is checked by the Line holding the station (line.stations[2].stop_m)
        if not isinstance(self.name, str):
            raise ConfigError("station.name", self.name, "a string")


@dataclass(frozen=True)
class Line:
    """Gradients [per mille, + uphill], curves [radius m], speed limits [m/s], stations.

    Everything outside the given segments is level, straight and unrestricted.
    """

    gradients: tuple[Segment, ...] = ()
    curves: tuple[Segment, ...] = ()
    speed_limits: tuple[Segment, ...] = ()
    stations: tuple[StopPoint, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        for name in ("gradients", "curves", "speed_limits", "stations"):
            _check_items(
                f"line.{name}", getattr(self, name), StopPoint if name == "stations" else Segment
            )
        for i, seg in enumerate(self.gradients):
            seg.check(f"line.gradients[{i}]")
        for i, seg in enumerate(self.curves):
            seg.check(f"line.curves[{i}]")
            if seg.value <= 0:
                raise ConfigError(f"line.curves[{i}].radius_m", seg.value, "a radius > 0 [m]")
        for i, seg in enumerate(self.speed_limits):
            seg.check(f"line.speed_limits[{i}]")
            # bounded above too: a limit squares into the drive profile's v**2 (overflow)
            if not 0 < seg.value <= MAX_SPEED_MPS:
                raise ConfigError(
                    f"line.speed_limits[{i}].limit",
                    seg.value,
                    f"a limit > 0 and <= {MAX_SPEED_MPS:.4g} m/s ({MAX_SPEED_KMH:g} km/h)",
                )
        for i, station in enumerate(self.stations):
            check_number(
                f"line.stations[{i}].stop_m",
                station.stop_m,
                allowed="a finite number [m]",
                error=ConfigError,
            )

    def resistance_profile(self) -> tuple[np.ndarray, np.ndarray]:
        """Additional specific resistance of the line as a step function.

        Returns ``(edges_m, values_n_per_kn)``: the resistance is ``values[i]`` on
        ``[edges[i], edges[i+1])`` and 0 outside ``[edges[0], edges[-1])``. Gradient
        (1 N/kN per mille) and curve (600/R N/kN) resistances add where they overlap.
        """
        pieces = [
            (s.start_m, s.end_m, float(gradient_permille_to_specific(s.value)))
            for s in self.gradients
        ]
        pieces += [
            (s.start_m, s.end_m, float(curve_specific_resistance(s.value))) for s in self.curves
        ]
        if not pieces:
            return np.array([0.0, 1.0]), np.array([0.0])
        edges = np.unique(np.array([p[0] for p in pieces] + [p[1] for p in pieces]))
        mids = 0.5 * (edges[:-1] + edges[1:])
        values = np.zeros(len(mids))
        for start, end, w in pieces:
            values[(mids >= start) & (mids < end)] += w
        return edges, values

    def additional_resistance(self, position_m: np.ndarray | float) -> np.ndarray:
        """Specific gradient + curve resistance [N/kN] at ``position_m`` [m]."""
        edges, values = self.resistance_profile()
        return step_lookup(edges, values, np.asarray(position_m, dtype=float))

    def speed_limit(self, position_m: np.ndarray | float) -> np.ndarray:
        """Lowest speed limit [m/s] in force at ``position_m`` (``inf`` if none)."""
        pos = np.asarray(position_m, dtype=float)
        limit = np.full(pos.shape, np.inf)
        for seg in self.speed_limits:
            inside = (pos >= seg.start_m) & (pos < seg.end_m)
            limit = np.where(inside, np.minimum(limit, seg.value), limit)
        return limit


def _check_items(field: str, items: object, kind: type) -> None:
    """A ConfigError naming ``field`` (or the item) unless ``items`` is a tuple or list of
    ``kind``."""
    if not isinstance(items, tuple | list):
        raise ConfigError(field, items, f"a tuple of {kind.__name__}")
    for i, item in enumerate(items):
        if not isinstance(item, kind):
            raise ConfigError(f"{field}[{i}]", item, f"a {kind.__name__}")


def step_lookup(edges: np.ndarray, values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Value of the step function ``(edges, values)`` at ``x``; 0 outside it."""
    idx = np.searchsorted(edges, x, side="right") - 1
    inside = (idx >= 0) & (idx < len(values))
    return np.where(inside, values[np.clip(idx, 0, len(values) - 1)], 0.0)
