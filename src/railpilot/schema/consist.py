"""The consist file's format (docs/consist.md): its tables, keys, types and bounds.

Units are in the key names (t, kN, mm, kPa). These models check each key alone; the
rules across keys and files (a type or draft gear named in the file or the library, one
rotating mass, a brake where there is an air brake, the lead locomotive) are the reader's,
railpilot.scenario.consist_file.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Annotated, Any, Literal

from pydantic import Field

from railpilot.schema.fields import NOT_GIVEN, Choice, FileTable, Says, Unit
from railpilot.vehicle.consist import (
    DISTRIBUTORS,
    MAX_BRAKE_PIPE_KPA,
    MAX_DAVIS,
    MAX_DP_DELAY_S,
    MAX_ROTATING_MASS_FACTOR,
    MAX_VEHICLE_LENGTH_M,
    MAX_VEHICLE_MASS_KG,
    Consist,
)
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import Locomotive, hxd1_locomotive

#: locomotive models a type may name: name -> factory (traction and regeneration envelopes)
LOCOMOTIVE_MODELS: dict[str, Callable[[], Locomotive]] = {"HXD1": hxd1_locomotive}
#: the loads a wagon block may run at
LOADS = ("loaded", "empty")
#: most vehicles in one consist (a 10 km train of 1 m vehicles)
MAX_VEHICLES = 10_000
#: heaviest vehicle [t] a file may give (the model's own bound)
MAX_MASS_T = MAX_VEHICLE_MASS_KG / 1000.0
#: largest net braking ratio (shoe force over weight) [-]
MAX_BRAKING_RATIO = 2.0
#: largest draft-gear slack and travel [mm] (DraftGear allows up to 1 m)
MAX_GEAR_MM = 1000.0
#: largest draft-gear force [kN], stop stiffness [kN/mm] and damping [kN s/m]
MAX_GEAR_KN = 1e6
MAX_GEAR_STIFFNESS = 1e9


def _default(cls: type, name: str) -> Any:
    """A dataclass field's default: defaults are written once, in the model's dataclass."""
    return next(f for f in dataclasses.fields(cls) if f.name == name).default


Davis = Annotated[
    list[Annotated[float, Field(ge=0.0, le=MAX_DAVIS)]],
    Field(min_length=3, max_length=3, description="Davis resistance a0, a1, a2 [N/kN, v in km/h]"),
    Says("a list of 3 numbers [a0, a1, a2] (N/kN, v in km/h)"),
]
Tonnes = Annotated[float, Field(gt=0.0, le=MAX_MASS_T), Unit("t")]
Length = Annotated[float, Field(gt=0.0, le=MAX_VEHICLE_LENGTH_M), Unit("m")]
BrakeForce = Annotated[float, Field(ge=0.0, le=MAX_MASS_T * 10.0), Unit("kN")]
BrakingRatio = Annotated[float, Field(ge=0.0, le=MAX_BRAKING_RATIO)]
ShoeFriction = Annotated[float, Field(gt=0.0, le=1.0)]
GearName = Annotated[str, Says("a draft gear of the file or the library")]


class DraftGearTable(FileTable):
    """``[draft_gears.NAME]``: a draft gear of the file's own."""

    slack_mm: Annotated[float, Field(ge=0.0, le=MAX_GEAR_MM), Unit("mm")]
    travel_mm: Annotated[float, Field(gt=0.0, le=MAX_GEAR_MM), Unit("mm")]
    preload_kn: Annotated[float, Field(ge=0.0, le=MAX_GEAR_KN), Unit("kN")]
    #: at least preload_kn (the reader's rule)
    force_at_travel_kn: Annotated[float, Field(gt=0.0, le=MAX_GEAR_KN), Unit("kN")]
    unloading_ratio: Annotated[float, Field(gt=0.0, le=1.0)]
    stop_stiffness_kn_per_mm: Annotated[float, Field(gt=0.0, le=MAX_GEAR_STIFFNESS), Unit("kN/mm")]
    damping_kn_s_per_m: Annotated[float, Field(ge=0.0, le=MAX_GEAR_STIFFNESS), Unit("kN s/m")]
    switching_speed_mps: Annotated[float, Field(gt=0.0, le=10.0), Unit("m/s")] = _default(
        DraftGear, "switching_speed_mps"
    )


