"""The ``[line]`` table of a scenario file: gradients, curves, speed limits and stations by
km post (docs/line-data.md has the line files of the line runs, a richer format)."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from railpilot.schema.config import ConfigTable
from railpilot.schema.fields import Unit
from railpilot.units import MAX_KM_POST

KmPost = Annotated[float, Field(ge=-MAX_KM_POST, le=MAX_KM_POST), Unit("km")]


class _Span(ConfigTable):
    start_km: KmPost
    end_km: KmPost


class GradientTable(_Span):
    """A constant gradient from ``start_km`` to ``end_km`` [per mille, + uphill]."""

    permille: float


class CurveTable(_Span):
    """A curve of radius ``radius_m`` [m] from ``start_km`` to ``end_km``."""

    radius_m: float


class SpeedLimitTable(_Span):
    """A speed limit [km/h] from ``start_km`` to ``end_km``."""

    limit_kmh: Annotated[float, Unit("km/h")]


class StationTable(ConfigTable):
    """A station: where trains stop."""

    name: str = "station"
    stop_km: KmPost


class LineTable(ConfigTable):
    """``[line]``: the line the run drives along (every list may be left out)."""

    gradients: list[GradientTable] = Field(default_factory=list)
    curves: list[CurveTable] = Field(default_factory=list)
    speed_limits: list[SpeedLimitTable] = Field(default_factory=list)
    stations: list[StationTable] = Field(default_factory=list)
