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
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from railpilot.errors import ConfigError, ScenarioError, is_finite_number
from railpilot.textfile import TOO_MANY_DIGITS, read_text
from railpilot.units import G_MPS2, kn_to_n, tonne_to_kg
from railpilot.vehicle.consist import (
    DISTRIBUTORS,
    MAX_BRAKE_PIPE_KPA,
    MAX_DAVIS,
    MAX_DP_DELAY_S,
    MAX_ROTATING_MASS_FACTOR,
    MAX_VEHICLE_LENGTH_M,
    MAX_VEHICLE_MASS_KG,
    Consist,
    Vehicle,
)
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import Locomotive, hxd1_locomotive
from railpilot.vehicle.train import MAX_LENGTH_M

#: locomotive models a type may name: name -> factory (traction and regeneration envelopes)
LOCOMOTIVE_MODELS: dict[str, Callable[[], Locomotive]] = {"HXD1": hxd1_locomotive}
#: the loads a wagon block may run at
LOADS = ("loaded", "empty")
#: the library of types and draft gears, in railpilot/vehicle/data/consists/
LIBRARY_FILE = "library.toml"

#: most vehicles in one consist (a 10 km train of 1 m vehicles)
MAX_VEHICLES = 10_000
#: heaviest vehicle [t] and longest [m] a file may give (the model's own bounds)
MAX_MASS_T = MAX_VEHICLE_MASS_KG / 1000.0
#: largest net braking ratio (shoe force over weight) [-]
MAX_BRAKING_RATIO = 2.0
#: largest draft-gear slack and travel [mm] (DraftGear allows up to 1 m)
MAX_GEAR_MM = 1000.0

TOP_KEYS = ("name", "description", "brake_pipe_kpa", "dp_radio_delay_s", "train",
            "vehicle_types", "draft_gears")  # fmt: skip
BLOCK_KEYS = ("type", "count", "load", "mass_t", "draft_gear", "name")
COMMON_TYPE_KEYS = ("kind", "length_m", "rotating_mass_t", "rotating_mass_factor",
                    "distributor", "draft_gear", "shoe_friction")  # fmt: skip
WAGON_KEYS = (*COMMON_TYPE_KEYS, "tare_t", "payload_t", "loaded", "empty")
LOCOMOTIVE_KEYS = (*COMMON_TYPE_KEYS, "model", "mass_t", "davis", "brake_force_kn",
                   "braking_ratio")  # fmt: skip
LOAD_KEYS = ("davis", "brake_force_kn", "braking_ratio")
GEAR_KEYS = ("slack_mm", "travel_mm", "preload_kn", "force_at_travel_kn", "unloading_ratio",
             "stop_stiffness_kn_per_mm", "damping_kn_s_per_m", "switching_speed_mps")  # fmt: skip


class ConsistError(ScenarioError):
    """A consist file is malformed: ``field`` names the entry as the file writes it
    (``train[2] (C80 x 105).mass_t``); ``source`` (optional) is the file and prefixes the
    message."""

    def __init__(self, field: str, value: Any, allowed: str, source: str | None = None) -> None:
        super().__init__(field, value, allowed)
        self.source = source
        if source is not None:
            self.args = (f"{source}: {self.args[0]}",)


# --- reading one table ----------------------------------------------------------------


