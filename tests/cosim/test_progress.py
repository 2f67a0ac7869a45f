"""The progress of ``railpilot line simulate`` on a terminal (commands/line.py
``RunProgress``): the simulated clock and the trains running and arrived on one line of
stderr, rewritten at most once a second of wall clock (a clock the test moves by hand),
cleared at the end, nothing when stderr is no terminal or with --quiet; and a run watched
so gives the same numbers as one not watched."""

from __future__ import annotations

import io
import re
import sys
from types import SimpleNamespace

import pytest

from cosim.tiny_line_run import TINY
from railpilot.cli import main
from railpilot.commands import line as command
from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping

TINY_TOML = """
name = "tiny"
line = "heavy-haul"
duration_h = 0.5
[[services]]
kind = "loaded"
from = 1
to = 2
first_departure_min = 1.0
every_min = 20.0
count = 2
first_id = 101
"""


class Terminal(io.StringIO):
    """A stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class Clock:
    """A wall clock the test moves: each reading is ``step_s`` after the one before."""

    def __init__(self, step_s: float) -> None:
        self.now_s = 0.0
        self.step_s = step_s

    def __call__(self) -> float:
        self.now_s += self.step_s
        return self.now_s


def _sim(start_s: dict[int, float], arrived: set[int]) -> SimpleNamespace:
    """What the progress reads of a LinkSim: its trains' start times and those retiring."""
    trains = {i: SimpleNamespace(start_s=s) for i, s in start_s.items()}
    return SimpleNamespace(trains=trains, retiring=arrived)


def test_the_line_says_the_clock_and_the_trains_running_and_arrived() -> None:
    text = command.progress_text(
        "advised", 3725.0, 10800.0, _sim({1: 0.0, 2: 0.0, 3: 4000.0}, set()).trains, {1}
    )
    # train 1 arrived, train 2 running, train 3 not up yet
    assert text == "advised: 1:02:05 of 3:00:00 simulated, 1 running, 1 arrived of 3"


def test_the_line_is_rewritten_at_most_once_a_second_of_wall_clock() -> None:
    stream = Terminal()
    # the simulation calls once a simulated second; 0.25 s of wall clock pass between calls
    progress = command.RunProgress(stream, clock=Clock(0.25))
    watch = progress.watch("advised", 100.0)
    sim = _sim({101: 0.0}, set())
    for t in range(100):
        watch(sim, float(t))  # type: ignore[arg-type]
    written = stream.getvalue().split("\r")[1:]
    # the first call at once, then one every four calls (a second): t = 0, 4, ..., 96
    assert len(written) == 25
    assert [w.split(" of ")[0] for w in written] == [
        f"advised: 0:{t // 60:02d}:{t % 60:02d}" for t in range(0, 100, 4)
    ]
    assert all("\n" not in w for w in written)  # one line, rewritten in place


def test_clearing_leaves_the_terminal_as_it_was() -> None:
    stream = Terminal()
    progress = command.RunProgress(stream, clock=Clock(2.0))
    progress.planning(40)
    assert stream.getvalue() == "\rplanning 40 trains..."
    watch = progress.watch("minimum-time baseline", 60.0)
    watch(_sim({1: 0.0}, set()), 5.0)  # type: ignore[arg-type]
    shown = stream.getvalue().split("\r")[-1]
    progress.clear()
    # spaces over the whole line, the cursor back at its start
    assert stream.getvalue().endswith("\r" + " " * len(shown) + "\r")
    progress.clear()  # nothing on the line: nothing written
    assert stream.getvalue().endswith("\r" + " " * len(shown) + "\r")
    # a shorter line over a longer one leaves none of the longer behind
    progress.planning(1)
    progress.planning(2)
    assert stream.getvalue().endswith("\rplanning 2 trains...")


def _args(quiet: bool) -> SimpleNamespace:
    return SimpleNamespace(quiet=quiet)


def test_progress_only_on_a_terminal_and_without_quiet(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sys, "stderr", Terminal())
    assert command._progress(_args(False)) is not None  # type: ignore[arg-type]
    assert command._progress(_args(True)) is None  # type: ignore[arg-type]
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a file or a pipe
    assert command._progress(_args(False)) is None  # type: ignore[arg-type]


def test_the_trains_a_file_asks_for_are_counted_before_it_is_planned(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_TOML + '\n[[services]]\nkind = "empty"\nfrom = 2\nto = 1\n')
    assert command._trains_asked(path) == 3
    path.write_text('name = "x"\nservices = "none"\n')
    assert command._trains_asked(path) is None  # the loader says what is wrong


@pytest.mark.slow
def test_a_watched_run_gives_the_same_numbers() -> None:
    scenario = line_scenario_from_mapping(TINY)
    stream = Terminal()
    watched = run_line(
        scenario, on_watch=command.RunProgress(stream, clock=Clock(1.0)).watch("advised", 1800.0)
    )
    alone = run_line(scenario)
    a, b = watched.kpis(), alone.kpis()
    for kpis in (a, b):
        del kpis["wall_s"], kpis["realtime_factor"]
    assert a == b
    assert "1 arrived of 1" in stream.getvalue()  # it watched the run to its end


@pytest.mark.slow
def test_quiet_and_no_terminal_write_no_progress(
    tmp_path, capsys, monkeypatch: pytest.MonkeyPatch
) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_TOML)
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main(["line", "simulate", str(path), "--no-baseline", "--quiet"]) == 0
    assert terminal.getvalue() == ""
    assert "2 trains" in capsys.readouterr().out
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main(["line", "simulate", str(path), "--no-baseline"]) == 0
    shown = terminal.getvalue()
    assert shown.startswith("\rplanning 2 trains...")
    assert re.search(r"\radvised: 0:00:0\d of 0:30:00 simulated, \d running, 0 arrived of 2", shown)
    # cleared before the command's next line: nothing of it left on the terminal
    assert re.search(r"\r +\rtiny: 1800 s simulated", shown)
