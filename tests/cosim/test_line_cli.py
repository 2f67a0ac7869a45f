"""``railpilot line simulate``: the JSON object, and bad input refused before anything runs."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re

import pytest

from railpilot.cli import main
from railpilot.cosim.kpis import dig as _dig
from railpilot.cosim.kpis import swept

SWEPT = swept()

TINY = """
name = "tiny"
line = "heavy-haul"
duration_h = 0.5
[channel]
loss = 0.1
[[services]]
kind = "loaded"
from = 1
to = 2
first_departure_min = 1.0
first_id = 101
"""


@pytest.mark.slow
def test_simulate_prints_the_kpis(tmp_path, capsys):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    assert main(["line", "simulate", str(path), "--json", "--out", str(tmp_path)]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in (
        "trains",
        "conformity_pct",
        "energy_kwh",
        "baseline_energy_kwh",
        "energy_traction_against_air_kwh",
        "red_signal_stops",
        "tsr_violations",
        "target_points_passed",
        "overspeeds",
        "link",
    ):
        assert key in out, key
    assert out["trains"]["101"]["finished"]
    assert out["link"]["ground"]["frames_received"] > 0
    assert (tmp_path / "time_distance.png").stat().st_size > 10_000
    # the run's files: what was printed, and the tables behind it
    assert json.loads((tmp_path / "kpis.json").read_text()) == out
    assert out["files"] == [
        str(tmp_path / name)
        for name in ("time_distance.png", "trace.csv", "sections.csv", "events.json", "kpis.json")
    ]
    with (tmp_path / "sections.csv").open(newline="") as f:
        sections = list(csv.DictReader(f))
    assert [r["driver"] for r in sections] == ["advised", "baseline"]  # one section each
    advised = sections[0]
    assert float(advised["conformity_pct"]) == pytest.approx(
        out["trains"]["101"]["conformity_pct"]["sections"][0], abs=5e-4
    )
    net = float(advised["energy_traction_kwh"]) - float(advised["energy_regenerated_kwh"])
    assert net == pytest.approx(out["trains"]["101"]["energy_kwh"], abs=0.05)
    with (tmp_path / "trace.csv").open(newline="") as f:
        trace = list(csv.DictReader(f))
    assert {r["driver"] for r in trace} == {"advised", "baseline"}
    events = json.loads((tmp_path / "events.json").read_text())
    assert events["run"]["driver"] == "advised"
    assert events["baseline"]["driver"] == "baseline"
    # without a baseline: the run's rows and events alone
    alone = tmp_path / "alone"
    assert main(["line", "simulate", str(path), "--no-baseline", "--out", str(alone)]) == 0
    assert json.loads((alone / "events.json").read_text())["driver"] == "advised"
    with (alone / "sections.csv").open(newline="") as f:
        assert [r["driver"] for r in csv.DictReader(f)] == ["advised"]


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--runs", "0"], "--runs"),
        (["--seed", "-3"], "--seed"),
        (["--seed", str(2**63)], "--seed"),
        (["--runs", "2", "--seed", str(2**63 - 1)], "--seed"),  # its second seed is too big
        (["--scheduler", "tcp://127.0.0.1:8786"], "--scheduler"),  # one run, no cluster
        (["--runs", "2", "--scheduler", "no-port"], "--scheduler"),
        (["--runs", "2", "--scheduler", "xyz://127.0.0.1:8786"], "--scheduler"),
    ],
)
def test_bad_arguments_are_refused(tmp_path, capsys, args, field):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    assert main(["line", "simulate", str(path), *args]) == 2
    assert field in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--speedup", "0"], "--speedup"),
        (["--speedup", "nan"], "--speedup"),
        (["--until-min", "-5"], "--until-min"),
        (["--http-port", "70000"], "--http-port"),
        (["--screenshot-at-min", "5"], "--screenshot-at-min"),  # without --screenshot
        (["--screenshot", "x.png", "--screenshot-at-min", "999"], "--screenshot-at-min"),
        (["--seed", "-1"], "--seed"),
        (["--seed", str(2**63)], "--seed"),
    ],
)
def test_line_run_refuses_bad_arguments_before_starting_anything(
    tmp_path, capsys, monkeypatch, args, field
):
    import railpilot.cosim.live as live

    def refuse(*args, **kwargs):
        raise AssertionError("the live run started although its input is bad")

    monkeypatch.setattr(live, "run_live", refuse)
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    assert main(["line", "run", str(path), *args]) == 2
    captured = capsys.readouterr()
    assert field in captured.err and captured.out == ""
    assert not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_line_run_writes_the_runs_files_as_simulate_does(tmp_path, capsys, monkeypatch):
    # the live run itself is tests/cosim/test_live.py's; here, what the command does with
    # the LineResult it returns (a co-simulated one stands in for it)
    import railpilot.cosim.live as live
    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_line_scenario

    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    result = run_line(load_line_scenario(path))
    monkeypatch.setattr(live, "run_live", lambda *args, **kwargs: result)
    folder = tmp_path / "live"
    assert main(["line", "run", str(path), "--json", "--out", str(folder)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert json.loads((folder / "kpis.json").read_text()) == out
    assert [p.rsplit("/", 1)[1] for p in out["files"]] == [
        "time_distance.png",
        "trace.csv",
        "sections.csv",
        "events.json",
        "kpis.json",
    ]
    with (folder / "sections.csv").open(newline="") as f:
        assert [r["driver"] for r in csv.DictReader(f)] == ["advised"]


@pytest.mark.parametrize("seed", [-1, 2**63, True, 1.0])
def test_live_options_refuse_a_seed_out_of_range(tmp_path, seed):
    from railpilot.cosim.live import LiveOptions
    from railpilot.cosim.scenario import load_line_scenario
    from railpilot.errors import ConfigError

    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    with pytest.raises(ConfigError, match=r"^seed = .* a seed in \[0, 9223372036854775807\]"):
        LiveOptions(seed=seed).check(load_line_scenario(path))


@pytest.mark.parametrize("name", ["a_dir", "latin1.toml"])
def test_a_path_that_is_no_readable_line_run_file_is_refused(tmp_path, capsys, name):
    (tmp_path / "a_dir").mkdir()
    (tmp_path / "latin1.toml").write_bytes(TINY.replace("tiny", "Kl\xf6ster").encode("latin-1"))
    assert main(["line", "simulate", str(tmp_path / name), "--json"]) == 2
    captured = capsys.readouterr()
    assert f"SCENARIO = '{tmp_path / name}' is not allowed" in captured.err
    assert captured.out == ""


def test_a_bad_file_is_refused_naming_the_field(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(TINY.replace('kind = "loaded"', 'kind = "tram"'))
    assert main(["line", "simulate", str(path), "--json"]) == 2
    captured = capsys.readouterr()
    assert "services[0].kind" in captured.err and captured.out == ""


# --- sweeps -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_runs(tmp_path_factory):
    """The tiny day's KPIs run one seed at a time, seeds 5, 6 and 7: what a sweep summarises."""
    path = tmp_path_factory.mktemp("sweep") / "tiny.toml"
    path.write_text(TINY)
    runs = {}
    for seed in (5, 6, 7):
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            args = ["line", "simulate", str(path), "--seed", str(seed), "--no-baseline", "--json"]
            assert main(args) == 0
        runs[seed] = json.loads(buffer.getvalue())
    return path, runs