class _Table:
    """One TOML table being read: its label for errors, its allowed keys, typed getters."""

    def __init__(self, data: Any, label: str, allowed: tuple[str, ...]) -> None:
        if not isinstance(data, Mapping):
            raise ConsistError(label or "<file>", data, f"a table with keys {', '.join(allowed)}")
        self.data = data
        self.label = label
        self.allowed = allowed

    def key(self, key: str) -> str:
        return f"{self.label}.{key}" if self.label else key

    def check_keys(self) -> None:
        """Refuse a key the format does not know here, listing the ones it does."""
        for key in self.data:
            if key not in self.allowed:
                raise ConsistError(
                    self.key(key),
                    self.data[key],
                    f"a known key instead of '{key}' (allowed here: {', '.join(self.allowed)})",
                )

    def has(self, key: str) -> bool:
        return key in self.data

    def number(
        self,
        key: str,
        default: float | None = None,
        *,
        gt: float | None = None,
        ge: float | None = None,
        le: float | None = None,
        unit: str = "",
    ) -> float:
        """A finite number within the bounds (in the file's unit); ``default`` when the key
        is absent (None: the key is required)."""
        if key not in self.data:
            if default is None:
                raise ConsistError(self.key(key), None, "a number (the key is required)")
            return default
        value = self.data[key]
        bounds = [f"{op} {b:g}" for op, b in ((">", gt), (">=", ge), ("<=", le)) if b is not None]
        allowed = "a finite number" + (" " + " and ".join(bounds) if bounds else "")
        allowed += f" [{unit}]" if unit else ""
        if not is_finite_number(value):  # nan, inf, a bool, a string, 10**400
            raise ConsistError(self.key(key), value, allowed)
        if (
            (gt is not None and not value > gt)
            or (ge is not None and not value >= ge)
            or (le is not None and not value <= le)
        ):
            raise ConsistError(self.key(key), value, allowed)
        return float(value)

    def integer(self, key: str, low: int, high: int) -> int:
        value = self.data.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise ConsistError(
                self.key(key), value, f"a whole number from {low} to {high} (the key is required)"
            )
        return value

    def string(self, key: str, default: str | None = None) -> str:
        if key not in self.data and default is not None:
            return default
        value = self.data.get(key)
        if not isinstance(value, str) or not value:
            raise ConsistError(self.key(key), value, "a non-empty string (the key is required)")
        return value

    def choice(self, key: str, choices: tuple[str, ...], default: str | None = None) -> str:
        value = self.data.get(key, default)
        if not (isinstance(value, str) and value in choices):
            raise ConsistError(self.key(key), value, f"one of {', '.join(choices)}")
        return value

    def davis(self, key: str = "davis") -> tuple[float, float, float]:
        """``[a0, a1, a2]`` [N/kN, v in km/h], each in [0, MAX_DAVIS] (required)."""
        value = self.data.get(key)
        if not isinstance(value, list) or len(value) != 3:
            raise ConsistError(
                self.key(key), value, "a list of 3 numbers [a0, a1, a2] (N/kN, v in km/h)"
            )
        for i, item in enumerate(value):
            if not is_finite_number(item) or not 0.0 <= item <= MAX_DAVIS:
                raise ConsistError(
                    f"{self.key(key)}[{i}]", item, f"a finite number >= 0 and <= {MAX_DAVIS:g}"
                )
        return (float(value[0]), float(value[1]), float(value[2]))


def _names(data: Mapping[str, Any], key: str) -> Mapping[str, Any]:
    """The table of named sub-tables ``key`` (``vehicle_types``, ``draft_gears``)."""
    value = data.get(key, {})
    if not isinstance(value, Mapping):
        raise ConsistError(key, value, "a table of named tables")
    return value


# --- draft gears ----------------------------------------------------------------------


def _draft_gear(name: str, raw: Any) -> DraftGear:
    t = _Table(raw, f"draft_gears.{name}", GEAR_KEYS)
    t.check_keys()
    preload_kn = t.number("preload_kn", ge=0.0, le=1e6, unit="kN")
    gear = DraftGear(
        name=name,
        slack_m=t.number("slack_mm", ge=0.0, le=MAX_GEAR_MM, unit="mm") / 1000.0,
        travel_m=t.number("travel_mm", gt=0.0, le=MAX_GEAR_MM, unit="mm") / 1000.0,
        preload_n=kn_to_n(preload_kn),
        force_at_travel_n=kn_to_n(
            t.number("force_at_travel_kn", ge=max(preload_kn, 1e-9), le=1e6, unit="kN")
        ),
        unloading_ratio=t.number("unloading_ratio", gt=0.0, le=1.0),
        stop_stiffness_n_per_m=t.number("stop_stiffness_kn_per_mm", gt=0.0, le=1e9, unit="kN/mm")
        * 1e6,
        damping_n_s_per_m=kn_to_n(t.number("damping_kn_s_per_m", ge=0.0, le=1e9, unit="kN s/m")),
        switching_speed_mps=t.number("switching_speed_mps", 0.01, gt=0.0, le=10.0, unit="m/s"),
    )
    return gear


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


def _brake(t: _Table, distributor: str, shoe_friction: float | None) -> tuple[
    float | None, float | None
]:  # fmt: skip
    """``(brake_force_n, braking_ratio)`` of a table giving at most one of the two keys."""
    if t.has("brake_force_kn") and t.has("braking_ratio"):
        raise ConsistError(
            t.key("braking_ratio"),
            t.data["braking_ratio"],
            "no braking_ratio when brake_force_kn is given (one or the other)",
        )
    force = ratio = None
    if t.has("brake_force_kn"):
        force = kn_to_n(t.number("brake_force_kn", ge=0.0, le=MAX_MASS_T * 10.0, unit="kN"))
    elif t.has("braking_ratio"):
        ratio = t.number("braking_ratio", ge=0.0, le=MAX_BRAKING_RATIO)
        if shoe_friction is None:
            raise ConsistError(
                t.key("braking_ratio"),
                ratio,
                "a type that gives shoe_friction too (the force is ratio x friction x weight)",
            )
    if distributor == "none" and ((force or 0.0) > 0.0 or (ratio or 0.0) > 0.0):
        key = "brake_force_kn" if force is not None else "braking_ratio"
        raise ConsistError(
            t.key(key), t.data[key], "0 or no key: the type has no air brake (distributor 'none')"
        )
    if distributor != "none" and force is None and ratio is None:
        raise ConsistError(
            t.key("brake_force_kn"),
            None,
            "brake_force_kn or braking_ratio: the type has an air brake "
            f"(distributor {distributor!r})",
        )
    return force, ratio


