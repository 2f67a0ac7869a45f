"""Bad input to a physical model's constructor never crashes: it gets a ConfigError (a
ValueError) naming the argument, short enough to read. Valid edge values stay valid.

The models of railpilot.brakes, railpilot.vehicle and railpilot.eddy, as
tests/control/test_constructor_inputs.py does for the controllers.
"""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from bad_values import BAD, every_bad_value
from railpilot.brakes.base import PackContext
from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.ep_blend import EPBrake
from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.brakes.lag_delay import LagDelay
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.control import base
from railpilot.eddy.coil import CoilParams
from railpilot.eddy.scenario import EddyScenario
from railpilot.eddy.table import TorqueTable
from railpilot.eddy.torque_model import EddyBrakeParams
from railpilot.eddy.train import TrainParams
from railpilot.errors import ConfigError
from railpilot.vehicle.consist import Consist, Vehicle
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.line import Line, Segment, StopPoint
from railpilot.vehicle.traction import (
    Locomotive,
    RegenEnvelope,
    TractionEnvelope,
)
from railpilot.vehicle.train import ElectricBrakeCurve, Train
from vehicle.consist_helpers import GEAR_FIELDS, WAGON_FIELDS, lead, wagon

#: every model class with constructor arguments to check, with the fewest that build it
BASE: dict[type, dict[str, object]] = {
    # brakes
    BrakePipeBrake: {},
    EPBrake: {},
    FreightAirBrake: {},
    LagDelay: {"lag_s": 0.5, "delay_s": 0.3, "dt": 0.01},
    LagDelayBrake: {},
    LocomotiveDrive: {},
    PackContext: {"dt_s": 0.01, "load_weighed_eff_mass_kg": 5e5, "train": Train()},
    # vehicle
    Segment: {"start_m": 0.0, "end_m": 100.0, "value": 1.0},
    StopPoint: {"name": "A", "stop_m": 100.0},
    Line: {},
    TractionEnvelope: {"max_force_n": 1e5, "max_power_w": 1e6},
    RegenEnvelope: {"max_force_n": 1e5, "max_power_w": 1e6},
    Locomotive: {
        "name": "L",
        "mass_kg": 1e5,
        "length_m": 20.0,
        "traction": TractionEnvelope(1e5, 1e6),
        "regen": RegenEnvelope(1e5, 1e6),
    },
    ElectricBrakeCurve: {},
    Train: {},
    DraftGear: GEAR_FIELDS,
    Vehicle: WAGON_FIELDS,
    Consist: {"name": "c", "vehicles": (lead(), wagon())},
    # eddy
    CoilParams: {},
    EddyBrakeParams: {},
    TrainParams: {},
    EddyScenario: {"torque_demand_nm": 3500, "initial_speed_kmh": 160},
    TorqueTable: {
        "currents_a": np.array([0.0, 1.0]),
        "speeds_mps": np.array([0.0, 1.0]),
        "torque_nm": np.zeros((2, 2)),
    },
}

#: public classes of the three packages not checked here, and why
NOT_CHECKED: dict[str, str] = {
    "BrakeModel": "a Protocol",
    "BrakeEntry": "the registry's own entries (a name, a class and a compiled step)",
    "GroupTiming": "an output (a NamedTuple of computed arrays)",
    "ResistanceTable": "an output (a NamedTuple of computed arrays)",
    "StepMetrics": "an output (a run's metrics, nan where undefined)",
    "EddyResult": "an output (a run's time series)",
    "EddyScenarioFile": "a file format's model (tests/eddy/test_scenario.py checks its errors)",
}


_NAMES = ("str", "empty-str")
_ENDS = ("start_m", "end_m", "value")

