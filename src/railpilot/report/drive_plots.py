"""Figures of one drive (``railpilot drive``): speed over distance, energy, and on the
consist model the section's brake cycles, forces and coupler-force envelope."""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from railpilot.onboard.drive import DriveOutcome
from railpilot.sim.result import SimResult
from railpilot.units import mps_to_kmh


def _plot_replans(ax: Axes, outcome: DriveOutcome, label: str) -> None:
    """Each re-planned curve, dashed, the first one labelled."""
    for i, replan in enumerate(outcome.replans):
        ax.plot(
            outcome.km_post(replan.plan.s_m + replan.from_m) / 1000.0,
            mps_to_kmh(replan.plan.speed_mps),
            color="tab:green",
            lw=1.0,
            ls="--",
            label=label if i == 0 else None,
        )


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
    _plot_replans(ax, outcome, "re-planned (TSR, target point)")
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


#: how each kind of brake event is marked on the driven curve: marker, colour, label (of
#: ``n`` events)
BRAKE_EVENT_MARKS = {
    "application": ("v", "tab:red", "applied ({n}; reduction along the top)"),
    "release": ("^", "tab:cyan", "released ({n})"),
    "emergency": ("X", "k", "emergency ({n})"),
}


def section_figure(outcome: DriveOutcome) -> Figure:
    """One section on the consist model, three panels over the km post: speed (MRSP,
    static limit, planned and driven, each brake application and release where the head
    was), the locomotives' traction and regeneration and the air brake's force, and the
    coupler-force envelope (the largest tension and compression along the train at each
    recorded sample) against its limit.

    Reads what the run did: ``result.meta["brake_events"]`` and the series
    ``max_coupler_tension_n`` / ``max_coupler_compression_n`` (onboard/consist_drive.py).
    """
    r = outcome.result
    events = r.meta.get("brake_events")
    if events is None or "max_coupler_tension_n" not in r.series:
        raise ValueError("section_figure needs a drive on the consist model (--model consist)")
    fig = Figure(figsize=(13, 9.5), constrained_layout=True)
    speed_ax, force_ax, coupler_ax = fig.subplots(
        3, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1.0, 1.0]}
    )
    x_km = outcome.km_post(r["position_m"]) / 1000.0
    start_km, end_km = (outcome.km_post(np.array([0.0, r["position_m"][-1]])) / 1000.0).tolist()
    applied = _applied_spans_km(outcome, events)
    for ax in (speed_ax, force_ax, coupler_ax):
        for a, b in applied:
            ax.axvspan(a, b, color="tab:red", alpha=0.07, lw=0)
        ax.grid(alpha=0.3)
    _speed_panel(speed_ax, outcome, x_km, events)
    _force_panel(force_ax, r, x_km)
    _coupler_panel(coupler_ax, r, x_km)
    # the train runs left to right whichever way the km posts count
    pad = 0.01 * (end_km - start_km)
    coupler_ax.set_xlim(start_km - pad, end_km + pad)
    coupler_ax.set_xlabel("km post [km] (shaded: from each application to its release)")
    m = r.metrics
    counts = {kind: sum(e["kind"] == kind for e in events) for kind in BRAKE_EVENT_MARKS}
    speed_ax.set_title(
        f"{r.meta.get('consist', '')}: station {outcome.from_station} -> "
        f"{outcome.to_station}, driven in {m['running_time_s']:.0f} s (planned "
        f"{outcome.plan.running_time_s:.0f} s); {_count(counts['application'], 'application')}, "
        f"{_count(counts['release'], 'release')}"
        + (
            f", {_count(counts['emergency'], 'emergency application')}"
            if counts["emergency"]
            else ""
        )
        + (
            f"; least recharge margin {margin:.0f} s"
            if (margin := m.get("min_recharge_margin_s")) is not None and np.isfinite(margin)
            else ""
        ),
        loc="left",
    )
    return fig


