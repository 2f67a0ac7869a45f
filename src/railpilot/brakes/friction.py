"""Brake shoe friction coefficient (paper 000 eq. 3)."""

from __future__ import annotations

import numpy as np

from railpilot.units import Num

#: Paper 000 eq. 3 coefficients (after Nankyo et al. 2006), v in km/h.
BETA1 = 0.138
BETA2 = 0.168
BETA3 = 0.221


def shoe_friction(
    speed_kmh: Num, beta1: float = BETA1, beta2: float = BETA2, beta3: float = BETA3
) -> Num:
    """Shoe friction coefficient ``mu(v) = beta1 exp(-beta2 v) + beta3`` [-], v in [km/h]."""
    return beta1 * np.exp(-beta2 * np.abs(speed_kmh)) + beta3


def friction_ratio(
    speed_kmh: Num, beta1: float = BETA1, beta2: float = BETA2, beta3: float = BETA3
) -> Num:
    """``g(v) = mu(v) / mu0`` with ``mu0 = beta3`` (paper 000 eq. 5) [-].

    The brake manager sets cylinder pressure for the force it wants assuming
    ``mu0``; the shoe then delivers ``g(v)`` times that force: 1.0 at speed,
    1.23 at 6 km/h, 1.62 at standstill with the paper's coefficients.
    """
    return shoe_friction(speed_kmh, beta1, beta2, beta3) / beta3
