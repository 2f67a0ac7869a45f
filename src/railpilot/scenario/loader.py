"""Read a scenario TOML file into a :class:`~railpilot.scenario.model.Scenario`.

Papers' units at the edge (t, km/h, kN, km posts), SI inside. Every key is checked:
unknown keys, wrong types and out-of-range values raise ScenarioError naming the
dotted key, the value and what is allowed; nothing runs on a bad file.

``name`` is the one key a file must give; every other key has a default, and the
defaults live in one place only, the typed config dataclasses (Scenario, Train, EPBrake,
SmoothStopSpec, ...): a key the file leaves out is not passed to the constructor, so a
file with only ``name = "x"`` loads as exactly ``Scenario(name="x")``.

The file layout (examples/paper000_smarc_ep.toml is a complete one)::

    name = "..."                   # required
    kind = "ep-braking"            # "eddy-brake" files are routed to railpilot.eddy
    [train]  mass_t, rotating_mass_factor, length_m, davis = [a0, a1, a2],
             max_service_decel_mps2, motor_cars
    [train.electric_brake]  max_force_kn, max_power_kw
    [line]   gradients = [{start_km, end_km, permille}], curves = [{start_km, end_km,
             radius_m}], speed_limits = [{start_km, end_km, limit_kmh}],
             stations = [{name, stop_km}]
    [brake]  model = "ep-blended" (default): delay_s, air_lag_s, electric_lag_s,
             jerk_limit_mps3, changeover_kmh, fade_rate_kn_per_s, prenotice_s,
             cutout_cars, cutout_time_s, beta = [b1, b2, b3]
             model = "lag-delay" (paper 002): lag_s, delay_s, max_decel_mps2
             model = "brake-pipe" (heavy haul): position = "G" | "P", application_time_s,
             release_time_s, application_wave_mps, release_wave_mps, n_segments,
             max_decel_mps2, reaction_s (docs/heavy-haul-brake.md)
             model = "locomotive-drive" (an HXD1-class locomotive's traction and
             regeneration with the brake-pipe air brake): traction_lag_s, regen_enabled,
             [brake.air] the brake-pipe keys (docs/locomotive-drive.md)
    [reference]  shape = "smooth" | "constant", start_km, v0_kmh, decel_mps2,
             jerk_mps3, final_decel_mps2, final_phase_speed_kmh,
             coast_s, ease_out
             shape = "drive" (a whole run): start_km, stop_km, cruise_kmh, accel_mps2,
             decel_mps2, v0_kmh; the line's speed limits apply
    [disturbance]  constant_kn, random_std_kn, random_hold_s, target_fraction, seed,
             regions = [{start_km, end_km, force_kn | accel_mps2}]
    [ato]    mass_t, davis = [a0, a1, a2], brake_delay_s, brake_lag_s,
             reference = "time" | "distance", gradient_feedforward, preview_s
    [controller]  name = "pid" | "smarc" | "qsmc" | "pstop" | "module:Name" (your own,
             control/user.py); [controller.NAME] a built-in's parameters
    [sim]    dt_s, duration_s, control_period_s, record_every
    [realism]  speed_noise_std_mps, speed_resolution_mps, wheel_scale_error, slide_slip,
             balises_km = [...], adhesion, slide_ratio, notches, seed
    [montecarlo]  runs, seed, chunk; [montecarlo.vary] "KEY" = {dist, min, max, mean, std}
             (docs/montecarlo.md)
"""

from __future__ import annotations

