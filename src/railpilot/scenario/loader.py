"""Read a scenario TOML file into a :class:`~railpilot.scenario.model.Scenario`.

Papers' units at the edge (t, km/h, kN, km posts), SI inside. Every key is checked:
unknown keys, wrong types and out-of-range values raise ScenarioError naming the
dotted key, the value and what is allowed; nothing runs on a bad file. The keys and
their types are declared once, in railpilot.schema.scenario (which also gives the
format's JSON Schema, ``railpilot schema scenario``); this module applies the rules
across keys and builds the typed config objects.

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

import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.brakes.registry import BRAKES
from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import ConfigError, ScenarioError
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
from railpilot.schema.config import ConfigTable, config_kwargs, given_values
from railpilot.schema.line_table import LineTable
from railpilot.schema.reading import read_document
from railpilot.schema.scenario import (
    AtoTable,
    ConstantReferenceTable,
    DisturbanceTable,
    DriveReferenceTable,
    MonteCarloTable,
    NormalTable,
    RealismTable,
    ScenarioFileTable,
    SimTable,
    SmoothReferenceTable,
    TrainTable,
)
from railpilot.schema.validate import check
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
from railpilot.vehicle.line import Line, Segment, StopPoint
from railpilot.vehicle.train import ElectricBrakeCurve, Train

T = TypeVar("T")

KINDS = ("ep-braking", "eddy-brake")


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


def _train(t: TrainTable) -> Train:
    kw = given_values(t, "rotating_mass_factor", "length_m", "max_service_decel_mps2")
    kw |= given_values(t, "motor_cars")
    if t.given("mass_t"):
        kw["mass_kg"] = tonne_to_kg(float(t.mass_t))
    if t.given("davis"):
        kw["davis_a0"], kw["davis_a1"], kw["davis_a2"] = (float(v) for v in t.davis)
    if t.given("electric_brake"):
        eb = t.electric_brake
        curve_kw: dict[str, Any] = {}
        if eb.given("max_force_kn"):
            curve_kw["max_force_n"] = kn_to_n(float(eb.max_force_kn))
        if eb.given("max_power_kw"):
            curve_kw["max_power_w"] = float(eb.max_power_kw) * 1000.0
        kw["electric_brake"] = _build(
            "train.electric_brake", lambda: ElectricBrakeCurve(**curve_kw)
        )
    return _build("train", lambda: Train(**kw))


def line_from_table(t: LineTable) -> Line:
    """The :class:`Line` of a checked ``[line]`` table (railpilot.schema.line_table)."""

    def spans(
        items: Sequence[Any], key: str, scale: Callable[[float], float]
    ) -> tuple[Segment, ...]:
        return tuple(
            Segment(
                km_post_to_m(float(s.start_km)),
                km_post_to_m(float(s.end_km)),
                scale(float(getattr(s, key))),
            )
            for s in items
        )

    gradients = spans(t.gradients, "permille", float)
    curves = spans(t.curves, "radius_m", float)
    limits = spans(t.speed_limits, "limit_kmh", kmh_to_mps)
    stations = tuple(StopPoint(s.name, km_post_to_m(float(s.stop_km))) for s in t.stations)
    return _build("line", lambda: Line(gradients, curves, limits, stations))


def _brake(t: ConfigTable) -> EPBrake | LagDelayBrake | BrakePipeBrake | LocomotiveDrive:
    """``[brake]``: ``model`` picks the registered brake model; its keys are its config
    dataclass's fields (brakes/base.py: ``FILE_KEYS`` and ``FILE_LISTS`` for keys the
    file writes in other units or as one list), read without a line per model here."""
    cls = BRAKES[getattr(t, "model")].cls  # noqa: B009 (a key of every brake's table)
    kw = config_kwargs(t, cls, nested=_nested("brake"))
    brake: EPBrake | LagDelayBrake | BrakePipeBrake | LocomotiveDrive = _build(
        "brake", lambda: cls(**kw)
    )
    return brake


def _nested(path: str) -> Callable[[str, ConfigTable, type], Any]:
    """How a config dataclass's sub-table (a locomotive drive's ``air``) is built: as its
    own dataclass, its errors named under ``path.NAME``."""

    def build(name: str, table: ConfigTable, cls: type) -> Any:
        where = f"{path}.{name}"
        kw = config_kwargs(table, cls, nested=_nested(where))
        return _build(where, lambda: cls(**kw))

    return build


def _reference(
    t: SmoothReferenceTable | ConstantReferenceTable | DriveReferenceTable,
    line: Line,
    train: Train,
) -> BrakingCurve | DriveProfile:
    kw: dict[str, Any] = {}
    if t.given("start_km"):
        kw["start_m"] = km_post_to_m(float(t.start_km))
    if isinstance(t, DriveReferenceTable):
        kw["stop_m"] = km_post_to_m(float(t.stop_km))
        _check_drive_span(t, kw)
        kw |= _renamed(t, {"cruise_kmh": "cruise_mps", "v0_kmh": "v_start_mps"}, kmh_to_mps)
        kw |= given_values(t, "accel_mps2", "decel_mps2")
        drive = _build("reference", lambda: DriveSpec(**kw))
        return _build("reference", lambda: drive.build(line, train))
    kw |= _renamed(t, {"v0_kmh": "v0_mps"}, kmh_to_mps)
    kw |= given_values(t, "coast_s", "decel_mps2")
    spec: SmoothStopSpec | ConstantDecelSpec
    if isinstance(t, ConstantReferenceTable):
        spec = _build("reference", lambda: ConstantDecelSpec(**kw))
    else:
        kw |= given_values(t, "jerk_mps3", "final_decel_mps2", "ease_out")
        kw |= _renamed(t, {"final_phase_speed_kmh": "final_phase_speed_mps"}, kmh_to_mps)
        spec = _build("reference", lambda: SmoothStopSpec(**kw))
    curve = _build("reference", spec.build)
    stop_km = m_to_km_post(curve.stop_m)
    if not -MAX_KM_POST <= stop_km <= MAX_KM_POST:
        # a deceleration this small stops the reference beyond any line: the run would
        # simply never stop, and its stop error would be no number
        raise ScenarioError(
            "reference.decel_mps2",
            spec.decel_mps2,
            f"a deceleration that brings the reference to rest within km +-{MAX_KM_POST:g} "
            f"(from km {m_to_km_post(curve.start_m):g} at {mps_to_kmh(curve.v0_mps):g} km/h "
            f"it comes to rest at km {stop_km:.4g})",
        )
    return curve


def _renamed(
    t: ConfigTable, names: Mapping[str, str], convert: Callable[[float], float]
) -> dict[str, Any]:
    """``{field: convert(value)}`` of the keys of ``names`` the file gives (a key written
    in the file's unit, its field in SI)."""
    return {field: convert(float(getattr(t, key))) for key, field in names.items() if t.given(key)}


def _check_drive_span(t: DriveReferenceTable, kw: dict[str, Any]) -> None:
    """A drive's stop after its start and within what its profile tabulates, named in km
    as the file writes them (the profile names its metres: reference.stop_m, dx_m)."""
    start_m = kw.get("start_m", DriveSpec.start_m)
    start_km = float(t.start_km) if t.given("start_km") else m_to_km_post(start_m)
    stop_km = float(t.stop_km)
    if not kw["stop_m"] > start_m:
        raise ScenarioError(
            "reference.stop_km",
            stop_km,
            f"a km post after reference.start_km = {start_km:g} (a drive runs towards "
            "increasing km)",
        )
    if (kw["stop_m"] - start_m) / DEFAULT_DX_M > MAX_GRID_POINTS:
        longest_km = m_to_km_post(MAX_GRID_POINTS * DEFAULT_DX_M)
        raise ScenarioError(
            "reference.stop_km",
            stop_km,
            f"a km post at most {longest_km:g} km after reference.start_km = {start_km:g} "
            f"(a drive's profile has at most {MAX_GRID_POINTS:,} knots, "
            f"{DEFAULT_DX_M:g} m apart)",
        )


def _disturbance(
    t: DisturbanceTable, written: Sequence[Mapping[str, Any]], effective_mass_kg: float
) -> Disturbance:
    """``[disturbance]`` (``written``: its regions as the file gives them, for errors)."""
    regions = []
    for i, (item, raw) in enumerate(zip(t.regions, written, strict=True)):
        if item.given("accel_mps2") == item.given("force_kn"):
            raise ScenarioError(
                f"disturbance.regions[{i}].force_kn",
                {k: raw.get(k) for k in ("force_kn", "accel_mps2")},
                "exactly one of force_kn or accel_mps2 in each region",
            )
        force = (
            kn_to_n(float(item.force_kn))
            if item.given("force_kn")
            else float(item.accel_mps2) * effective_mass_kg
        )
        start_m, end_m = km_post_to_m(float(item.start_km)), km_post_to_m(float(item.end_km))
        regions.append(Region(start_m, end_m, force))
    kw: dict[str, Any] = {"regions": tuple(regions)}
    kw |= _renamed(t, {"constant_kn": "constant_n", "random_std_kn": "random_std_n"}, kn_to_n)
    kw |= given_values(t, "random_hold_s", "target_fraction", "seed")
    return _build("disturbance", lambda: Disturbance(**kw))


def _realism(t: RealismTable) -> Realism:
    kw: dict[str, Any] = {}
    if t.given("balises_km") and t.balises_km:
        kw["balises_m"] = tuple(km_post_to_m(float(b)) for b in t.balises_km)
    kw |= given_values(
        t,
        "speed_noise_std_mps",
        "speed_resolution_mps",
        "wheel_scale_error",
        "slide_slip",
        "adhesion",
        "slide_ratio",
        "notches",
        "seed",
    )
    return _build("realism", lambda: Realism(**kw))


def _distribution_maker(key: str, item: ConfigTable) -> Callable[[], Distribution]:
    """One ``[montecarlo.vary]`` entry; the Distribution checks it when built."""
    low = float(getattr(item, "min")) if item.given("min") else -np.inf  # noqa: B009
    high = float(getattr(item, "max")) if item.given("max") else np.inf  # noqa: B009
    if not isinstance(item, NormalTable):
        return lambda: Distribution(key, "uniform", low, high)
    mean, std = float(item.mean), float(item.std)
    return lambda: Distribution(key, "normal", low, high, mean=mean, std=std)


def _montecarlo(t: MonteCarloTable) -> MonteCarloSpec | None:
    if not t.model_fields_set:
        return None
    vary = tuple(
        _build("montecarlo.vary", _distribution_maker(key, item)) for key, item in t.vary.items()
    )
    kw: dict[str, Any] = {"vary": vary, **given_values(t, "runs", "seed", "chunk")}
    return _build("montecarlo", lambda: MonteCarloSpec(**kw))


def _ato(t: AtoTable) -> ATOModel:
    kw = given_values(t, "brake_delay_s", "brake_lag_s", "preview_s")
    kw |= given_values(t, "reference", "gradient_feedforward")
    if t.given("mass_t"):
        kw["mass_kg"] = tonne_to_kg(float(t.mass_t))
    if t.given("davis"):
        kw["davis"] = tuple(float(v) for v in t.davis)
    return _build("ato", lambda: ATOModel(**kw))


def _controller(t: ConfigTable) -> ControllerSpec:
    kw = given_values(t, "name")
    params: dict[str, dict[str, Any]] = {}
    for ctrl in CONTROLLERS:
        if t.given(ctrl):
            params[ctrl] = {
                k: tuple(tuple(x) if isinstance(x, list) else x for x in v)
                if isinstance(v, list)
                else v
                for k, v in getattr(t, ctrl).items()
            }
    return _build("controller", lambda: ControllerSpec(params=params, **kw))


def _sim(t: SimTable) -> SimSettings:
    kw = given_values(t, "dt_s", "duration_s", "control_period_s", "record_every")
    return _build("sim", lambda: SimSettings(**kw))


def scenario_and_spec_from_mapping(
    data: Mapping[str, Any],
) -> tuple[Scenario, MonteCarloSpec | None]:
    """Build and validate a scenario and its optional ``[montecarlo]`` spec."""
    top = check(ScenarioFileTable, data, ScenarioError)
    train = _train(top.train)
    line = line_from_table(top.line)
    brake = _brake(top.brake)
    reference = _reference(top.reference, line, train)
    regions = data.get("disturbance", {}).get("regions", [])
    disturbance = _disturbance(top.disturbance, regions, train.effective_mass_kg)
    ato = _ato(top.ato)
    controller = _controller(top.controller)
    sim = _sim(top.sim)
    realism = _realism(top.realism)
    montecarlo = _montecarlo(top.montecarlo) if top.given("montecarlo") else None
    scenario = Scenario(
        top.name, train, line, brake, reference, disturbance, ato, controller, sim, realism
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
    """Parse a scenario file (TOML, or JSON if its name ends in ``.json``); a missing,
    unreadable or malformed file is a ScenarioError."""
    data: dict[str, Any] = read_document(path, "SCENARIO", "TOML file", ScenarioError)
    return data


def load_scenario(path: Path | str) -> Scenario | EddyScenario:
    """Read and validate a scenario file of either kind: ``kind = "ep-braking"`` (the
    default) gives a :class:`Scenario`, ``kind = "eddy-brake"`` an
    :class:`~railpilot.eddy.scenario.EddyScenario` (paper 003), its files named relative
    to the scenario's folder (as ``railpilot simulate`` reads it)."""
    data = read_toml(Path(path))
    if data.get("kind") == "eddy-brake":
        return EddyScenario.from_mapping(data, base_dir=Path(path).parent)
    return scenario_from_mapping(data)


def load_scenario_and_spec(path: Path | str) -> tuple[Scenario, MonteCarloSpec | None]:
    """Read and validate a scenario file and its ``[montecarlo]`` table, if any."""
    return scenario_and_spec_from_mapping(read_toml(Path(path)))