def _check_sweep(out, runs):
    assert out["runs"] == 3 and out["seeds"] == [5, 7]
    connects = sorted(r["link"]["connects"] for r in runs.values())
    # the lossy radio gives the seeds their own days, else the spread below proves nothing
    assert connects[0] != connects[-1]
    for key, values in (
        ("link.connects", connects),
        ("energy_kwh", sorted(r["energy_kwh"] for r in runs.values())),
        (
            "energy_traction_against_air_kwh",
            sorted(r["energy_traction_against_air_kwh"] for r in runs.values()),
        ),
    ):
        spread = out["kpis"][key]
        assert (spread["min"], spread["median"], spread["max"]) == tuple(values), key
        by_seed = {seed: _dig(run, key) for seed, run in runs.items()}
        assert by_seed[spread["min_seed"]] == spread["min"], key
        assert by_seed[spread["max_seed"]] == spread["max"], key
    assert out["runs_with_tsr_violations"] == sum(1 for r in runs.values() if r["tsr_violations"])
    assert out["runs_with_overspeeds"] == sum(1 for r in runs.values() if r["overspeeds"])


@pytest.mark.slow
def test_a_sweep_summarises_the_runs_it_would_give_one_by_one(tiny_runs, capsys):
    path, runs = tiny_runs
    assert main(["line", "simulate", str(path), "--runs", "3", "--seed", "5", "--json"]) == 0
    captured = capsys.readouterr()
    _check_sweep(json.loads(captured.out), runs)
    # one progress line a finished run, on stderr
    progress = [line for line in captured.err.splitlines() if line.startswith("seed ")]
    assert sorted(line.split(":")[0] for line in progress) == ["seed 5", "seed 6", "seed 7"]
    assert re.fullmatch(r"seed \d: \d+ TSR violations, .* \(3/3, \d+ s\)", progress[-1])


