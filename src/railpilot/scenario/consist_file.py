"""Read a consist TOML file into a :class:`~railpilot.vehicle.consist.Consist`, and write one.

Units in the key names at the edge (t, kN, mm, kPa), SI inside. Every key is checked: an
unknown key, a wrong type or an out-of-range value raises :class:`ConsistError` naming the
file, the entry as the file writes it (``train[2] (C80 x 105).load``,
``vehicle_types.C80.loaded.braking_ratio``), the value and what is allowed; nothing is
built from a bad file. docs/consist.md describes the format; the layout::

    name = "..."                       # required
    description = "..."                # optional free text
    brake_pipe_kpa = 600.0             # optional (default: railpilot.vehicle.consist)
    dp_radio_delay_s = 1.5             # optional (default: railpilot.vehicle.consist)

    [[train]]                          # the train from the head, one block per run
    type = "HXD1"                      # a vehicle type: the file's or the library's
    count = 1                          # how many in a row
    load = "loaded" | "empty"          # wagons only (required for them)
    mass_t = 95.0                      # optional: each vehicle's mass instead of the load's
    draft_gear = "MT-2"                # optional: instead of the type's
    name = "C80"                       # optional: vehicle names NAME-k (default: the type)

    [vehicle_types.NAME]               # optional: a type of the file's own
    kind = "wagon"                     # "wagon" | "locomotive"
    length_m, rotating_mass_t | rotating_mass_factor, distributor, draft_gear,
    shoe_friction                      # with braking_ratio
      wagon: tare_t, payload_t,
             loaded = {davis = [a0, a1, a2], brake_force_kn | braking_ratio}, empty = {...}
      locomotive: model = "HXD1", mass_t, length_m (both default to the model's),
             davis, brake_force_kn | braking_ratio (none: no friction brake)

    [draft_gears.NAME]                 # optional: a draft gear of the file's own
    slack_mm, travel_mm, preload_kn, force_at_travel_kn, unloading_ratio,
    stop_stiffness_kn_per_mm, damping_kn_s_per_m, switching_speed_mps

The built-in library (``railpilot/vehicle/data/consists/library.toml``: HXD1, C80,
MT-2) is always there; a type or draft gear the file defines under a library name replaces
the library's for that file. The first vehicle must be a locomotive (the lead); every other
locomotive is a distributed-power remote.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError, ScenarioError
from railpilot.schema.consist import (
    LOADS,
    LOCOMOTIVE_MODELS,
    MAX_GEAR_KN,
    MAX_MASS_T,
    MAX_VEHICLES,
    BlockTable,
    ConsistFileTable,
    ConsistLibraryTable,
    DraftGearTable,
    LoadTable,
    LocomotiveTypeTable,
    WagonTypeTable,
)
from railpilot.schema.fields import number_words
from railpilot.schema.reading import parse_text, read_document
from railpilot.schema.validate import Loc, check, dotted
from railpilot.units import G_MPS2, kn_to_n, tonne_to_kg
from railpilot.vehicle.consist import CONSIST_PRESETS, PRESET_FILES, Consist, Vehicle
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import Locomotive
from railpilot.vehicle.train import MAX_LENGTH_M

__all__ = [
    "LOCOMOTIVE_MODELS",
    "ConsistError",
    "consist_to_mapping",
    "consist_to_toml",
    "library_draft_gears",
    "library_types",
    "load_consist",
    "load_shipped_consist",
    "parse_consist",
    "write_consist",
]

#: the library of types and draft gears, in railpilot/vehicle/data/consists/
LIBRARY_FILE = "library.toml"


class ConsistError(ScenarioError):
    """A consist file is malformed: ``field`` names the entry as the file writes it
    (``train[2] (C80 x 105).mass_t``); ``source`` (optional) is the file and prefixes the
    message."""

    def __init__(self, field: str, value: Any, allowed: str, source: str | None = None) -> None:
        super().__init__(field, value, allowed)
        self.source = source
        if source is not None:
            self.args = (f"{source}: {self.args[0]}",)


def _block_label(index: int, raw: Any) -> str:
    """``train[2] (C80 x 105)``: a block named by its place, type and count, as far as the
    file gives them readably."""
    if isinstance(raw, Mapping):
        kind, count = raw.get("type"), raw.get("count")
        readable = isinstance(kind, str) and len(kind) <= 40
        if (
            readable
            and isinstance(count, int)
            and not isinstance(count, bool)
            and abs(count) < 10**9
        ):
            return f"train[{index}] ({kind} x {count})"
    return f"train[{index}]"


def _place(loc: Loc, data: Any) -> str:
    """A key's place as the errors write it: a train block by its label."""
    if len(loc) >= 2 and loc[0] == "train" and isinstance(loc[1], int):
        blocks = data.get("train") if isinstance(data, Mapping) else None
        raw = blocks[loc[1]] if isinstance(blocks, list) and loc[1] < len(blocks) else None
        rest = dotted(loc[2:])
        label = _block_label(loc[1], raw)
        return f"{label}.{rest}" if rest else label
    return dotted(loc)