class LoadTable(FileTable):
    """``loaded = {...}`` / ``empty = {...}`` of a wagon type: its resistance and brake
    under that load (``brake_force_kn`` or ``braking_ratio``, not both)."""

    davis: Davis
    brake_force_kn: BrakeForce = NOT_GIVEN
    braking_ratio: BrakingRatio = NOT_GIVEN


class _VehicleTypeTable(FileTable):
    kind: str
    length_m: Length = NOT_GIVEN
    #: exactly one of rotating_mass_t and rotating_mass_factor (the reader's rule)
    rotating_mass_t: Annotated[float, Field(ge=0.0, le=MAX_MASS_T), Unit("t")] = NOT_GIVEN
    rotating_mass_factor: Annotated[float, Field(ge=0.0, le=MAX_ROTATING_MASS_FACTOR)] = NOT_GIVEN
    distributor: Annotated[str, Choice(DISTRIBUTORS)]
    draft_gear: GearName
    shoe_friction: ShoeFriction = NOT_GIVEN


class WagonTypeTable(_VehicleTypeTable):
    """``[vehicle_types.NAME]`` with ``kind = "wagon"``."""

    kind: Literal["wagon"]
    length_m: Length
    tare_t: Tonnes
    #: at most the heaviest vehicle less tare_t (the reader's rule)
    payload_t: Annotated[float, Field(ge=0.0, le=MAX_MASS_T), Unit("t")]
    loaded: LoadTable
    empty: LoadTable


class LocomotiveTypeTable(_VehicleTypeTable):
    """``[vehicle_types.NAME]`` with ``kind = "locomotive"``: mass and length default to
    the model's."""

    kind: Literal["locomotive"]
    model: Annotated[str, Choice(tuple(LOCOMOTIVE_MODELS))]
    mass_t: Tonnes = NOT_GIVEN
    davis: Davis
    brake_force_kn: BrakeForce = NOT_GIVEN
    braking_ratio: BrakingRatio = NOT_GIVEN


VehicleTypeTable = Annotated[LocomotiveTypeTable | WagonTypeTable, Field(discriminator="kind")]


class BlockTable(FileTable):
    """``[[train]]``: a run of ``count`` vehicles of one type, from the head."""

    type: Annotated[str, Says("a vehicle type of the file or the library")]
    count: Annotated[int, Field(ge=1, le=MAX_VEHICLES)]
    #: wagons only, and required for them (the reader's rule)
    load: Annotated[str, Choice(LOADS)] = NOT_GIVEN
    mass_t: Tonnes = NOT_GIVEN
    draft_gear: GearName = NOT_GIVEN
    name: Annotated[str, Field(min_length=1)] = NOT_GIVEN


class ConsistLibraryTable(FileTable):
    """The library of vehicle types and draft gears (a consist file's types without a
    train)."""

    vehicle_types: dict[str, VehicleTypeTable] = Field(default_factory=dict)
    draft_gears: dict[str, DraftGearTable] = Field(default_factory=dict)


class ConsistFileTable(FileTable):
    """A consist file: a train of vehicles from the head (docs/consist.md)."""

    name: Annotated[str, Field(min_length=1)]
    description: str = NOT_GIVEN
    brake_pipe_kpa: Annotated[float, Field(gt=0.0, le=MAX_BRAKE_PIPE_KPA), Unit("kPa")] = _default(
        Consist, "brake_pipe_kpa"
    )
    dp_radio_delay_s: Annotated[float, Field(ge=0.0, le=MAX_DP_DELAY_S), Unit("s")] = _default(
        Consist, "dp_radio_delay_s"
    )
    train: Annotated[
        list[BlockTable],
        Field(min_length=1),
        Says("a non-empty list of [[train]] blocks from the head, the first a locomotive"),
    ]
    vehicle_types: dict[str, VehicleTypeTable] = Field(default_factory=dict)
    draft_gears: dict[str, DraftGearTable] = Field(default_factory=dict)
