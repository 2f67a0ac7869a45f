"""Figures of the ground's re-timing (``railpilot reproduce retiming``): time-distance graph
of the trains as planned, under the fixed plan and re-timed, and what it changed per train."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from railpilot.ground.running_time_lp import RetimeProblem, RetimeResult, TrainPlan, TrainTimes

#: seconds per hour (the figure's time axis)
_H = 3600.0


def train_path(
    plan: TrainPlan, times: TrainTimes | None, station_km: Mapping[int, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The train's line in a time-distance graph: ``(time [s], km)`` at every departure and
    arrival, its committed sections first; ``times`` None: the timetable's times."""
    t: list[float] = []
    x: list[float] = []
    for c in plan.committed:
        t += [c.departure_s, c.arrival_s]
        x += [station_km[c.from_station], station_km[c.to_station]]
    if times is None:
        dep = np.asarray(plan.planned_departures_s)
        run = np.array([s.planned_running_s for s in plan.sections])
    else:
        dep, run = times.departure_s, times.running_s
    for s, d, r in zip(plan.sections, dep, run, strict=True):
        t += [float(d), float(d + r)]
        x += [station_km[s.from_station], station_km[s.to_station]]
    return np.asarray(t), np.asarray(x)


def _events(
    plan: TrainPlan, times: TrainTimes | None, station_km: Mapping[int, float]
) -> tuple[np.ndarray, np.ndarray]:
    """``(km, time [s])`` of each remaining departure and arrival (``times`` None: the
    timetable's)."""
    t, x = train_path(plan, times, station_km)
    skip = 2 * len(plan.committed)
    return x[skip:], t[skip:]


def _graph(
    ax: Axes,
    problem: RetimeProblem,
    fixed: RetimeResult,
    retimed: RetimeResult,
    station_km: Mapping[int, float],
    origin_s: float,
    label: bool,
) -> None:
    styles: tuple[tuple[str, RetimeResult | None, dict[str, Any]], ...] = (
        ("timetable", None, dict(color="0.65", lw=0.8, ls=":")),
        ("fixed plan", fixed, dict(color="tab:orange", lw=1.4, ls="--")),
        ("re-timed (LP)", retimed, dict(color="tab:blue", lw=1.1)),
    )
    for name, result, style in styles:
        for i, plan in enumerate(problem.trains):
            times = None if result is None else result.trains[i]
            t, x = train_path(plan, times, station_km)
            ax.plot((t - origin_s) / _H, x, label=name if (label and i == 0) else None, **style)
    ax.axvline((problem.now_s - origin_s) / _H, color="tab:red", lw=0.8, ls="-.")


def retiming_figure(
    problem: RetimeProblem,
    fixed: RetimeResult,
    retimed: RetimeResult,
    station_km: Mapping[int, float],
    station_names: Mapping[int, str],
    *,
    origin_s: float = 0.0,
    delay_trains: int = 6,
    title: str = "",
) -> Figure:
    """Time-distance graph of all trains; the delay along the line of the first
    ``delay_trains``; lateness at the destination and net energy per train, fixed plan
    against re-timed."""
    fig = Figure(figsize=(13, 10.5), constrained_layout=True)
    grid = fig.add_gridspec(2, 2, height_ratios=(1.0, 1.0), width_ratios=(1.5, 1.0))
    whole = fig.add_subplot(grid[0, :])
    delay_ax = fig.add_subplot(grid[1, 0])
    right = grid[1, 1].subgridspec(2, 1)
    late_ax = fig.add_subplot(right[0])
    energy_ax = fig.add_subplot(right[1])

    ids = sorted(station_km, key=lambda i: station_km[i])
    km = [station_km[i] for i in ids]
    _graph(whole, problem, fixed, retimed, station_km, origin_s, label=True)
    whole.set_yticks(km, [f"{i} {station_names[i]}" for i in ids], fontsize=7)
    whole.set_xlabel("time [h from the first train's departure]")
    whole.set_ylabel("station (km from the origin)")
    whole.grid(alpha=0.3)
    whole.legend(loc="upper left", fontsize=9)
    whole.set_title(title or "Time-distance graph: timetable, fixed plan and re-timed")
    whole.annotate(
        "re-timing",
        ((problem.now_s - origin_s) / _H, km[-1]),
        color="tab:red",
        fontsize=8,
        ha="right",
        va="top",
        rotation=90,
    )

    # how the first trains' delays develop along the line: the fixed plan carries them to
    # the port, the re-timing wins them back
    n = min(delay_trains, len(problem.trains))
    colours = [f"C{i}" for i in range(10)]
    # the front train drawn last, on top: the delayed one, whose line others may share
    for i in reversed(range(n)):
        plan = problem.trains[i]
        x, planned = _events(plan, None, station_km)
        colour = colours[i % len(colours)]
        for result, style, name in (
            (fixed, "--", "fixed plan"),
            (retimed, "-", "re-timed"),
        ):
            _, t = _events(plan, result.trains[i], station_km)
            delay_ax.plot(
                x,
                (t - planned) / 60.0,
                color=colour,
                ls=style,
                lw=1.4,
                marker="." if style == "-" else None,
                ms=4,
                label=f"{plan.train_id} {name}",
            )
    delay_ax.set_xticks(km, [str(i) for i in ids], fontsize=8)
    delay_ax.set_xlabel("station (at its km from the origin)")
    delay_ax.set_ylabel("delay against the timetable [min]")
    delay_ax.grid(alpha=0.3)
    handles, names = delay_ax.get_legend_handles_labels()
    delay_ax.legend(handles[::-1], names[::-1], fontsize=7, ncols=2, loc="upper right")
    delay_ax.set_title(f"delay at each departure and arrival, the first {n} trains", fontsize=10)

    at = np.arange(len(problem.trains))
    labels = [t.train_id for t in problem.trains]
    late_ax.bar(at - 0.2, fixed.lateness_s / 60.0, 0.4, color="tab:orange", label="fixed plan")
    late_ax.bar(at + 0.2, retimed.lateness_s / 60.0, 0.4, color="tab:blue", label="re-timed")
    late_ax.set_ylabel("lateness at the\ndestination [min]")
    late_ax.set_xticks(at, labels, rotation=90, fontsize=7)
    late_ax.grid(axis="y", alpha=0.3)
    late_ax.legend(fontsize=8)
    if np.all(retimed.lateness_s < 1.0):
        late_ax.text(
            0.5,
            0.5,
            "re-timed: every train on time",
            transform=late_ax.transAxes,
            color="tab:blue",
            ha="center",
        )

    delta = np.array(
        [
            float(np.sum(r.energy_kwh) - np.sum(f.energy_kwh))
            for r, f in zip(retimed.trains, fixed.trains, strict=True)
        ]
    )
    energy_ax.bar(at, delta, 0.6, color=np.where(delta > 0, "tab:red", "tab:green"))
    energy_ax.axhline(0.0, color="k", lw=0.8)
    energy_ax.set_ylabel("net energy,\nre-timed - fixed [kWh]")
    energy_ax.set_xticks(at, labels, rotation=90, fontsize=7)
    energy_ax.grid(axis="y", alpha=0.3)
    return fig