# --- draft gears ----------------------------------------------------------------------


def _draft_gear(name: str, t: DraftGearTable) -> DraftGear:
    floor_kn = max(t.preload_kn, 1e-9)
    if not t.force_at_travel_kn >= floor_kn:
        raise ConsistError(
            f"draft_gears.{name}.force_at_travel_kn",
            t.force_at_travel_kn,
            number_words(ge=floor_kn, le=MAX_GEAR_KN, unit="kN"),
        )
    return DraftGear(
        name=name,
        slack_m=t.slack_mm / 1000.0,
        travel_m=t.travel_mm / 1000.0,
        preload_n=kn_to_n(t.preload_kn),
        force_at_travel_n=kn_to_n(t.force_at_travel_kn),
        unloading_ratio=t.unloading_ratio,
        stop_stiffness_n_per_m=t.stop_stiffness_kn_per_mm * 1e6,
        damping_n_s_per_m=kn_to_n(t.damping_kn_s_per_m),
        switching_speed_mps=t.switching_speed_mps,
    )


# --- vehicle types --------------------------------------------------------------------


@dataclass(frozen=True)
class _LoadSpec:
    """What a type runs at under one load: mass [kg], Davis, and its brake: a force [N] at
    the rail, or a braking ratio times the type's shoe friction times the weight."""

    mass_kg: float
    davis: tuple[float, float, float]
    brake_force_n: float | None
    braking_ratio: float | None

    def brake_n(self, mass_kg: float, shoe_friction: float | None) -> float:
        if self.brake_force_n is not None:
            return self.brake_force_n
        if self.braking_ratio is None or shoe_friction is None:
            return 0.0
        return self.braking_ratio * shoe_friction * mass_kg * G_MPS2


@dataclass(frozen=True)
class _VehicleType:
    name: str
    kind: str
    length_m: float
    rotating_mass_kg: float | None  # or a factor:
    rotating_mass_factor: float | None
    distributor: str
    draft_gear: DraftGear
    shoe_friction: float | None
    loads: Mapping[str, _LoadSpec]  # "loaded"/"empty" for a wagon, "" for a locomotive
    locomotive: Locomotive | None


