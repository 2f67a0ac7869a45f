"""Figures of one drive (``railpilot drive``): speed over distance, and energy."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from railpilot.onboard.drive import DriveOutcome
from railpilot.units import mps_to_kmh


def speed_figure(outcome: DriveOutcome) -> Figure:
    """Speed over km post: static limits, MRSP (TSRs, targets), planned and driven curves."""
    fig = Figure(figsize=(11, 5.5), constrained_layout=True)
    ax = fig.add_subplot(1, 1, 1)
    plan = outcome.plan
    x_plan = outcome.km_post(plan.s_m) / 1000.0
    ends = [x_plan[0], x_plan[-1], *(s / 1000.0 for s in outcome.target_signals_m)]
    lo, hi = min(ends) - 0.2, max(ends) + 0.2
    grid = np.linspace(lo, hi, 4000) * 1000.0
    static = outcome.static.at(grid)
    mrsp = outcome.mrsp.at(grid)
    ax.plot(grid / 1000.0, mps_to_kmh(static), color="0.6", lw=1.2, label="static limit")
    ax.plot(grid / 1000.0, mps_to_kmh(mrsp), color="tab:red", lw=1.5, ls="--", label="MRSP")
    for i, curve in enumerate(outcome.supervision):
        speeds = np.linspace(curve.target_speed_mps, float(curve.speed_mps[-1]), 200)
        at_s = curve.target_m - curve.intervention_distance_m(speeds)
        keep = np.isfinite(at_s) & (at_s >= 0.0)
        ax.plot(
            outcome.km_post(at_s[keep]) / 1000.0,
            mps_to_kmh(speeds[keep]),
            color="tab:orange",
            lw=1.0,
            label="intervention (full service)" if i == 0 else None,
        )
    ax.plot(x_plan, mps_to_kmh(plan.speed_mps), color="tab:green", lw=1.5, label="planned")
    for i, replan in enumerate(outcome.replans):
        ax.plot(
            outcome.km_post(replan.plan.s_m + replan.from_m) / 1000.0,
            mps_to_kmh(replan.plan.speed_mps),
            color="tab:green",
            lw=1.0,
            ls="--",
            label="re-planned (TSR, target point)" if i == 0 else None,
        )
    r = outcome.result
    ax.plot(
        outcome.km_post(r["position_m"]) / 1000.0,
        mps_to_kmh(r["speed_mps"]),
        color="tab:blue",
        lw=1.2,
        label="driven",
    )
    for request in outcome.target_requests:
        signal = request.signal_m
        ax.axvline(signal / 1000.0, color="k", lw=1.0, ls=":")
        held = "red signal" + (
            f" {request.set_s:.0f}-{request.clear_s:.0f} s"
            if np.isfinite(request.clear_s) or request.set_s > 0
            else ""
        )
        ax.annotate(held, (signal / 1000.0, 30), rotation=90, fontsize=8, ha="left", va="bottom")
    for i, stop in enumerate(outcome.targets):
        ax.axvline(
            stop.position_m / 1000.0,
            color="tab:purple",
            lw=1.0,
            ls="-.",
            label="target stop (safety distance)" if i == 0 else None,
        )
    ax.set_xlabel("km post [km]")
    ax.set_ylabel("speed [km/h]")
    ax.set_ylim(
        0, max(90.0, float(np.nanmax(mps_to_kmh(np.where(np.isfinite(static), static, 0))))) + 10
    )
    ax.set_xlim(lo, hi)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower center", ncols=4)
    ax.set_title(
        f"{plan.strategy} plan for {plan.requested_time_s:.0f} s, driven in "
        f"{r.metrics['running_time_s']:.0f} s"
    )
    return fig


def energy_figure(outcome: DriveOutcome) -> Figure:
    """Traction drawn and regeneration returned, planned against driven [kWh]."""
    fig = Figure(figsize=(6, 4), constrained_layout=True)
    ax = fig.add_subplot(1, 1, 1)
    plan, metrics = outcome.plan, outcome.result.metrics
    labels = ["traction drawn", "regeneration returned", "net"]
    planned = [plan.energy_traction_kwh, plan.energy_regenerated_kwh, plan.energy_net_kwh]
    drawn, returned = metrics["energy_traction_kwh"], metrics["energy_regenerated_kwh"]
    driven = [drawn, returned, drawn - returned]
    at = np.arange(len(labels))
    ax.bar(at - 0.2, planned, 0.4, label="planned", color="tab:green")
    ax.bar(at + 0.2, driven, 0.4, label="driven", color="tab:blue")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(at, labels)
    ax.set_ylabel("energy [kWh]")
    ax.legend()
    ax.grid(axis="y", alpha=0.3)
    return fig
