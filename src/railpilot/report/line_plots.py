"""Figures of a whole-line run (``railpilot line simulate --out``): the time-distance graph
of every train, as planned against as run, with the TSRs, the radio's dead zones and the
run's events, and the energy of every train."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, MultipleLocator

from railpilot.cosim.line_run import LineResult
from railpilot.cosim.scenario import LineScenario

#: seconds per hour (the time axis is in hours, its ticks read h:mm)
_H = 3600.0
#: the time axis runs this share of the day shown past the last arrival (room for the
#: last train's label and the stations' names)
_TAIL = 0.04
#: each train's colour by kind (any other kind red)
KIND_COLOURS = {"heavy-haul-loaded": "tab:blue", "heavy-haul-empty": "tab:green"}
KIND_NAMES = {"heavy-haul-loaded": "loaded", "heavy-haul-empty": "empty"}
#: how the graph draws each part, one style each (the legend names every one)
PLANNED: dict[str, Any] = {"color": "black", "lw": 0.8, "ls": ":"}
BASELINE: dict[str, Any] = {"color": "0.6", "lw": 0.6, "ls": "-"}
TSR: dict[str, Any] = {"color": "tab:orange", "alpha": 0.3, "lw": 0}
DEAD_ZONE: dict[str, Any] = {"color": "tab:purple", "alpha": 0.12, "lw": 0}
GROUND_DOWN: dict[str, Any] = {"color": "0.3", "alpha": 0.15, "lw": 0}
FAILURE: dict[str, Any] = {
    "marker": "X",
    "color": "tab:red",
    "ms": 8,
    "ls": "none",
    "mec": "black",
    "mew": 0.5,
}
TSR_SET: dict[str, Any] = {"color": "tab:orange", "lw": 1.0, "ls": "-"}
TSR_CANCELLED: dict[str, Any] = {"color": "tab:orange", "lw": 1.0, "ls": "--"}


def time_distance(result: LineResult, baseline: LineResult | None = None) -> Figure:
    """Km post against the clock for every train: the timetable (dotted: planned
    departures and arrivals joined), the run (solid), the baseline's run (thin grey) if
    given; the TSRs set (shaded in their validity, until cancelled), the dead zones
    (bands), the run's events (:func:`plan_against_run`)."""
    return plan_against_run(
        result.scenario,
        result.trace,
        result.events,
        None if baseline is None else baseline.trace,
    )


def clock_label(hours: float, _: object = None) -> str:
    """A time on the axis [h since the run's start] as ``h:mm``."""
    minutes = round(hours * 60.0)
    return f"{minutes // 60}:{minutes % 60:02d}"


def shown_until_s(
    scenario: LineScenario,
    trace: Mapping[int, np.ndarray],
    baseline_trace: Mapping[int, np.ndarray] | None = None,
) -> float:
    """Where the time axis ends [s since the run's start]: when the last train arrives
    (its last sample: a train leaves the trackside at its destination) or is due to (the
    timetable shown whole), in the run or the baseline's, with a little room after; the
    scenario's end if a train is still out then."""
    ends = [stop.arrival_s for s in scenario.services for stop in s.stops[-1:]]
    for rows in (*trace.values(), *(baseline_trace or {}).values()):
        if len(rows):
            ends.append(float(rows[-1, 0]))
    last = max((e for e in ends if np.isfinite(e)), default=scenario.duration_s)
    return min(last * (1.0 + _TAIL), scenario.duration_s)


