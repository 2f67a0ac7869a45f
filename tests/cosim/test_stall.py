"""A line run that stands still is named, train by train (cosim/stall.py), and ends the
run with RunFailed; trains that wait for their timetable, a failure, or a train ahead that
is itself held are not named."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.cli import main
from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import load_line_scenario
from railpilot.cosim.stall import MOVED_M, StallWatch, TrainAt
from railpilot.errors import RunFailed
from railpilot.link.messages import TravelDirection

UP, DOWN = TravelDirection.UP, TravelDirection.DOWN
STALL_S = 600.0
EXAMPLES = Path(__file__).parents[2] / "examples"


def _watch_named(ticks: list[dict[int, TrainAt]]) -> list[set[int]]:
    """The trains named at each tick (one a second)."""
    watch = StallWatch(STALL_S)
    return [{s.train_id for s in watch.look(float(t), trains)} for t, trains in enumerate(ticks)]


@settings(max_examples=60, deadline=None)
@given(
    stand_s=st.integers(0, 1_500),
    due=st.booleans(),
    direction=st.sampled_from([UP, DOWN]),
    head_m=st.floats(0.0, 500_000.0),
)
def test_a_lone_train_is_named_once_it_has_stood_the_stall_time_when_due(
    stand_s: int, due: bool, direction: TravelDirection, head_m: float
) -> None:
    """It runs 100 s, then stands ``stand_s``: named from the tick that makes it stand
    ``STALL_S`` on, and only if it is due to move."""
    sign = 1.0 if direction is UP else -1.0
    ticks = [{7: TrainAt(head_m + sign * 10.0 * t, direction, True)} for t in range(100)]
    stop = head_m + sign * 990.0
    ticks += [{7: TrainAt(stop, direction, due)} for _ in range(stand_s)]
    named = _watch_named(ticks)
    stood_from = 99  # its last move
    for t, names in enumerate(named):
        expected = due and t >= 100 and t - stood_from >= STALL_S
        assert (7 in names) is expected, t


@settings(max_examples=60, deadline=None)
@given(
    front_due=st.booleans(),
    front_moves=st.booleans(),
    direction=st.sampled_from([UP, DOWN]),
)
def test_a_train_behind_is_held_exactly_when_the_train_ahead_is(
    front_due: bool, front_moves: bool, direction: TravelDirection
) -> None:
    """Two trains of one direction, the rear one standing behind the front one for
    longer than the stall time: the rear is named only if the front is (standing, due)."""
    sign = 1.0 if direction is UP else -1.0
    ticks = []
    for t in range(int(STALL_S) + 5):
        front_m = sign * (20_000.0 + (2.0 * MOVED_M * t if front_moves else 0.0))
        ticks.append(
            {
                1: TrainAt(sign * 10_000.0, direction, True),
                2: TrainAt(front_m, direction, front_due),
            }
        )
    last = _watch_named(ticks)[-1]
    front_named = front_due and not front_moves
    assert (2 in last) is front_named
    assert (1 in last) is front_named


def test_trains_of_the_other_direction_do_not_hold_a_train() -> None:
    """A train standing with only a failed train of the other track 'ahead' is named."""
    ticks = [
        {1: TrainAt(10_000.0, UP, True), 2: TrainAt(12_000.0, DOWN, False)}
        for _ in range(int(STALL_S) + 1)
    ]
    assert _watch_named(ticks)[-1] == {1}


def test_a_line_run_whose_trains_stand_on_one_another_ends_naming_them() -> None:
    """The short day's three loaded trains placed one, two minutes apart at the origin
    (a timetable the file check refuses, built here in code): each holds the others' block
    section, nothing moves, and the run ends naming all three and where they stand."""
    scenario = load_line_scenario(EXAMPLES / "line_short_day.toml")
    first = scenario.services[0].stops[0].departure_s

    def departing(service, at_s):  # type: ignore[no-untyped-def]
        by = at_s - service.stops[0].departure_s
        stops = tuple(
            dataclasses.replace(s, arrival_s=s.arrival_s + by, departure_s=s.departure_s + by)
            for s in service.stops
        )
        return dataclasses.replace(service, stops=stops)

    loaded = [s for s in scenario.services if s.kind == "heavy-haul-loaded"]
    stacked = tuple(departing(s, first + 60.0 * k) for k, s in enumerate(loaded))
    with pytest.raises(RunFailed) as failed:
        run_line(scenario.with_(services=stacked, events=()), stall_after_s=300.0)
    message = str(failed.value)
    for service in loaded:
        assert f"train {service.train_id} at km 2.320" in message
    assert "stands still" in message


def test_the_command_line_exits_1_and_writes_nothing_when_a_run_stands_still(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def stands_still(*args: object, **kwargs: object) -> None:
        raise RunFailed("the run stands still at 0:13:00: train 101 at km 2.320")

    monkeypatch.setattr("railpilot.cosim.line_run.run_line", stands_still)
    out = tmp_path / "out"
    code = main(
        [
            "line",
            "simulate",
            str(EXAMPLES / "line_short_day.toml"),
            "--no-baseline",
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err
    assert code == 1
    assert err.strip() == "railpilot: error: the run stands still at 0:13:00: train 101 at km 2.320"
    assert not out.exists() or not any(out.iterdir())