def _gear_ref(t: _Table, key: str, gears: Mapping[str, DraftGear]) -> DraftGear:
    name = t.data.get(key)
    if not isinstance(name, str) or name not in gears:
        raise ConsistError(
            t.key(key), name, f"a draft gear of the file or the library ({', '.join(gears)})"
        )
    return gears[name]


def _vehicle_type(name: str, raw: Any, gears: Mapping[str, DraftGear]) -> _VehicleType:
    label = f"vehicle_types.{name}"
    probe = _Table(raw, label, WAGON_KEYS)
    kind = probe.choice("kind", ("locomotive", "wagon"))
    t = _Table(raw, label, WAGON_KEYS if kind == "wagon" else LOCOMOTIVE_KEYS)
    t.check_keys()
    distributor = t.choice("distributor", DISTRIBUTORS)
    shoe_friction = t.number("shoe_friction", gt=0.0, le=1.0) if t.has("shoe_friction") else None
    if t.has("rotating_mass_t") == t.has("rotating_mass_factor"):
        raise ConsistError(
            t.key("rotating_mass_t"),
            t.data.get("rotating_mass_t"),
            "exactly one of rotating_mass_t (equivalent mass of the rotating parts) and "
            "rotating_mass_factor (gamma)",
        )
    rotating_kg = factor = None
    if t.has("rotating_mass_t"):
        rotating_kg = tonne_to_kg(t.number("rotating_mass_t", ge=0.0, le=MAX_MASS_T, unit="t"))
    else:
        factor = t.number("rotating_mass_factor", ge=0.0, le=MAX_ROTATING_MASS_FACTOR)
    draft_gear = _gear_ref(t, "draft_gear", gears)
    locomotive: Locomotive | None = None
    loads: dict[str, _LoadSpec] = {}
    if kind == "wagon":
        tare_t = t.number("tare_t", gt=0.0, le=MAX_MASS_T, unit="t")
        payload_t = t.number("payload_t", ge=0.0, le=MAX_MASS_T - tare_t, unit="t")
        length_m = t.number("length_m", gt=0.0, le=MAX_VEHICLE_LENGTH_M, unit="m")
        for load, mass_t in (("loaded", tare_t + payload_t), ("empty", tare_t)):
            sub = _Table(t.data.get(load), t.key(load), LOAD_KEYS)
            sub.check_keys()
            force, ratio = _brake(sub, distributor, shoe_friction)
            loads[load] = _LoadSpec(tonne_to_kg(mass_t), sub.davis(), force, ratio)
    else:
        model = t.choice("model", tuple(LOCOMOTIVE_MODELS))
        base = LOCOMOTIVE_MODELS[model]()
        mass_t = t.number("mass_t", base.mass_kg / 1000.0, gt=0.0, le=MAX_MASS_T, unit="t")
        length_m = t.number("length_m", base.length_m, gt=0.0, le=MAX_VEHICLE_LENGTH_M, unit="m")
        locomotive = dataclasses.replace(base, mass_kg=tonne_to_kg(mass_t), length_m=length_m)
        force, ratio = _brake(t, distributor, shoe_friction)
        loads[""] = _LoadSpec(tonne_to_kg(mass_t), t.davis(), force, ratio)
    return _VehicleType(
        name, kind, length_m, rotating_kg, factor, distributor, draft_gear, shoe_friction,
        loads, locomotive,
    )  # fmt: skip


def _types_and_gears(
    data: Mapping[str, Any],
    base_types: Mapping[str, _VehicleType],
    base_gears: Mapping[str, DraftGear],
) -> tuple[dict[str, _VehicleType], dict[str, DraftGear]]:
    """The file's draft gears and vehicle types over the library's (the file's win)."""
    gears = dict(base_gears)
    for name, raw in _names(data, "draft_gears").items():
        gears[name] = _draft_gear(name, raw)
    types = dict(base_types)
    for name, raw in _names(data, "vehicle_types").items():
        types[name] = _vehicle_type(name, raw, gears)
    return types, gears


