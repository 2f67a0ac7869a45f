"""Figures of paper 000 (EP braking): speed-distance, deceleration, speed error."""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from railpilot.sim.result import SimResult
from railpilot.units import mps_to_kmh

COLORS = {"pid": "tab:orange", "smarc": "tab:blue", "qsmc": "tab:green", "pstop": "tab:purple"}


def _moving(result: SimResult) -> np.ndarray:
    """Samples up to and including the stop (a run that starts at rest: its final stop)."""
    v = result["speed_mps"]
    moved = np.nonzero(v > 0.0)[0]
    start = moved[0] if len(moved) else 0
    stopped = np.nonzero(v[start:] <= 0.0)[0]
    end = start + stopped[0] + 1 if len(stopped) else len(v)
    return np.arange(end)


def _kmh_text(speed_mps: float) -> str:
    """A speed for a title: ``6 km/h``, ``7.5 km/h``."""
    return f"{float(mps_to_kmh(speed_mps)):.3g} km/h"


def speed_distance(results: Mapping[str, SimResult], changeover_mps: float) -> Figure:
    """Fig. 4: speed over distance to go, with the target curve and a zoom on the stop.

    ``changeover_mps``: the scenario's electric/air changeover speed [m/s], drawn dotted.
    """
    fig, (ax, zoom) = plt.subplots(1, 2, figsize=(11, 4.2), width_ratios=[2, 1], dpi=110)
    first = next(iter(results.values()))
    stop_m = first.meta["stop_point_m"]
    for name, r in results.items():
        i = _moving(r)
        ax.plot(
            r["position_m"][i] - stop_m,
            mps_to_kmh(r["speed_mps"][i]),
            color=COLORS.get(name),
            label=name.upper(),
        )
        zoom.plot(
            r["position_m"][i] - stop_m, mps_to_kmh(r["speed_mps"][i]), color=COLORS.get(name)
        )
    i = _moving(first)
    ref_x = first["ref_position_m"] - stop_m
    ref_v = mps_to_kmh(first["ref_speed_mps"])
    for a in (ax, zoom):
        a.plot(ref_x, ref_v, "k--", lw=1, label="target curve" if a is ax else None)
        if changeover_mps > 0.0:  # a brake without an electric/air changeover has none
            a.axhline(float(mps_to_kmh(changeover_mps)), color="grey", lw=0.6, ls=":")
        a.grid(alpha=0.3)
        a.set_xlabel("position relative to the stop point [m]")
    ax.set_ylabel("speed [km/h]")
    ax.set_title("Speed-distance tracking")
    ax.legend()
    zoom.set_xlim(-25, 2)
    zoom.set_ylim(0, 12)
    zoom.axvline(0, color="k", lw=0.8)
    zoom.set_title(
        f"Last 25 m (dotted: {_kmh_text(changeover_mps)} changeover)"
        if changeover_mps > 0.0
        else "Last 25 m"
    )
    fig.tight_layout()
    return fig


def deceleration(results: Mapping[str, SimResult], limit_mps2: float) -> Figure:
    """Fig. 5: deceleration over time, with the service limit; brake split below."""
    fig, (ax, split) = plt.subplots(
        2, 1, figsize=(10, 6.2), sharex=True, height_ratios=[3, 2], dpi=110
    )
    first = next(iter(results.values()))
    for name, r in results.items():
        i = _moving(r)
        ax.plot(r["time_s"][i], -r["accel_mps2"][i], color=COLORS.get(name), label=name.upper())
        split.plot(
            r["time_s"][i],
            r["electric_n"][i] / 1e3,
            color=COLORS.get(name),
            lw=1,
            label=f"{name.upper()} electric",
        )
        split.plot(
            r["time_s"][i],
            r["air_n"][i] / 1e3,
            color=COLORS.get(name),
            lw=1,
            ls="--",
            label=f"{name.upper()} air",
        )
    i = _moving(first)
    ax.plot(first["time_s"][i], -first["ref_accel_mps2"][i], "k--", lw=1, label="target")
    ax.axhline(limit_mps2, color="red", lw=0.8, ls=":", label="max service deceleration")
    ax.set_ylabel("deceleration [m/s²]")
    ax.set_title("Deceleration")
    ax.legend(loc="lower center", ncol=4, fontsize=8)
    ax.grid(alpha=0.3)
    split.set_ylabel("brake force [kN]")
    split.set_xlabel("time [s]")
    split.legend(ncol=2, fontsize=8)
    split.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def speed_error(results: Mapping[str, SimResult], changeover_mps: float) -> Figure:
    """Fig. 6: speed error ``v - v_ref(t)`` over time, changeover marked.

    ``changeover_mps``: the scenario's electric/air changeover speed [m/s]; a dotted line
    marks when each train first reaches it.
    """
    fig, ax = plt.subplots(figsize=(10, 3.8), dpi=110)
    for name, r in results.items():
        i = _moving(r)
        err = r["speed_mps"][i] - r["ref_speed_mps"][i]
        ax.plot(r["time_s"][i], err, color=COLORS.get(name), label=name.upper())
        v = r["speed_mps"][i]
        below = np.nonzero(v <= changeover_mps)[0]
        if changeover_mps > 0.0 and len(below):
            ax.axvline(r["time_s"][i][below[0]], color=COLORS.get(name), lw=0.7, ls=":")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("speed error v - v_ref [m/s]")
    ax.set_title(
        f"Speed tracking error (dotted: train reaches the {_kmh_text(changeover_mps)} changeover)"
        if changeover_mps > 0.0
        else "Speed tracking error"
    )
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig
