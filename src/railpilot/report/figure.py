"""Writing a figure: every plot function returns a Figure, callers save it here."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure


def save_figure(fig: Figure, path: Path) -> Path:
    """Write ``fig`` to ``path`` at the figure's own resolution, close it, return ``path``."""
    fig.savefig(path, dpi=fig.dpi)
    plt.close(fig)
    return path
