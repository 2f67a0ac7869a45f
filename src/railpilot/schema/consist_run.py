"""The ``kind = "train-dynamics"`` scenario file (docs/consist-run.md): a consist driven
along a line by a script."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.schema.config import ConfigTable, config_table
from railpilot.schema.fields import NOT_GIVEN, FloatHeld, Unit, WhenMissing
from railpilot.schema.line_table import LineTable
from railpilot.vehicle.consist import CONSIST_PRESETS

KIND = "train-dynamics"

Positive = Annotated[float, Field(gt=0.0)]
AtLeastZero = Annotated[float, Field(ge=0.0)]
Speed = Annotated[float, Field(ge=0.0), Unit("km/h")]

#: the air brake's table: every field of FreightAirBrake but the charge, which is the
#: consist's brake_pipe_kpa
AirTable = config_table(FreightAirBrake, frozenset({"charged_kpa"}))


class ConsistSimTable(ConfigTable):
    """``[sim]``: the run's settings (defaults: railpilot.sim.consist_run)."""

    dt_s: Annotated[Positive, Unit("s")] = NOT_GIVEN
    duration_s: Annotated[Positive, Unit("s")] = NOT_GIVEN
    record_every_s: Annotated[Positive, Unit("s")] = NOT_GIVEN
    distributed_power: bool = NOT_GIVEN
    compare_without_distributed_power: bool = NOT_GIVEN
    coupler_limit_kn: Annotated[Positive, Unit("kN")] = NOT_GIVEN
    lump: Annotated[int, FloatHeld()] = NOT_GIVEN
    start_km: Annotated[float, Unit("km")] = NOT_GIVEN
    start_kmh: Speed = NOT_GIVEN


class DriverCommandTable(ConfigTable):
    """``[[driver.commands]]``: when (``at_s``, ``at_km``, ``below_kmh``, ``above_kmh``)
    and what (``effort``, ``hold_kmh``, ``reduction_kpa``, ``release``, ``emergency``)."""

    at_s: Annotated[AtLeastZero, Unit("s")] = NOT_GIVEN
    at_km: Annotated[float, Unit("km")] = NOT_GIVEN
    below_kmh: Speed = NOT_GIVEN
    above_kmh: Speed = NOT_GIVEN
    effort: Annotated[float, Field(ge=-1.0, le=1.0)] = NOT_GIVEN
    hold_kmh: Speed = NOT_GIVEN
    reduction_kpa: Annotated[AtLeastZero, Unit("kPa")] = NOT_GIVEN
    release: bool = NOT_GIVEN
    emergency: bool = NOT_GIVEN


class DriverTable(ConfigTable):
    """``[driver]``: the driver's gains and brake rules, and its script."""

    kp: AtLeastZero = NOT_GIVEN
    ki: AtLeastZero = NOT_GIVEN
    apply_above_kmh: Speed = NOT_GIVEN
    release_below_kmh: Speed = NOT_GIVEN
    min_release_kmh: Speed = NOT_GIVEN
    cycle_reduction_kpa: Annotated[Positive, Unit("kPa")] = NOT_GIVEN
    end_at_rest: bool = NOT_GIVEN
    commands: list[DriverCommandTable] = Field(default_factory=list)


class ConsistRunFileTable(ConfigTable):
    """A train-dynamics scenario file: a consist driven along a line by a script."""

    kind: Literal["train-dynamics"] = "train-dynamics"
    name: Annotated[str, WhenMissing("a scenario name (the key is required)")]
    #: a shipped consist (a preset) or a consist file, relative to this file's folder
    consist: str = CONSIST_PRESETS[0]
    line: LineTable = Field(default_factory=LineTable)
    air: AirTable = Field(default_factory=AirTable)  # type: ignore[valid-type]
    sim: ConsistSimTable = Field(default_factory=ConsistSimTable)
    driver: DriverTable = Field(default_factory=DriverTable)