import dataclasses
import re
import typing
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from railpilot import textfile
from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.brakes.registry import BRAKES
from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import ConfigError, ScenarioError, is_finite_number
from railpilot.scenario.model import (
    CONTROLLERS,
    ATOModel,
    ConstantDecelSpec,
    ControllerSpec,
    DriveSpec,
    Scenario,
    SimSettings,
    SmoothStopSpec,
)
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.disturbance import Disturbance, Region
from railpilot.sim.drive_profile import DEFAULT_DX_M, MAX_GRID_POINTS, DriveProfile
from railpilot.sim.realism import Realism
from railpilot.sim.reference import BrakingCurve
from railpilot.units import (
    MAX_KM_POST,
    km_post_to_m,
    kmh_to_mps,
    kn_to_n,
    m_to_km_post,
    mps_to_kmh,
    tonne_to_kg,
)
from railpilot.vehicle.line import Line, Segment, Station
from railpilot.vehicle.train import ElectricBrakeCurve, Train

T = TypeVar("T")

KINDS = ("ep-braking", "eddy-brake")


class _Table:
    """A TOML table being read: remembers its dotted path and which keys were used."""

    def __init__(self, data: Any, path: str) -> None:
        if not isinstance(data, Mapping):
            raise ScenarioError(path or "<file>", data, "a table")
        self.data = data
        self.path = path
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def has(self, name: str) -> bool:
        return name in self.data

    def number(
        self,
        name: str,
        default: float | None = None,
        *,
        gt: float | None = None,
        ge: float | None = None,
        le: float | None = None,
    ) -> float:
        """A finite number, optionally ``> gt`` or ``>= ge`` and ``<= le`` (checked in the
        file's units)."""
        self.used.add(name)
        if name not in self.data:
            if default is None:
                raise ScenarioError(self.key(name), None, "a number (the key is required)")
            return default
        value = self.data[name]
        if not is_finite_number(value):  # nan, inf, and an int no float holds (10**400)
            raise ScenarioError(self.key(name), value, "a finite number")
        bounds = [
            f"{op} {bound:g}"
            for op, bound in ((">", gt), (">=", ge), ("<=", le))
            if bound is not None
        ]
        if (
            (gt is not None and not value > gt)
            or (ge is not None and not value >= ge)
            or (le is not None and not value <= le)
        ):
            raise ScenarioError(self.key(name), value, "a number " + " and ".join(bounds))
        return float(value)

    def optional_number(self, name: str) -> float | None:
        return self.number(name) if name in self.data else None

    def integer(self, name: str, default: int) -> int:
        self.used.add(name)
        value = self.data.get(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(self.key(name), value, "an integer")
        if not is_finite_number(value):  # 10**400: the brakes' packed parameters are floats
            raise ScenarioError(
                self.key(name), value, "an integer a float can hold (below 1.8e308 in size)"
            )
        return value

    def string(self, name: str, default: str, choices: tuple[str, ...] | None = None) -> str:
        self.used.add(name)
        value = self.data.get(name, default)
        if not isinstance(value, str):
            raise ScenarioError(self.key(name), value, "a string")
        if choices is not None and value not in choices:
            raise ScenarioError(self.key(name), value, f"one of {', '.join(choices)}")
        return value

    def flag(self, name: str, default: bool) -> bool:
        self.used.add(name)
        value = self.data.get(name, default)
        if not isinstance(value, bool):
            raise ScenarioError(self.key(name), value, "true or false")
        return value

    def numbers(self, name: str, count: int) -> tuple[float, ...] | None:
        self.used.add(name)
        if name not in self.data:
            return None
        value = self.data[name]
        if (
            not isinstance(value, list)
            or len(value) != count
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)
        ):
            raise ScenarioError(self.key(name), value, f"a list of {count} numbers")
        for i, v in enumerate(value):
            if isinstance(v, int) and not is_finite_number(v):  # 10**400: no float holds it
                raise ScenarioError(f"{self.key(name)}[{i}]", v, "a finite number")
        return tuple(float(v) for v in value)

    def put(
        self,
        kwargs: dict[str, Any],
        name: str,
        field: str,
        convert: Callable[[float], Any] = float,
        *,
        read: str = "number",
        gt: float | None = None,
        ge: float | None = None,
        le: float | None = None,
    ) -> None:
        """``kwargs[field] = convert(value)`` when the file gives ``name``; nothing otherwise.

        The typed constructor's own default applies to every key the file leaves out:
        defaults are written once, in the config dataclasses.
        """
        self.used.add(name)
        if name not in self.data:
            return
        if read == "integer":
            kwargs[field] = self.integer(name, 0)
        elif read == "flag":
            kwargs[field] = self.flag(name, False)
        elif read == "string":
            kwargs[field] = self.string(name, "")
        else:
            kwargs[field] = convert(self.number(name, gt=gt, ge=ge, le=le))

    def table(self, name: str) -> _Table:
        self.used.add(name)
        return _Table(self.data.get(name, {}), self.key(name))

    def tables(self, name: str) -> list[_Table]:
        self.used.add(name)
        value = self.data.get(name, [])
        if not isinstance(value, list):
            raise ScenarioError(self.key(name), value, "a list of tables")
        return [_Table(item, f"{self.key(name)}[{i}]") for i, item in enumerate(value)]

    def raw(self, name: str) -> Any:
        self.used.add(name)
        return self.data.get(name)

    def done(self) -> None:
        """Reject keys nobody asked for (typos must not pass silently)."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used)) or "none"
            raise ScenarioError(
                self.key(unknown[0]),
                self.data[unknown[0]],
                f"a known key instead of '{unknown[0]}' (known here: {known})",
            )


#: SI field names of the typed constructors -> (the key as written in the file, the
#: value converted back to the file's unit), so an error names what the user wrote
_FILE_KEYS: dict[str, tuple[str, Callable[[Any], Any]]] = {
    "train.mass_kg": ("train.mass_t", lambda v: v / 1000.0),
    "ato.mass_kg": ("ato.mass_t", lambda v: v / 1000.0),
    "train.electric_brake.max_force_n": ("train.electric_brake.max_force_kn", lambda v: v / 1000.0),
    "train.electric_brake.max_power_w": ("train.electric_brake.max_power_kw", lambda v: v / 1000.0),
    "train.davis_a0": ("train.davis[0]", lambda v: v),
    "train.davis_a1": ("train.davis[1]", lambda v: v),
    "train.davis_a2": ("train.davis[2]", lambda v: v),
    "reference.v0": ("reference.v0_kmh", mps_to_kmh),
    "reference.decel": ("reference.decel_mps2", lambda v: v),
    "reference.jerk": ("reference.jerk_mps3", lambda v: v),
    "reference.final_decel": ("reference.final_decel_mps2", lambda v: v),
    "reference.final_phase_speed": ("reference.final_phase_speed_kmh", mps_to_kmh),
    "reference.cruise_mps": ("reference.cruise_kmh", mps_to_kmh),
    "reference.v_start_mps": ("reference.v0_kmh", mps_to_kmh),
    "disturbance.constant_n": ("disturbance.constant_kn", lambda v: v / 1000.0),
    "disturbance.random_std_n": ("disturbance.random_std_kn", lambda v: v / 1000.0),
}


def _brake_file_keys() -> dict[str, tuple[str, Callable[[Any], Any]]]:
    """The brake models' own file keys (brakes/base.py ``FILE_KEYS``, ``FILE_LISTS``)."""
    out: dict[str, tuple[str, Callable[[Any], Any]]] = {}
    for entry in BRAKES.values():
        for key, (field, _, back) in getattr(entry.cls, "FILE_KEYS", {}).items():
            out[f"brake.{field}"] = (f"brake.{key}", back)
        for key, fields in getattr(entry.cls, "FILE_LISTS", {}).items():
            for i, field in enumerate(fields):
                out[f"brake.{field}"] = (f"brake.{key}[{i}]", lambda v: v)
    return out


