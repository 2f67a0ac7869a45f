"""The line file's format (docs/line-data.md): stations, gradients, curves, speed limits,
signals and block sections by km post.

These models check each key alone (its type, and a km post within ``MAX_KM_POST`` either
way, so that no error writes out ``1e300`` km); the values' ranges and the rules across
entries (sorted, contiguous, inside the line, unique ids) are the line model's,
railpilot.line.model, and the reader (railpilot.line.loader) names each entry by its
label (``gradients[3] (km 12.400-11.900)``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, Literal

from pydantic import Field

from railpilot.schema.fields import NOT_GIVEN, FileTable, Says, Unit, WhenMissing, Words, one_of
from railpilot.schema.line_table import CurveTable, GradientTable, KmPost
from railpilot.units import MAX_KM_POST

REQUIRED = "(the key is required)"
#: what a required word (a signal's direction, ...) is told when the file leaves it out
A_WORD = WhenMissing(f"a string {REQUIRED}")


class LineWords(Words):
    """The line file's way: a number is "a finite number", a km post out of bounds "a km
    post in [-10000, 10000]"; a key's type is told as required."""

    float_values = True

    @staticmethod
    def number(fault: str, gt: float | None, ge: float | None, le: float | None, unit: str) -> str:
        if fault in ("greater_than_equal", "less_than_equal"):
            return f"a km post in [{-MAX_KM_POST:g}, {MAX_KM_POST:g}]"
        return "a finite number"

    @staticmethod
    def whole(ge: float | None, le: float | None) -> str:
        return f"an integer {REQUIRED}"

    @staticmethod
    def string(non_empty: bool) -> str:
        return f"a string {REQUIRED}"

    @staticmethod
    def choice(options: Sequence[object], value: Any) -> str:
        return one_of(options) if isinstance(value, str) else f"a string {REQUIRED}"

    @staticmethod
    def required(allowed: str) -> str:
        if allowed.endswith(REQUIRED):
            return allowed
        if allowed.startswith("a finite number") or allowed.startswith("a km post"):
            allowed = "a number"
        return f"{allowed} {REQUIRED}"


class LineFileTable(FileTable):
    WORDS = LineWords


#: a station's stop points: the station's ``km`` when left out
StopPost = Annotated[KmPost, Field(description="default: the station's km")]


class LineStationTable(LineFileTable):
    """``stations``: a station and its loop; trains stop at ``stop_up_km`` going up and
    ``stop_down_km`` going down (both default to ``km``)."""

    id: int
    name: str
    #: the loop's centre
    km: KmPost
    loop_length_m: Annotated[float, Unit("m")]
    stop_up_km: StopPost = NOT_GIVEN
    stop_down_km: StopPost = NOT_GIVEN


class LineGradientTable(GradientTable):
    """``gradients``: a constant gradient from ``start_km`` to ``end_km`` [per mille,
    + rising towards increasing km]; the gradients tile the line."""

    WORDS = LineWords


class LineCurveTable(CurveTable):
    """``curves``: a curve of radius ``radius_m`` [m] from ``start_km`` to ``end_km``."""

    WORDS = LineWords


class LineSpeedLimitTable(LineFileTable):
    """``speed_limits``: the static limit of one train category, in one direction or both;
    for each category and direction they tile the line."""

    category: str
    start_km: KmPost
    end_km: KmPost
    limit_kmh: Annotated[float, Unit("km/h")]
    direction: Literal["both", "up", "down"] = "both"


class SignalTable(LineFileTable):
    """``signals``: a signal at ``km``, facing trains going ``direction``."""

    id: str
    km: KmPost
    direction: Annotated[Literal["up", "down"], A_WORD]
    kind: Annotated[Literal["home", "exit", "block"], A_WORD]


class BlockSectionTable(LineFileTable):
    """``block_sections``: a block section of one direction (derived from the signals when
    the file gives none)."""

    id: str
    direction: Annotated[Literal["up", "down"], A_WORD]
    start_km: KmPost
    end_km: KmPost


class LineFile(LineFileTable):
    """A line file: the line's km posts, its train categories, and its stations,
    gradients, curves, speed limits, signals and block sections."""

    name: str
    description: str = ""
    start_km: float = 0.0
    end_km: float
    start_elevation_m: Annotated[float, Unit("m")] = 0.0
    categories: Annotated[
        list[Any],
        Field(min_length=1, json_schema_extra={"items": {"type": "string"}}),
        Says("a non-empty list of category names"),
        WhenMissing("a non-empty list of category names"),
    ]
    stations: list[LineStationTable] = Field(default_factory=list)
    gradients: list[LineGradientTable] = Field(default_factory=list)
    curves: list[LineCurveTable] = Field(default_factory=list)
    speed_limits: list[LineSpeedLimitTable] = Field(default_factory=list)
    signals: list[SignalTable] = Field(default_factory=list)
    block_sections: list[BlockSectionTable] = Field(default_factory=list)
