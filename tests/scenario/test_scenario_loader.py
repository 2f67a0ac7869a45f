"""Scenario files (railpilot.scenario.loader): bad input is named, good input loads.

Each bad case must raise ScenarioError whose message names the dotted key, the
offending value and what is allowed, before anything runs.
"""

import pytest

from railpilot.errors import ScenarioError
from railpilot.scenario.loader import load_scenario, scenario_from_mapping
from railpilot.scenario.model import Scenario
from railpilot.units import kmh_to_mps

MINIMAL = """\
name = "minimal"

[train]
mass_t = 300.0
davis = [0.5, 0.002, 0.0001]

[reference]
shape = "constant"
start_km = 1.2
v0_kmh = 54.0
decel_mps2 = 0.6

[controller]
name = "pid"

[sim]
dt_s = 0.01
duration_s = 40.0
"""


def test_minimal_file_loads_with_units_converted(tmp_path):
    path = tmp_path / "minimal.toml"
    path.write_text(MINIMAL)
    scenario = load_scenario(path)
    assert scenario.name == "minimal"
    assert scenario.train.mass_kg == 300e3
    assert scenario.train.davis_a1 == 0.002
    assert scenario.reference.start_m == 1200.0
    assert scenario.reference.v0_mps == pytest.approx(kmh_to_mps(54.0))
    # 15 m/s at 0.6 m/s^2 -> 187.5 m past km 1.2
    assert scenario.reference.stop_m == pytest.approx(1387.5)
    assert scenario.controller.name == "pid"
    assert scenario.sim.n_steps == 4000


def test_a_file_naming_only_what_is_required_gives_exactly_the_dataclass_defaults(tmp_path):
    # defaults live in the typed config dataclasses only: the loader passes on
    # what the file says and nothing else
    path = tmp_path / "minimal.toml"
    path.write_text('name = "minimal"\n')
    assert load_scenario(path) == Scenario(name="minimal")
    # and they are paper 000's world: braking at the 20 km point after a 2 s coast at
    # 72 km/h (the curve starts 40 m before it)
    scenario = Scenario(name="minimal")
    assert scenario.reference.start_m == 20_000.0 - 2.0 * 20.0
    assert scenario.train.mass_kg == 536e3
    assert scenario.brake.delay_s == 0.3
    assert scenario.controller.name == "smarc"
    assert scenario.sim.control_period_s == scenario.sim.dt_s


def test_an_empty_scenario_file_is_an_error_naming_what_is_missing(tmp_path):
    path = tmp_path / "empty.toml"
    path.write_text("")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.field == "name"
    assert "the one key every scenario file must give" in str(info.value)


@pytest.mark.parametrize(
    ("table", "given"),
    [
        ("train", {"mass_t": 500.0}),
        ("brake", {"air_lag_s": 0.7}),
        ("reference", {"coast_s": 1.0}),
        ("sim", {"dt_s": 0.02}),
        ("realism", {"adhesion": 0.2}),
        ("disturbance", {"constant_kn": 1.0}),
    ],
)
def test_a_table_naming_one_key_keeps_every_other_default(table, given):
    scenario = scenario_from_mapping({"name": "t", table: given})
    default = Scenario(name="t")
    for other in ("train", "brake", "reference", "sim", "realism", "disturbance", "line"):
        if other != table:
            assert getattr(scenario, other) == getattr(default, other), other


def test_units_at_the_edge_become_si():
    scenario = scenario_from_mapping(
        {
            "name": "t",
            "train": {"electric_brake": {"max_force_kn": 300.0, "max_power_kw": 4000.0}},
            "brake": {"fade_rate_kn_per_s": 200.0},
            "disturbance": {
                "constant_kn": -5.0,
                "regions": [{"start_km": 1.0, "end_km": 1.5, "force_kn": 10.0}],
            },
            "line": {"gradients": [{"start_km": 0.5, "end_km": 0.8, "permille": 3.0}]},
        }
    )
    assert scenario.train.electric_brake.max_force_n == 300e3
    assert scenario.train.electric_brake.max_power_w == 4e6
    assert scenario.brake.fade_rate_n_per_s == 200e3
    assert scenario.disturbance.constant_n == -5e3
    assert scenario.disturbance.regions[0].start_m == 1000.0
    assert scenario.disturbance.regions[0].force_n == 10e3
    assert scenario.line.gradients[0].end_m == 800.0


def test_controller_parameter_lists_become_tuples():
    scenario = scenario_from_mapping(
        {
            "name": "t",
            "controller": {
                "smarc": {"gamma": [0.1, 0.2], "theta_bounds": [[0.8, 1.3], [-0.2, 0.2]]}
            },
        }
    )
    params = scenario.controller.params["smarc"]
    assert params["gamma"] == (0.1, 0.2)
    assert params["theta_bounds"] == ((0.8, 1.3), (-0.2, 0.2))


#: a key the file leaves out: its message says it is missing, no value shown
MISSING_KEY = "<missing>"