#: (class, argument, id) of bad-looking values an argument legitimately takes
ALLOWED: set[tuple[type, str, str]] = {
    # inf: an ideal valve, an ideal pipe, no limit on the reference's lead
    (BrakePipeBrake, "valve_flow_mps", "inf"),
    (BrakePipeBrake, "pipe_diffusivity_m2ps", "inf"),
    (CoilParams, "reference_lead_a", "inf"),
    (LocomotiveDrive, "regen_enabled", "True"),
    (LocomotiveDrive, "regen_enabled", "np-bool"),
    # the lag's output before the first step: any finite number
    (LagDelay, "initial", "-1e300"),
    # a segment takes any number; the line then names a non-finite or backwards one by
    # its place (line.gradients[3]), as tests/vehicle/test_line.py checks
    *((Segment, end, v) for end in _ENDS for v in ("nan", "inf", "-inf", "-1e300")),
    (StopPoint, "stop_m", "-1e300"),
    # names are any string
    *((cls, "name", v) for cls in (StopPoint, Locomotive, EddyScenario) for v in _NAMES),
    # a vehicle's, a consist's and a draft gear's name is any non-empty string
    *((cls, "name", "str") for cls in (Vehicle, Consist, DraftGear)),
    (TorqueTable, "source", "str"),
    (TorqueTable, "source", "empty-str"),
    (EddyScenario, "table_csv", "str"),
}

#: (class, argument, id) left out: valid for the argument, but the table then fails
#: on another argument's shape (tests/eddy/test_table.py checks that message)
SHAPED: set[tuple[type, str, str]] = {
    (TorqueTable, axis, v) for axis in ("currents_a", "speeds_mps") for v in ("pair", "long-list")
}


#: (class, argument) the class takes as given and the object holding it checks, naming
#: the item's place: a station's stop point (tests/line/test_queries.py compares a
#: StopPoint built with pytest.approx)
HELD: dict[tuple[type, str], Callable[[object], object]] = {
    (StopPoint, "stop_m"): lambda station: Line(stations=(StopPoint("A", 1.0), station)),
}


def _build(cls: type, name: str, value: object) -> object:
    made = cls(**(BASE[cls] | {name: value}))
    holder = HELD.get((cls, name))
    return made if holder is None else holder(made)


def _arguments(cls: type) -> list[str]:
    return [
        p.name
        for p in inspect.signature(cls).parameters.values()
        if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]


def _default(cls: type, name: str) -> object:
    return inspect.signature(cls).parameters[name].default


#: (class, argument, kind of bad value) the argument refuses: every pair but the allowed
#: and the shaped
CASES = [
    (cls, name, kind)
    for cls in BASE
    for name in _arguments(cls)
    for kind, value in BAD
    if (cls, name, kind) not in ALLOWED | SHAPED
    # None is what an optional argument defaults to (application_time_s, max_speed_mps)
    and not (value is None and _default(cls, name) is None)
]


@every_bad_value(CASES)
def test_bad_argument_gets_a_short_config_error_naming_it(case, value):
    cls, name, _ = case
    with pytest.raises(ValueError) as info:
        _build(cls, name, value)
    message = str(info.value)
    assert isinstance(info.value, ConfigError), message
    assert name in message
    assert len(message) < 400, message


@pytest.mark.parametrize(
    ("cls", "name", "value_id"), sorted(ALLOWED, key=lambda c: (c[0].__name__, c[1], c[2]))
)
def test_allowed_special_values_stay_allowed(cls, name, value_id):
    _build(cls, name, dict(BAD)[value_id])


def _public_classes() -> list[type]:
    found = []
    for package in ("railpilot.brakes", "railpilot.vehicle", "railpilot.eddy"):
        root = importlib.import_module(package)
        for info in pkgutil.iter_modules(root.__path__):
            module = importlib.import_module(f"{package}.{info.name}")
            for name, obj in vars(module).items():
                if (
                    inspect.isclass(obj)
                    and obj.__module__ == module.__name__
                    and not name.startswith("_")
                    and not issubclass(obj, BaseException)
                ):
                    found.append(obj)
    return found


def test_every_public_model_class_is_checked_or_said_why_not():
    names = {cls.__name__ for cls in _public_classes()}
    assert names == {cls.__name__ for cls in BASE} | set(NOT_CHECKED)


# --- valid edge values --------------------------------------------------------------------

