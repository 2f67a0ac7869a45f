"""Figures of Monte Carlo sweeps: stop-error histograms."""

from __future__ import annotations

from collections.abc import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from railpilot.report.ep_plots import COLORS
from railpilot.sim.batch import MonteCarloResult


def stop_error_histogram(
    results: Mapping[str, MonteCarloResult], tolerance_m: float = 0.30, title: str = ""
) -> Figure:
    """Histograms of signed stop errors per controller: all runs, and a zoom on the band."""
    fig, (full, zoom) = plt.subplots(1, 2, figsize=(12, 4.2), dpi=110)
    finite = {n: r.stop_errors[np.isfinite(r.stop_errors)] for n, r in results.items()}
    all_err = np.concatenate(list(finite.values())) if finite else np.zeros(1)
    span = max(float(np.max(np.abs(all_err))) if all_err.size else 0.0, tolerance_m * 1.2)
    near = 3 * tolerance_m
    for name, r in results.items():
        err = finite[name]
        share = np.mean(np.abs(r.stop_errors) <= tolerance_m)
        label = f"{name.upper()}: {share:.1%} within ±{tolerance_m:g} m of {len(r.stop_errors)}"
        full.hist(
            err, bins=np.linspace(-span, span, 81), alpha=0.55, color=COLORS.get(name), label=label
        )
        # in the zoom, runs beyond the window are piled into its end bins
        zoom.hist(
            np.clip(err, -near, near),
            bins=np.linspace(-near, near, 61),
            alpha=0.55,
            color=COLORS.get(name),
        )
    full.set_yscale("log")
    full.set_title("all runs (log scale)")
    zoom.set_title(f"±{near:g} m (runs beyond piled into the end bins)")
    for ax in (full, zoom):
        ax.axvspan(-tolerance_m, tolerance_m, color="green", alpha=0.08)
        ax.axvline(0, color="k", lw=0.7)
        ax.set_xlabel("stop error [m] (+ beyond the stop point)")
        ax.grid(alpha=0.3)
    full.set_ylabel("runs")
    full.legend(fontsize=8)
    fig.suptitle(title or "Stop error distribution")
    fig.tight_layout()
    return fig
