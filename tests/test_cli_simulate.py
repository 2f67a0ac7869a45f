"""``railpilot simulate`` (railpilot.commands.simulate) end to end.

files written with ``--out`` are named after the scenario *and* the
controller, so runs of several controllers into one folder keep every file (the eddy
CSV used to be named after the scenario only); an eddy-brake run's metrics use every
step (they used to be computed on the series thinned to ``record_every``).
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.commands._common import file_stem
from railpilot.eddy.metrics import step_metrics
from railpilot.eddy.scenario import EddyScenario
from railpilot.eddy.simulate import simulate_eddy
from railpilot.reproduce.eddy_torque import run_case

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def simulate_json(capsys, *args: str) -> dict:
    assert main(["simulate", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture
def short_eddy_case2(tmp_path: Path) -> Path:
    """examples/eddy_case2.toml (recorded every 10th step) cut to 12 s.

    Its PID torque peaks at 7.58 s, between two recorded samples.
    """
    text = (EXAMPLES / "eddy_case2.toml").read_text()
    assert "duration_s" not in text and "record_every" not in text  # the defaults: 100 s, 10
    top = '\ncontroller = "pid"\n'
    assert top in text
    path = tmp_path / "case2.toml"
    path.write_text(text.replace(top, top + "duration_s = 12\nrecord_every = 10\n", 1))
    return path


def test_file_stem_joins_scenario_and_controller_safely():
    assert file_stem("paper000-smarc-ep", "pid") == "paper000-smarc-ep_pid"
    assert file_stem("eddy case 1: 3500 N m from 160 km/h", "fuzzy_pi") == (
        "eddy-case-1-3500-N-m-from-160-km-h_fuzzy_pi"
    )
    assert file_stem("../x/y", "pid") == "x-y_pid"  # no folder can be named
    assert file_stem("", "") == "run"


def test_eddy_controllers_into_one_folder_keep_their_own_csv(capsys, short_eddy_case2, tmp_path):
    out = tmp_path / "out"
    written = {}
    for controller in ("pid", "fuzzy"):
        payload = simulate_json(
            capsys, str(short_eddy_case2), "--controller", controller, "--out", str(out)
        )
        (path,) = payload["files"]
        written[controller] = Path(path)
    assert written["pid"] != written["fuzzy"]
    assert written["pid"].name == "eddy-case-2-4500-N-m-from-200-km-h_pid.csv"
    pid, fuzzy = (written[c].read_text() for c in ("pid", "fuzzy"))
    assert pid != fuzzy  # the second run did not overwrite the first
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in written.values())


@pytest.mark.slow
def test_braking_controllers_into_one_folder_keep_their_own_files(capsys, tmp_path):
    out = tmp_path / "out"
    scenario = str(EXAMPLES / "paper000_smarc_ep.toml")
    files = {
        c: simulate_json(capsys, scenario, "--controller", c, "--out", str(out))["files"]
        for c in ("pid", "smarc")
    }
    names = {c: [Path(f).name for f in fs] for c, fs in files.items()}
    assert names["pid"] == [
        "paper000-smarc-ep_pid.csv",
        "paper000-smarc-ep_pid.parquet",
        "paper000-smarc-ep_pid_speed_distance.png",
        "paper000-smarc-ep_pid_speed_error.png",
    ]
    assert sorted(p.name for p in out.iterdir()) == sorted(names["pid"] + names["smarc"])


def test_eddy_metrics_use_every_step_not_the_recorded_series(capsys, short_eddy_case2):
    payload = simulate_json(capsys, str(short_eddy_case2), "--controller", "pid")
    # the same run at full resolution, through the public pieces
    scenario = EddyScenario.from_mapping(tomllib.loads(short_eddy_case2.read_text()))
    assert scenario.record_every == 10
    table = scenario.build_table()
    full = simulate_eddy(
        scenario.make_controller("pid", table),
        table=table,
        torque_demand_nm=scenario.torque_demand_nm,
        initial_speed_mps=scenario.initial_speed_mps,
        coil=scenario.coil,
        train=scenario.train,
        duration_s=scenario.duration_s,
        dt_s=scenario.dt_s,
        record_every=1,
    )
    _, expected = scenario.run("pid", record_every=1)
    assert payload["metrics"] == expected.to_dict()
    direct = step_metrics(
        full.time_s, full.torque_nm, full.speed_kmh, scenario.torque_demand_nm
    ).to_dict()
    assert payload["metrics"]["peak_time_s"] == direct["peak_time_s"]
    assert payload["metrics"]["overshoot_nm"] == direct["overshoot_nm"]


def test_eddy_peak_time_agrees_with_the_reproduction(capsys, short_eddy_case2):
    payload = simulate_json(capsys, str(short_eddy_case2), "--controller", "pid")
    reproduced, _, _ = run_case(4500.0, 200.0, duration_s=12.0)
    assert payload["metrics"]["peak_time_s"] == pytest.approx(7.5782)
    for key in ("peak_time_s", "overshoot_nm", "steady_variance_nm2", "settling_time_s"):
        assert payload["metrics"][key] == reproduced["pid"][key]


def test_eddy_series_are_still_thinned_for_storage(short_eddy_case2):
    scenario = EddyScenario.from_mapping(tomllib.loads(short_eddy_case2.read_text()))
    thinned, m10 = scenario.run("fuzzy")
    full, m1 = scenario.run("fuzzy", record_every=1)
    assert len(thinned.time_s) == 12_001 and len(full.time_s) == 120_001
    assert thinned.metadata["record_every"] == 10
    assert m10 == m1


# --- train-dynamics scenarios (a consist driven by a script) ------------------------------

SHORT_DYNAMICS = """
name = "short"
kind = "train-dynamics"
consist = "{consist}"
[sim]
start_kmh = 40.0
duration_s = 60.0
[[driver.commands]]
at_s = 0.0
effort = 0.0
[[driver.commands]]
at_s = 2.0
reduction_kpa = 60.0
"""

BAD_WAGON = """
name = "bad"
[[train]]
type = "HXD1"
count = 1
[[train]]
type = "C80"
count = 10
load = "loaded"
mass_t = {mass}
"""


def test_a_train_dynamics_run_prints_its_coupler_forces_and_writes_its_figures(capsys, tmp_path):
    path = tmp_path / "short.toml"
    path.write_text(SHORT_DYNAMICS.format(consist="heavy-haul-10kt"))
    out = tmp_path / "out"
    payload = simulate_json(capsys, str(path), "--out", str(out))
    metrics = payload["metrics"]
    for key in (
        "max_coupler_tension_kn",
        "max_coupler_compression_kn",
        "coupler_force_limit_exceeded_s",
        "air_brake_applications",
        "air_brake_releases",
        "min_recharge_margin_s",
    ):
        assert key in metrics
    assert metrics["air_brake_applications"] == 1
    assert metrics["max_coupler_compression_kn"] > 0.0
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(Path(f).name for f in payload["files"])
    assert "short_coupler_forces.png" in names and "short_brake_pipe.png" in names


@pytest.mark.parametrize("mass", ["-5.0", "0", '"heavy"', "1e9"])
def test_a_bad_consist_file_exits_2_naming_the_vehicle_and_field_and_writes_nothing(
    capsys, tmp_path, mass
):
    consist = tmp_path / "bad_train.toml"
    consist.write_text(BAD_WAGON.format(mass=mass))
    path = tmp_path / "run.toml"
    path.write_text(SHORT_DYNAMICS.format(consist="bad_train.toml"))
    out = tmp_path / "out"
    assert main(["simulate", str(path), "--out", str(out), "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "train[1]" in captured.err and "C80" in captured.err and "mass_t" in captured.err
    assert "Traceback" not in captured.err
    assert not out.exists()
