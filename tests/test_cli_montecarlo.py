"""``railpilot montecarlo`` (railpilot.commands.montecarlo) end to end.

Paper 000's sweep (examples/paper000_montecarlo.toml: mass +/-10 %, brake delay
0.2-0.5 s, running resistance +/-20 %) cut to 50 runs. Exit codes as railpilot.cli
documents them: 0 success, 2 bad input with nothing run or written.
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from railpilot.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "paper000_montecarlo.toml"
ARGS = ["montecarlo", str(EXAMPLE), "--runs", "50", "--json", "--controller", "pid"]
STATS_KEYS = {
    "runs",
    "not_stopped",
    "mean_stop_error_m",
    "std_stop_error_m",
    "p50_abs_stop_error_m",
    "p95_abs_stop_error_m",
    "p99_abs_stop_error_m",
    "max_abs_stop_error_m",
    "share_within_0_30_m",
    "max_jerk_mps3",
    "worst_run",
    "worst_run_seed",
}


def run_cli(capsys, *extra):
    code = main([*ARGS, "--no-progress", *extra])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_json_is_exactly_one_object_on_stdout():
    proc = subprocess.run(
        [sys.executable, "-m", "railpilot.cli", *ARGS, "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    payload = json.loads(proc.stdout)  # one object, nothing else on stdout
    assert isinstance(payload, dict)
    assert "pid: 50 runs" in proc.stderr  # the log goes to stderr
    pid = payload["results"]["pid"]
    assert set(pid) >= STATS_KEYS
    assert pid["runs"] == 50
    assert pid["not_stopped"] + round(pid["share_within_0_30_m"] * 50) <= 50
    assert 0.0 <= pid["share_within_0_30_m"] <= 1.0
    assert isinstance(pid["worst_run_seed"], int)
    assert pid["p99_abs_stop_error_m"] <= pid["max_abs_stop_error_m"]


def test_payload_names_the_sweep(capsys):
    code, out, _ = run_cli(capsys)
    payload = json.loads(out)
    assert code == 0
    assert payload["scenario"] == "paper000-montecarlo"
    assert (payload["runs"], payload["seed"]) == (50, 2026)  # --runs over the file's 1000
    assert [v["key"] for v in payload["vary"]] == [
        "train.mass_t",
        "brake.delay_s",
        "train.davis_scale",
    ]
    assert payload["files"] == []


def test_same_command_gives_the_same_numbers(capsys):
    first = json.loads(run_cli(capsys)[1])["results"]["pid"]
    second = json.loads(run_cli(capsys)[1])["results"]["pid"]
    first.pop("wall_s"), second.pop("wall_s")
    assert first == second


def test_seed_option_changes_the_numbers(capsys):
    default = json.loads(run_cli(capsys)[1])
    other = json.loads(run_cli(capsys, "--seed", "7")[1])
    assert other["seed"] == 7
    assert other["results"]["pid"]["worst_run_seed"] != default["results"]["pid"]["worst_run_seed"]
    assert (
        other["results"]["pid"]["mean_stop_error_m"]
        != default["results"]["pid"]["mean_stop_error_m"]
    )


def test_several_controllers_each_get_their_statistics(capsys):
    code, out, _ = run_cli(capsys, "--controller", "smarc")
    assert code == 0
    results = json.loads(out)["results"]
    assert set(results) == {"pid", "smarc"}
    assert results["pid"]["mean_stop_error_m"] != results["smarc"]["mean_stop_error_m"]


def test_out_writes_the_stop_error_histogram(capsys, tmp_path):
    out_dir = tmp_path / "mc"
    code, out, _ = run_cli(capsys, "--out", str(out_dir))
    assert code == 0
    (png,) = out_dir.iterdir()
    assert png.name == "paper000-montecarlo_stop_errors.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads(out)["files"] == [str(png)]


def test_text_output_without_json(capsys):
    code = main(
        ["montecarlo", str(EXAMPLE), "--runs", "20", "--controller", "pid", "--no-progress"]
    )
    out, _ = capsys.readouterr()
    assert code == 0
    assert out.startswith("paper000-montecarlo  controller=pid  runs=20  seed=2026")
    assert "share_within_0_30_m" in out


BAD_FILE = """\
name = "bad"
[montecarlo]
runs = 10
[montecarlo.vary]
"train.mass_t" = { dist = "uniform", min = 600.0, max = 500.0 }
"""


def test_bad_file_exits_2_naming_the_key_and_writes_nothing(capsys, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(BAD_FILE)
    out_dir = tmp_path / "out"
    code = main(["montecarlo", str(path), "--json", "--no-progress", "--out", str(out_dir)])
    out, err = capsys.readouterr()
    assert code == 2
    assert "montecarlo.vary.train.mass_t.min" in err
    assert "(600.0, 500.0)" in err
    assert out == ""
    assert not out_dir.exists()


def test_key_that_does_not_apply_exits_2(capsys, tmp_path):
    path = tmp_path / "lag_on_ep.toml"
    path.write_text('name = "t"\n[montecarlo.vary]\n"brake.lag_s" = { min = 0.4, max = 0.6 }\n')
    code = main(["montecarlo", str(path), "--json", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 2
    assert "montecarlo.vary.brake.lag_s" in err
    assert out == ""


@pytest.mark.parametrize(("option", "value"), [("--runs", "0"), ("--runs", "-3"), ("--seed", "-5")])
def test_bad_run_count_or_seed_exits_2_naming_the_option_once(capsys, option, value):
    code = main(["montecarlo", str(EXAMPLE), option, value, "--json", "--no-progress"])
    out, err = capsys.readouterr()
    assert code == 2
    # the option as given, in one sentence (it was "--runs/--seed = (0, None) is not
    # allowed: expected montecarlo.runs = 0 is not allowed: expected ...")
    assert f"{option} = {value} is not allowed: expected an integer" in err
    assert err.count("is not allowed") == 1
    assert out == ""


def test_a_scheduler_address_dask_cannot_read_exits_2_and_writes_nothing(capsys, tmp_path):
    out_dir = tmp_path / "out"
    code = main([*ARGS, "--no-progress", "--scheduler", "no-port", "--out", str(out_dir)])
    out, err = capsys.readouterr()
    assert code == 2
    assert "--scheduler = 'no-port'" in err and "port" in err.split("expected", 1)[1]
    assert out == ""
    assert not out_dir.exists()


@pytest.mark.parametrize("second", ["nomod:Foo", "fuzzy"])
def test_a_bad_controller_in_second_place_is_refused_before_the_first_sweep(capsys, second) -> None:  # type: ignore[no-untyped-def]
    args = ["montecarlo", str(EXAMPLE), "--runs", "2", "--no-progress"]
    code = main([*args, "--controller", "smarc", "--controller", second])
    out, err = capsys.readouterr()
    assert code == 2 and f"'{second}' is not allowed" in err
    assert out == "" and "runs in" not in err  # smarc's sweep did not run
