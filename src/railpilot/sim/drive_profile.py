"""A driving reference for a whole run: start, accelerate, cruise, obey limits, stop.

:class:`DriveProfile` is the flat-out (minimum-time) speed profile of train control --
full acceleration, speed holding, full braking (Howlett & Pudney, *Energy-Efficient
Train Control*, Springer 1995, ch. 2) -- between a start and a station stop, under a
cruise speed and line speed limits. It offers what a
:class:`~railpilot.sim.reference.BrakingCurve` offers (``sample(t) -> (x, v, a)``,
``duration_s``, ``start_m``, ``stop_m``, ``v0_mps``, ``speed_at_position``), so the
simulation's reference builders (:mod:`railpilot.sim.inputs`) take either.

Notes
-----
With ``u = x - start_m`` [m], ``D = stop_m - start_m``, acceleration ``a`` and
deceleration ``d`` [m/s^2], the target speed ``v*(u)`` [m/s] is the most restrictive of

(a) acceleration from the start, ``v^2 = v_start^2 + 2 a u``;
(b) the cruise speed, ``v^2 = V^2``;
(c) each limit ``lim`` on ``[s, e]`` (``e`` extended by the train length, so the limit
    holds until the tail has left), entered at or below it and left accelerating:
    ``v^2 = lim^2 + 2 d max(s - u, 0) + 2 a max(u - e, 0)``;
(d) braking to the stop, ``v^2 = 2 d (D - u)``.

Each constraint is, in ``v^2``, a maximum of straight lines in ``u``, so ``v*^2`` is
continuous and piecewise linear, and every kink is where two of those lines cross. The
minimum of the forward (acceleration) and backward (braking) envelopes equals the
sequential forward-backward pass of minimum-time profile planning, because ``a`` and
``d`` are constant: the profile is the fastest one the train can follow.

The knots are a uniform grid of ``dx_m`` plus every such crossing, so between two knots
``v^2`` is exactly linear in ``u``: the acceleration is constant, ``a = d(v^2)/(2 du)``,
and the time over a cell is exactly ``dt = 2 du / (v_i + v_{i+1})`` (the mean speed of a
uniform acceleration). This is the trapezoid rule on ``v`` in time, exact here, and
unlike the trapezoid rule on ``1/v`` it has no singularity where ``v = 0``: from rest the
first cell gives ``t = v / a`` exactly, and the last cell ends exactly at ``stop_m``.
Positions, speeds, accelerations and times are therefore exact up to rounding (about
``1e-12`` relative) for every ``dx_m``; ``dx_m`` only sets the density of the table.
Knots closer than :data:`MIN_CELL_M` are merged (``v^2`` then errs by at most
``2 max(a, d) MIN_CELL_M``). The jerk is not limited: the acceleration steps at kinks.

Starting from rest, branch (a) is 0 at the start and a distance-based controller would
see a zero target and never move the train; :meth:`DriveProfile.speed_at_position` uses
``max(min_speed, ...)`` for branch (a), so the target at the start is ``min_speed`` and
the controller commands traction. The time law (:meth:`DriveProfile.sample`) is the
physical one without the floor (``v = a t`` from rest, ``a(0) = accel``): the two differ
only for ``u < (min_speed^2 - v_start^2) / (2 a)``, where ``v(t) < speed_at_position``.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from railpilot.errors import ConfigError
from railpilot.units import mps_to_kmh
from railpilot.vehicle.train import MAX_SPEED_KMH, MAX_SPEED_MPS

#: Knots closer than this [m] are merged.
MIN_CELL_M = 1e-6
#: Most knots a profile may have (guards against a tiny ``dx_m`` on a long run).
MAX_GRID_POINTS = 10_000_000
#: Default largest spacing of the knots [m] (a scenario file's drive uses it).
DEFAULT_DX_M = 1.0


@dataclass(frozen=True)
class DriveProfile:
    """Minimum-time driving reference from ``start_m`` to a stop at ``stop_m``.

    Build it with :func:`drive_profile`; the constructor validates the same way.

    Attributes
    ----------
    start_m, stop_m
        Start position and stop point [m], ``stop_m > start_m``.
    cruise_mps
        Cruise speed [m/s], > 0.
    accel_mps2, decel_mps2
        Acceleration and service deceleration of the profile [m/s^2], > 0.
    limits
        Speed-limit segments ``(start_m, end_m, limit_mps)``; each must overlap the run.
    v_start_mps
        Speed at ``start_m`` [m/s], >= 0, at most what (b)-(d) allow there.
    min_speed_mps
        Floor of the acceleration branch in :meth:`speed_at_position` [m/s], >= 0.
    train_length_m
        Train length [m], >= 0: each limit holds until the tail has left its segment.
    dx_m
        Largest spacing of the tabulated knots [m], > 0.
    """

    start_m: float
    stop_m: float
    cruise_mps: float
    accel_mps2: float
    decel_mps2: float
    limits: tuple[tuple[float, float, float], ...] = ()
    v_start_mps: float = 0.0
    min_speed_mps: float = 0.5
    train_length_m: float = 0.0
    dx_m: float = DEFAULT_DX_M
    # the knots: times [s], positions [m], speeds [m/s]; per cell: acceleration [m/s^2]
    _t: np.ndarray = field(init=False, repr=False, compare=False)
    _x: np.ndarray = field(init=False, repr=False, compare=False)
    _v: np.ndarray = field(init=False, repr=False, compare=False)
    _a: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._validate()
        u = self._knots_u()
        v2 = self._target_sq(u, floored=False)
        v = np.sqrt(v2)
        du = np.diff(u)
        a = np.diff(v2) / (2.0 * du)
        dt = 2.0 * du / (v[:-1] + v[1:])
        t = np.concatenate(([0.0], np.cumsum(dt)))
        x = self.start_m + u
        x[-1] = self.stop_m
        for name, arr in (("_t", t), ("_x", x), ("_v", v), ("_a", a)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    # --- the public, BrakingCurve-like interface ------------------------------------------

    @property
    def v0_mps(self) -> float:
        """Speed at ``start_m`` and t = 0 [m/s] (``v_start_mps``)."""
        return float(self.v_start_mps)

    @property
    def duration_s(self) -> float:
        """Time from the start to standstill at ``stop_m`` [s]."""
        return float(self._t[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference ``(position [m], speed [m/s], acceleration [m/s^2])`` at times ``t`` [s].

        Exact piecewise uniform acceleration between knots (module Notes), so
        ``a = v dv/dx``. Like :meth:`BrakingCurve.sample`: before t = 0 the state at
        t = 0; from ``duration_s`` on, at rest at ``stop_m`` with ``a = 0`` (just before
        it the acceleration is ``-decel_mps2``).
        """
        return sample_knots(t, self._t, self._x, self._v, self._a, self.stop_m)

    def speed_at_position(self, position_m: np.ndarray) -> np.ndarray:
        """Target speed [m/s] at ``position_m`` [m] (the speed-distance curve), exact.

        The acceleration branch is floored at ``min_speed_mps`` (module Notes), so from
        rest the target at ``start_m`` is ``min_speed_mps``, not 0. Before ``start_m``
        the target at ``start_m``; at and beyond ``stop_m``, 0.
        """
        u = np.clip(np.asarray(position_m, dtype=float) - self.start_m, 0.0, None)
        return np.sqrt(self._target_sq(u, floored=True))

    # --- construction -------------------------------------------------------------------

    def _limits_u(self) -> list[tuple[float, float, float]]:
        """The limits as ``(s, e, lim)`` with ``s, e`` relative to the start, ``e`` extended."""
        return [
            (s - self.start_m, e + self.train_length_m - self.start_m, lim)
            for s, e, lim in self.limits
        ]

    def _target_sq(self, u: np.ndarray, floored: bool) -> np.ndarray:
        """``v*(u)^2`` [m^2/s^2], the most restrictive of (a)-(d) (module Notes)."""
        a, d = self.accel_mps2, self.decel_mps2
        dist = self.stop_m - self.start_m
        accel = self.v_start_mps**2 + 2.0 * a * u
        if floored:
            accel = np.maximum(accel, self.min_speed_mps**2)
        v2 = np.minimum(accel, self.cruise_mps**2)
        v2 = np.minimum(v2, 2.0 * d * (dist - u))
        for s, e, lim in self._limits_u():
            limit = lim**2 + 2.0 * d * np.maximum(s - u, 0.0) + 2.0 * a * np.maximum(u - e, 0.0)
            v2 = np.minimum(v2, limit)
        return np.maximum(v2, 0.0)

    def _lines(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every line ``v^2 = c + m u`` the target is made of, with the interval
        ``[lo, hi]`` of ``u`` where it can be the active piece: ``(m, c, lo, hi)``."""
        a, d = self.accel_mps2, self.decel_mps2
        dist = self.stop_m - self.start_m
        inf = np.inf
        rows = [
            (2.0 * a, self.v_start_mps**2, -inf, inf),  # (a) acceleration from the start
            (0.0, self.min_speed_mps**2, -inf, inf),  # its floor
            (0.0, self.cruise_mps**2, -inf, inf),  # (b) cruise
            (-2.0 * d, 2.0 * d * dist, -inf, inf),  # (d) braking to the stop
        ]
        for s, e, lim in self._limits_u():  # (c) entry ramp, the limit, exit ramp
            rows.append((-2.0 * d, lim**2 + 2.0 * d * s, -inf, s))
            rows.append((0.0, lim**2, s, e))
            rows.append((2.0 * a, lim**2 - 2.0 * a * e, e, inf))
        m, c, lo, hi = (np.array(col) for col in zip(*rows, strict=True))
        return m, c, lo, hi

    def _breakpoints(self) -> np.ndarray:
        """Every ``u`` where two lines of :meth:`_lines`, both where they can be active,
        cross: a superset of the kinks of ``v*^2``. O(lines^2) time, O(lines) memory."""
        m, c, lo, hi = self._lines()
        tol = MIN_CELL_M
        found = [lo[np.isfinite(lo)], hi[np.isfinite(hi)]]
        for i in range(len(m) - 1):
            dm = m[i] - m[i + 1 :]
            crossing = dm != 0.0
            with np.errstate(divide="ignore", invalid="ignore"):
                u = (c[i + 1 :] - c[i]) / dm
            crossing &= (u >= lo[i] - tol) & (u <= hi[i] + tol)
            crossing &= (u >= lo[i + 1 :] - tol) & (u <= hi[i + 1 :] + tol)
            found.append(u[crossing])
        return np.concatenate(found)

    def _knots_u(self) -> np.ndarray:
        """Knot positions relative to the start: the ``dx_m`` grid and every breakpoint."""
        dist = self.stop_m - self.start_m
        tol = MIN_CELL_M
        bp = self._breakpoints()
        bp = np.unique(bp[(bp > tol) & (bp < dist - tol)])
        if bp.size:
            bp = bp[np.concatenate(([True], np.diff(bp) > tol))]
        n_cells = max(1, int(np.ceil(dist / self.dx_m - 1e-9)))
        grid = np.linspace(0.0, dist, n_cells + 1)
        if bp.size:  # a grid point next to a breakpoint gives way to it
            j = np.clip(np.searchsorted(bp, grid), 1, bp.size) - 1
            near = np.minimum(
                np.abs(grid - bp[j]), np.abs(grid - bp[np.minimum(j + 1, bp.size - 1)])
            )
            inner = (grid > 0.0) & (grid < dist)
            grid = grid[~(inner & (near <= tol))]
        u = np.unique(np.concatenate((grid, bp)))
        u[0], u[-1] = 0.0, dist
        return u

    def _validate(self) -> None:
        _check_finite("reference.start_m", self.start_m)
        if not (np.isfinite(self.stop_m) and self.stop_m > self.start_m):
            raise ConfigError(
                "reference.stop_m",
                self.stop_m,
                f"a finite position > reference.start_m ({self.start_m})",
            )
        for name, value in (
            ("reference.cruise_mps", self.cruise_mps),
            ("reference.accel_mps2", self.accel_mps2),
            ("reference.decel_mps2", self.decel_mps2),
            ("reference.dx_m", self.dx_m),
        ):
            _check_positive(name, value)
        for name, value in (
            ("reference.v_start_mps", self.v_start_mps),
            ("reference.min_speed_mps", self.min_speed_mps),
            ("reference.train_length_m", self.train_length_m),
        ):
            _check_non_negative(name, value)
        # bounded: the target squares speeds (v**2), which overflows floats far beyond
        for name, value in (
            ("reference.cruise_mps", self.cruise_mps),
            ("reference.v_start_mps", self.v_start_mps),
        ):
            if value > MAX_SPEED_MPS:
                raise ConfigError(
                    name, value, f"a speed <= {MAX_SPEED_MPS:.4g} m/s ({MAX_SPEED_KMH:g} km/h)"
                )
        dist = self.stop_m - self.start_m
        if dist / self.dx_m > MAX_GRID_POINTS:
            raise ConfigError(
                "reference.dx_m",
                self.dx_m,
                f"a step >= {dist / MAX_GRID_POINTS:.4g} m (at most {MAX_GRID_POINTS} knots)",
            )
        for i, seg in enumerate(self.limits):
            _check_limit(i, seg, self.start_m, self.stop_m, self.train_length_m)
        allowed = float(np.sqrt(self._target_sq(np.array([0.0]), floored=False)[0]))
        v_start = self.v_start_mps
        if v_start > allowed * (1.0 + 1e-12):
            raise ConfigError(
                "reference.v_start_mps",
                v_start,
                f"a speed <= {allowed:.6g} m/s ({mps_to_kmh(allowed):.6g} km/h): what the cruise "
                "speed, the limits and the stop allow at the start",
            )


def sample_knots(
    t: np.ndarray,
    tk: np.ndarray,
    xk: np.ndarray,
    vk: np.ndarray,
    ak: np.ndarray,
    stop_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, v, a)`` at times ``t`` [s] on knots of uniform acceleration per cell.

    ``tk, xk, vk`` the knots' times [s], positions [m] and speeds [m/s], ``ak`` each
    cell's acceleration [m/s^2]; before the first knot the first state, from the last on
    at rest at ``stop_m`` (module Notes).
    """
    t = np.asarray(t, dtype=float)
    n_cells = len(ak)
    idx = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, n_cells)
    at_rest = idx == n_cells
    cell = np.minimum(idx, n_cells - 1)
    h = np.clip(t - tk[cell], 0.0, None)
    a = ak[cell]
    v = np.maximum(vk[cell] + a * h, 0.0)
    x = np.minimum(xk[cell] + h * (vk[cell] + v) / 2.0, xk[cell + 1])
    x = np.where(at_rest, stop_m, x)
    v = np.where(at_rest, 0.0, v)
    a = np.where(at_rest, 0.0, a)
    return x, v, a