def _load(
    label: str,
    t: LoadTable | LocomotiveTypeTable,
    mass_kg: float,
    distributor: str,
    shoe_friction: float | None,
) -> _LoadSpec:
    """A load's mass, Davis and brake (``brake_force_kn`` or ``braking_ratio``, at most
    one; some unless the type has no air brake)."""
    if t.given("brake_force_kn") and t.given("braking_ratio"):
        raise ConsistError(
            f"{label}.braking_ratio",
            t.braking_ratio,
            "no braking_ratio when brake_force_kn is given (one or the other)",
        )
    force = kn_to_n(t.brake_force_kn) if t.given("brake_force_kn") else None
    ratio = t.braking_ratio if t.given("braking_ratio") else None
    if ratio is not None and shoe_friction is None:
        raise ConsistError(
            f"{label}.braking_ratio",
            ratio,
            "a type that gives shoe_friction too (the force is ratio x friction x weight)",
        )
    if distributor == "none" and ((force or 0.0) > 0.0 or (ratio or 0.0) > 0.0):
        key = "brake_force_kn" if force is not None else "braking_ratio"
        raise ConsistError(
            f"{label}.{key}",
            getattr(t, key),
            "0 or no key: the type has no air brake (distributor 'none')",
        )
    if distributor != "none" and force is None and ratio is None:
        raise ConsistError(
            f"{label}.brake_force_kn",
            None,
            "brake_force_kn or braking_ratio: the type has an air brake "
            f"(distributor {distributor!r})",
        )
    davis = (float(t.davis[0]), float(t.davis[1]), float(t.davis[2]))
    return _LoadSpec(mass_kg, davis, force, ratio)


def _gear_ref(field: str, name: str, gears: Mapping[str, DraftGear]) -> DraftGear:
    if name not in gears:
        raise ConsistError(
            field, name, f"a draft gear of the file or the library ({', '.join(gears)})"
        )
    return gears[name]


def _vehicle_type(
    name: str, t: WagonTypeTable | LocomotiveTypeTable, gears: Mapping[str, DraftGear]
) -> _VehicleType:
    label = f"vehicle_types.{name}"
    shoe_friction = t.shoe_friction if t.given("shoe_friction") else None
    if t.given("rotating_mass_t") == t.given("rotating_mass_factor"):
        raise ConsistError(
            f"{label}.rotating_mass_t",
            t.rotating_mass_t,
            "exactly one of rotating_mass_t (equivalent mass of the rotating parts) and "
            "rotating_mass_factor (gamma)",
        )
    rotating_kg = tonne_to_kg(t.rotating_mass_t) if t.given("rotating_mass_t") else None
    factor = t.rotating_mass_factor if t.given("rotating_mass_factor") else None
    draft_gear = _gear_ref(f"{label}.draft_gear", t.draft_gear, gears)
    locomotive: Locomotive | None = None
    loads: dict[str, _LoadSpec] = {}
    if isinstance(t, WagonTypeTable):
        if not t.payload_t <= MAX_MASS_T - t.tare_t:
            raise ConsistError(
                f"{label}.payload_t",
                t.payload_t,
                number_words(ge=0.0, le=MAX_MASS_T - t.tare_t, unit="t"),
            )
        length_m = t.length_m
        for load, mass_t, table in (
            ("loaded", t.tare_t + t.payload_t, t.loaded),
            ("empty", t.tare_t, t.empty),
        ):
            loads[load] = _load(
                f"{label}.{load}", table, tonne_to_kg(mass_t), t.distributor, shoe_friction
            )
    else:
        base = LOCOMOTIVE_MODELS[t.model]()
        mass_t = t.mass_t if t.given("mass_t") else base.mass_kg / 1000.0
        length_m = t.length_m if t.given("length_m") else base.length_m
        locomotive = dataclasses.replace(base, mass_kg=tonne_to_kg(mass_t), length_m=length_m)
        loads[""] = _load(label, t, tonne_to_kg(mass_t), t.distributor, shoe_friction)
    return _VehicleType(
        name, t.kind, length_m, rotating_kg, factor, t.distributor, draft_gear, shoe_friction,
        loads, locomotive,
    )  # fmt: skip


