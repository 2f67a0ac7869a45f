"""Gradient and curve resistance averaged over the length of the train.

The train is a uniform mass spread over its length ``L``. Travelling towards increasing
``x`` with its head at ``x`` it occupies ``[x - L, x]``; travelling towards decreasing ``x``
it occupies ``[x, x + L]``. Each metre of it feels the line's specific resistance ``w(s)``
[N/kN] under it, so the train as a whole feels the length average

    w_bar(x) = (1 / L) * integral_{x - L}^{x} w(s) ds = (W(x) - W(x - L)) / L,

where ``W`` is the running integral of ``w``. For a gradient ``W / 1000`` is the elevation
[m] (per mille times metres is millimetres), so ``w_bar`` is the height difference between
head and tail over the length; with curves added ``W`` is the "equivalent elevation" of the
Chinese traction rules' equivalent (converted) gradient ``i_j = i + w_r``.

:func:`elevation_table` turns a :class:`~railpilot.vehicle.line.Line` into the step
profile plus its running integral at every edge; :func:`mean_specific_resistance` (Numba,
scalar, for the kernel) and :func:`length_averaged_resistance` (NumPy, vectorised) then give
``w_bar`` with two binary searches: O(log n) per call, whatever the train's length.
The point model of ``Line.additional_resistance`` is the case ``L = 0``; the simulator's
loop (sim/engine.py) averages over the train's length.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.vehicle.line import Line, Segment

#: Direction of travel: towards increasing / decreasing position.
FORWARD = 1.0
BACKWARD = -1.0


class ResistanceTable(NamedTuple):
    """The line's gradient + curve resistance for one direction of travel.

    ``values_n_per_kn[i]`` [N/kN] holds on ``[edges_m[i], edges_m[i+1])`` and 0 outside
    ``[edges_m[0], edges_m[-1])``; ``cumulative[i]`` [N/kN m] is its integral from
    ``edges_m[0]`` to ``edges_m[i]`` (``len(edges_m) = len(cumulative) = n + 1``,
    ``len(values_n_per_kn) = n``).
    """

    edges_m: np.ndarray
    cumulative: np.ndarray
    values_n_per_kn: np.ndarray


def _check_direction(direction: float) -> float:
    if direction not in (FORWARD, BACKWARD):
        raise ConfigError(
            "direction", direction, "+1 (towards increasing x) or -1 (towards decreasing x)"
        )
    return float(direction)


def elevation_table(line: Line, direction: float = FORWARD) -> ResistanceTable:
    """Step profile of a line's gradient + curve resistance and its running integral.

    Parameters
    ----------
    line
        The line; its ``resistance_profile`` gives the steps.
    direction
        ``+1``: for a train travelling towards increasing position (the line's gradients
        as given, + uphill); ``-1``: towards decreasing position (every gradient's sign
        flipped; curve resistance, which opposes motion either way, is unchanged).

    Returns
    -------
    ResistanceTable
        ``(edges_m [m], cumulative [N/kN m], values_n_per_kn [N/kN])``.

    Notes
    -----
    ``cumulative = [0, cumsum(values * diff(edges))]``. For a line of gradients alone,
    ``cumulative / 1000`` is the elevation [m] of each edge above the first (for
    ``direction = +1``). Gradient and curve parts can be had separately by building the
    table of ``Line(gradients=line.gradients)`` and of ``Line(curves=line.curves)``.
    """
    if _check_direction(direction) == BACKWARD:
        line = Line(
            gradients=tuple(Segment(s.start_m, s.end_m, -s.value) for s in line.gradients),
            curves=line.curves,
        )
    edges, values = line.resistance_profile()
    edges = np.ascontiguousarray(edges, dtype=float)
    values = np.ascontiguousarray(values, dtype=float)
    cumulative = np.concatenate(([0.0], np.cumsum(values * np.diff(edges))))
    return ResistanceTable(edges, cumulative, values)


@njit(cache=True)
def _value_at(values: np.ndarray, i: int) -> float:
    """``values[i]``, or 0 for a segment index outside the profile."""
    if i < 0 or i >= values.shape[0]:
        return 0.0
    return values[i]


@njit(cache=True)
def mean_specific_resistance(
    edges: np.ndarray,
    cumulative: np.ndarray,
    values: np.ndarray,
    x_head: float,
    length_m: float,
    direction: float,
) -> float:
    """Length-averaged gradient + curve resistance [N/kN] of a train (Numba scalar).

    Parameters
    ----------
    edges, cumulative, values
        The three arrays of :func:`elevation_table` (built for the same ``direction``).
    x_head
        Position of the head [m].
    length_m
        Train length ``L`` [m] >= 0.
    direction
        ``>= 0``: travelling towards increasing x, the train occupies ``[x_head - L,
        x_head]``; ``< 0``: towards decreasing x, it occupies ``[x_head, x_head + L]``.

    Returns
    -------
    float
        The mean of the step profile over the occupied interval [N/kN] (0 outside the
        profile). ``L = 0`` gives the point value at the head, exactly as
        ``Line.additional_resistance``. The same arithmetic as
        :func:`length_averaged_resistance`.

    Notes
    -----
    With ``a < b`` the occupied interval, ``ia`` and ``ib`` the segments holding ``a``
    and ``b``: if ``ia == ib`` the mean is that segment's value (no subtraction, so no
    rounding for a short train); otherwise the integral is the tail piece
    ``w[ia] (e[ia+1] - a)``, the whole segments between, ``C[ib] - C[ia+1]``, and the head
    piece ``w[ib] (b - e[ib])``, divided by ``b - a``.
    """
    if length_m <= 0.0:
        return _value_at(values, int(np.searchsorted(edges, x_head, side="right")) - 1)
    if direction >= 0.0:
        a = x_head - length_m
        b = x_head
    else:
        a = x_head
        b = x_head + length_m
    ia = int(np.searchsorted(edges, a, side="right")) - 1
    ib = int(np.searchsorted(edges, b, side="right")) - 1
    if ia == ib:
        return _value_at(values, ia)
    tail = _value_at(values, ia) * (edges[ia + 1] - a)
    middle = cumulative[ib] - cumulative[ia + 1]
    head = _value_at(values, ib) * (b - edges[ib])
    return (tail + middle + head) / (b - a)


def length_averaged_resistance(
    table: ResistanceTable,
    x_head_m: npt.ArrayLike,
    length_m: npt.ArrayLike,
    direction: float = FORWARD,
) -> np.ndarray:
    """Gradient + curve resistance [N/kN] averaged over the length of a uniform train.

    Parameters
    ----------
    table
        :func:`elevation_table` of the line for this ``direction``.
    x_head_m
        Position of the head [m]; broadcast against ``length_m``.
    length_m
        Train length ``L`` [m] >= 0.
    direction
        ``+1``: travelling towards increasing x, occupying ``[x - L, x]``; ``-1``:
        towards decreasing x, occupying ``[x, x + L]``.

    Returns
    -------
    numpy.ndarray
        ``w_bar`` [N/kN], the broadcast shape of the inputs; times ``m g / 1000``
        (:func:`railpilot.units.specific_to_force_n`) it is the force [N] opposing motion.

    Notes
    -----
    ``w_bar = (1/L) integral over the occupied interval of w(s) ds``: the resultant of the
    gradient (and curve) forces on every metre of a uniform train. It is exact for the step
    profile, continuous in ``x`` (a grade change is felt linearly over the ``L / v``
    seconds the train takes to pass it) and tends to the point value at the head as
    ``L -> 0`` (at a grade change: the value on the side the train occupies). Rollback is
    not covered: curve resistance would change sign with the motion, gradient force not.
    :func:`mean_specific_resistance` is the Numba twin (same arithmetic, same order).
    """
    fwd = _check_direction(direction) == FORWARD
    edges, cumulative, values = table
    x, length = np.broadcast_arrays(
        np.asarray(x_head_m, dtype=float), np.asarray(length_m, dtype=float)
    )
    if not np.all(np.isfinite(length) & (length >= 0.0)):
        raise ConfigError("length_m", length_m, "finite lengths >= 0 [m]")
    n = values.shape[0]

    def value_at(i: np.ndarray) -> np.ndarray:
        return np.where((i >= 0) & (i < n), values[np.clip(i, 0, n - 1)], 0.0)

    a = x - length if fwd else x
    b = x if fwd else x + length
    ia = np.searchsorted(edges, a, side="right") - 1
    ib = np.searchsorted(edges, b, side="right") - 1
    ia1 = np.clip(ia + 1, 0, n)
    ibc = np.clip(ib, 0, n)
    tail = value_at(ia) * (edges[ia1] - a)
    middle = cumulative[ibc] - cumulative[ia1]
    head = value_at(ib) * (b - edges[ibc])
    span = b - a
    straddle = np.divide(
        tail + middle + head, span, out=np.zeros(span.shape), where=(ia != ib) & (span > 0.0)
    )
    point = value_at(np.searchsorted(edges, x, side="right") - 1)
    return np.where(length <= 0.0, point, np.where(ia == ib, value_at(ia), straddle))