_FILE_KEYS.update(_brake_file_keys())

#: fields whose value is a (start, end) pair in metres; the file writes km
_KM_SPANS = re.compile(r"^(line\.(gradients|curves|speed_limits)|disturbance\.regions)\[\d+\]$")
#: a speed limit's value in m/s (vehicle/line.py); the file writes limit_kmh
_LIMITS = re.compile(r"^line\.speed_limits\[\d+\]\.limit$")


def _km_post(t: _Table, name: str) -> float:
    """The km post ``name`` of table ``t`` (required) in metres, within ``MAX_KM_POST``."""
    return float(km_post_to_m(t.number(name, ge=-MAX_KM_POST, le=MAX_KM_POST)))


def _file_error(exc: ConfigError) -> ScenarioError:
    """The constructor's error in the file's words: key as written, value in its unit."""
    if exc.field in _FILE_KEYS:
        key, convert = _FILE_KEYS[exc.field]
        try:
            value = convert(exc.value)
        except TypeError:
            value = exc.value
        return ScenarioError(key, value, exc.allowed)
    if _LIMITS.match(exc.field):
        return ScenarioError(f"{exc.field}_kmh", mps_to_kmh(exc.value), exc.allowed)
    if _KM_SPANS.match(exc.field) and isinstance(exc.value, tuple):
        return ScenarioError(
            exc.field, tuple(v / 1000.0 for v in exc.value), "finite start_km < end_km"
        )
    return ScenarioError(exc.field, exc.value, exc.allowed)