def _types_and_gears(
    table: ConsistFileTable | ConsistLibraryTable,
    base_types: Mapping[str, _VehicleType],
    base_gears: Mapping[str, DraftGear],
) -> tuple[dict[str, _VehicleType], dict[str, DraftGear]]:
    """The file's draft gears and vehicle types over the library's (the file's win)."""
    gears = dict(base_gears)
    for name, gear in table.draft_gears.items():
        gears[name] = _draft_gear(name, gear)
    types = dict(base_types)
    for name, vtype in table.vehicle_types.items():
        types[name] = _vehicle_type(name, vtype, gears)
    return types, gears


def parse_library(
    data: Any, source: str
) -> tuple[Mapping[str, _VehicleType], Mapping[str, DraftGear]]:
    """A consist library's vehicle types and draft gears from its parsed file ``data``;
    errors name ``source`` (the file) and the entry."""

    def error(field: str, value: Any, allowed: str) -> ConsistError:
        return ConsistError(field, value, allowed, source=source)

    table = check(ConsistLibraryTable, data, error)
    try:
        return _types_and_gears(table, {}, {})
    except ConsistError as exc:
        raise ConsistError(exc.field, exc.value, exc.allowed, source=source) from exc


@functools.cache
def _library() -> tuple[Mapping[str, _VehicleType], Mapping[str, DraftGear]]:
    """The built-in types and draft gears, parsed once a process (a shipped file)."""
    resource = resources.files("railpilot.vehicle") / "data" / "consists" / LIBRARY_FILE
    source = "consist library"
    return parse_library(_parse_toml(resource.read_text(encoding="utf-8"), source), source)


def library_types() -> tuple[str, ...]:
    """Names of the built-in vehicle types."""
    return tuple(_library()[0])


def library_draft_gears() -> tuple[str, ...]:
    """Names of the built-in draft gears."""
    return tuple(_library()[1])


# --- the train ------------------------------------------------------------------------

#: Vehicle fields -> (the key a file writes, the value converted to its unit)
_FILE_KEYS: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "mass_kg": ("mass_t", lambda v: v / 1000.0),
    "service_brake_force_n": ("brake_force_kn", lambda v: v / 1000.0),
    "davis_a0": ("davis[0]", lambda v: v),
    "davis_a1": ("davis[1]", lambda v: v),
    "davis_a2": ("davis[2]", lambda v: v),
}


@dataclass(frozen=True)
class _Block:
    label: str
    vtype: _VehicleType
    count: int
    load: str
    mass_kg: float | None
    draft_gear: DraftGear
    prefix: str


def _block(
    index: int,
    label: str,
    t: BlockTable,
    types: Mapping[str, _VehicleType],
    gears: Mapping[str, DraftGear],
) -> _Block:
    if t.type not in types:
        raise ConsistError(
            f"{label}.type",
            t.type,
            f"a vehicle type of the file or the library ({', '.join(types)})",
        )
    vtype = types[t.type]
    if vtype.kind == "wagon":
        if not t.given("load"):
            raise ConsistError(f"{label}.load", None, f"one of {', '.join(LOADS)}")
        load = t.load
    elif t.given("load"):
        raise ConsistError(f"{label}.load", t.load, "no load: a locomotive's type")
    else:
        load = ""
    mass_kg = tonne_to_kg(t.mass_t) if t.given("mass_t") else None
    gear = (
        _gear_ref(f"{label}.draft_gear", t.draft_gear, gears)
        if t.given("draft_gear")
        else vtype.draft_gear
    )
    if index == 0 and vtype.kind != "locomotive":
        raise ConsistError(
            f"{label}.type", t.type, "a locomotive type: the first vehicle is the lead locomotive"
        )
    prefix = t.name if t.given("name") else vtype.name
    return _Block(label, vtype, t.count, load, mass_kg, gear, prefix)


