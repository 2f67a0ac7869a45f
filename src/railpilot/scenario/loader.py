"""Read a scenario TOML file into a :class:`~railpilot.scenario.model.Scenario`.

Papers' units at the edge (t, km/h, kN, km posts), SI inside. Every key is checked:
unknown keys, wrong types and out-of-range values raise ScenarioError naming the
dotted key, the value and what is allowed; nothing runs on a bad file.

The file layout (examples/paper000_smarc_ep.toml is a complete one)::

    name = "..."
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
    [reference]  shape = "smooth" | "constant", start_km, v0_kmh, decel_mps2,
             jerk_mps3, final_decel_mps2, final_phase_speed_kmh,
             coast_s, ease_out
    [disturbance]  constant_kn, random_std_kn, random_hold_s, target_fraction, seed,
             regions = [{start_km, end_km, force_kn | accel_mps2}]
    [ato]    mass_t, davis = [a0, a1, a2], brake_delay_s, brake_lag_s,
             reference = "time" | "distance"
    [controller]  name = "pid" | "smarc" | "qsmc"; [controller.NAME] its parameters
    [sim]    dt_s, duration_s, control_period_s, record_every
    [realism]  speed_noise_std_mps, speed_resolution_mps, wheel_scale_error, slide_slip,
             balises_km = [...], adhesion, slide_ratio, notches, seed
    [montecarlo]  runs, seed, chunk; [montecarlo.vary] "KEY" = {dist, min, max, mean, std}
             (docs/montecarlo.md)
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.errors import ConfigError, ScenarioError
from railpilot.scenario.model import CONTROLLERS, ATOModel, ControllerSpec, Scenario, SimSettings
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.disturbance import Disturbance, Region
from railpilot.sim.realism import Realism
from railpilot.sim.reference import BrakingCurve, constant_deceleration, smooth_stop
from railpilot.units import km_post_to_m, kmh_to_mps, kn_to_n, tonne_to_kg
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
    ) -> float:
        """A finite number, optionally ``> gt`` or ``>= ge`` (checked in the file's units)."""
        self.used.add(name)
        if name not in self.data:
            if default is None:
                raise ScenarioError(self.key(name), None, "a number (the key is required)")
            return default
        value = self.data[name]
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or value != value
            or value in (float("inf"), float("-inf"))
        ):
            raise ScenarioError(self.key(name), value, "a finite number")
        if gt is not None and not value > gt:
            raise ScenarioError(self.key(name), value, f"a number > {gt:g}")
        if ge is not None and not value >= ge:
            raise ScenarioError(self.key(name), value, f"a number >= {ge:g}")
        return float(value)

    def optional_number(self, name: str) -> float | None:
        return self.number(name) if name in self.data else None

    def integer(self, name: str, default: int) -> int:
        self.used.add(name)
        value = self.data.get(name, default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(self.key(name), value, "an integer")
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
        return tuple(float(v) for v in value)

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
    "brake.fade_rate_n_per_s": ("brake.fade_rate_kn_per_s", lambda v: v / 1000.0),
    "train.davis_a0": ("train.davis[0]", lambda v: v),
    "train.davis_a1": ("train.davis[1]", lambda v: v),
    "train.davis_a2": ("train.davis[2]", lambda v: v),
    "brake.beta1": ("brake.beta[0]", lambda v: v),
    "brake.beta2": ("brake.beta[1]", lambda v: v),
    "brake.beta3": ("brake.beta[2]", lambda v: v),
    "reference.v0": ("reference.v0_kmh", lambda v: v * 3.6),
    "reference.decel": ("reference.decel_mps2", lambda v: v),
    "reference.jerk": ("reference.jerk_mps3", lambda v: v),
    "reference.final_decel": ("reference.final_decel_mps2", lambda v: v),
    "reference.final_phase_speed": ("reference.final_phase_speed_kmh", lambda v: v * 3.6),
    "disturbance.constant_n": ("disturbance.constant_kn", lambda v: v / 1000.0),
    "disturbance.random_std_n": ("disturbance.random_std_kn", lambda v: v / 1000.0),
}
#: fields whose value is a (start, end) pair in metres; the file writes km
_KM_SPANS = re.compile(r"^(line\.(gradients|curves|speed_limits)|disturbance\.regions)\[\d+\]$")


