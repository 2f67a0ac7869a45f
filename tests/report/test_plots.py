"""Figures take their labels from the results and scenario, not from paper 000's values."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import matplotlib.pyplot as plt
import pytest
from matplotlib.figure import Figure

from railpilot.brakes.ep_blend import EPBrake
from railpilot.cli import main
from railpilot.report import ep_plots
from railpilot.report.figure import save_figure
from railpilot.scenario.model import Scenario, SimSettings
from railpilot.sim.run import simulate
from railpilot.units import kmh_to_mps

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def runs_8kmh():
    """Paper 000's clean run with the changeover at 8 km/h instead of 6."""
    scenario = dataclasses.replace(
        Scenario(name="changeover-8"),
        brake=EPBrake(changeover_kmh=8.0),
        sim=SimSettings(duration_s=50.0),
    )
    return {"pid": simulate(scenario, "pid")}, kmh_to_mps(scenario.changeover_kmh)


def _titles(fig: Figure) -> list[str]:
    titles = [ax.get_title() for ax in fig.axes]
    plt.close(fig)
    return titles


def test_speed_distance_title_names_the_scenario_changeover(runs_8kmh):
    runs, changeover = runs_8kmh
    fig = ep_plots.speed_distance(runs, changeover)
    assert isinstance(fig, Figure)
    assert "Last 25 m (dotted: 8 km/h changeover)" in _titles(fig)


def test_speed_error_title_names_the_scenario_changeover(runs_8kmh):
    runs, changeover = runs_8kmh
    titles = _titles(ep_plots.speed_error(runs, changeover))
    assert titles == ["Speed tracking error (dotted: train reaches the 8 km/h changeover)"]


def test_fractional_changeover_is_printed_as_given(runs_8kmh):
    runs, _ = runs_8kmh
    assert "dotted: 7.5 km/h changeover" in " ".join(
        _titles(ep_plots.speed_distance(runs, kmh_to_mps(7.5)))
    )


def test_save_figure_writes_a_png_and_returns_its_path(runs_8kmh, tmp_path):
    runs, changeover = runs_8kmh
    path = save_figure(ep_plots.speed_error(runs, changeover), tmp_path / "e.png")
    assert path == tmp_path / "e.png"
    assert path.read_bytes().startswith(b"\x89PNG")
    assert not plt.get_fignums()  # closed once written


def test_simulate_command_titles_come_from_the_scenario_file(tmp_path, monkeypatch, capsys):
    # the example scenario with its changeover moved to 8 km/h
    text = (EXAMPLES / "paper000_smarc_ep.toml").read_text()
    assert "\nchangeover_kmh = 6.0 " in text
    scenario = tmp_path / "co8.toml"
    scenario.write_text(text.replace("\nchangeover_kmh = 6.0 ", "\nchangeover_kmh = 8.0 ", 1))
    titles: list[str] = []

    def capture(fig: Figure, path: Path) -> Path:
        titles.extend(ax.get_title() for ax in fig.axes)
        plt.close(fig)
        return path

    monkeypatch.setattr("railpilot.report.figure.save_figure", capture)
    assert main(["simulate", str(scenario), "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    assert any("8 km/h changeover" in t for t in titles)
    assert not any("6 km/h" in t for t in titles)