S = 1.5  # a time, a speed or a size
EDGES: list[tuple[type, dict[str, object]]] = [
    # NumPy scalars for masses, times and counts
    (Train, {"mass_kg": np.float64(5e5), "length_m": np.int64(200), "motor_cars": np.int64(2)}),
    (Train, {"mass_kg": np.int64(500_000), "rotating_mass_factor": np.float32(0.05)}),
    (Train, {"rotating_mass_factor": 0, "davis_a0": 0, "davis_a1": 0.0, "davis_a2": 0}),
    (Train, {"length_m": 10_000.0, "motor_cars": 1}),
    (ElectricBrakeCurve, {"max_force_n": 0, "max_power_w": np.float64(0.0)}),
    (TrainParams, {"axle_mass_kg": np.int64(16_000), "wheel_diameter_m": np.float64(0.9)}),
    (TrainParams, {"resistance_a": 0, "resistance_b": 0, "resistance_c": 0}),
    (LagDelayBrake, {"lag_s": np.int64(1), "delay_s": np.float64(1.2)}),
    (LagDelayBrake, {"lag_s": 0, "delay_s": 0.0, "max_decel_mps2": np.int64(1)}),
    (LagDelayBrake, {"lag_s": 60, "delay_s": 60.0}),
    (EPBrake, {"delay_s": np.float64(0.3), "air_lag_s": np.int64(1), "cutout_cars": np.int64(1)}),
    (EPBrake, {"delay_s": 0, "air_lag_s": 0, "electric_lag_s": 0, "prenotice_s": 0}),
    (EPBrake, {"delay_s": 60, "air_lag_s": 60.0, "electric_lag_s": 60, "prenotice_s": 60}),
    (EPBrake, {"changeover_kmh": 0, "cutout_time_s": 0, "beta1": 0, "beta2": 0}),
    (BrakePipeBrake, {"application_time_s": np.int64(20), "release_time_s": np.float64(50)}),
    (BrakePipeBrake, {"application_time_s": None, "release_time_s": None, "position": "P"}),
    (BrakePipeBrake, {"application_time_s": 120, "release_time_s": 120.0}),
    (BrakePipeBrake, {"valve_flow_mps": math.inf, "pipe_diffusivity_m2ps": np.inf}),
    (BrakePipeBrake, {"n_segments": np.int64(2), "reaction_s": np.float64(0.0)}),
    (BrakePipeBrake, {"n_segments": 200, "reaction_s": 60, "application_wave_mps": 400}),
    (LocomotiveDrive, {"traction_lag_s": np.int64(2), "handover_kmh": np.float64(30)}),
    (LocomotiveDrive, {"traction_lag_s": 0, "handover_kmh": 200, "regen_enabled": False}),
    (LocomotiveDrive, {"traction_lag_s": 60.0, "handover_kmh": 0, "regen_enabled": np.bool_(0)}),
    (LagDelay, {"lag_s": np.int64(1), "delay_s": np.float64(0.3), "dt": np.float64(0.01)}),
    (LagDelay, {"lag_s": 0, "delay_s": 0, "dt": 1, "initial": np.float64(-2.0)}),
    (LagDelay, {"lag_s": 0.5, "delay_s": 0.3, "dt": 0.01, "method": "pade", "pade_order": 3}),
    (LagDelay, {"lag_s": 0.5, "delay_s": 0.3, "dt": 0.01, "pade_order": np.int64(2)}),
    (PackContext, {"dt_s": np.float64(0.01), "load_weighed_eff_mass_kg": np.int64(500_000)}),
    (TractionEnvelope, {"max_force_n": np.int64(1), "max_power_w": 1, "max_speed_mps": None}),
    (TractionEnvelope, {"max_force_n": 1e5, "max_power_w": 1e6, "max_speed_mps": np.float64(S)}),
    (RegenEnvelope, {"max_force_n": 0, "max_power_w": 0, "fade_below_mps": 0}),
    (Locomotive, {"mass_kg": np.int64(200_000), "traction_efficiency": 1, "regen_efficiency": 1.0}),
    (Segment, {"start_m": np.float64(-5.0), "end_m": np.int64(5), "value": np.float32(-3.0)}),
    (Segment, {"start_m": -1e300, "end_m": 1e300, "value": math.nan}),
    (StopPoint, {"stop_m": np.float64(-3.5)}),
    (StopPoint, {"name": "", "stop_m": 0}),
    (Line, {"gradients": [Segment(0, 1, 2)], "curves": (Segment(0, 1, 300.0),)}),
    (Line, {"speed_limits": (Segment(0.0, 1.0, 20.0),), "stations": (StopPoint("A", 1.0),)}),
    (Line, {"stations": [StopPoint("A", 1.0), StopPoint("B", 2.0)]}),
    (CoilParams, {"reference_lead_a": math.inf, "freewheel_voltage_v": 0}),
    (CoilParams, {"resistance_ohm": np.float64(0.6), "inductance_h": np.int64(1)}),
    (EddyBrakeParams, {"turns": np.int64(12), "pole_pairs": 4, "air_gap_m": np.float32(0.004)}),
    (EddyScenario, {"torque_demand_nm": np.int64(3500), "duration_s": np.float64(2.0)}),
    (EddyScenario, {"dt_s": np.float64(1e-3), "record_every": np.int64(5), "table_csv": None}),
    (EddyScenario, {"table_csv": Path("fe.csv"), "controller": "pid", "name": ""}),
    (TorqueTable, {"currents_a": [0, 1, 2], "torque_nm": [[0, 0], [1, 1], [2, 2]]}),
    (TorqueTable, {"speeds_mps": (0.0, 1.0), "torque_nm": np.ones((2, 2), dtype=np.int64)}),
]


