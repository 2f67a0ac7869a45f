"""The figure of one section on the consist model (report/drive_plots.py
``section_figure``): three panels over the km post, every brake event of the run marked, and
what the drive's result carries for it (onboard/consist_drive.py ``ConsistDrive.result``)."""

from __future__ import annotations

import dataclasses

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.lines import Line2D

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.line import load_line
from railpilot.onboard.drive import DriveOutcome, drive, heavy_haul_loaded
from railpilot.onboard.timetable import load_timetable
from railpilot.report.drive_plots import BRAKE_EVENT_MARKS, section_figure
from railpilot.sim.result import SimResult


@pytest.fixture(scope="module")
def outcome() -> DriveOutcome:
    """The loaded train's first descent (1 -> 2) in its timetabled time, on the consist."""
    (section,) = load_timetable("heavy-haul").between(1, 2)
    return drive(
        load_line("heavy-haul"),
        heavy_haul_loaded(),
        1,
        2,
        running_time_s=section.running_time_s,
        model="consist",
    )


def _marks(fig, kind: str) -> int:  # type: ignore[no-untyped-def]
    """How many points the figure marks as brake events of ``kind``."""
    lines = [
        line
        for ax in fig.axes
        for line in ax.get_lines()
        if isinstance(line, Line2D) and line.get_gid() == f"brake-{kind}"
    ]
    return sum(len(line.get_xdata()) for line in lines)


def test_the_result_carries_the_coupler_force_envelope(outcome: DriveOutcome) -> None:
    r = outcome.result
    tension, compression = r["max_coupler_tension_n"], r["max_coupler_compression_n"]
    assert tension.shape == compression.shape == r["time_s"].shape
    assert np.all(tension >= 0.0) and np.all(compression >= 0.0)
    # the samples are every second, the run's largest forces over every step: never less
    assert 0.0 < tension.max() / 1e3 <= r.metrics["max_coupler_tension_kn"] + 1e-9
    assert 0.0 < compression.max() / 1e3 <= r.metrics["max_coupler_compression_kn"] + 1e-9


def test_the_result_carries_every_brake_application_and_release(outcome: DriveOutcome) -> None:
    r = outcome.result
    events = r.meta["brake_events"]
    kinds = [e["kind"] for e in events]
    assert kinds.count("application") == r.metrics["air_brake_applications"] > 0
    assert kinds.count("release") == r.metrics["air_brake_releases"]
    times = [e["time_s"] for e in events]
    assert times == sorted(times)
    assert all(0.0 <= e["head_m"] <= r["position_m"][-1] + 1e-6 for e in events)
    air = FreightAirBrake()
    sampled = r["time_s"]
    for i, e in enumerate(events):
        if e["kind"] != "application":
            assert e["reduction_kpa"] is None
            continue
        until = events[i + 1]["time_s"] if i + 1 < len(events) else np.inf
        if e["reduction_kpa"] is None:
            # unknown only for an application no recorded sample saw
            assert not np.any((sampled >= e["time_s"]) & (sampled < until))
        else:
            # a reduction a driver can make at the brake valve (the first is at least the
            # minimum; a held one may be deepened, never beyond full service)
            assert air.min_reduction_kpa <= e["reduction_kpa"]
            assert e["reduction_kpa"] <= air.full_service_reduction_kpa() + 1e-9
    assert any(e["reduction_kpa"] is not None for e in events)


def test_the_figure_has_three_panels_sharing_the_km_post(outcome: DriveOutcome) -> None:
    fig = section_figure(outcome)
    speed_ax, force_ax, coupler_ax = fig.axes
    assert speed_ax.get_shared_x_axes().joined(speed_ax, coupler_ax)
    assert force_ax.get_shared_x_axes().joined(force_ax, coupler_ax)
    assert "km post" in coupler_ax.get_xlabel()
    assert "speed" in speed_ax.get_ylabel()
    assert {"traction", "regeneration", "air brake"} <= {
        line.get_label() for line in force_ax.get_lines()
    }
    limit_kn = outcome.result.metrics["coupler_force_limit_kn"]
    drawn = [line.get_ydata()[0] for line in coupler_ax.get_lines()]
    assert limit_kn in drawn and -limit_kn in drawn
    plt.close(fig)


def test_the_figure_marks_every_brake_event_of_the_run(outcome: DriveOutcome) -> None:
    events = outcome.result.meta["brake_events"]
    fig = section_figure(outcome)
    for kind in BRAKE_EVENT_MARKS:
        assert _marks(fig, kind) == sum(e["kind"] == kind for e in events)
    assert sum(_marks(fig, kind) for kind in BRAKE_EVENT_MARKS) == len(events)
    plt.close(fig)


def test_the_figure_marks_an_emergency_and_a_run_without_events(outcome: DriveOutcome) -> None:
    r = outcome.result
    emergency = {"time_s": 100.0, "kind": "emergency", "head_m": 500.0, "reduction_kpa": None}
    for events in ([emergency], []):
        changed = SimResult(r.series, r.metrics, dict(r.meta, brake_events=events))
        fig = section_figure(dataclasses.replace(outcome, result=changed))
        assert _marks(fig, "emergency") == len(events)
        assert _marks(fig, "application") == _marks(fig, "release") == 0
        plt.close(fig)


def test_a_point_mass_result_is_refused_naming_the_model(outcome: DriveOutcome) -> None:
    r = outcome.result
    point_mass = SimResult(r.series, r.metrics, {"model": "point-mass"})
    with pytest.raises(ValueError, match="consist model"):
        section_figure(dataclasses.replace(outcome, result=point_mass))
