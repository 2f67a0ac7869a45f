"""Figures of the eddy-brake reproduction (paper 003 fig. 7 and 8)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from railpilot.eddy.simulate import EddyResult

LABELS = {
    "open_loop": "open loop",
    "pid": "PID",
    "fuzzy": "fuzzy",
    "fuzzy_pi": "fuzzy adaptive PI",
}
STYLES: dict[str, dict[str, Any]] = {
    "open_loop": {"color": "0.45", "ls": "--"},
    "pid": {"color": "tab:red"},
    "fuzzy": {"color": "tab:blue"},
    "fuzzy_pi": {"color": "tab:green"},
}


def plot_torque_vs_speed(results: Mapping[str, EddyResult], demand_nm: float, title: str) -> Figure:
    """Fig. 7: braking torque against train speed (speed falls from right to left)."""
    fig, ax = plt.subplots(figsize=(7.5, 4.2), constrained_layout=True, dpi=130)
    for name, res in results.items():
        ax.plot(res.speed_kmh, res.torque_nm, lw=1.0, label=LABELS.get(name, name), **STYLES[name])
    ax.axhline(demand_nm, color="k", lw=0.6, ls=":", label=f"demand {demand_nm:.0f} N m")
    ax.set_xlabel("train speed [km/h]")
    ax.set_ylabel("braking torque [N m]")
    ax.set_title(title)
    ax.set_xlim(left=0)
    ax.set_ylim(0, demand_nm * 1.2)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    return fig


def plot_torque_vs_time(
    results: Mapping[str, EddyResult], demand_nm: float, title: str, zoom_s: float = 1.0
) -> Figure:
    """Fig. 8: torque against time, whole run (left) and the first ``zoom_s`` s (right)."""
    fig, (ax, az) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True, dpi=130)
    for name, res in results.items():
        style = STYLES[name]
        label = LABELS.get(name, name)
        ax.plot(res.time_s, res.torque_nm, lw=0.9, label=label, **style)
        first = res.time_s <= zoom_s
        az.plot(res.time_s[first], res.torque_nm[first], lw=0.9, label=label, **style)
    for a in (ax, az):
        a.axhline(demand_nm, color="k", lw=0.6, ls=":")
        a.set_xlabel("time [s]")
        a.set_ylabel("braking torque [N m]")
        a.grid(alpha=0.3)
    ax.set_ylim(0, demand_nm * 1.2)
    ax.set_title(f"{title}: whole run")
    az.set_title(f"first {zoom_s:g} s (demand dotted)")
    az.set_xlim(0, zoom_s)
    ax.legend(loc="lower left", fontsize=8)
    return fig


def plot_settled_ripple(results: Mapping[str, EddyResult], demand_nm: float, title: str) -> Figure:
    """A short full-resolution window of the settled torque: the chopper ripple.

    Each result must carry ``metadata["ripple"] = (time_s, torque_nm)`` sampled at
    every step (thinned series would alias the kilohertz ripple).
    """
    fig, ax = plt.subplots(figsize=(7.5, 3.6), constrained_layout=True, dpi=130)
    start_s = 0.0
    for name, res in results.items():
        if name == "open_loop" or "ripple" not in res.metadata:
            continue
        t, m = res.metadata["ripple"]
        if len(t) == 0:
            continue
        start_s = float(t[0])
        ax.plot((t - start_s) * 1e3, m, lw=0.9, label=LABELS.get(name, name), **STYLES[name])
    ax.axhline(demand_nm, color="k", lw=0.6, ls=":")
    ax.set_xlabel(f"time after t = {start_s:g} s [ms]")
    ax.set_ylabel("braking torque [N m]")
    ax.set_title(f"{title}: chopper ripple (closed loop)")
    ax.grid(alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8)
    return fig