def _vehicle(block: _Block, name: str, remote: bool) -> Vehicle:
    vtype, spec = block.vtype, block.vtype.loads[block.load]
    mass_kg = spec.mass_kg if block.mass_kg is None else block.mass_kg
    if vtype.rotating_mass_kg is not None:
        factor = vtype.rotating_mass_kg / mass_kg
    else:
        factor = vtype.rotating_mass_factor or 0.0
    try:
        return Vehicle(
            name=name,
            kind=vtype.kind,
            mass_kg=mass_kg,
            rotating_mass_factor=factor,
            length_m=vtype.length_m,
            davis_a0=spec.davis[0],
            davis_a1=spec.davis[1],
            davis_a2=spec.davis[2],
            service_brake_force_n=spec.brake_n(mass_kg, vtype.shoe_friction),
            distributor=vtype.distributor,
            draft_gear=block.draft_gear,
            locomotive=vtype.locomotive,
            remote=remote,
        )
    except ConfigError as exc:  # a combination the type's checks cannot see (a mass_t)
        field = exc.field.rpartition(".")[2]
        key, convert = _FILE_KEYS.get(field, (field, lambda v: v))
        try:
            value = convert(exc.value)
        except TypeError:
            value = exc.value
        raise ConsistError(f"{block.label}.{key}", value, exc.allowed) from exc


def _vehicles(blocks: list[_Block]) -> tuple[Vehicle, ...]:
    """The vehicles of the blocks, named ``PREFIX-k``: k counts the vehicles of each name
    prefix from the head, zero-padded to the width of their number (``C80-001``)."""
    totals: dict[str, int] = {}
    for block in blocks:
        totals[block.prefix] = totals.get(block.prefix, 0) + block.count
    counters = dict.fromkeys(totals, 0)
    vehicles: list[Vehicle] = []
    for block in blocks:
        width = len(str(totals[block.prefix]))
        for _ in range(block.count):
            counters[block.prefix] += 1
            name = f"{block.prefix}-{counters[block.prefix]:0{width}d}"
            remote = block.vtype.kind == "locomotive" and bool(vehicles)
            vehicles.append(_vehicle(block, name, remote))
    return tuple(vehicles)


def parse_consist(data: Mapping[str, Any], source: str = "<consist>") -> Consist:
    """Build a :class:`Consist` from a parsed consist file (see the module docstring).

    Raises
    ------
    ConsistError
        Naming ``source``, the entry and key, the value and what is allowed.
    """

    def error(field: str, value: Any, allowed: str) -> ConsistError:
        return ConsistError(field, value, allowed, source=source)

    top = check(ConsistFileTable, data, error, name=_place)
    try:
        types, gears = _types_and_gears(top, *_library())
        blocks = [
            _block(i, _block_label(i, raw), block, types, gears)
            for i, (raw, block) in enumerate(zip(data["train"], top.train, strict=True))
        ]
        count = sum(b.count for b in blocks)
        if count > MAX_VEHICLES:
            raise ConsistError("train", f"{count} vehicles", f"at most {MAX_VEHICLES} vehicles")
        length_m = math.fsum(b.count * b.vtype.length_m for b in blocks)
        if length_m > MAX_LENGTH_M:
            raise ConsistError(
                "train",
                f"{length_m:.1f} m",
                f"a train at most {MAX_LENGTH_M:g} m long over couplers",
            )
        vehicles = _vehicles(blocks)
        try:
            return Consist(
                top.name,
                vehicles,
                brake_pipe_kpa=top.brake_pipe_kpa,
                dp_radio_delay_s=top.dp_radio_delay_s,
            )
        except ConfigError as exc:  # every part was checked: a rule across vehicles
            raise ConsistError(exc.field, exc.value, exc.allowed) from exc
    except ConsistError as exc:
        if exc.source is not None:
            raise
        raise ConsistError(exc.field, exc.value, exc.allowed, source=source) from exc


def _parse_toml(text: str, source: str) -> Any:
    def error(field: str, value: Any, allowed: str) -> ConsistError:
        return ConsistError(field, value, allowed, source=source)

    return parse_text(text, source, "CONSIST", error)