@pytest.mark.parametrize(
    ("cls", "kwargs"), EDGES, ids=[f"{c.__name__}-{'-'.join(k)}" for c, k in EDGES]
)
def test_valid_edge_values_stay_valid(cls, kwargs):
    cls(**(BASE[cls] | kwargs))


def test_a_segment_out_of_range_is_named_by_its_place_in_the_line():
    for value in (math.nan, math.inf):
        with pytest.raises(ConfigError) as info:
            Line(gradients=(Segment(0.0, 1.0, 0.0), Segment(0.0, 1.0, value)))
        assert info.value.field == "line.gradients[1]"
    with pytest.raises(ConfigError) as info:
        Line(curves=(Segment(0.0, math.inf, 300.0),))
    assert info.value.field == "line.curves[0]"
    with pytest.raises(ConfigError) as info:
        Line(speed_limits=[Segment(0.0, 1.0, 1.0), "fast"])  # type: ignore[list-item]
    assert info.value.field == "line.speed_limits[1]"


def test_a_station_s_stop_point_is_named_by_its_place_in_the_line():
    StopPoint("S", pytest.approx(2650.0))  # as tests/line/test_queries.py compares one
    with pytest.raises(ConfigError) as info:
        Line(stations=[StopPoint("A", 0.0), StopPoint("B", "x")])  # type: ignore[arg-type]
    assert info.value.field == "line.stations[1].stop_m"


def test_fields_are_named_as_before():
    # the scenario loader turns these names into the file's keys (scenario/loader.py)
    cases = [
        (lambda: Train(mass_kg="x"), "train.mass_kg"),
        (lambda: Train(motor_cars=True), "train.motor_cars"),
        (lambda: Train(length_m=10**400), "train.length_m"),
        (lambda: ElectricBrakeCurve(max_power_w=None), "train.electric_brake.max_power_w"),
        (lambda: EPBrake(delay_s="x"), "brake.delay_s"),
        (lambda: EPBrake(cutout_cars=10**400), "brake.cutout_cars"),
        (lambda: LagDelayBrake(lag_s=(1, 2)), "brake.lag_s"),
        (lambda: BrakePipeBrake(valve_flow_mps=10**400), "brake.valve_flow_mps"),
        (lambda: BrakePipeBrake(position=["G"]), "brake.position"),
        (lambda: LocomotiveDrive(handover_kmh="x"), "brake.handover_kmh"),
        (lambda: CoilParams(resistance_ohm=10**400), "coil.resistance_ohm"),
        (lambda: EddyBrakeParams(turns=None), "brake.turns"),
        (lambda: TrainParams(axle_mass_kg=(1, 2)), "train.axle_mass_kg"),
        (lambda: TractionEnvelope("x", 1.0), "locomotive.traction.max_force_n"),
        (lambda: LagDelay(0.5, 0.3, "x"), "dt"),
        (lambda: LagDelay(0.5, 0.3, 0.01, method="pade", pade_order=10**400), "pade_order"),
        (lambda: PackContext(dt_s=0.0, load_weighed_eff_mass_kg=1.0, train=Train()), "sim.dt_s"),
    ]
    for make, field in cases:
        with pytest.raises(ConfigError) as info:
            make()
        assert info.value.field == field


