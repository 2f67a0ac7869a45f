"""The time-distance graph of a line run (report/line_plots.py ``plan_against_run``): a
legend naming every line style drawn, the baseline's too; clock times (h:mm) on the time
axis, which ends when the last train arrives, not at the scenario's end; the run's events
marked (a train failure where the train was, the ground's time down, a TSR set and
cancelled, its shading ended by the cancel).

The runs are made up (each train straight from its origin to its destination, on time):
the graph draws what it is given, and a test of it needs no simulation."""

from __future__ import annotations

import re

import numpy as np
import pytest
from matplotlib.collections import PolyCollection

from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.report.line_plots import clock_label, plan_against_run, shown_until_s

H = 3600.0
SCENARIO = {
    "name": "legend",
    "line": "heavy-haul",
    "seed": 1,
    "duration_h": 3.0,
    "channel": {"dead_zones": [{"start_km": 10.0, "end_km": 12.0}]},
    "services": [
        {"kind": "loaded", "from": 1, "to": 2, "first_departure_min": 2.0, "first_id": 101},
        {"kind": "empty", "from": 2, "to": 1, "first_departure_min": 5.0, "first_id": 201},
    ],
}
#: the run's events as ``LineResult.events`` holds them (times on the run's clock)
TSR_FROM_S, TSR_UNTIL_S, CANCEL_S = 600.0, 5400.0, 1500.0
EVENTS = [
    {
        "t_s": TSR_FROM_S,
        "event": "tsr_set",
        "result": {"session": 1, "trains": [101]},
        "tsr": {
            "session": 1,
            "start_km": 14.0,
            "end_km": 16.0,
            "limit_kmh": 45.0,
            "from_s": TSR_FROM_S,
            "until_s": TSR_UNTIL_S,
        },
    },
    {"t_s": 900.0, "event": "train_failure", "train": 101},
    {"t_s": 1200.0, "event": "ground_restart", "down_s": 120.0},
    {"t_s": CANCEL_S, "event": "tsr_cancel", "result": {"session": 1, "trains": [101]}},
]


@pytest.fixture(scope="module")
def scenario():  # type: ignore[no-untyped-def]
    return line_scenario_from_mapping(SCENARIO)


def _on_time(scenario, late_s: float = 0.0) -> dict[int, np.ndarray]:  # type: ignore[no-untyped-def]
    """Each train straight from its origin to its destination (``late_s`` late there):
    rows of (t [s], head km post [m], speed [m/s]) every second, as the trackside's."""
    trace = {}
    for service in scenario.services:
        first, last = service.stops[0], service.stops[-1]
        t = np.arange(first.departure_s, last.arrival_s + late_s + 1.0)
        x0, x1 = (scenario.line.station(s.station).centre_m for s in (first, last))
        x = np.interp(t, [t[0], t[-1]], [x0, x1])
        trace[service.train_id] = np.column_stack([t, x, np.full_like(t, 10.0)])
    return trace


def _legend(fig) -> list[str]:  # type: ignore[no-untyped-def]
    return [text.get_text() for legend in fig.legends for text in legend.get_texts()]


def test_the_legend_names_every_style_the_baselines_too(scenario) -> None:  # type: ignore[no-untyped-def]
    fig = plan_against_run(scenario, _on_time(scenario), EVENTS, _on_time(scenario, 60.0))
    assert _legend(fig) == [
        "radio dead zone",
        "run: empty",
        "run: loaded",
        "timetable (in the train's colour)",
        "minimum-time baseline's run",
        "TSR in force (shaded over its stretch)",
        "TSR set",
        "TSR cancelled",
        "train failure",
        "ground down (killed, then restarted)",
    ]
    # without a baseline or events, the legend names only what is drawn
    alone = _legend(plan_against_run(scenario, _on_time(scenario), []))
    assert not any("baseline" in name or "TSR" in name for name in alone)


def test_the_time_axis_reads_clock_times_and_ends_at_the_last_arrival(scenario) -> None:  # type: ignore[no-untyped-def]
    trace, baseline = _on_time(scenario), _on_time(scenario, 300.0)
    fig = plan_against_run(scenario, trace, EVENTS, baseline)
    ax = fig.axes[0]
    last_arrival_s = max(rows[-1, 0] for rows in (*trace.values(), *baseline.values()))
    start, end = ax.get_xlim()
    assert start == 0.0
    assert last_arrival_s / H < end < scenario.duration_s / H
    assert end == shown_until_s(scenario, trace, baseline) / H
    fig.canvas.draw()
    # the labels of the ticks on the axis (the locator gives one either side of it too)
    ticks = [t.get_text() for t in ax.get_xticklabels() if start <= t.get_position()[0] <= end]
    assert ticks and all(re.fullmatch(r"\d+:\d\d", t) for t in ticks)
    assert ticks[0] == "0:00"
    assert "h:mm" in ax.get_xlabel()


def test_a_train_still_out_at_the_end_keeps_the_whole_day(scenario) -> None:  # type: ignore[no-untyped-def]
    trace = _on_time(scenario)
    rows = trace[101]
    # stuck on the line from its first hundred seconds to the scenario's end
    end = np.arange(rows[100, 0], scenario.duration_s + 1.0)
    trace[101] = np.vstack(
        [rows[:100], np.column_stack([end, np.full_like(end, rows[100, 1]), 0 * end])]
    )
    assert shown_until_s(scenario, trace) == scenario.duration_s


@pytest.mark.parametrize(
    ("hours", "shown"), [(0.0, "0:00"), (0.25, "0:15"), (1.5, "1:30"), (2.999, "3:00")]
)
def test_clock_label(hours: float, shown: str) -> None:
    assert clock_label(hours) == shown


def test_the_events_are_marked(scenario) -> None:  # type: ignore[no-untyped-def]
    trace = _on_time(scenario)
    fig = plan_against_run(scenario, trace, EVENTS)
    ax = fig.axes[0]
    # the failure: a cross where the train was at that time
    crosses = [line for line in ax.get_lines() if line.get_marker() == "X"]
    assert len(crosses) == 1
    rows = trace[101]
    at = rows[np.searchsorted(rows[:, 0], 900.0)]
    assert crosses[0].get_xdata()[0] == pytest.approx(900.0 / H)
    assert crosses[0].get_ydata()[0] == pytest.approx(at[1] / 1000.0)
    # a line where the TSR was set and one where it was cancelled
    upright = {
        (round(line.get_xdata()[0] * H), line.get_linestyle())
        for line in ax.get_lines()
        if len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1]
    }
    assert {(round(TSR_FROM_S), "-"), (round(CANCEL_S), "--")} <= upright
    # the TSR shaded over its stretch from when it holds until the cancel, not its end
    shaded = [c for c in ax.collections if isinstance(c, PolyCollection)]
    (tsr,) = [c for c in shaded if c.get_paths()[0].vertices[:, 1].min() == pytest.approx(14.0)]
    times = tsr.get_paths()[0].vertices[:, 0]
    assert times.min() == pytest.approx(TSR_FROM_S / H)
    assert times.max() == pytest.approx(CANCEL_S / H)