@dataclass(frozen=True)
class PlannedProfile:
    """A driving reference from a table of speeds by position (the onboard planner's).

    ``x_m`` [m] strictly increasing from the start to the stop point, ``v_mps`` [m/s] the
    planned speed at each, 0 at the stop (and at the start for a start from rest). Between
    knots ``v^2`` is linear in ``x`` (uniform acceleration, as the planner's passes
    compute it), so the time law is exact, as :class:`DriveProfile`'s: the same interface
    (``sample``, ``duration_s``, ``start_m``, ``stop_m``, ``v0_mps``,
    ``speed_at_position``), for the simulator's reference builders.
    """

    x_m: np.ndarray
    v_mps: np.ndarray
    min_speed_mps: float = 0.5
    _t: np.ndarray = field(init=False, repr=False, compare=False)
    _a: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        x = np.array(self.x_m, dtype=float)
        v = np.array(self.v_mps, dtype=float)
        if x.ndim != 1 or x.size < 2 or v.shape != x.shape:
            raise ConfigError("reference.x_m", x.shape, "two or more positions, one speed each")
        if not (np.all(np.isfinite(x)) and np.all(np.diff(x) > 0)):
            raise ConfigError("reference.x_m", self.x_m, "finite, strictly increasing positions")
        if not (np.all(np.isfinite(v)) and np.all(v >= 0) and v[-1] == 0.0):
            raise ConfigError("reference.v_mps", self.v_mps, "finite speeds >= 0, 0 at the stop")
        if np.any((v[:-1] == 0) & (v[1:] == 0)):
            raise ConfigError("reference.v_mps", self.v_mps, "no cell at rest before the stop")
        du = np.diff(x)
        a = np.diff(v * v) / (2.0 * du)
        t = np.concatenate(([0.0], np.cumsum(2.0 * du / (v[:-1] + v[1:]))))
        for name, arr in (("x_m", x), ("v_mps", v), ("_t", t), ("_a", a)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def start_m(self) -> float:
        return float(self.x_m[0])

    @property
    def stop_m(self) -> float:
        return float(self.x_m[-1])

    @property
    def v0_mps(self) -> float:
        return float(self.v_mps[0])

    @property
    def duration_s(self) -> float:
        return float(self._t[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference ``(position [m], speed [m/s], acceleration [m/s^2])`` at times ``t``."""
        return sample_knots(t, self._t, self.x_m, self.v_mps, self._a, self.stop_m)

    def speed_at_position(self, position_m: np.ndarray) -> np.ndarray:
        """Planned speed [m/s] at ``position_m`` [m] (``v^2`` linear between knots), floored
        at ``min_speed_mps`` before the first moving knot so a distance-based controller
        starts the train; 0 at and beyond the stop."""
        x = np.asarray(position_m, dtype=float)
        v2 = np.interp(x, self.x_m, self.v_mps**2)
        peak = int(np.argmax(self.v_mps))
        floor = np.where(x < self.x_m[peak], self.min_speed_mps**2, 0.0)
        v2 = np.where(x >= self.stop_m, 0.0, np.maximum(v2, floor))
        return np.sqrt(v2)


def drive_profile(
    start_m: float,
    stop_m: float,
    cruise_mps: float,
    accel_mps2: float,
    decel_mps2: float,
    limits: Iterable[Sequence[float]] = (),
    v_start_mps: float = 0.0,
    min_speed_mps: float = 0.5,
    dx_m: float = DEFAULT_DX_M,
    train_length_m: float = 0.0,
) -> DriveProfile:
    """The minimum-time driving reference of a run (see :class:`DriveProfile`).

    Parameters
    ----------
    start_m, stop_m
        Start position and stop point [m], ``stop_m > start_m``.
    cruise_mps
        Cruise speed [m/s].
    accel_mps2, decel_mps2
        Acceleration and deceleration of the profile [m/s^2].
    limits
        Speed-limit segments ``(start_m, end_m, limit_mps)`` [m, m, m/s]; each must
        overlap the run, limits may overlap each other (the lowest holds).
    v_start_mps
        Speed at the start [m/s]; 0 = from rest.
    min_speed_mps
        Floor of the acceleration branch of the speed-distance target [m/s], so a
        distance-based controller commands traction from rest.
    dx_m
        Largest spacing of the knots [m]; the profile is exact for any value.
    train_length_m
        Train length [m]: each limit is extended by it on its exit side.

    Raises
    ------
    ConfigError
        Naming the field (``reference.cruise_mps``, ``reference.limits[2]``, ...).
    """
    segs: list[tuple[float, float, float]] = []
    for i, seg in enumerate(limits):
        try:
            s, e, lim = (float(value) for value in seg)
        except (TypeError, ValueError):
            raise ConfigError(
                f"reference.limits[{i}]", seg, "a (start_m, end_m, limit_mps) triple of numbers"
            ) from None
        segs.append((s, e, lim))
    return DriveProfile(
        start_m=float(start_m),
        stop_m=float(stop_m),
        cruise_mps=float(cruise_mps),
        accel_mps2=float(accel_mps2),
        decel_mps2=float(decel_mps2),
        limits=tuple(segs),
        v_start_mps=float(v_start_mps),
        min_speed_mps=float(min_speed_mps),
        train_length_m=float(train_length_m),
        dx_m=float(dx_m),
    )


def _check_finite(name: str, value: float) -> None:
    if not np.isfinite(value):
        raise ConfigError(name, value, "a finite number")


def _check_positive(name: str, value: float) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ConfigError(name, value, "a finite number > 0")


def _check_non_negative(name: str, value: float) -> None:
    if not (np.isfinite(value) and value >= 0):
        raise ConfigError(name, value, "a finite number >= 0")


def _check_limit(
    i: int, seg: tuple[float, ...], start_m: float, stop_m: float, length_m: float
) -> None:
    name = f"reference.limits[{i}]"
    if len(seg) != 3:
        raise ConfigError(name, seg, "a (start_m, end_m, limit_mps) triple")
    s, e, lim = seg
    if not (np.isfinite(s) and np.isfinite(e) and e > s):
        raise ConfigError(name, seg, "finite start_m < end_m")
    if not (np.isfinite(lim) and lim > 0):
        raise ConfigError(name, seg, "a finite limit_mps > 0")
    if not (s < stop_m and e + length_m > start_m):
        raise ConfigError(
            name,
            seg,
            f"a segment overlapping the run [{start_m}, {stop_m}] m "
            "(positions in m, like reference.start_m and reference.stop_m)",
        )