def _build(path: str, make: Callable[[], T]) -> T:
    """Run a constructor; turn its ConfigError into a ScenarioError in the file's words."""
    try:
        return make()
    except ScenarioError:
        raise
    except ConfigError as exc:
        # a field of the constructor's own, unless it names a table of the file (a brake
        # packed for the step names sim.dt_s, not brake.sim.dt_s)
        if exc.field.split(".")[0] not in (path.split(".")[0], *_TABLES):
            exc = ConfigError(f"{path}.{exc.field}", exc.value, exc.allowed)
        raise _file_error(exc) from exc


#: the file's top-level tables
_TABLES = (
    "train",
    "line",
    "brake",
    "reference",
    "disturbance",
    "ato",
    "controller",
    "sim",
    "realism",
    "montecarlo",
)


def _train(t: _Table) -> Train:
    kw: dict[str, Any] = {}
    t.put(kw, "mass_t", "mass_kg", tonne_to_kg, gt=0)
    t.put(kw, "rotating_mass_factor", "rotating_mass_factor")
    t.put(kw, "length_m", "length_m", gt=0)
    t.put(kw, "max_service_decel_mps2", "max_service_decel_mps2", gt=0)
    t.put(kw, "motor_cars", "motor_cars", read="integer")
    davis = t.numbers("davis", 3)
    if davis is not None:
        kw["davis_a0"], kw["davis_a1"], kw["davis_a2"] = davis
    if t.has("electric_brake"):
        eb = t.table("electric_brake")
        curve_kw: dict[str, Any] = {}
        eb.put(curve_kw, "max_force_kn", "max_force_n", kn_to_n)
        eb.put(curve_kw, "max_power_kw", "max_power_w", lambda v: v * 1000.0)
        kw["electric_brake"] = _build(
            "train.electric_brake", lambda: ElectricBrakeCurve(**curve_kw)
        )
        eb.done()
    train = _build("train", lambda: Train(**kw))
    t.done()
    return train


def _segments(
    t: _Table, name: str, value_key: str, scale: Callable[[float], float]
) -> tuple[Segment, ...]:
    out = []
    for item in t.tables(name):
        seg = Segment(
            _km_post(item, "start_km"), _km_post(item, "end_km"), scale(item.number(value_key))
        )
        item.done()
        out.append(seg)
    return tuple(out)