def plan_against_run(
    scenario: LineScenario,
    trace: Mapping[int, np.ndarray],
    events: Sequence[Mapping[str, Any]],
    baseline_trace: Mapping[int, np.ndarray] | None = None,
    baseline_label: str = "minimum-time baseline",
) -> Figure:
    """:func:`time_distance` from the parts of a run it draws: the trackside's samples
    (``LineResult.trace``) and the events played (``LineResult.events``; their ``t_s``
    and a TSR's ``tsr`` on the run's clock). A run made in another process sends these
    back, not its :class:`LineResult` (which does not pickle). ``baseline_label`` names
    the baseline's run in the legend."""
    fig = Figure(figsize=(10.0, 6.5), layout="constrained")
    ax = fig.add_subplot()
    line = scenario.line
    end_h = shown_until_s(scenario, trace, baseline_trace) / _H
    legend: list[tuple[Any, str]] = []
    for zone in scenario.channel.dead_zones:
        ax.axhspan(zone.start_km, zone.end_km, **DEAD_ZONE)
    if scenario.channel.dead_zones:
        legend.append((Patch(**DEAD_ZONE), "radio dead zone"))
    services = sorted(scenario.services, key=lambda s: s.train_id)
    kinds = sorted({s.kind for s in services})
    for kind in kinds:
        colour = KIND_COLOURS.get(kind, "tab:red")
        legend.append((Line2D([], [], color=colour, lw=1.2), f"run: {KIND_NAMES.get(kind, kind)}"))
    legend.append((Line2D([], [], **PLANNED), "timetable (in the train's colour)"))
    if baseline_trace is not None:
        legend.append((Line2D([], [], **BASELINE), f"{baseline_label}'s run"))
    for service in services:
        train_id = service.train_id
        colour = KIND_COLOURS.get(service.kind, "tab:red")
        t_plan, x_plan = [], []
        for stop in service.stops:
            station_km = line.station(stop.station).centre_m / 1000.0
            for at in (stop.arrival_s, stop.departure_s):
                if np.isfinite(at):
                    t_plan.append(at / _H)
                    x_plan.append(station_km)
        ax.plot(t_plan, x_plan, **{**PLANNED, "color": colour})
        if baseline_trace is not None and train_id in baseline_trace:
            rows = baseline_trace[train_id]
            ax.plot(rows[:, 0] / _H, rows[:, 1] / 1000.0, **BASELINE)
        rows = trace.get(train_id, np.empty((0, 3)))
        if rows.size:
            ax.plot(rows[:, 0] / _H, rows[:, 1] / 1000.0, color=colour, lw=1.2)
            ax.annotate(
                service.number,
                (rows[0, 0] / _H, rows[0, 1] / 1000.0),
                fontsize=7,
                color=colour,
                xytext=(2, 2),
                textcoords="offset points",
            )
    legend += _events(ax, events, trace, end_h)
    used = [
        line.station(stop.station).centre_m / 1000.0
        for service in services
        for stop in service.stops
    ]
    low, high = min(used) - 3.0, max(used) + 3.0
    for station in line.stations:
        km = station.centre_m / 1000.0
        if low <= km <= high:
            ax.axhline(km, color="0.85", lw=0.5, zorder=0)
            ax.annotate(station.name, (end_h, km), fontsize=6, color="0.5", ha="right", va="bottom")
    ax.set_ylim(low, high)
    ax.set_xlim(0.0, end_h)
    # a tick every quarter of an hour on a short day, every hour on a long one
    ax.xaxis.set_major_locator(MultipleLocator(0.25 if end_h <= 4.0 else 1.0))
    ax.xaxis.set_major_formatter(FuncFormatter(clock_label))
    ax.set_xlabel("time from the run's start [h:mm]")
    ax.set_ylabel("km post")
    ax.set_title(f"{scenario.name}: the timetable against the run", fontsize=9)
    handles, labels = zip(*legend, strict=True)
    fig.legend(handles, labels, loc="outside lower center", ncols=4, fontsize=7, frameon=False)
    return fig