def _file_error(exc: ConfigError) -> ScenarioError:
    """The constructor's error in the file's words: key as written, value in its unit."""
    if exc.field in _FILE_KEYS:
        key, convert = _FILE_KEYS[exc.field]
        try:
            value = convert(exc.value)
        except TypeError:
            value = exc.value
        return ScenarioError(key, value, exc.allowed)
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
        if not exc.field.startswith(path.split(".")[0]):
            exc = ConfigError(f"{path}.{exc.field}", exc.value, exc.allowed)
        raise _file_error(exc) from exc


def _train(t: _Table) -> Train:
    davis = t.numbers("davis", 3) or (0.42, 0.0016, 0.000132)
    eb = t.table("electric_brake")
    curve = _build(
        "train.electric_brake",
        lambda: ElectricBrakeCurve(
            max_force_n=kn_to_n(eb.number("max_force_kn", 380.0)),
            max_power_w=eb.number("max_power_kw", 4800.0) * 1000.0,
        ),
    )
    eb.done()
    train = _build(
        "train",
        lambda: Train(
            mass_kg=tonne_to_kg(t.number("mass_t", 536.0, gt=0)),
            rotating_mass_factor=t.number("rotating_mass_factor", 0.06),
            length_m=t.number("length_m", 140.0, gt=0),
            davis_a0=davis[0],
            davis_a1=davis[1],
            davis_a2=davis[2],
            max_service_decel_mps2=t.number("max_service_decel_mps2", 1.0, gt=0),
            electric_brake=curve,
            motor_cars=t.integer("motor_cars", 4),
        ),
    )
    t.done()
    return train