def test_wording_of_the_messages_is_kept():
    with pytest.raises(ConfigError, match=r"^brake\.lag_s = 'x' is not allowed: expected a "):
        LagDelayBrake(lag_s="x")
    with pytest.raises(ConfigError) as info:
        LagDelayBrake(delay_s=61.0)
    assert info.value.allowed == "a number in [0, 60] s"
    with pytest.raises(ConfigError) as info:
        EPBrake(air_lag_s=-1.0)
    assert info.value.allowed == "a finite number >= 0"
    with pytest.raises(ConfigError) as info:
        EPBrake(air_lag_s=61.0)
    assert info.value.allowed == "a number in [0, 60] s"
    with pytest.raises(ConfigError) as info:
        Train(length_m=10_001.0)
    assert info.value.allowed == "a length in (0, 10000] m"
    with pytest.raises(ConfigError, match=r"^train\.mass_kg = 1\.000e\+400 is not allowed"):
        Train(mass_kg=10**400)


# --- the shared checks (railpilot.checks, re-exported by railpilot.control.base) --------


def _checks():  # imported here, so the cases above run without the module too
    return importlib.import_module("railpilot.checks")


def test_control_base_exports_the_shared_checks():
    checks = _checks()
    assert base.check_number is checks.check_number
    assert base.check_count is checks.check_count
    assert base.check_flag is checks.check_flag
    assert base.check_pair is checks.check_pair
    assert base._as_float is checks.as_float


def test_check_number_bounds_wording_and_error_class():
    checks = _checks()
    assert checks.check_number("t", 60, minimum=0.0, maximum=60.0) == 60.0
    assert checks.check_number("t", math.inf, positive=True, allow_inf=True) == math.inf
    with pytest.raises(
        ValueError, match=r"^t = 61 is not allowed: expected a finite number >= 0 and <= 60$"
    ):
        checks.check_number("t", 61, minimum=0.0, maximum=60.0)
    with pytest.raises(ConfigError) as info:
        checks.check_number("a.t", "x", positive=True, allowed="a time > 0", error=ConfigError)
    assert (info.value.field, info.value.value, info.value.allowed) == ("a.t", "x", "a time > 0")
    with pytest.raises(ValueError) as plain:
        checks.check_number("t", None)
    assert type(plain.value) is ValueError


def test_check_count_without_an_upper_bound():
    checks = _checks()
    assert checks.check_count("n", np.int64(7), 0) == 7
    assert checks.check_count("n", 2**60, 1) == 2**60
    for bad in (-1, 10**400, 1.0, True, None, "1"):
        with pytest.raises(ValueError, match=r"^n = .* expected a whole number >= 0$"):
            checks.check_count("n", bad, 0)
    with pytest.raises(ConfigError, match=r"^n = True is not allowed: expected an integer$"):
        checks.check_count("n", True, 0, allowed="an integer", error=ConfigError)


def test_check_flag_wording():
    checks = _checks()
    assert checks.check_flag("f", np.bool_(False)) is False
    with pytest.raises(ConfigError, match=r"^f = 1 is not allowed: expected true or false$"):
        checks.check_flag("f", 1, allowed="true or false", error=ConfigError)
