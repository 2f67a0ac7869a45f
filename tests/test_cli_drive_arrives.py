"""A drive arrives or the tool says why not: a train arrives at a station on a steep
descent, from either side, at its stop and on time; a section the train cannot climb is
refused before anything runs, and a train that stops away from its station is an error
naming where and on what gradient (exit 1, nothing on stdout, a timetable's drive stopping
there)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.errors import ConfigError
from railpilot.line import load_line
from railpilot.onboard import drive as drive_module
from railpilot.onboard.drive import check_reachable, station_route, train_preset
from railpilot.onboard.planner import fastest
from railpilot.units import G_MPS2

#: 30 km, the middle station on a 12 per mille descent going up (a climb going down)
DESCENT_LINE = """
name = "descent"
description = "30 km, station 2 on a 12 per mille grade"
start_km = 0.0
end_km = 30.0
start_elevation_m = 500.0
categories = ["freight_loaded", "freight_empty"]
stations = [
  { id = 1, name = "A", km = 2.0, loop_length_m = 1700, stop_up_km = 2.82, stop_down_km = 1.18 },
  { id = 2, name = "B", km = 15.0, loop_length_m = 1700, stop_up_km = 15.82, stop_down_km = 14.18 },
  { id = 3, name = "C", km = 28.0, loop_length_m = 1700, stop_up_km = 28.82, stop_down_km = 27.18 },
]
gradients = [
  { start_km = 0.0, end_km = 8.0, permille = 0.0 },
  { start_km = 8.0, end_km = 22.0, permille = -12.0 },
  { start_km = 22.0, end_km = 30.0, permille = 0.0 },
]
speed_limits = [
  { category = "freight_loaded", start_km = 0.0, end_km = 30.0, limit_kmh = 60.0 },
  { category = "freight_empty", start_km = 0.0, end_km = 30.0, limit_kmh = 60.0 },
]
signals = [
  { id = "D1X", km = 1.150, direction = "down", kind = "exit" },
  { id = "U1X", km = 2.850, direction = "up", kind = "exit" },
  { id = "D2X", km = 14.150, direction = "down", kind = "exit" },
  { id = "U2X", km = 15.850, direction = "up", kind = "exit" },
  { id = "D3X", km = 27.150, direction = "down", kind = "exit" },
  { id = "U3X", km = 28.850, direction = "up", kind = "exit" },
]
"""


#: 30 km, the middle station (its loop km 14.15-15.85) on a 3 km stretch of 12 per mille:
#: arriving going up, the train brakes to its stop down the grade; going down it climbs to it
#: (a loaded train cannot start up it, but arrives with the way it has on)
STATION_ON_DESCENT = DESCENT_LINE.replace(
    """  { start_km = 0.0, end_km = 8.0, permille = 0.0 },
  { start_km = 8.0, end_km = 22.0, permille = -12.0 },
  { start_km = 22.0, end_km = 30.0, permille = 0.0 },""",
    """  { start_km = 0.0, end_km = 13.0, permille = 0.0 },
  { start_km = 13.0, end_km = 16.0, permille = -12.0 },
  { start_km = 16.0, end_km = 30.0, permille = 0.0 },""",
)


@pytest.mark.parametrize("limit_kmh", [60.0, 100.0])
@pytest.mark.parametrize("train", ["heavy-haul-loaded", "heavy-haul-empty"])
@pytest.mark.parametrize("from_id", [1, 3])
def test_a_station_on_a_steep_descent_is_reached_at_its_stop_and_on_time(
    tmp_path: Path, limit_kmh: float, train: str, from_id: int
) -> None:
    """The consist (every wagon, couplers, the freight air brake along the train: the
    drive's default) arrives at station 2 from either side within 2 m of its stop point
    and within 3 % of its plan's running time."""
    assert STATION_ON_DESCENT != DESCENT_LINE
    path = tmp_path / "station_on_descent.toml"
    path.write_text(STATION_ON_DESCENT.replace("limit_kmh = 60.0", f"limit_kmh = {limit_kmh}"))
    outcome = drive_module.drive(load_line(path), train_preset(train), from_id, 2, model="consist")
    summary = outcome.summary()
    assert abs(summary["stop_error_m"]) <= 2.0
    planned = summary["planned_running_time_s"]
    assert abs(summary["running_time_s"] - planned) <= 0.03 * planned
    assert summary["max_overspeed_kmh"] == 0.0


@pytest.fixture(scope="module")
def descent_line(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("descent") / "descent.toml"
    path.write_text(DESCENT_LINE)
    return path


@pytest.mark.parametrize(("train", "from_id", "to_id"), [("loaded", 3, 2), ("loaded", 2, 1)])
def test_a_climb_the_train_cannot_pull_is_refused_with_its_forces(
    descent_line: Path, train: str, from_id: int, to_id: int
) -> None:
    """The 10,700 t train on the 12 per mille climb: the grade alone takes 1,260 kN, its one
    HXD1 pulls 760 kN at most. Refused, with where it stalls and both forces; the empty
    train (2,300 t: 271 kN of grade) runs the same sections."""
    line = load_line(descent_line)
    preset = train_preset(f"heavy-haul-{train}")
    assert 12.0 * preset.train.mass_kg * G_MPS2 / 1e6 > (
        preset.brake.locomotive.traction.max_force_n / 1e3
    )
    route = station_route(line, preset, from_id, to_id, 5.0, (), (), 0.0)
    _, sec = route.section_from(route.mrsp_at(0.0), 0.0, 0.0)
    with pytest.raises(ConfigError) as refused:
        check_reachable(route, sec, fastest(preset.driving, sec), from_id, to_id)
    message = str(refused.value)
    assert f"section {from_id} -> {to_id}" in message and "stalls at km" in message
    assert "+12.0 per mille" in message and "at most 760 kN" in message

    empty = train_preset("heavy-haul-empty")
    route = station_route(line, empty, from_id, to_id, 5.0, (), (), 0.0)
    _, sec = route.section_from(route.mrsp_at(0.0), 0.0, 0.0)
    check_reachable(route, sec, fastest(empty.driving, sec), from_id, to_id)


def test_the_command_refuses_the_climb_with_exit_2_and_nothing_on_stdout(
    descent_line: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["drive", str(descent_line), "--train", "heavy-haul-loaded", "--from", "3"]
    assert main([*argv, "--to", "2", "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "stalls at km" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("error_m", "words"), [(120.8, "120.8 m past"), (-85.6, "85.6 m short of")]
)
def test_a_drive_that_stops_away_from_its_station_is_an_error(
    descent_line: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    error_m: float,
    words: str,
) -> None:
    """The drive ran (here the point mass, its outcome's stop moved ``error_m`` from the
    stop point): farther than a line run's 50 m from the stop, the command says where and
    on what gradient and exits 1, printing no result."""
    real_drive = drive_module.drive

    def stopping_away(*args: object, **kwargs: object):  # type: ignore[no-untyped-def]
        outcome = real_drive(*args, **kwargs)  # type: ignore[arg-type]
        metrics = dict(outcome.result.metrics, stop_error_m=error_m)
        result = dataclasses.replace(outcome.result, metrics=metrics)
        return dataclasses.replace(outcome, result=result)

    monkeypatch.setattr(drive_module, "drive", stopping_away)
    argv = ["drive", str(descent_line), "--train", "heavy-haul-empty", "--model", "point-mass"]
    assert main([*argv, "--from", "1", "--to", "2", "--json"]) == 1
    out, err = capsys.readouterr()
    assert out == ""
    assert f"stopped {words} station 2's stop point (km 15.820, on a descent of 12.0" in err


@pytest.mark.slow
def test_the_20000_t_train_with_distributed_power_comes_to_rest_and_arrives() -> None:
    """Its remote locomotive's residual drive leaves it creeping at round-off speed at a
    stand (sim/consist_run.py ``AT_REST_MPS``): the drive still ends at rest, at its stop."""
    outcome = drive_module.drive(
        load_line("heavy-haul"), train_preset("heavy-haul-20kt"), 1, 2, model="consist"
    )
    summary = outcome.summary()
    assert math.isfinite(summary["running_time_s"])
    assert abs(summary["stop_error_m"]) <= drive_module.ARRIVED_WITHIN_M
    assert summary["max_overspeed_kmh"] == 0.0
