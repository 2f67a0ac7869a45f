"""Line data by km post: stations, gradients, curves, static limits, signals, block sections.

One :class:`RailLine` holds a whole line in both directions; :func:`load_line` reads a
shipped line (``"heavy-haul"``, ``"metro"``) or a TOML file (docs/line-data.md), and
:meth:`RailLine.to_vehicle_line` gives the simulation core's
:class:`~railpilot.vehicle.line.Line` for one train category and direction::

    line = load_line("heavy-haul")
    edges_m, limit_mps = line.static_limit("freight_loaded", UP)
    sim_line = line.to_vehicle_line("freight_loaded", UP)
"""

from __future__ import annotations

from .loader import SHIPPED_LINES, line_from_mapping, load_line, parse_line, read_line
from .model import (
    DIRECTIONS,
    DOWN,
    UP,
    BlockSection,
    Curve,
    Gradient,
    RailLine,
    Signal,
    SpeedLimit,
    Station,
    direction_name,
)

__all__ = [
    "DIRECTIONS",
    "DOWN",
    "SHIPPED_LINES",
    "UP",
    "BlockSection",
    "Curve",
    "Gradient",
    "RailLine",
    "Signal",
    "SpeedLimit",
    "Station",
    "direction_name",
    "line_from_mapping",
    "load_line",
    "parse_line",
    "read_line",
]