def load_consist(path: str | os.PathLike[str]) -> Consist:
    """Read the consist file at ``path`` (TOML, or JSON if its name ends in ``.json``;
    errors name the file)."""
    file = Path(path)

    def error(field: str, value: Any, allowed: str) -> ConsistError:
        return ConsistError(field, value, allowed, source=str(file))

    data = read_document(file, "CONSIST", "consist TOML file", ConsistError, parse_error=error)
    return parse_consist(data, source=str(file))


def load_shipped_consist(filename: str, source: str) -> Consist:
    """A consist file shipped in ``railpilot/vehicle/data/consists/`` (the presets)."""
    resource = resources.files("railpilot.vehicle") / "data" / "consists" / filename
    return parse_consist(_parse_toml(resource.read_text(encoding="utf-8"), source), source)


def consist_preset(name: str) -> Consist:
    """A shipped consist by name (:data:`CONSIST_PRESETS`).

    ``"heavy-haul-10kt"``: one HXD1 and 105 loaded C80 coal wagons;
    ``"heavy-haul-10kt-empty"``: the same train empty; ``"heavy-haul-20kt-dp"``: the
    Daqin 20,000 t combined train, an HXD1 at the head and one (a distributed-power remote)
    after wagon 105, 210 loaded C80 in all. Numbers and sources: docs/consist.md.

    Raises
    ------
    ConfigError
        Naming the allowed names, for any other.
    """
    if not isinstance(name, str) or name not in PRESET_FILES:
        raise ConfigError("consist", name, f"one of {', '.join(CONSIST_PRESETS)}")
    return _preset(name)


@functools.cache
def _preset(name: str) -> Consist:
    return load_shipped_consist(PRESET_FILES[name], f"consist '{name}'")


# --- writing --------------------------------------------------------------------------


def _gear_table(gear: DraftGear) -> dict[str, Any]:
    return {
        "slack_mm": gear.slack_m * 1000.0,
        "travel_mm": gear.travel_m * 1000.0,
        "preload_kn": gear.preload_n / 1000.0,
        "force_at_travel_kn": gear.force_at_travel_n / 1000.0,
        "unloading_ratio": gear.unloading_ratio,
        "stop_stiffness_kn_per_mm": gear.stop_stiffness_n_per_m / 1e6,
        "damping_kn_s_per_m": gear.damping_n_s_per_m / 1000.0,
        "switching_speed_mps": gear.switching_speed_mps,
    }


def _model_of(vehicle: Vehicle, where: str) -> str:
    loco = vehicle.locomotive
    for model, factory in LOCOMOTIVE_MODELS.items():
        base = factory()
        if loco == dataclasses.replace(base, mass_kg=vehicle.mass_kg, length_m=vehicle.length_m):
            return model
    raise ConfigError(
        f"{where}.locomotive",
        getattr(loco, "name", loco),
        f"a locomotive model a file can name ({', '.join(LOCOMOTIVE_MODELS)})",
    )


def _type_table(vehicle: Vehicle, gear_name: str, where: str) -> dict[str, Any]:
    common: dict[str, Any] = {
        "kind": vehicle.kind,
        "length_m": vehicle.length_m,
        "rotating_mass_factor": vehicle.rotating_mass_factor,
        "distributor": vehicle.distributor,
        "draft_gear": gear_name,
    }
    davis = [vehicle.davis_a0, vehicle.davis_a1, vehicle.davis_a2]
    brake = (
        {}
        if vehicle.distributor == "none"
        else {"brake_force_kn": vehicle.service_brake_force_n / 1000.0}
    )
    if vehicle.kind == "locomotive":
        return common | {
            "model": _model_of(vehicle, where),
            "mass_t": vehicle.mass_kg / 1000.0,
            "davis": davis,
        } | brake  # fmt: skip
    load = {"davis": davis} | brake
    return common | {
        "tare_t": vehicle.mass_kg / 1000.0,
        "payload_t": 0.0,
        "loaded": load,
        "empty": dict(load),
    }


