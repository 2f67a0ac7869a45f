"""Basic running resistance (Davis formula) in the papers' convention and in SI."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from railpilot.jit import njit
from railpilot.units import G_MPS2, KMH_PER_MPS, Num


def _davis_specific_resistance(speed_kmh: Num, a0: float, a1: float, a2: float) -> Num:
    """Specific basic resistance ``w = a0 + a1 v + a2 v^2`` [N/kN], v in [km/h].

    Paper 000 eq. 6 and paper 003 eq. 28 (``A + B v + C v^2``). Resistance always
    opposes motion; for ``v >= 0`` this is the formula as printed. Compiled, so the
    simulators' loops call this one formula too (scalars or arrays).
    """
    return a0 + a1 * speed_kmh + a2 * speed_kmh * speed_kmh


#: :func:`_davis_specific_resistance`, compiled (one formula for Python and the kernels)
davis_specific_resistance: Callable[..., Any] = njit(cache=True)(_davis_specific_resistance)


def davis_resistance_n(speed_mps: Num, mass_kg: float, a0: float, a1: float, a2: float) -> Num:
    """Basic resistance force [N] of a train of ``mass_kg`` [kg] at ``speed_mps`` [m/s].

    ``w`` [N/kN] from :func:`davis_specific_resistance` times the weight in kN:
    ``F = w * m * g / 1000``.
    """
    speed_kmh = np.abs(speed_mps) * KMH_PER_MPS
    return davis_specific_resistance(speed_kmh, a0, a1, a2) * (mass_kg * G_MPS2 / 1000.0)


def davis_deceleration_mps2(
    speed_mps: Num, rotating_mass_factor: float, a0: float, a1: float, a2: float
) -> Num:
    """Deceleration [m/s^2] the basic resistance alone causes.

    Paper 000 eq. 6: ``dv/dt = -chi w`` with ``chi = 0.0098 / (1 + gamma)``
    (``g/1000`` per N/kN, divided by the rotating mass factor).
    """
    chi = G_MPS2 / 1000.0 / (1.0 + rotating_mass_factor)
    return chi * davis_specific_resistance(np.abs(speed_mps) * KMH_PER_MPS, a0, a1, a2)
