"""The checks a constructor runs on its arguments: bad input gets a clear error, never a crash.

Each check returns the value in its plain Python type (a float, an int, a bool) or raises
an error naming the argument, the value and what is allowed::

    delay_s = 'x' is not allowed: expected a finite number >= 0 [s]

The controllers (railpilot.control) raise a plain ValueError; the physical models
(railpilot.brakes, railpilot.vehicle, railpilot.eddy) pass ``error=ConfigError`` (or a
subclass), whose ``field``, ``value`` and ``allowed`` the scenario loaders turn into the
file's words, and ``allowed=`` to keep their own wording of what is allowed. The message
is the same either way.

Constructors only: these run once per object, never per simulation step.
"""

from __future__ import annotations

import math
from numbers import Integral, Real
from typing import NoReturn

import numpy as np

from railpilot.errors import ConfigError, is_finite_number, shown


def as_float(value: object) -> float | None:
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


def refuse(
    name: str, value: object, allowed: str, error: type[ValueError] = ValueError
) -> NoReturn:
    """Raise ``error`` saying ``name = value is not allowed: expected allowed``.

    A :class:`~railpilot.errors.ConfigError` (or subclass) is given the three parts, so it
    keeps them as ``field``, ``value`` and ``allowed``; any other ValueError the message.
    """
    if issubclass(error, ConfigError):
        raise error(name, value, allowed)
    raise error(f"{name} = {shown(value)} is not allowed: expected {allowed}")


def check_number(
    name: str,
    value: object,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    positive: bool = False,
    unit: str = "",
    allow_inf: bool = False,
    allow_nan: bool = False,
    allowed: str | None = None,
    error: type[ValueError] = ValueError,
) -> float:
    """Return ``value`` as a float, or raise ``error`` naming ``name``.

    ``value`` must be a real number (an int, a float or a NumPy scalar; not a bool),
    finite, ``> 0`` if ``positive``, ``>= minimum`` and ``<= maximum`` if given.
    ``allow_inf``: an infinity within those bounds is allowed too (``tau_d = inf``: no
    estimate); ``allow_nan``: nan is allowed (``stop_m = nan``: no stop point). ``unit``
    is quoted in the message, e.g. ``"s"``; ``allowed`` replaces the message's statement
    of what is allowed (a model's own wording, e.g. ``"a number in [0, 60] s"``).
    """
    number = as_float(value)
    if number is not None:
        if math.isnan(number):
            ok = allow_nan
        else:
            ok = (
                (is_finite_number(number) or allow_inf)
                and (not positive or number > 0.0)
                and (minimum is None or number >= minimum)
                and (maximum is None or number <= maximum)
            )
        if ok:
            return number
    if allowed is None:
        bounds = ["> 0"] if positive else ([f">= {minimum:g}"] if minimum is not None else [])
        if maximum is not None:
            bounds.append(f"<= {maximum:g}")
        allowed = ("a number" if allow_inf else "a finite number") + "".join(
            f" {'and ' if i else ''}{bound}" for i, bound in enumerate(bounds)
        )
        if unit:
            allowed += f" [{unit}]"
        if allow_inf:
            allowed += " or inf"
        if allow_nan:
            allowed += " or nan"
    refuse(name, value, allowed, error)


def check_count(
    name: str,
    value: object,
    low: int,
    high: int | None = None,
    *,
    allowed: str | None = None,
    error: type[ValueError] = ValueError,
) -> int:
    """Return ``value`` as an int, or raise ``error`` naming ``name`` unless it is a whole
    number (an int or a NumPy integer, not a bool) with ``low <= value <= high``; without
    ``high``, any such number a float holds (the packed parameters are floats)."""
    if isinstance(value, Integral) and not isinstance(value, bool | np.bool_):
        number = int(value)
        if low <= number and (number <= high if high is not None else is_finite_number(number)):
            return number
    if allowed is None:
        allowed = (
            f"a whole number from {low} to {high}"
            if high is not None
            else f"a whole number >= {low}"
        )
    refuse(name, value, allowed, error)


def check_flag(
    name: str,
    value: object,
    *,
    allowed: str = "True or False",
    error: type[ValueError] = ValueError,
) -> bool:
    """Return ``value`` as a bool, or raise ``error`` naming ``name`` unless it is True or
    False (NumPy's included)."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    refuse(name, value, allowed, error)


def check_pair(
    name: str,
    value: object,
    size: int = 2,
    what: str = "a pair",
    *,
    error: type[ValueError] = ValueError,
) -> tuple[object, ...]:
    """``value`` as a tuple of ``size`` items, or ``error`` naming ``name`` unless it is a
    tuple, a list or a NumPy array (along its first axis) of that length; the items are
    not checked."""
    sequence = isinstance(value, tuple | list) or (
        isinstance(value, np.ndarray) and value.ndim >= 1
    )
    if sequence and len(value) == size:  # type: ignore[arg-type]
        return tuple(value)  # type: ignore[arg-type]
    refuse(name, value, what, error)