def _line(t: _Table) -> Line:
    gradients = _segments(t, "gradients", "permille", float)
    curves = _segments(t, "curves", "radius_m", float)
    limits = _segments(t, "speed_limits", "limit_kmh", kmh_to_mps)
    stations = []
    for item in t.tables("stations"):
        stations.append(Station(item.string("name", "station"), _km_post(item, "stop_km")))
        item.done()
    line = _build("line", lambda: Line(gradients, curves, limits, tuple(stations)))
    t.done()
    return line


def _brake(t: _Table) -> EPBrake | LagDelayBrake | BrakePipeBrake | LocomotiveDrive:
    """``[brake]``: ``model`` picks the registered brake model; its keys are its config
    dataclass's fields (brakes/base.py: ``FILE_KEYS`` and ``FILE_LISTS`` for keys the
    file writes in other units or as one list), read without a line per model here."""
    model = t.string("model", EPBrake.name, tuple(BRAKES))
    cls = BRAKES[model].cls
    brake = _build("brake", lambda: cls(**_config_keys(t, cls)))
    t.done()
    return brake


def _nested_config(t: _Table, cls: type) -> Any:
    """A config dataclass read from its own sub-table (every key checked)."""
    value = _build(t.path, lambda: cls(**_config_keys(t, cls)))
    t.done()
    return value


def _config_keys(t: _Table, cls: type) -> dict[str, Any]:
    """Keyword arguments of config dataclass ``cls`` from the keys ``t`` gives (only
    those: the dataclass's defaults apply to the rest). A field that is itself a config
    dataclass is read from a sub-table of its name."""
    file_keys: dict[str, tuple[str, Callable[[float], Any], Any]] = getattr(cls, "FILE_KEYS", {})
    file_lists: dict[str, tuple[str, ...]] = getattr(cls, "FILE_LISTS", {})
    written_otherwise = {field for field, _, _ in file_keys.values()}
    written_otherwise |= {field for fields in file_lists.values() for field in fields}
    hints = typing.get_type_hints(cls)
    kw: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init or f.name in written_otherwise:
            continue
        kind = hints[f.name]
        if dataclasses.is_dataclass(kind) and isinstance(kind, type):
            if t.has(f.name):
                kw[f.name] = _nested_config(t.table(f.name), kind)
            continue
        if kind is bool:
            t.put(kw, f.name, f.name, read="flag")
        elif kind is int:
            t.put(kw, f.name, f.name, read="integer")
        elif kind is str or typing.get_origin(kind) is typing.Literal:
            t.put(kw, f.name, f.name, read="string")
        else:
            t.put(kw, f.name, f.name)
    for key, (field, convert, _) in file_keys.items():
        t.put(kw, key, field, convert)
    for key, fields in file_lists.items():
        values = t.numbers(key, len(fields))
        if values is not None:
            kw.update(zip(fields, values, strict=True))
    return kw


