"""Figures of paper 002 (precise stopping): tracking and displacement error."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure

from railpilot.report.ep_plots import COLORS, _moving
from railpilot.sim.result import SimResult


def tracking(results: Mapping[str, SimResult]) -> Figure:
    """Figs. 6-7: speed tracking over time and position error over time."""
    fig, (speed, pos) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, dpi=110)
    first = next(iter(results.values()))
    for name, r in results.items():
        i = _moving(r)
        speed.plot(r["time_s"][i], r["speed_mps"][i], color=COLORS.get(name), label=name.upper())
        pos.plot(
            r["time_s"][i],
            r["position_m"][i] - r["ref_position_m"][i],
            color=COLORS.get(name),
            label=name.upper(),
        )
    speed.plot(first["time_s"], first["ref_speed_mps"], "k--", lw=1, label="reference")
    speed.set_ylabel("speed [m/s]")
    speed.set_title("Speed tracking")
    pos.axhline(0, color="k", lw=0.6)
    pos.set_ylabel("x - x_ref [m]")
    pos.set_xlabel("time [s]")
    pos.set_title("Position tracking error")
    for ax in (speed, pos):
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    return fig


def position_error_runs(
    runs: Mapping[str, Sequence[SimResult]], tolerance_m: float, condition: str = ""
) -> Figure:
    """Fig. 8: displacement error over position for several seeded runs per controller.

    ``condition``: what the runs have in common, for the titles (e.g. the disturbance).
    """
    fig, axes = plt.subplots(
        1, len(runs), figsize=(6 * len(runs), 4), sharey=True, squeeze=False, dpi=110
    )
    for ax, (name, results) in zip(axes[0], runs.items(), strict=True):
        for r in results:
            i = _moving(r)
            ax.plot(
                r["ref_position_m"][i],
                r["position_m"][i] - r["ref_position_m"][i],
                color=COLORS.get(name),
                lw=0.7,
                alpha=0.6,
            )
        ax.axhspan(-tolerance_m, tolerance_m, color="green", alpha=0.08)
        ax.axhline(0, color="k", lw=0.6)
        title = f"{name.upper()}: {len(results)} runs"
        ax.set_title(f"{title}, {condition}" if condition else title)
        ax.set_xlabel("reference position [m]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("displacement error x - x_ref [m]")
    fig.tight_layout()
    return fig