def _events(
    ax: Axes, events: Sequence[Mapping[str, Any]], trace: Mapping[int, np.ndarray], end_h: float
) -> list[tuple[Any, str]]:
    """The run's events on the graph: each TSR shaded over its stretch from when it holds
    until it expires or is cancelled, a line where it was set and where cancelled, each
    train failure a cross where the train was, and the ground's time down after a
    restart; returns the legend's entry of each kind drawn."""
    cancelled_at = {
        e["result"]["session"]: e["t_s"]
        for e in events
        if e.get("event") == "tsr_cancel" and isinstance(e.get("result"), Mapping)
    }
    drawn: dict[str, tuple[Any, str]] = {}
    for event in events:
        t_h = float(event["t_s"]) / _H
        tsr = event.get("tsr")
        kind = event.get("event")
        if tsr is not None:
            until_s = min(tsr["until_s"], cancelled_at.get(tsr["session"], np.inf))
            ax.fill_between(
                [tsr["from_s"] / _H, min(until_s / _H, end_h)],
                tsr["start_km"],
                tsr["end_km"],
                **TSR,
            )
            drawn["tsr"] = (Patch(**TSR), "TSR in force (shaded over its stretch)")
        if kind == "tsr_set":
            ax.axvline(t_h, **TSR_SET)
            drawn["tsr_set"] = (Line2D([], [], **TSR_SET), "TSR set")
        elif kind == "tsr_cancel":
            ax.axvline(t_h, **TSR_CANCELLED)
            drawn["tsr_cancel"] = (Line2D([], [], **TSR_CANCELLED), "TSR cancelled")
        elif kind == "ground_restart":
            ax.axvspan(t_h, t_h + float(event.get("down_s", 0.0)) / _H, **GROUND_DOWN)
            drawn["ground"] = (Patch(**GROUND_DOWN), "ground down (killed, then restarted)")
        elif kind == "train_failure":
            rows = trace.get(int(event["train"]), np.empty((0, 3)))
            if len(rows):
                at = int(np.clip(np.searchsorted(rows[:, 0], event["t_s"]), 0, len(rows) - 1))
                ax.plot([t_h], [rows[at, 1] / 1000.0], **FAILURE)
            else:  # the train never ran: the time only
                ax.axvline(t_h, color=FAILURE["color"], lw=1.0, ls="-.")
            drawn["failure"] = (Line2D([], [], **FAILURE), "train failure")
    order = ("tsr", "tsr_set", "tsr_cancel", "failure", "ground")
    return [drawn[k] for k in order if k in drawn]


def energy_by_train(advised: Mapping[str, Any], baseline: Mapping[str, Any]) -> Figure:
    """Every train's energy, the advised run beside the baseline's, from the two runs'
    KPIs (``LineResult.kpis()``): traction drawn (bar up), regeneration returned (hatched
    bar down) and the net energy (diamond, labelled)."""
    fig = Figure(figsize=(8.0, 4.5), layout="constrained")
    ax = fig.add_subplot()
    ids = sorted(advised["trains"], key=int)
    x = np.arange(len(ids), dtype=float)
    width = 0.38
    for offset, kpis, colour, label in (
        (-width / 2, advised, "tab:blue", "advised"),
        (width / 2, baseline, "0.55", "baseline"),
    ):
        trains = [kpis["trains"][i] for i in ids]
        traction = [t["energy_traction_kwh"] for t in trains]
        regenerated = [-t["energy_regenerated_kwh"] for t in trains]
        net = [t["energy_kwh"] for t in trains]
        ax.bar(x + offset, traction, width, color=colour, label=f"{label}: traction")
        ax.bar(
            x + offset,
            regenerated,
            width,
            color=colour,
            alpha=0.45,
            hatch="//",
            edgecolor="white",
            label=f"{label}: regenerated",
        )
        ax.plot(x + offset, net, "D", color="black", ms=5, label="_net")
        for xi, value in zip(x + offset, net, strict=True):
            ax.annotate(
                f"{value:.0f}",
                (xi, value),
                fontsize=7,
                ha="center",
                va="bottom",
                xytext=(0, 4),
                textcoords="offset points",
            )
    ax.plot([], [], "D", color="black", ms=5, label="net (labelled) [kWh]")
    ax.axhline(0.0, color="black", lw=0.6)
    ax.set_xticks(x, [f"{advised['trains'][i]['number']}" for i in ids])
    ax.set_ylabel("energy [kWh]")
    ax.legend(fontsize=7, ncols=3, loc="upper center", bbox_to_anchor=(0.5, -0.1))
    ax.set_title(
        f"{advised['scenario']}: energy per train, advised (blue) and baseline (grey)", fontsize=9
    )
    return fig
