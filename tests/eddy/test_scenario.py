"""Scenario validation errors and the example files."""

import tomllib
from pathlib import Path

import pytest

from railpilot.eddy.scenario import EddyScenario
from railpilot.errors import MISSING, ScenarioError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BASE = {"kind": "eddy-brake", "torque_demand_nm": 3500, "initial_speed_kmh": 160}


@pytest.mark.parametrize("name", ["eddy_case1.toml", "eddy_case2.toml"])
def test_examples_load(name):
    s = EddyScenario.from_mapping(tomllib.loads((EXAMPLES / name).read_text()))
    assert s.torque_demand_nm in (3500.0, 4500.0)


@pytest.mark.parametrize(
    ("patch", "field"),
    [
        ({"speed": 1}, "speed"),
        ({"kind": "ep-brake"}, "kind"),
        ({"controller": "lqr"}, "controller"),
        ({"torque_demand_nm": -1}, "torque_demand_nm"),
        ({"torque_demand_nm": "big"}, "torque_demand_nm"),
        ({"initial_speed_kmh": 0}, "initial_speed_kmh"),
        ({"dt_s": 0.5}, "dt_s"),
        ({"record_every": 1.5}, "record_every"),
        ({"pid": {"kp": 1, "kq": 2}}, "pid.kq"),
        ({"coil": {"inductance_h": 0}}, "coil.inductance_h"),
        ({"coil": {"current_limit_a": 1000}}, "coil.current_limit_a"),
        ({"brake": {"air_gap": 0.004}}, "brake.air_gap"),
        ({"train": {"axle_mass_kg": True}}, "train.axle_mass_kg"),
        ({"table": {"csv": "x.csv", "max_current_a": 10}}, "table"),
        ({"fuzzy": {"e_scale": 0}}, "fuzzy"),
    ],
)
def test_bad_input_names_the_key(patch, field):
    data = {**BASE, **patch}
    with pytest.raises(ScenarioError) as info:
        EddyScenario.from_mapping(data)
    assert info.value.field == field
    assert "expected" in str(info.value)


def test_missing_required_key():
    with pytest.raises(ScenarioError, match="initial_speed_kmh"):
        EddyScenario.from_mapping({"torque_demand_nm": 3500})


def test_user_csv_table(tmp_path):
    from railpilot.eddy.table import TorqueTable

    (tmp_path / "fe.csv").write_text(
        TorqueTable.from_model(current_step_a=10, speed_step_kmh=5).to_csv_text()
    )
    s = EddyScenario.from_mapping(
        {**BASE, "table": {"csv": "fe.csv"}, "duration_s": 2}, base_dir=tmp_path
    )
    result, metrics = s.run("pid")
    assert result.metadata["table_source"] == "fe.csv"
    assert metrics.rise_time_s > 0


def test_a_scenario_file_s_table_is_read_beside_it(tmp_path, monkeypatch):
    """load_scenario reads ``table.csv`` from the scenario's folder, as simulate does,
    whatever the working directory."""
    from railpilot.eddy.table import TorqueTable
    from railpilot.scenario.loader import load_scenario

    folder = tmp_path / "case"
    folder.mkdir()
    (folder / "fe.csv").write_text(
        TorqueTable.from_model(current_step_a=10, speed_step_kmh=5).to_csv_text()
    )
    (folder / "eddy.toml").write_text(
        'kind = "eddy-brake"\ntorque_demand_nm = 3500\ninitial_speed_kmh = 100\n'
        '[table]\ncsv = "fe.csv"\n'
    )
    monkeypatch.chdir(tmp_path)
    scenario = load_scenario(folder / "eddy.toml")
    assert isinstance(scenario, EddyScenario)
    assert scenario.table_csv == folder / "fe.csv"


@pytest.mark.parametrize("dt_s", [1e-12, 5e-324])
def test_simulate_eddy_refuses_more_steps_than_it_may_take(dt_s):
    # the scenario refuses such a step at load (tests/scenario/test_value_bounds.py); the
    # simulator itself does too, before it allocates a row per step
    from railpilot.control.open_loop import OpenLoop
    from railpilot.eddy.simulate import MAX_STEPS, simulate_eddy
    from railpilot.eddy.table import TorqueTable
    from railpilot.errors import ConfigError

    table = TorqueTable.from_model(max_current_a=50.0, current_step_a=25.0, speed_step_kmh=100.0)
    with pytest.raises(ConfigError) as info:
        simulate_eddy(
            OpenLoop(1.0), table=table, torque_demand_nm=1.0, initial_speed_mps=10.0, dt_s=dt_s
        )
    assert info.value.field == "dt_s"
    assert f"{MAX_STEPS:,}" in info.value.allowed


@pytest.mark.parametrize(
    ("patch", "field", "value", "allowed"),
    [
        ({"torque_demand_nm": -1}, "torque_demand_nm", -1.0, "a torque in (0, 100000] N m"),
        ({"torque_demand_nm": "big"}, "torque_demand_nm", "big", "a number"),
        ({"duration_s": float("nan")}, "duration_s", None, "a finite number"),
        ({"record_every": 1.5}, "record_every", 1.5, "an integer"),
        ({"record_every": 0}, "record_every", 0, "an integer >= 1"),
        ({"fuzzy": {"n_grid": True}}, "fuzzy.n_grid", True, "an integer"),
        ({"pid": 3}, "pid", 3, "a table of keys"),
        ({"controller": "lqr"}, "controller", "lqr", "one of open_loop, pid, fuzzy, fuzzy_pi"),
        ({"kind": "ep-braking"}, "kind", "ep-braking", "'eddy-brake'"),
        ({"table": {"csv": ""}}, "table.csv", "", "a path string"),
        ({"table": {"csv": "x.csv", "rows": 3}}, "table.rows", 3, None),
    ],
)
def test_bad_input_says_the_value_and_what_is_allowed(patch, field, value, allowed):
    with pytest.raises(ScenarioError) as info:
        EddyScenario.from_mapping({**BASE, **patch})
    assert info.value.field == field
    if value is not None:
        assert info.value.value == value and type(info.value.value) is type(value)
    if allowed is not None:
        assert info.value.allowed == allowed


def test_a_whole_number_written_as_a_float_is_taken():
    scenario = EddyScenario.from_mapping({**BASE, "record_every": 5.0, "fuzzy": {"n_grid": 41.0}})
    assert scenario.record_every == 5 and type(scenario.record_every) is int
    assert scenario.fuzzy["n_grid"] == 41.0


def test_a_missing_required_key_says_it_is_required():
    with pytest.raises(ScenarioError) as info:
        EddyScenario.from_mapping({"torque_demand_nm": 3500})
    assert (info.value.field, info.value.value) == ("initial_speed_kmh", MISSING)
    assert info.value.allowed == "a number (this key is required)"
    assert str(info.value).startswith("initial_speed_kmh is missing: expected")
