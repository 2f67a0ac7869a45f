"""Figures of a whole-line run (``railpilot line simulate --out``): the time-distance graph
of every train, as planned against as run, with the TSRs and the radio's dead zones."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from railpilot.cosim.line_run import LineResult
from railpilot.cosim.scenario import LineScenario

#: seconds per hour (the time axis)
_H = 3600.0


def time_distance(result: LineResult, baseline: LineResult | None = None) -> Figure:
    """Km post against time for every train: the timetable (dotted: planned departures
    and arrivals joined), the run (solid), the baseline's run (thin grey) if given; the
    TSRs set (shaded in their validity) and the dead zones (hatched bands)."""
    return plan_against_run(
        result.scenario,
        result.trace,
        result.events,
        None if baseline is None else baseline.trace,
    )


def plan_against_run(
    scenario: LineScenario,
    trace: Mapping[int, np.ndarray],
    events: Sequence[Mapping[str, Any]],
    baseline_trace: Mapping[int, np.ndarray] | None = None,
) -> Figure:
    """:func:`time_distance` from the parts of a run it draws: the trackside's samples
    (``LineResult.trace``) and the events played (``LineResult.events``). A run made in
    another process sends these back, not its :class:`LineResult` (which does not pickle)."""
    fig = Figure(figsize=(10.0, 6.0), layout="constrained")
    ax = fig.add_subplot()
    line = scenario.line
    end_h = scenario.duration_s / _H
    for zone in scenario.channel.dead_zones:
        ax.axhspan(zone.start_km, zone.end_km, color="tab:purple", alpha=0.12, lw=0)
    for event in events:
        tsr = event.get("tsr")
        if tsr is not None:
            ax.fill_between(
                [tsr["from_s"] / _H, min(tsr["until_s"] / _H, end_h)],
                tsr["start_km"],
                tsr["end_km"],
                color="tab:orange",
                alpha=0.3,
                lw=0,
            )
    colours = {"heavy-haul-loaded": "tab:blue", "heavy-haul-empty": "tab:green"}
    services = sorted(scenario.services, key=lambda s: s.train_id)
    for service in services:
        train_id = service.train_id
        colour = colours.get(service.kind, "tab:red")
        t_plan, x_plan = [], []
        for stop in service.stops:
            station_km = line.station(stop.station).centre_m / 1000.0
            for at in (stop.arrival_s, stop.departure_s):
                if np.isfinite(at):
                    t_plan.append(at / _H)
                    x_plan.append(station_km)
        ax.plot(t_plan, x_plan, color=colour, lw=0.8, ls=":")
        if baseline_trace is not None and train_id in baseline_trace:
            rows = baseline_trace[train_id]
            ax.plot(rows[:, 0] / _H, rows[:, 1] / 1000.0, color="0.6", lw=0.6)
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
    ax.set_xlabel("time [h]")
    ax.set_ylabel("km post")
    ax.set_title(
        f"{scenario.name}: planned (dotted) and run (solid); loaded blue, empty green; "
        "TSR orange, dead zone purple",
        fontsize=9,
    )
    return fig


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