def _count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless one."""
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _applied_spans_km(
    outcome: DriveOutcome, events: list[dict[str, Any]]
) -> list[tuple[float, float]]:
    """The km-post spans [km] over which the air brake was applied (an application or
    an emergency to the next event; to the run's end if none follows)."""
    end_m = float(outcome.result["position_m"][-1])
    spans = []
    for i, event in enumerate(events):
        if event["kind"] == "release":
            continue
        until = events[i + 1]["head_m"] if i + 1 < len(events) else end_m
        a, b = outcome.km_post(np.array([event["head_m"], until])) / 1000.0
        spans.append((float(min(a, b)), float(max(a, b))))
    return spans


def _speed_panel(
    ax: Axes, outcome: DriveOutcome, x_km: np.ndarray, events: list[dict[str, Any]]
) -> None:
    """Limits, planned and driven speed, and the brake events marked on the driven curve."""
    r = outcome.result
    lo, hi = sorted((float(x_km[0]), float(x_km[-1])))
    grid = np.linspace(lo - 0.5, hi + 0.5, 4000) * 1000.0
    static = mps_to_kmh(outcome.static.at(grid))
    ax.plot(grid / 1000.0, static, color="0.6", lw=1.2, label="static limit")
    ax.plot(
        grid / 1000.0,
        mps_to_kmh(outcome.mrsp.at(grid)),
        "--",
        color="tab:red",
        lw=1.3,
        label="MRSP",
    )
    ax.plot(
        outcome.km_post(outcome.plan.s_m) / 1000.0,
        mps_to_kmh(outcome.plan.speed_mps),
        color="tab:green",
        lw=2.6,
        alpha=0.55,  # wide and pale: the driven curve stays visible where it follows
        label="planned",
    )
    _plot_replans(ax, outcome, "re-planned")
    speed_kmh = mps_to_kmh(r["speed_mps"])
    ax.plot(x_km, speed_kmh, color="tab:blue", lw=1.2, label="driven (head)")
    labelled_km: list[float] = []
    min_gap_km = 0.05 * (hi - lo)  # closer reduction labels would overlap
    for kind, (marker, colour, label) in BRAKE_EVENT_MARKS.items():
        mine = [e for e in events if e["kind"] == kind]
        if not mine:
            continue
        at_km = outcome.km_post(np.array([e["head_m"] for e in mine])) / 1000.0
        at_kmh = np.interp([e["time_s"] for e in mine], r["time_s"], speed_kmh)
        ax.plot(
            at_km,
            at_kmh,
            ls="none",
            marker=marker,
            color=colour,
            mec="k",
            mew=0.6,
            ms=7,
            label=label.format(n=len(mine)),
            gid=f"brake-{kind}",
        )
        for e, km in zip(mine, at_km, strict=True):
            reduction = e.get("reduction_kpa")
            if reduction is None or any(abs(km - k) < min_gap_km for k in labelled_km):
                continue
            labelled_km.append(float(km))
            # along the top, clear of the curves, at the start of the shaded application;
            # one near the section's end is set inwards, not across the frame
            side = (km - x_km[0]) / (x_km[-1] - x_km[0])
            ax.text(
                km,
                0.985,
                f"{reduction:.0f} kPa",
                transform=ax.get_xaxis_transform(),
                ha="right" if side > 0.96 else "left",
                va="top",
                fontsize=8,
                color="tab:red",
            )
    top = np.nanmax(np.where(np.isfinite(static), static, 0.0))
    # headroom over the limits for the reductions written along the top
    ax.set_ylim(0, max(top, float(np.nanmax(speed_kmh))) * 1.18)
    ax.set_ylabel("speed [km/h]")
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8.5)


def _force_panel(ax: Axes, r: SimResult, x_km: np.ndarray) -> None:
    """The locomotives' traction and regeneration and the air brake's force [kN], each
    positive."""
    traction_kn = r["traction_n"] / 1e3
    # electric_n is the electric force in the brake's sign: regeneration less traction
    regeneration_kn = (r["electric_n"] + r["traction_n"]) / 1e3
    ax.plot(x_km, traction_kn, color="tab:orange", lw=1.0, label="traction")
    ax.plot(x_km, regeneration_kn, color="tab:green", lw=1.0, label="regeneration")
    ax.plot(x_km, r["air_n"] / 1e3, color="tab:red", lw=1.0, label="air brake")
    ax.set_ylim(bottom=0)
    ax.set_ylabel("force [kN]")
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8.5)


def _coupler_panel(ax: Axes, r: SimResult, x_km: np.ndarray) -> None:
    """The coupler-force envelope [kN]: tension up, compression down, the limit both ways."""
    tension_kn = r["max_coupler_tension_n"] / 1e3
    compression_kn = r["max_coupler_compression_n"] / 1e3
    limit_kn = float(r.metrics["coupler_force_limit_kn"])
    ax.fill_between(
        x_km, 0.0, tension_kn, color="tab:blue", alpha=0.5, lw=0, label="largest tension"
    )
    ax.fill_between(
        x_km, 0.0, -compression_kn, color="tab:brown", alpha=0.5, lw=0, label="largest compression"
    )
    ax.axhline(limit_kn, color="k", lw=1.0, ls="--", label=f"limit {limit_kn:,.0f} kN")
    ax.axhline(-limit_kn, color="k", lw=1.0, ls="--")
    ax.axhline(0.0, color="k", lw=0.6)
    reach = max(
        limit_kn, float(tension_kn.max(initial=0.0)), float(compression_kn.max(initial=0.0))
    )
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_ylabel("coupler force [kN]\n(+ tension)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8.5)