@functools.cache
def _library() -> tuple[Mapping[str, _VehicleType], Mapping[str, DraftGear]]:
    """The built-in types and draft gears, parsed once a process (a shipped file)."""
    resource = resources.files("railpilot.vehicle") / "data" / "consists" / LIBRARY_FILE
    source = "consist library"
    data = _parse_toml(resource.read_text(encoding="utf-8"), source)
    try:
        _Table(data, "", ("vehicle_types", "draft_gears")).check_keys()
        return _types_and_gears(data, {}, {})
    except ConsistError as exc:
        raise ConsistError(exc.field, exc.value, exc.allowed, source=source) from exc


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


def _block_label(index: int, raw: Any) -> str:
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
    index: int, raw: Any, types: Mapping[str, _VehicleType], gears: Mapping[str, DraftGear]
) -> _Block:
    t = _Table(raw, _block_label(index, raw), BLOCK_KEYS)
    t.check_keys()
    name = t.data.get("type")
    if not isinstance(name, str) or name not in types:
        raise ConsistError(
            t.key("type"), name, f"a vehicle type of the file or the library ({', '.join(types)})"
        )
    vtype = types[name]
    count = t.integer("count", 1, MAX_VEHICLES)
    if vtype.kind == "wagon":
        load = t.choice("load", LOADS)
    elif t.has("load"):
        raise ConsistError(t.key("load"), t.data["load"], "no load: a locomotive's type")
    else:
        load = ""
    mass_kg = (
        tonne_to_kg(t.number("mass_t", gt=0.0, le=MAX_MASS_T, unit="t"))
        if t.has("mass_t")
        else None
    )
    gear = _gear_ref(t, "draft_gear", gears) if t.has("draft_gear") else vtype.draft_gear
    if index == 0 and vtype.kind != "locomotive":
        raise ConsistError(
            t.key("type"), name, "a locomotive type: the first vehicle is the lead locomotive"
        )
    return _Block(t.label, vtype, count, load, mass_kg, gear, t.string("name", vtype.name))


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
    try:
        top = _Table(data, "", TOP_KEYS)
        top.check_keys()
        name = top.string("name")
        if top.has("description") and not isinstance(data["description"], str):
            raise ConsistError("description", data["description"], "a string")
        pipe_kpa = top.number(
            "brake_pipe_kpa", _default("brake_pipe_kpa"), gt=0.0, le=MAX_BRAKE_PIPE_KPA, unit="kPa"
        )
        delay_s = top.number(
            "dp_radio_delay_s", _default("dp_radio_delay_s"), ge=0.0, le=MAX_DP_DELAY_S, unit="s"
        )
        types, gears = _types_and_gears(data, *_library())
        raw_blocks = data.get("train")
        if not isinstance(raw_blocks, list) or not raw_blocks:
            raise ConsistError(
                "train",
                raw_blocks,
                "a non-empty list of [[train]] blocks from the head, the first a locomotive",
            )
        blocks = [_block(i, raw, types, gears) for i, raw in enumerate(raw_blocks)]
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
            return Consist(name, vehicles, brake_pipe_kpa=pipe_kpa, dp_radio_delay_s=delay_s)
        except ConfigError as exc:  # every part was checked: a rule across vehicles
            raise ConsistError(exc.field, exc.value, exc.allowed) from exc
    except ConsistError as exc:
        if exc.source is not None:
            raise
        raise ConsistError(exc.field, exc.value, exc.allowed, source=source) from exc


def _default(field: str) -> float:
    """The default of a Consist field: defaults are written once, in the dataclass."""
    default = next(f for f in dataclasses.fields(Consist) if f.name == field).default
    assert isinstance(default, float)
    return default


def _parse_toml(text: str, source: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConsistError("CONSIST", source, f"valid TOML ({exc})", source=source) from None
    except ValueError:  # tomllib's int() of a literal past Python's digit limit
        raise ConsistError(
            "CONSIST", source, f"valid TOML ({TOO_MANY_DIGITS})", source=source
        ) from None


def load_consist(path: str | os.PathLike[str]) -> Consist:
    """Read the consist file at ``path`` (errors name the file)."""
    file = Path(path)
    text = read_text(file, "CONSIST", "consist TOML file", ConsistError)
    return parse_consist(_parse_toml(text, str(file)), source=str(file))


def load_shipped_consist(filename: str, source: str) -> Consist:
    """A consist file shipped in ``railpilot/vehicle/data/consists/`` (the presets)."""
    resource = resources.files("railpilot.vehicle") / "data" / "consists" / filename
    return parse_consist(_parse_toml(resource.read_text(encoding="utf-8"), source), source)


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