def _reference(t: _Table, line: Line, train: Train) -> BrakingCurve | DriveProfile:
    shape = t.string("shape", "smooth", ("smooth", "constant", "drive"))
    kw: dict[str, Any] = {}
    t.put(kw, "start_km", "start_m", km_post_to_m, ge=-MAX_KM_POST, le=MAX_KM_POST)
    if shape == "drive":
        t.put(kw, "stop_km", "stop_m", km_post_to_m, ge=-MAX_KM_POST, le=MAX_KM_POST)
        if "stop_m" not in kw:
            t.number("stop_km")  # required for this shape: raises naming the key
        _check_drive_span(t, kw)
        t.put(kw, "cruise_kmh", "cruise_mps", kmh_to_mps)
        t.put(kw, "accel_mps2", "accel_mps2")
        t.put(kw, "decel_mps2", "decel_mps2")
        t.put(kw, "v0_kmh", "v_start_mps", kmh_to_mps)
        drive = _build("reference", lambda: DriveSpec(**kw))
        profile = _build("reference", lambda: drive.build(line, train))
        t.done()
        return profile
    t.put(kw, "v0_kmh", "v0_mps", kmh_to_mps)
    t.put(kw, "coast_s", "coast_s")
    t.put(kw, "decel_mps2", "decel_mps2")
    if shape == "constant":
        if "decel_mps2" not in kw:
            t.number("decel_mps2")  # required for this shape: raises naming the key
        spec: SmoothStopSpec | ConstantDecelSpec = _build(
            "reference", lambda: ConstantDecelSpec(**kw)
        )
    else:
        t.put(kw, "jerk_mps3", "jerk_mps3")
        t.put(kw, "final_decel_mps2", "final_decel_mps2")
        t.put(kw, "final_phase_speed_kmh", "final_phase_speed_mps", kmh_to_mps)
        t.put(kw, "ease_out", "ease_out", read="flag")
        spec = _build("reference", lambda: SmoothStopSpec(**kw))
    curve = _build("reference", spec.build)
    stop_km = m_to_km_post(curve.stop_m)
    if not -MAX_KM_POST <= stop_km <= MAX_KM_POST:
        # a deceleration this small stops the reference beyond any line: the run would
        # simply never stop, and its stop error would be no number
        raise ScenarioError(
            t.key("decel_mps2"),
            spec.decel_mps2,
            f"a deceleration that brings the reference to rest within km +-{MAX_KM_POST:g} "
            f"(from km {m_to_km_post(curve.start_m):g} at {mps_to_kmh(curve.v0_mps):g} km/h "
            f"it comes to rest at km {stop_km:.4g})",
        )
    t.done()
    return curve


def _check_drive_span(t: _Table, kw: dict[str, Any]) -> None:
    """A drive's stop after its start and within what its profile tabulates, named in km
    as the file writes them (the profile names its metres: reference.stop_m, dx_m)."""
    start_m = kw.get("start_m", DriveSpec.start_m)
    start_km = t.number("start_km", m_to_km_post(start_m))
    stop_km = t.number("stop_km")
    if not kw["stop_m"] > start_m:
        raise ScenarioError(
            t.key("stop_km"),
            stop_km,
            f"a km post after reference.start_km = {start_km:g} (a drive runs towards "
            "increasing km)",
        )
    if (kw["stop_m"] - start_m) / DEFAULT_DX_M > MAX_GRID_POINTS:
        longest_km = m_to_km_post(MAX_GRID_POINTS * DEFAULT_DX_M)
        raise ScenarioError(
            t.key("stop_km"),
            stop_km,
            f"a km post at most {longest_km:g} km after reference.start_km = {start_km:g} "
            f"(a drive's profile has at most {MAX_GRID_POINTS:,} knots, "
            f"{DEFAULT_DX_M:g} m apart)",
        )


def _disturbance(t: _Table, effective_mass_kg: float) -> Disturbance:
    regions = []
    for item in t.tables("regions"):
        if item.has("accel_mps2") == item.has("force_kn"):
            raise ScenarioError(
                item.key("force_kn"),
                {k: item.data.get(k) for k in ("force_kn", "accel_mps2")},
                "exactly one of force_kn or accel_mps2 in each region",
            )
        force = (
            kn_to_n(item.number("force_kn"))
            if item.has("force_kn")
            else item.number("accel_mps2") * effective_mass_kg
        )
        regions.append(Region(_km_post(item, "start_km"), _km_post(item, "end_km"), force))
        item.done()
    kw: dict[str, Any] = {"regions": tuple(regions)}
    t.put(kw, "constant_kn", "constant_n", kn_to_n)
    t.put(kw, "random_std_kn", "random_std_n", kn_to_n)
    t.put(kw, "random_hold_s", "random_hold_s")
    t.put(kw, "target_fraction", "target_fraction")
    t.put(kw, "seed", "seed", read="integer")
    dist = _build("disturbance", lambda: Disturbance(**kw))
    t.done()
    return dist


