"""``railpilot drive``: one object on stdout with the documented
keys; bad values exit 2 and write nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railpilot.cli import main

KEYS = {
    "running_time_s",
    "planned_running_time_s",
    "energy_traction_kwh",
    "energy_regenerated_kwh",
    "max_overspeed_kmh",
    "target_points_passed",
    "tsr_checks",
    "supervision_curves",
    "above_intervention_s",
}


def test_drive_prints_one_object_with_the_documented_keys(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    code = main(
        [
            "drive",
            "heavy-haul",
            "--from",
            "1",
            "--to",
            "2",
            "--tsr",
            "12:14:45",
            "--target",
            "20.5",
            "--out",
            str(tmp_path),
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= KEYS
    assert out["max_overspeed_kmh"] == 0.0
    assert out["target_points_passed"] == 0
    # the 75 km/h limit, the TSR and the target stop each have a supervision curve
    assert out["supervision_curves"] == 3
    # the train stops before the red signal, at the target stop a safety distance before it
    assert out["to_km"] < 20.5
    (check,) = out["tsr_checks"]
    assert check["regen_sufficient"] in (True, False)
    assert check["feasible"] is True
    # the planned curve meets the running time asked (fastest + 10 %) within 0.1 s
    assert abs(out["planned_running_time_s"] - out["requested_running_time_s"]) <= 0.1
    # speed, energy, and on the consist model (the default) the brake cycles
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "heavy-haul_1_2_cycles.png",
        "heavy-haul_1_2_energy.png",
        "heavy-haul_1_2_speed.png",
    ]
    assert sorted(out["figures"]) == sorted(str(p) for p in tmp_path.glob("*.png"))


@pytest.mark.parametrize(
    ("args", "field"),
    [
        (["--tsr", "14:12:45"], "--tsr"),
        (["--tsr", "12:14"], "--tsr"),
        (["--running-time", "-5"], "--running-time"),
        (["--to", "999"], "--to"),
        (["--margin", "-1"], "--margin"),
        (["--tsr", "12:14:45@-3"], "--tsr"),
        (["--tsr", "12:14:45@soon"], "--tsr"),
        (["--target", "20.5@300:100"], "--target"),
        (["--target", "20.5@x"], "--target"),
        (["--target", "far"], "--target"),
        # off the line (0-590 km): planned for and never met; -5 named TargetPoint.position_m
        (["--target", "-5"], "--target = '-5' is not allowed: expected km posts on line"),
        (["--target", "9999@1:2"], "--target = '9999@1:2'"),
        (["--tsr", "589:600:60"], "--tsr = '589:600:60' is not allowed: expected km posts"),
        (["--tsr", "9000:9001:60", "--timetable", "heavy-haul"], "--tsr = '9000:9001:60'"),
    ],
)
def test_bad_values_exit_2_naming_the_field_and_write_nothing(
    tmp_path, capsys, args, field
) -> None:  # type: ignore[no-untyped-def]
    base = ["drive", "heavy-haul", "--from", "1", "--to", "2", "--out", str(tmp_path), "--json"]
    # a later --to replaces the first
    code = main(base + args)
    assert code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert field in captured.err
    assert list(tmp_path.iterdir()) == []


def test_the_plan_keeps_the_margin_below_the_mrsp() -> None:
    from railpilot.line import load_line
    from railpilot.onboard.drive import drive, heavy_haul_loaded

    outcome = drive(load_line("heavy-haul"), heavy_haul_loaded(), 1, 2, margin_kmh=5.0)
    s = outcome.plan.s_m
    # the MRSP under the whole train, at the planner's grid (head positions)
    x = outcome.km_post(s)
    length = outcome.train_length_m
    ceiling = np.minimum(outcome.mrsp.at(x), outcome.mrsp.at(x - length))
    allowed = np.maximum(ceiling - 5.0 / 3.6, ceiling / 2.0)
    assert np.all(outcome.plan.speed_mps <= allowed + 1e-9)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("20.5", (20_500.0, 0.0, float("inf"))),
        ("20.5@600", (20_500.0, 600.0, float("inf"))),
        ("20.5@600:780", (20_500.0, 600.0, 780.0)),
    ],
)
def test_target_syntax(text, expected) -> None:  # type: ignore[no-untyped-def]
    from railpilot.commands.drive import parse_target

    assert parse_target(text) == expected


def test_tsr_syntax() -> None:
    from railpilot.commands.drive import parse_tsr

    start, end, limit, set_s = parse_tsr("12:14:45@500")
    assert (start, end, set_s) == (12_000.0, 14_000.0, 500.0)
    assert limit == pytest.approx(12.5)
    assert parse_tsr("12:14:45")[3] == 0.0