BAD = [
    # (case, mapping, dotted key, value as printed, fragment of what is allowed)
    ("unknown key", {"train": {"mas_t": 500}}, "train.mas_t", "500", "known key"),
    ("unknown table", {"brakes": {}}, "brakes", "{}", "known key"),
    ("wrong type", {"train": {"mass_t": "heavy"}}, "train.mass_t", "'heavy'", "finite number"),
    (
        "bool is not a number",
        {"brake": {"delay_s": True}},
        "brake.delay_s",
        "True",
        "finite number",
    ),
    ("negative mass", {"train": {"mass_t": -5}}, "train.mass_t", "-5", "> 0"),
    ("not an integer", {"train": {"motor_cars": 4.5}}, "train.motor_cars", "4.5", "integer"),
    (
        "wrong list length",
        {"train": {"davis": [1, 2]}},
        "train.davis",
        "[1, 2]",
        "list of 3 numbers",
    ),
    (
        "negative rotating mass",
        {"train": {"rotating_mass_factor": -0.1}},
        "train.rotating_mass_factor",
        "-0.1",
        ">= 0",
    ),
    (
        "control period not a multiple of dt",
        {"sim": {"control_period_s": 0.015}},
        "sim.control_period_s",
        "0.015",
        "whole multiple",
    ),
    ("step too long", {"sim": {"dt_s": 0.5}}, "sim.dt_s", "0.5", "(0, 0.1]"),
    (
        "delay not a multiple of dt",
        {"brake": {"delay_s": 0.305}},
        "brake.delay_s",
        "0.305",
        "whole number of simulation steps",
    ),
    (
        "more cut-out cars than motor cars",
        {"brake": {"cutout_cars": 5}},
        "brake.cutout_cars",
        "5",
        "at most",
    ),
    ("unknown controller", {"controller": {"name": "lqr"}}, "controller.name", "'lqr'", "one of"),
    (
        "unknown controller parameter",
        {"controller": {"pid": {"kq": 1.0}}},
        "controller.pid.kq",
        "1.0",
        "kp",
    ),
    (
        "bad controller parameter value",
        {"controller": {"smarc": {"phi": -1.0}}},
        "controller.smarc.phi",
        "-1.0",
        "a finite number >= 0",
    ),
    (
        "unknown reference shape",
        {"reference": {"shape": "parabolic"}},
        "reference.shape",
        "'parabolic'",
        "one of",
    ),
    (
        "constant reference without deceleration",
        {"reference": {"shape": "constant"}},
        "reference.decel_mps2",
        MISSING_KEY,
        "required",
    ),
    (
        "backwards segment",
        {"line": {"gradients": [{"start_km": 2, "end_km": 1, "permille": 3}]}},
        "line.gradients[0]",
        "",
        "start_km < end_km",
    ),
    (
        "segment missing a key",
        {"line": {"gradients": [{"start_km": 2, "end_km": 3}]}},
        "line.gradients[0].permille",
        MISSING_KEY,
        "required",
    ),
    ("table expected", {"train": 3}, "train", "3", "a table"),
    ("unsupported kind", {"kind": "maglev"}, "kind", "'maglev'", "ep-braking"),
]


@pytest.mark.parametrize(
    ("mapping", "key", "value", "allowed"), [pytest.param(*case[1:], id=case[0]) for case in BAD]
)
def test_bad_input_raises_scenario_error_naming_key_value_and_allowed(mapping, key, value, allowed):
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({"name": "t", **mapping})
    message = str(info.value)
    assert info.value.field == key
    assert message.startswith(f"{key} is missing" if value is MISSING_KEY else f"{key} = {value}")
    assert allowed in message


BAD_IN_FILE_UNITS = [
    pytest.param(
        {"train": {"electric_brake": {"max_force_kn": -1.0}}},
        "train.electric_brake.max_force_kn",
        -1.0,
        id="electric brake force in kN",
    ),
    pytest.param(
        {"brake": {"fade_rate_kn_per_s": -5.0}},
        "brake.fade_rate_kn_per_s",
        -5.0,
        id="fade rate in kN/s",
    ),
    pytest.param({"ato": {"mass_t": -1.0}}, "ato.mass_t", -1.0, id="ATO mass in t"),
    pytest.param(
        {"reference": {"final_decel_mps2": 0.9}},
        "reference.final_decel_mps2",
        0.9,
        id="reference key name",
    ),
]


@pytest.mark.parametrize(("mapping", "key", "value"), BAD_IN_FILE_UNITS)
def test_error_names_the_key_and_value_as_written_in_the_file(mapping, key, value):
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({"name": "t", **mapping})
    assert info.value.field == key
    assert info.value.value == value


def test_negative_seed_is_rejected_at_load():
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({"name": "t", "disturbance": {"random_std_kn": 10.0, "seed": -1}})
    assert info.value.field == "disturbance.seed"


def test_missing_file_is_a_scenario_error(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(ScenarioError, match="existing TOML file") as info:
        load_scenario(missing)
    assert str(missing) in str(info.value)


def test_malformed_toml_is_a_scenario_error(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[train\nmass_t = 5\n")
    with pytest.raises(ScenarioError, match="valid TOML") as info:
        load_scenario(path)
    assert str(path) in str(info.value)


def test_a_brake_models_file_keys_are_its_config_fields():
    # no per-model reader in the loader: a registered model's dataclass fields are its keys
    # (adding a brake touches its module and the registry only)
    from railpilot.brakes.brake_pipe import BrakePipeBrake
    from railpilot.brakes.locomotive_drive import LocomotiveDrive

    pipe = scenario_from_mapping(
        {"name": "t", "brake": {"model": "brake-pipe", "position": "P", "n_segments": 12}}
    ).brake
    assert pipe == BrakePipeBrake(position="P", n_segments=12)
    drive = scenario_from_mapping(
        {
            "name": "t",
            "brake": {
                "model": "locomotive-drive",
                "traction_lag_s": 2.0,
                "air": {"max_decel_mps2": 0.4},
            },
        }
    ).brake
    assert drive == LocomotiveDrive(traction_lag_s=2.0, air=BrakePipeBrake(max_decel_mps2=0.4))
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping(
            {"name": "t", "brake": {"model": "locomotive-drive", "air": {"n_segmnts": 3}}}
        )
    assert info.value.field == "brake.air.n_segmnts"