def _realism(t: _Table) -> Realism:
    balises = t.raw("balises_km")
    if balises is None:
        balises = []
    if not isinstance(balises, list) or any(
        isinstance(b, bool) or not isinstance(b, int | float) for b in balises
    ):
        raise ScenarioError(t.key("balises_km"), balises, "a list of km posts")
    for i, km in enumerate(balises):
        if not -MAX_KM_POST <= km <= MAX_KM_POST:  # NaN too
            raise ScenarioError(
                f"{t.key('balises_km')}[{i}]",
                km,
                f"a km post in [{-MAX_KM_POST:g}, {MAX_KM_POST:g}]",
            )
    kw: dict[str, Any] = {}
    if balises:
        kw["balises_m"] = tuple(km_post_to_m(float(b)) for b in balises)
    t.put(kw, "speed_noise_std_mps", "speed_noise_std_mps", ge=0)
    t.put(kw, "speed_resolution_mps", "speed_resolution_mps", ge=0)
    t.put(kw, "wheel_scale_error", "wheel_scale_error")
    t.put(kw, "slide_slip", "slide_slip")
    t.put(kw, "adhesion", "adhesion", ge=0)
    t.put(kw, "slide_ratio", "slide_ratio")
    t.put(kw, "notches", "notches", read="integer")
    t.put(kw, "seed", "seed", read="integer")
    realism = _build("realism", lambda: Realism(**kw))
    t.done()
    return realism


def _distribution_maker(key: str, item: _Table) -> Callable[[], Distribution]:
    """Read one ``[montecarlo.vary]`` entry; the Distribution checks it when built."""
    kind = item.string("dist", "uniform", ("uniform", "normal"))
    if kind == "uniform":
        low, high = item.number("min"), item.number("max")
        return lambda: Distribution(key, "uniform", low, high)
    low, high = item.number("min", -np.inf), item.number("max", np.inf)
    mean, std = item.number("mean"), item.number("std")
    return lambda: Distribution(key, "normal", low, high, mean=mean, std=std)


def _montecarlo(t: _Table) -> MonteCarloSpec | None:
    if not t.data:
        return None
    vary = []
    table = t.table("vary")
    for key in list(table.data):
        item = table.table(key)
        vary.append(_build("montecarlo.vary", _distribution_maker(key, item)))
        item.done()
    table.done()
    kw: dict[str, Any] = {"vary": tuple(vary)}
    for name in ("runs", "seed", "chunk"):
        t.put(kw, name, name, read="integer")
    spec = _build("montecarlo", lambda: MonteCarloSpec(**kw))
    t.done()
    return spec


def _ato(t: _Table) -> ATOModel:
    kw: dict[str, Any] = {}
    t.put(kw, "mass_t", "mass_kg", tonne_to_kg)
    t.put(kw, "brake_delay_s", "brake_delay_s")
    t.put(kw, "brake_lag_s", "brake_lag_s")
    t.put(kw, "reference", "reference", read="string")
    t.put(kw, "gradient_feedforward", "gradient_feedforward", read="flag")
    t.put(kw, "preview_s", "preview_s")
    davis = t.numbers("davis", 3)
    if davis is not None:
        kw["davis"] = davis
    ato = _build("ato", lambda: ATOModel(**kw))
    t.done()
    return ato


def _controller(t: _Table) -> ControllerSpec:
    kw: dict[str, Any] = {}
    t.put(kw, "name", "name", read="string")
    params: dict[str, dict[str, Any]] = {}
    for ctrl in CONTROLLERS:
        if t.has(ctrl):
            sub = t.raw(ctrl)
            if not isinstance(sub, Mapping):
                raise ScenarioError(t.key(ctrl), sub, "a table of controller parameters")
            params[ctrl] = {
                k: tuple(tuple(x) if isinstance(x, list) else x for x in v)
                if isinstance(v, list)
                else v
                for k, v in sub.items()
            }
    t.done()
    return _build("controller", lambda: ControllerSpec(params=params, **kw))


