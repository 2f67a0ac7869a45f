"""Figures of one consist run: coupler force along the train over time, the brake pipe
along the train during an application and a release, and the run's speed and forces."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure

from railpilot.sim.consist_run import ConsistResult
from railpilot.units import mps_to_kmh


def coupler_heat_map(result: ConsistResult) -> Figure:
    """Coupler force [kN] against time and position along the train (tension red,
    compression blue), the limit's contour drawn, with the lead's speed above."""
    fig = Figure(figsize=(11, 6.5), constrained_layout=True)
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(1, 3))
    t = result.series["time_s"]
    top.plot(t, mps_to_kmh(result.series["speed_mps"]), color="tab:blue", lw=1.2)
    top.set_ylabel("lead speed [km/h]")
    top.grid(alpha=0.3)
    for time, kind in zip(result.events["time_s"], result.events["kind"], strict=True):
        colour = {"application": "tab:orange", "release": "tab:green"}.get(kind, "tab:red")
        top.axvline(time, color=colour, lw=0.8, ls="--")
    force_kn = result.fields["coupler_force_n"] / 1e3
    where = np.asarray(result.meta["coupling_from_head_m"])
    limit = float(result.metrics["coupler_force_limit_kn"] or 0.0)
    span = max(float(np.max(np.abs(force_kn))) if force_kn.size else 1.0, 1.0)
    mesh = bottom.pcolormesh(
        t,
        where,
        force_kn.T,
        cmap="RdBu_r",
        norm=TwoSlopeNorm(0.0, -span, span),
        shading="nearest",
        rasterized=True,
    )
    if span > limit:
        bottom.contour(t, where, np.abs(force_kn.T), levels=[limit], colors="k", linewidths=0.8)
    bottom.invert_yaxis()
    bottom.set_xlabel("time [s]")
    bottom.set_ylabel("coupling, distance from the head [m]")
    fig.colorbar(mesh, ax=bottom, label="coupler force [kN] (+ tension, - compression)")
    fig.suptitle(
        f"{result.meta['name']}: coupler forces (max tension "
        f"{result.metrics['max_coupler_tension_kn']:.0f} kN, max compression "
        f"{result.metrics['max_coupler_compression_kn']:.0f} kN; limit {limit:.0f} kN)"
    )
    return fig


def _snapshot_times(result: ConsistResult, kind: str) -> np.ndarray:
    """Times after the first event of ``kind`` at which to show the pipe along the train."""
    times = [
        t for t, k in zip(result.events["time_s"], result.events["kind"], strict=True) if k == kind
    ]
    if not times:
        return np.array([])
    return times[0] + np.array([0.0, 2.0, 5.0, 10.0, 20.0, 40.0, 80.0])


def brake_pipe_along_train(result: ConsistResult) -> Figure:
    """Brake-pipe and brake-cylinder pressure along the train at moments after the first
    service application and after the first release."""
    fig = Figure(figsize=(11, 7), constrained_layout=True)
    axes = fig.subplots(2, 2, sharex=True)
    t = result.series["time_s"]
    x = np.asarray(result.meta["vehicle_centre_m"])
    for col, kind in enumerate(("application", "release")):
        moments = _snapshot_times(result, kind)
        moments = moments[moments <= t[-1]] if t.size else moments
        colours = [
            (0.1 + 0.8 * i / max(len(moments) - 1, 1), 0.3, 0.9 - 0.8 * i / max(len(moments), 1))
            for i in range(len(moments))
        ]
        for moment, colour in zip(moments, colours, strict=True):
            row = int(np.searchsorted(t, moment))
            row = min(row, t.size - 1)
            label = f"+{moment - moments[0]:.0f} s"
            axes[0, col].plot(x, result.fields["brake_pipe_kpa"][row], color=colour, label=label)
            axes[1, col].plot(x, result.fields["brake_cylinder_kpa"][row], color=colour)
        axes[0, col].set_title(f"after the first {kind}" if len(moments) else f"no {kind}")
        if len(moments):
            axes[0, col].legend(fontsize=8, ncol=2)
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
        axes[1, col].set_xlabel("vehicle, distance from the head [m]")
    axes[0, 0].set_ylabel("brake pipe [kPa]")
    axes[1, 0].set_ylabel("brake cylinder [kPa]")
    fig.suptitle(f"{result.meta['name']}: the brake pipe along the train")
    return fig


def run_overview(result: ConsistResult) -> Figure:
    """Speed, the lead's brake-pipe command, and the train's forces over the head's km."""
    fig = Figure(figsize=(11, 7), constrained_layout=True)
    speed, pipe, forces = fig.subplots(3, 1, sharex=True)
    s = result.series
    km = s["position_m"] / 1000.0
    speed.plot(km, mps_to_kmh(s["speed_mps"]), color="tab:blue")
    speed.set_ylabel("lead speed [km/h]")
    pipe.plot(km, s["lead_er_kpa"], color="tab:orange")
    pipe.set_ylabel("lead's brake valve [kPa]")
    forces.plot(km, s["traction_n"] / 1e3, label="traction", color="tab:green")
    forces.plot(km, s["regeneration_n"] / 1e3, label="regeneration", color="tab:purple")
    forces.plot(km, s["air_brake_n"] / 1e3, label="air brake", color="tab:red")
    forces.set_ylabel("force [kN]")
    forces.set_xlabel("head position [km]")
    forces.legend()
    for ax in (speed, pipe, forces):
        ax.grid(alpha=0.3)
    fig.suptitle(f"{result.meta['name']}: speed, brake valve and forces")
    return fig