def _segments(
    t: _Table, name: str, value_key: str, scale: Callable[[float], float]
) -> tuple[Segment, ...]:
    out = []
    for item in t.tables(name):
        seg = Segment(
            km_post_to_m(item.number("start_km")),
            km_post_to_m(item.number("end_km")),
            scale(item.number(value_key)),
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
        stations.append(
            Station(item.string("name", "station"), km_post_to_m(item.number("stop_km")))
        )
        item.done()
    line = _build("line", lambda: Line(gradients, curves, limits, tuple(stations)))
    t.done()
    return line


def _brake(t: _Table) -> EPBrake | LagDelayBrake:
    model = t.string("model", "ep-blended", ("ep-blended", "lag-delay"))
    if model == "lag-delay":
        ld = _build(
            "brake",
            lambda: LagDelayBrake(
                lag_s=t.number("lag_s", 0.5),
                delay_s=t.number("delay_s", 1.2),
                max_decel_mps2=t.number("max_decel_mps2", 1.0, gt=0),
            ),
        )
        t.done()
        return ld
    beta = t.numbers("beta", 3) or (0.138, 0.168, 0.221)
    brake = _build(
        "brake",
        lambda: EPBrake(
            delay_s=t.number("delay_s", 0.3),
            air_lag_s=t.number("air_lag_s", 0.65),
            electric_lag_s=t.number("electric_lag_s", 0.3),
            jerk_limit_mps3=t.number("jerk_limit_mps3", 0.75),
            changeover_kmh=t.number("changeover_kmh", 6.0),
            fade_rate_n_per_s=kn_to_n(t.number("fade_rate_kn_per_s", 300.0)),
            prenotice_s=t.number("prenotice_s", 0.65),
            cutout_cars=t.integer("cutout_cars", 0),
            cutout_time_s=t.number("cutout_time_s", 0.0),
            beta1=beta[0],
            beta2=beta[1],
            beta3=beta[2],
        ),
    )
    t.done()
    return brake


def _reference(t: _Table) -> BrakingCurve:
    shape = t.string("shape", "smooth", ("smooth", "constant"))
    start = km_post_to_m(t.number("start_km", 0.0))
    v0 = kmh_to_mps(t.number("v0_kmh", 72.0))
    if shape == "constant":
        curve = _build(
            "reference",
            lambda: constant_deceleration(
                v0, t.number("decel_mps2"), start, coast_s=t.number("coast_s", 0.0)
            ),
        )
    else:
        curve = _build(
            "reference",
            lambda: smooth_stop(
                v0,
                t.number("decel_mps2", 0.5),
                t.number("jerk_mps3", 0.5),
                t.number("final_decel_mps2", 0.3),
                kmh_to_mps(t.number("final_phase_speed_kmh", 7.2)),
                start,
                coast_s=t.number("coast_s", 0.0),
                ease_out=t.flag("ease_out", False),
            ),
        )
    t.done()
    return curve


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
        regions.append(
            Region(
                km_post_to_m(item.number("start_km")), km_post_to_m(item.number("end_km")), force
            )
        )
        item.done()
    dist = _build(
        "disturbance",
        lambda: Disturbance(
            constant_n=kn_to_n(t.number("constant_kn", 0.0)),
            regions=tuple(regions),
            random_std_n=kn_to_n(t.number("random_std_kn", 0.0)),
            random_hold_s=t.number("random_hold_s", 1.0),
            target_fraction=t.number("target_fraction", 0.0),
            seed=t.integer("seed", 0),
        ),
    )
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
    realism = _build(
        "realism",
        lambda: Realism(
            speed_noise_std_mps=t.number("speed_noise_std_mps", 0.0, ge=0),
            speed_resolution_mps=t.number("speed_resolution_mps", 0.0, ge=0),
            wheel_scale_error=t.number("wheel_scale_error", 0.0),
            slide_slip=t.number("slide_slip", 0.0),
            balises_m=tuple(km_post_to_m(float(b)) for b in balises),
            adhesion=t.number("adhesion", 0.0, ge=0),
            slide_ratio=t.number("slide_ratio", 0.8),
            notches=t.integer("notches", 0),
            seed=t.integer("seed", 0),
        ),
    )
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
    spec = _build(
        "montecarlo",
        lambda: MonteCarloSpec(
            runs=t.integer("runs", 1000),
            seed=t.integer("seed", 0),
            vary=tuple(vary),
            chunk=t.integer("chunk", 500),
        ),
    )
    t.done()
    return spec


def _ato(t: _Table) -> ATOModel:
    mass_t = t.optional_number("mass_t")
    ato = _build(
        "ato",
        lambda: ATOModel(
            mass_kg=tonne_to_kg(mass_t) if mass_t is not None else None,
            davis=t.numbers("davis", 3),  # type: ignore[arg-type]
            brake_delay_s=t.optional_number("brake_delay_s"),
            brake_lag_s=t.optional_number("brake_lag_s"),
            reference=t.string("reference", "time", ("time", "distance")),
        ),
    )
    t.done()
    return ato


def _controller(t: _Table) -> ControllerSpec:
    name = t.string("name", "smarc")
    if name not in CONTROLLERS and ":" not in name:
        raise ScenarioError(
            t.key("name"),
            name,
            f"one of {', '.join(CONTROLLERS)} or module:Name (your own controller)",
        )
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
    return ControllerSpec(name, params)


def _sim(t: _Table) -> SimSettings:
    dt = t.number("dt_s", 0.01)
    sim = _build(
        "sim",
        lambda: SimSettings(
            dt_s=dt,
            duration_s=t.number("duration_s", 70.0),
            control_period_s=t.number("control_period_s", dt),
            record_every=t.integer("record_every", 1),
        ),
    )
    t.done()
    return sim


def scenario_and_spec_from_mapping(
    data: Mapping[str, Any],
) -> tuple[Scenario, MonteCarloSpec | None]:
    """Build and validate a scenario and its optional ``[montecarlo]`` spec."""
    top = _Table(data, "")
    top.string("kind", "ep-braking", ("ep-braking",))
    name = top.string("name", "scenario")
    train = _train(top.table("train"))
    line = _line(top.table("line"))
    brake = _brake(top.table("brake"))
    reference = _reference(top.table("reference"))
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
    """Parse a TOML file; a missing or malformed file is a ScenarioError."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError as exc:
        raise ScenarioError("SCENARIO", str(path), "an existing TOML file") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError("SCENARIO", str(path), f"valid TOML ({exc})") from exc


def load_scenario(path: Path | str) -> Scenario:
    """Read and validate an ``ep-braking`` scenario file."""
    return scenario_from_mapping(read_toml(Path(path)))


def load_scenario_and_spec(path: Path | str) -> tuple[Scenario, MonteCarloSpec | None]:
    """Read and validate a scenario file and its ``[montecarlo]`` table, if any."""
    return scenario_and_spec_from_mapping(read_toml(Path(path)))
