"""Torque table plant ``M(I, v)``: the brake body of paper 003 section 2.1.

The paper's brake body is a finite-element torque table looked up by coil current and
train speed (its fig. 4). :class:`TorqueTable` holds such a table as three float64 arrays
(current axis [A], speed axis [m/s], torque [N m] of shape ``(n_current, n_speed)``) and
interpolates bilinearly in the Numba kernel :func:`table_torque_nm`, which the compiled
simulation loop calls directly. A table is either generated from the analytic model
(:meth:`TorqueTable.from_model`) or parsed from a user's CSV (:func:`parse_torque_table_csv`;
:func:`load_torque_table_csv` is the thin file reader).

CSV layout (wide matrix, speeds in km/h because FE reports use them)::

    current_a,0,10,20,...        <- header: a label, then the speed axis [km/h]
    0,0,0,0,...                  <- one row per current [A]: current, torques [N m]
    10,0,12.5,17.1,...

Outside the table the inputs are clamped to its edges (no extrapolation): a brake
cannot be trusted beyond the data it was characterised with.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from railpilot.checks import check_number
from railpilot.eddy.torque_model import EddyBrakeParams, eddy_torque_at_speed_nm
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.textfile import read_text
from railpilot.units import kmh_to_mps, mps_to_kmh
from railpilot.vehicle.train import MAX_SPEED_KMH

MIN_POINTS = 2


@njit(cache=True)
def _bracket(axis: np.ndarray, x: float) -> tuple[int, float]:
    """Index ``i`` with ``axis[i] <= x <= axis[i+1]`` and the fraction along it (clamped)."""
    n = axis.shape[0]
    if x <= axis[0]:
        return 0, 0.0
    if x >= axis[n - 1]:
        return n - 2, 1.0
    i = int(np.searchsorted(axis, x, side="right")) - 1
    return i, float((x - axis[i]) / (axis[i + 1] - axis[i]))


@njit(cache=True)
def table_torque_nm(
    currents_a: np.ndarray,
    speeds_mps: np.ndarray,
    torque_nm: np.ndarray,
    current_a: float,
    speed_mps: float,
) -> float:
    """Bilinear interpolation of ``torque_nm[i, j] = M(currents_a[i], speeds_mps[j])``.

    Inputs outside the axes are clamped to the nearest edge.
    """
    i, fi = _bracket(currents_a, current_a)
    j, fj = _bracket(speeds_mps, speed_mps)
    m00 = torque_nm[i, j]
    m01 = torque_nm[i, j + 1]
    m10 = torque_nm[i + 1, j]
    m11 = torque_nm[i + 1, j + 1]
    return (1.0 - fi) * ((1.0 - fj) * m00 + fj * m01) + fi * ((1.0 - fj) * m10 + fj * m11)


def _as_array(name: str, value: object, allowed: str) -> np.ndarray:
    """``value`` as a contiguous float64 array, or a ConfigError naming ``name``."""
    try:
        return np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # 'x', [None, 'x'], 10**400, 1j
        raise ConfigError(name, value, allowed) from None


def _check_axis(name: str, axis: object) -> np.ndarray:
    axis = _as_array(name, axis, f"a one-dimensional axis of numbers, at least {MIN_POINTS}")
    if axis.ndim != 1 or axis.size < MIN_POINTS:
        raise ConfigError(
            name, axis.tolist(), f"a one-dimensional axis with at least {MIN_POINTS} points"
        )
    if not np.all(np.isfinite(axis)):
        bad = int(np.flatnonzero(~np.isfinite(axis))[0])
        raise ConfigError(f"{name}[{bad}]", float(axis[bad]), "a finite number (no NaN/inf)")
    steps = np.diff(axis)
    if np.any(steps <= 0.0):
        bad = int(np.flatnonzero(steps <= 0.0)[0])
        raise ConfigError(
            f"{name}[{bad + 1}]",
            float(axis[bad + 1]),
            f"a value > {name}[{bad}] = {axis[bad]} (the axis must increase strictly)",
        )
    if axis[0] < 0.0:
        raise ConfigError(f"{name}[0]", float(axis[0]), "a value >= 0")
    return axis


#: largest analytic grid (currents x speeds): 10 million points, 80 MB of float64
MAX_GRID_POINTS = 10_000_000


@dataclass(frozen=True)
class TorqueTable:
    """A validated torque table ``M(I, v)``.

    Attributes
    ----------
    currents_a
        Coil-current axis [A], strictly increasing, >= 0.
    speeds_mps
        Train-speed axis [m/s], strictly increasing, >= 0.
    torque_nm
        Braking torque [N m], shape ``(currents_a.size, speeds_mps.size)``, finite, >= 0.
    source
        Where it came from (``"analytic model"`` or the CSV's name), for reports.
    """

    currents_a: np.ndarray
    speeds_mps: np.ndarray
    torque_nm: np.ndarray
    source: str = "user"

    def __post_init__(self) -> None:
        if not isinstance(self.source, str):
            raise ConfigError("table.source", self.source, "a string")
        currents = _check_axis("table.currents_a", self.currents_a)
        speeds = _check_axis("table.speeds_mps", self.speeds_mps)
        torque = _as_array(
            "table.torque_nm", self.torque_nm, "an array of numbers, one row per current"
        )
        expected = (currents.size, speeds.size)
        if torque.shape != expected:
            raise ConfigError(
                "table.torque_nm",
                f"array of shape {torque.shape}",
                f"shape {expected} (one row per current, one column per speed)",
            )
        if not np.all(np.isfinite(torque)):
            i, j = np.argwhere(~np.isfinite(torque))[0]
            raise ConfigError(
                f"table.torque_nm[{i}, {j}]", float(torque[i, j]), "a finite number (no NaN/inf)"
            )
        if np.any(torque < 0.0):
            i, j = np.argwhere(torque < 0.0)[0]
            raise ConfigError(
                f"table.torque_nm[{i}, {j}]", float(torque[i, j]), "a braking torque >= 0"
            )
        object.__setattr__(self, "currents_a", currents)
        object.__setattr__(self, "speeds_mps", speeds)
        object.__setattr__(self, "torque_nm", torque)

    @classmethod
    def from_model(
        cls,
        brake: EddyBrakeParams | None = None,
        *,
        max_current_a: float = 500.0,
        current_step_a: float = 2.0,
        max_speed_kmh: float = 300.0,
        speed_step_kmh: float = 0.5,
    ) -> TorqueTable:
        """Tabulate the analytic model (eq. 24) on a regular grid.

        The default 2 A x 0.5 km/h grid keeps the bilinear error of the ``M ~ I^2``
        surface below 0.05 N m at the currents the controllers use (checked in tests).
        """
        brake = EddyBrakeParams() if brake is None else brake
        for name, value in (
            ("table.max_current_a", max_current_a),
            ("table.current_step_a", current_step_a),
            ("table.max_speed_kmh", max_speed_kmh),
            ("table.speed_step_kmh", speed_step_kmh),
        ):
            check_number(name, value, positive=True, error=ConfigError)
        # the table must cover the run's speeds (<= 400 km/h), not overflow round() below
        if max_speed_kmh > MAX_SPEED_KMH:
            raise ConfigError(
                "table.max_speed_kmh", max_speed_kmh, f"a speed in (0, {MAX_SPEED_KMH:g}] km/h"
            )
        # a step wider than its range would silently give the minimal grid instead
        for name, step, top_name, top in (
            ("table.current_step_a", current_step_a, "table.max_current_a", max_current_a),
            ("table.speed_step_kmh", speed_step_kmh, "table.max_speed_kmh", max_speed_kmh),
        ):
            if step > top:
                raise ConfigError(name, step, f"a step in (0, {top_name} = {top:g}]")
        ratio_i = max_current_a / current_step_a
        ratio_v = max_speed_kmh / speed_step_kmh
        # a ratio past a float's range (1e300 A in 1e-10 A steps) is inf: no round() of it
        too_many = max(ratio_i, ratio_v) > MAX_GRID_POINTS
        n_i = 0 if too_many else round(ratio_i) + 1
        n_v = 0 if too_many else round(ratio_v) + 1
        # a grid is a table in memory: refuse one that could not be built (or used)
        if too_many or n_i * n_v > MAX_GRID_POINTS:
            given = " x ".join(
                f"{round(r) + 1:,}" if r <= MAX_GRID_POINTS else f"{r:.3g}"
                for r in (ratio_i, ratio_v)
            )
            raise ConfigError(
                "table.current_step_a / table.speed_step_kmh",
                (current_step_a, speed_step_kmh),
                f"steps giving at most {MAX_GRID_POINTS:,} grid points (these give {given})",
            )
        currents = np.linspace(0.0, max_current_a, max(n_i, MIN_POINTS))
        speeds = kmh_to_mps(np.linspace(0.0, max_speed_kmh, max(n_v, MIN_POINTS)))
        torque = eddy_torque_at_speed_nm(currents[:, None], speeds[None, :], brake)
        return cls(currents, speeds, torque, source="analytic model (eq. 19-24)")

    def torque(self, current_a: float, speed_mps: float) -> float:
        """Interpolated torque [N m] at one (current [A], speed [m/s]) point."""
        return float(
            table_torque_nm(
                self.currents_a, self.speeds_mps, self.torque_nm, float(current_a), float(speed_mps)
            )
        )

    def torque_many(self, current_a: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`torque` over broadcast arrays of currents [A] and speeds [m/s]."""
        cur, spd = np.broadcast_arrays(
            np.asarray(current_a, dtype=float), np.asarray(speed_mps, dtype=float)
        )
        out = np.empty(cur.shape)
        for idx in np.ndindex(cur.shape):
            out[idx] = self.torque(float(cur[idx]), float(spd[idx]))
        return out

    def current_for_torque_a(self, torque_nm: float, speed_mps: float) -> float:
        """Smallest tabulated current [A] giving ``torque_nm`` at ``speed_mps`` (bisection).

        Returns the top of the current axis if even that is not enough.
        """
        lo, hi = float(self.currents_a[0]), float(self.currents_a[-1])
        if self.torque(hi, speed_mps) < torque_nm:
            return hi
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if self.torque(mid, speed_mps) < torque_nm:
                lo = mid
            else:
                hi = mid
        return hi

    def to_csv_text(self) -> str:
        """The table in the CSV layout :func:`parse_torque_table_csv` reads."""
        buf = io.StringIO()
        header = ["current_a"] + [f"{s:.10g}" for s in mps_to_kmh(self.speeds_mps)]
        buf.write(",".join(header) + "\n")
        for current, row in zip(self.currents_a, self.torque_nm, strict=True):
            buf.write(",".join([f"{current:.10g}"] + [f"{m:.10g}" for m in row]) + "\n")
        return buf.getvalue()


def parse_torque_table_csv(text: str, source: str = "csv") -> TorqueTable:
    """Parse the wide CSV layout described in the module docstring into a table."""
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    if len(lines) < 1 + MIN_POINTS:
        raise ConfigError(
            f"{source}: rows",
            len(lines) - 1 if lines else 0,
            f"a header row and at least {MIN_POINTS} current rows",
        )
    rows = [ln.split(",") for ln in lines]
    width = len(rows[0])
    for line_no, row in enumerate(rows[1:], start=2):
        if len(row) != width:
            raise ConfigError(
                f"{source}: line {line_no}",
                f"{len(row)} cells",
                f"{width} cells like the header (current, then one torque per speed)",
            )

    def to_number(cell: str, where: str) -> float:
        try:
            return float(cell)
        except ValueError:
            raise ConfigError(f"{source}: {where}", cell, "a number") from None

    speeds_kmh = np.array(
        [to_number(c, f"header column {k + 2}") for k, c in enumerate(rows[0][1:])]
    )
    data = np.array(
        [
            [to_number(c, f"line {r + 2} column {k + 1}") for k, c in enumerate(row)]
            for r, row in enumerate(rows[1:])
        ]
    )
    return TorqueTable(
        currents_a=data[:, 0],
        speeds_mps=kmh_to_mps(speeds_kmh),
        torque_nm=data[:, 1:],
        source=source,
    )


def load_torque_table_csv(path: str | Path) -> TorqueTable:
    """Read a torque table CSV file (thin reader over :func:`parse_torque_table_csv`)."""
    path = Path(path)
    text = read_text(path, "table.csv", "CSV file")
    return parse_torque_table_csv(text, source=path.name)
