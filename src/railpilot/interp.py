"""Linear interpolation at one point, for compiled loops.

Why not ``np.interp``: Numba's ``np.interp`` at a scalar builds arrays on every call (the
point as a 0-d array, the result, an empty slope table) and so costs 70-150 ns; the
simulator's loop calls it a few times a step and the precise-stop controller's
prediction once a predicted step, hundreds of times a control period while it stops
(benchmarks/line_speed.py). :func:`interp_at` does the same search and the same
arithmetic as NumPy's ``interp`` (numpy/_core/src/multiarray/compiled_base.c, which
Numba's follows), so it returns the same float, to the bit, in 15-80 ns
(tests/test_interp.py compares the two).
"""

from __future__ import annotations

import numpy as np

from railpilot.jit import njit


@njit(cache=True, inline="always")
def interp_at(x: float, xp: np.ndarray, fp: np.ndarray) -> float:
    """``np.interp(x, xp, fp)`` for one point ``x``, bit for bit.

    ``xp`` increasing (repeated knots allowed, as NumPy allows them), ``fp`` as long and
    at least one knot; held at ``fp[0]`` / ``fp[-1]`` beyond the ends, NaN at a NaN ``x``
    (``fp[0]`` with a single knot, as NumPy gives).
    """
    n = xp.shape[0]
    if n == 1:
        return fp[0]
    if np.isnan(x):
        return x
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    # the last knot at or before x (NumPy's search finds the same one, repeated knots too)
    lo = 0
    hi = n
    while lo < hi:
        mid = (lo + hi) >> 1
        if x >= xp[mid]:
            lo = mid + 1
        else:
            hi = mid
    j = lo - 1
    if j == n - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if np.isnan(y):
        # as NumPy: a NaN one way (an infinite slope) is tried the other way
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(y) and fp[j] == fp[j + 1]:
            y = fp[j]
    return y