@pytest.mark.slow
def test_a_sweep_with_out_writes_each_seeds_kpis_and_what_it_printed(tiny_runs, tmp_path, capsys):
    path, runs = tiny_runs
    folder = tmp_path / "sweep"  # not there yet: made
    args = ["line", "simulate", str(path), "--runs", "2", "--seed", "5", "--json"]
    assert main([*args, "--out", str(folder)]) == 0
    out = json.loads(capsys.readouterr().out)
    table, summary = folder / "runs.csv", folder / "sweep.json"
    assert out["files"] == [str(table), str(summary)]
    assert json.loads(summary.read_text(encoding="utf-8")) == out
    with table.open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [row["seed"] for row in rows] == ["5", "6"]
    assert list(rows[0]) == ["seed", *SWEPT]
    for row in rows:
        single = runs[int(row["seed"])]  # the seed run alone: line simulate --seed S
        for key in SWEPT:
            if key == "realtime_factor":  # the wall clock's, not the seed's
                assert float(row[key]) > 0
                continue
            expected = _dig(single, key)
            if expected is None:  # a KPI the run has none of
                assert row[key] == "", key
            else:
                assert json.loads(row[key]) == expected, key
    # the seeds differ (the lossy radio), so a row copied from another seed would show
    assert rows[0]["link.connects"] != rows[1]["link.connects"]


@pytest.mark.slow
def test_a_sweep_on_a_dask_cluster_gives_the_same_summary(tiny_runs, capsys):
    distributed = pytest.importorskip("dask.distributed")
    path, runs = tiny_runs
    # worker processes: each run really is read and run in another interpreter
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        args = ["line", "simulate", str(path), "--runs", "3", "--seed", "5", "--json"]
        assert main([*args, "--scheduler", cluster.scheduler_address]) == 0
    _check_sweep(json.loads(capsys.readouterr().out), runs)


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["1"], "event"),  # the tiny file has no events
        (["0", "--seed", "-1"], "--seed"),
    ],
)
def test_knock_on_refuses_bad_arguments_before_running(tmp_path, capsys, args, field):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    assert main(["line", "knock-on", str(path), *args]) == 2
    err = capsys.readouterr().err
    assert f"{field} = " in err and "Traceback" not in err


@pytest.mark.slow
def test_knock_on_prints_each_trains_difference(tmp_path, capsys):
    path = tmp_path / "tiny.toml"
    path.write_text(
        TINY + '[[events]]\nat_min = 5.0\nop = "train_failure"\ntrain = 101\nstand_min = 2.0\n'
    )
    assert main(["line", "knock-on", str(path), "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["own_train"] == 101 and list(out["trains"]) == ["101"]
    row = out["trains"]["101"]["arrival_delay_s"]
    assert row["knock_on"] == pytest.approx(row["with"] - row["without"], abs=0.15)
    # most of its 2 minutes' stand (the running-time supplement recovers some of it)
    assert row["knock_on"] >= 0.75 * 120.0
    assert out["knock_on_others_s"] == 0.0  # no other train
