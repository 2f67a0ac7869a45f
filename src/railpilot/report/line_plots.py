"""Figures of a whole-line run (``railpilot line simulate --out``): the time-distance graph
of every train, as planned against as run, with the TSRs and the radio's dead zones."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from railpilot.cosim.line_run import LineResult

#: seconds per hour (the time axis)
_H = 3600.0


def time_distance(result: LineResult, baseline: LineResult | None = None) -> Figure:
    """Km post against time for every train: the timetable (dotted: planned departures
    and arrivals joined), the run (solid), the baseline's run (thin grey) if given; the
    TSRs set (shaded in their validity) and the dead zones (hatched bands)."""
    fig = Figure(figsize=(10.0, 6.0), layout="constrained")
    ax = fig.add_subplot()
    line = result.scenario.line
    end_h = result.scenario.duration_s / _H
    for zone in result.scenario.channel.dead_zones:
        ax.axhspan(zone.start_km, zone.end_km, color="tab:purple", alpha=0.12, lw=0)
    for event in result.events:
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
    for train_id, driver in sorted(result.drivers.items()):
        colour = colours.get(driver.service.kind, "tab:red")
        t_plan, x_plan = [], []
        for stop in driver.service.stops:
            station_km = line.station(stop.station).centre_m / 1000.0
            for at in (stop.arrival_s, stop.departure_s):
                if np.isfinite(at):
                    t_plan.append(at / _H)
                    x_plan.append(station_km)
        ax.plot(t_plan, x_plan, color=colour, lw=0.8, ls=":")
        if baseline is not None and train_id in baseline.trace:
            rows = baseline.trace[train_id]
            ax.plot(rows[:, 0] / _H, rows[:, 1] / 1000.0, color="0.6", lw=0.6)
        rows = result.trace[train_id]
        if rows.size:
            ax.plot(rows[:, 0] / _H, rows[:, 1] / 1000.0, color=colour, lw=1.2)
            ax.annotate(
                driver.service.number,
                (rows[0, 0] / _H, rows[0, 1] / 1000.0),
                fontsize=7,
                color=colour,
                xytext=(2, 2),
                textcoords="offset points",
            )
    used = [
        line.station(stop.station).centre_m / 1000.0
        for driver in result.drivers.values()
        for stop in driver.service.stops
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
        f"{result.scenario.name}: planned (dotted) and run (solid); loaded blue, empty green; "
        "TSR orange, dead zone purple",
        fontsize=9,
    )
    return fig