def consist_to_mapping(consist: Consist) -> dict[str, Any]:
    """A consist file's contents (a mapping) that :func:`parse_consist` reads back into
    ``consist``: every vehicle type and draft gear defined in the file itself (wagons as
    run: tare = their mass, payload 0, ``load = "empty"``), one ``[[train]]`` block per
    run of identical vehicles.

    The types are named after the vehicles' names up to their last ``-`` (the name prefix),
    so names of the reader's own form (``PREFIX-k``, counted from the head) come back as
    they were; others come back in that form. Masses and forces pass through t and kN and
    may come back one unit in the last place apart.

    Raises
    ------
    ConfigError
        For a consist no file can write: a locomotive of no known model, or a locomotive
        other than the first that is not remote (the format makes every other one a remote).
    """
    gear_names: dict[DraftGear, str] = {}
    gears: dict[str, dict[str, Any]] = {}
    for vehicle in consist.vehicles:
        gear = vehicle.draft_gear
        if gear not in gear_names:
            name, k = gear.name, 1
            while name in gears:
                k += 1
                name = f"{gear.name}-{k}"
            gear_names[gear] = name
            gears[name] = _gear_table(gear)
    types: dict[str, dict[str, Any]] = {}
    blocks: list[dict[str, Any]] = []
    for i, vehicle in enumerate(consist.vehicles):
        where = f"consist.vehicles[{i}]"
        if vehicle.kind == "locomotive" and vehicle.remote != (i > 0):
            raise ConfigError(
                f"{where}.remote", vehicle.remote, f"{i > 0} (the file format's rule)"
            )
        table = _type_table(vehicle, gear_names[vehicle.draft_gear], where)
        stem = vehicle.name.rpartition("-")[0] or vehicle.name
        name, k = stem, 1
        while name in types and types[name] != table:
            k += 1
            name = f"{stem}-{k}"
        types[name] = table
        if blocks and blocks[-1]["type"] == name:
            blocks[-1]["count"] += 1
        else:
            block: dict[str, Any] = {"type": name, "count": 1}
            if vehicle.kind == "wagon":
                block["load"] = "empty"
            if name != stem:
                block["name"] = stem
            blocks.append(block)
    return {
        "name": consist.name,
        "brake_pipe_kpa": consist.brake_pipe_kpa,
        "dp_radio_delay_s": consist.dp_radio_delay_s,
        "draft_gears": gears,
        "vehicle_types": types,
        "train": blocks,
    }


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)  # the shortest text that reads back as the same float
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return (
            "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
        )
    raise TypeError(f"no TOML for {type(value).__name__}")


def _toml_key(key: str) -> str:
    bare = key and all(c.isascii() and (c.isalnum() or c in "-_") for c in key)
    return key if bare else _toml_value(key)


def consist_to_toml(consist: Consist) -> str:
    """The text of a consist file that reads back into ``consist`` (:func:`consist_to_mapping`)."""
    data = consist_to_mapping(consist)
    lines = [f"name = {_toml_value(data['name'])}"]
    lines += [f"{k} = {_toml_value(data[k])}" for k in ("brake_pipe_kpa", "dp_radio_delay_s")]
    for section in ("draft_gears", "vehicle_types"):
        for name, table in data[section].items():
            lines += ["", f"[{section}.{_toml_key(name)}]"]
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
    for block in data["train"]:
        lines += ["", "[[train]]"]
        lines += [f"{k} = {_toml_value(v)}" for k, v in block.items()]
    return "\n".join(lines) + "\n"


def write_consist(consist: Consist, path: str | os.PathLike[str]) -> None:
    """Write ``consist`` as a consist file at ``path`` (UTF-8)."""
    Path(path).write_text(consist_to_toml(consist), encoding="utf-8")
