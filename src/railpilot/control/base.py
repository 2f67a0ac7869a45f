"""The interface every controller implements.

Habits from simple-pid: ``reset()``, output limits, anti-windup, internal terms
inspectable for tuning, ``dt`` always explicit, no clock and no sleeping.

Fast path
---------
Controllers keep their numbers in two float64 arrays, ``params`` (fixed by the
constructor) and ``state`` (changed by every update), and do their arithmetic in a
Numba ``@njit`` kernel taking ``(params, state, ...)``. The Python object calls
that kernel, and so does the simulator's compiled inner loop, so there is one
implementation of every control law.

The simulator's step
--------------------
The simulator calls one compiled function per controller, with this signature (the
*step* of a registry entry, control/registry.py, or of a user's compiled controller)::

    step(params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, u_min, u_max, dt) -> u

``ref_*``: the reference position [m], speed [m/s] and the acceleration the ATO feeds
forward [m/s^2]; ``x, v``: measured position and speed; ``resist_mps2``: the ATO's model
of the running resistance as a deceleration [m/s^2] (positive), for a feed-forward;
``u_min, u_max``: where the ATO will clamp ``u`` [m/s^2]; ``dt``: control period [s]. It
returns the commanded acceleration ``u`` [m/s^2] (negative brakes) and may change
``state``, and ``params`` (the simulator passes private copies of both).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from numbers import Integral, Real
from typing import ClassVar

import numpy as np

from railpilot.errors import is_finite_number, shown


class Controller(ABC):
    """A discrete-time controller that knows nothing about the plant it drives."""

    #: Short name used on the command line and in reports (``"pid"``, ``"smarc"``).
    name: ClassVar[str]

    params: np.ndarray
    state: np.ndarray

    @abstractmethod
    def reset(self) -> None:
        """Forget all history (integrators, filters, estimates) and start again."""

    @property
    @abstractmethod
    def components(self) -> dict[str, float]:
        """The internal terms of the last update (for tuning and plots)."""


def _as_float(value: object) -> float | None:
    """``value`` as a float if it is a real number (NumPy's included; not a bool, not
    an int too large for a float), else None. nan and inf are returned as such."""
    if type(value) is float:
        return value
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value.item()  # a 0-d array, e.g. from np.sum
    if not isinstance(value, Real) or isinstance(value, bool | np.bool_):
        return None
    try:
        return float(value)
    except (OverflowError, TypeError, ValueError):  # 10**400
        return None


def check_number(
    name: str,
    value: object,
    *,
    minimum: float | None = None,
    positive: bool = False,
    unit: str = "",
    allow_inf: bool = False,
    allow_nan: bool = False,
) -> float:
    """Return ``value`` as a float, or raise a ValueError naming ``name``.

    ``value`` must be a real number (an int, a float or a NumPy scalar; not a bool),
    finite, ``> 0`` if ``positive`` and ``>= minimum`` if given. ``allow_inf``: an
    infinity within those bounds is allowed too (``tau_d = inf``: no estimate);
    ``allow_nan``: nan is allowed (``stop_m = nan``: no stop point). ``unit`` is quoted
    in the message, e.g. ``"s"``.
    """
    number = _as_float(value)
    if number is not None:
        if math.isnan(number):
            ok = allow_nan
        else:
            ok = (
                (is_finite_number(number) or allow_inf)
                and (not positive or number > 0.0)
                and (minimum is None or number >= minimum)
            )
        if ok:
            return number
    bound = " > 0" if positive else (f" >= {minimum:g}" if minimum is not None else "")
    allowed = ("a number" if allow_inf else "a finite number") + bound
    if unit:
        allowed += f" [{unit}]"
    if allow_inf:
        allowed += " or inf"
    if allow_nan:
        allowed += " or nan"
    raise ValueError(f"{name} = {shown(value)} is not allowed: expected {allowed}")


def check_count(name: str, value: object, low: int, high: int) -> int:
    """Return ``value`` as an int, or raise a ValueError naming ``name`` unless it is a
    whole number (an int or a NumPy integer, not a bool) with ``low <= value <= high``."""
    if (
        isinstance(value, Integral)
        and not isinstance(value, bool | np.bool_)
        and low <= int(value) <= high
    ):
        return int(value)
    raise ValueError(
        f"{name} = {shown(value)} is not allowed: expected a whole number from {low} to {high}"
    )


def check_flag(name: str, value: object) -> bool:
    """Return ``value`` as a bool, or raise a ValueError naming ``name`` unless it is
    True or False (NumPy's included)."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    raise ValueError(f"{name} = {shown(value)} is not allowed: expected True or False")


def check_pair(name: str, value: object, size: int = 2, what: str = "a pair") -> tuple[object, ...]:
    """``value`` as a tuple of ``size`` items, or a ValueError naming ``name`` unless it
    is a tuple, a list or a NumPy array (along its first axis) of that length; the items
    are not checked."""
    sequence = isinstance(value, tuple | list) or (
        isinstance(value, np.ndarray) and value.ndim >= 1
    )
    if sequence and len(value) == size:  # type: ignore[arg-type]
        return tuple(value)  # type: ignore[arg-type]
    raise ValueError(f"{name} = {shown(value)} is not allowed: expected {what}")


def check_dt(dt: object) -> float:
    """Return ``dt`` [s] as a float, or raise ValueError if it is not > 0 and finite."""
    if type(dt) is float and 0.0 < dt < math.inf:  # the fast path (nan fails both)
        return dt
    return check_number("dt", dt, positive=True, unit="s")


def check_limits(limits: object) -> tuple[float, float]:
    """Turn ``(low, high)`` output limits (None = unbounded) into floats, low < high;
    a ValueError naming ``output_limits`` if they are no such pair."""
    allowed = "(low, high), each a number or None (unbounded)"
    bounds = []
    for i, (entry, unbounded) in enumerate(
        zip(check_pair("output_limits", limits, what=allowed), (-math.inf, math.inf), strict=True)
    ):
        bound = unbounded if entry is None else _as_float(entry)
        if bound is None or math.isnan(bound):
            raise ValueError(
                f"output_limits[{i}] = {shown(entry)} is not allowed: expected a number or "
                "None (unbounded)"
            )
        bounds.append(bound)
    low, high = bounds
    if not low < high:
        raise ValueError(
            f"output_limits = {shown(limits)} is not allowed: expected (low, high) with low < high"
        )
    return low, high