def _sim(t: _Table) -> SimSettings:
    kw: dict[str, Any] = {}
    t.put(kw, "dt_s", "dt_s")
    t.put(kw, "duration_s", "duration_s")
    t.put(kw, "control_period_s", "control_period_s")
    t.put(kw, "record_every", "record_every", read="integer")
    sim = _build("sim", lambda: SimSettings(**kw))
    t.done()
    return sim


def scenario_and_spec_from_mapping(
    data: Mapping[str, Any],
) -> tuple[Scenario, MonteCarloSpec | None]:
    """Build and validate a scenario and its optional ``[montecarlo]`` spec."""
    top = _Table(data, "")
    top.string("kind", "ep-braking", ("ep-braking",))
    if not top.has("name"):
        raise ScenarioError(
            "name",
            None,
            "a scenario name: the one key every scenario file must give (every other key "
            "has a default: the config dataclasses of railpilot.scenario.model; the keys "
            "are listed at the top of railpilot/scenario/loader.py)",
        )
    name = top.string("name", "")
    train = _train(top.table("train"))
    line = _line(top.table("line"))
    brake = _brake(top.table("brake"))
    reference = _reference(top.table("reference"), line, train)
    disturbance = _disturbance(top.table("disturbance"), train.effective_mass_kg)
    ato = _ato(top.table("ato"))
    controller = _controller(top.table("controller"))
    sim = _sim(top.table("sim"))
    realism = _realism(top.table("realism"))
    montecarlo = _montecarlo(top.table("montecarlo"))
    top.done()
    scenario = Scenario(
        name, train, line, brake, reference, disturbance, ato, controller, sim, realism
    )
    _check_consistency(scenario)
    if montecarlo is not None:
        # every sampled key must apply to this scenario (e.g. brake.lag_s needs a lag-delay
        # brake): try each on its lower bound now, not in the middle of a sweep
        from railpilot.sim.batch import check_spec

        _build("montecarlo", lambda: check_spec(scenario, montecarlo))
    return scenario, montecarlo


def scenario_from_mapping(data: Mapping[str, Any]) -> Scenario:
    """Build and validate a scenario from a parsed TOML mapping."""
    return scenario_and_spec_from_mapping(data)[0]


def _check_consistency(scenario: Scenario) -> None:
    """Checks that need more than one table; raise before anything runs."""
    from railpilot.brakes.base import PackContext
    from railpilot.sim.run import make_controller

    context = PackContext(scenario.sim.dt_s, scenario.train.effective_mass_kg, scenario.train)
    _build("brake", lambda: scenario.brake.pack(context))
    # a controller given parameters it does not take is an error now, not mid-run
    for name in scenario.controller.params:
        try:
            make_controller(scenario, name)
        except ScenarioError:
            raise
        except ConfigError as exc:
            raise ScenarioError(exc.field, exc.value, exc.allowed) from exc


def read_toml(path: Path) -> dict[str, Any]:
    """Parse a TOML file; a missing, unreadable or malformed file is a ScenarioError."""
    return textfile.read_toml(path, "SCENARIO", "TOML file", ScenarioError)


def load_scenario(path: Path | str) -> Scenario | EddyScenario:
    """Read and validate a scenario file of either kind: ``kind = "ep-braking"`` (the
    default) gives a :class:`Scenario`, ``kind = "eddy-brake"`` an
    :class:`~railpilot.eddy.scenario.EddyScenario` (paper 003)."""
    data = read_toml(Path(path))
    if data.get("kind") == "eddy-brake":
        return EddyScenario.from_mapping(data)
    return scenario_from_mapping(data)


def load_scenario_and_spec(path: Path | str) -> tuple[Scenario, MonteCarloSpec | None]:
    """Read and validate a scenario file and its ``[montecarlo]`` table, if any."""
    return scenario_and_spec_from_mapping(read_toml(Path(path)))
