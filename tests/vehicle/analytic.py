"""Closed-form train motion for validating integrators (a test helper, not a test).

Import from another test folder as ``from vehicle.analytic import ...`` (``tests/`` is on
``sys.path`` when that folder is a package, i.e. has an ``__init__.py``).

Constant force against Davis resistance
---------------------------------------
``m_eff dv/dt = F - (a0 + a1 V + a2 V^2 + w_g) m g / 1000`` with ``V = 3.6 v`` [km/h],
``w_g`` a constant extra specific resistance [N/kN] (a uniform gradient), is

    dv/dt = A - B v - C v^2,   A = F / m_eff - (a0 + w_g) k,
                               B = 3.6 a1 k,   C = 3.6^2 a2 k,   k = m g / (1000 m_eff).

With ``D = sqrt(B^2 + 4 A C)`` the right-hand side factors as
``(D^2 / 4C) (1 - u^2)``, ``u = (2 C v + B) / D``, so (partial fractions, or artanh):

    t(v0 -> v1) = (2 / D) [artanh(u(v1)) - artanh(u(v0))],
    v(t)        = (D tanh(D t / 2 + phi0) - B) / (2 C),    phi0 = artanh(u(v0)),
    x(t)        = (1 / C) ln(cosh(D t / 2 + phi0) / cosh(phi0)) - B t / (2 C),

valid below the terminal speed ``v_inf = (D - B) / (2 C)`` where ``dv/dt = 0``. ``C = 0``
reduces to ``t = ln((A - B v0) / (A - B v1)) / B`` and ``B = C = 0`` to ``(v1 - v0) / A``.

Constant power, no resistance
-----------------------------
``m_eff v dv/dt = P`` gives ``t = m_eff (v1^2 - v0^2) / (2 P)``.
"""

from __future__ import annotations

import math

from railpilot.units import G_MPS2, KMH_PER_MPS


def quadratic_motion_coefficients(
    force_n: float,
    mass_kg: float,
    effective_mass_kg: float,
    a0: float,
    a1: float,
    a2: float,
    extra_specific_n_per_kn: float = 0.0,
) -> tuple[float, float, float]:
    """``(A [m/s^2], B [1/s], C [1/m])`` of ``dv/dt = A - B v - C v^2`` (module docstring).

    ``a0, a1, a2``: Davis coefficients [N/kN] with v in km/h, as in
    ``railpilot.vehicle.resistance``; ``extra_specific_n_per_kn``: a constant gradient +
    curve resistance [N/kN] (negative downhill).
    """
    k = mass_kg * G_MPS2 / 1000.0 / effective_mass_kg
    big_a = force_n / effective_mass_kg - (a0 + extra_specific_n_per_kn) * k
    big_b = a1 * KMH_PER_MPS * k
    big_c = a2 * KMH_PER_MPS * KMH_PER_MPS * k
    return big_a, big_b, big_c


def terminal_speed(big_a: float, big_b: float, big_c: float) -> float:
    """Speed [m/s] where ``A - B v - C v^2 = 0`` (``inf`` if it never is)."""
    if big_c > 0.0:
        return (math.sqrt(big_b * big_b + 4.0 * big_a * big_c) - big_b) / (2.0 * big_c)
    if big_b > 0.0:
        return big_a / big_b
    return math.inf


def time_to_speed_analytic(
    v1: float, big_a: float, big_b: float, big_c: float, v0: float = 0.0
) -> float:
    """Time [s] to accelerate from ``v0`` to ``v1`` [m/s] under ``dv/dt = A - B v - C v^2``.

    Requires ``A > 0`` and ``0 <= v0 <= v1 < terminal speed``; raises ``ValueError`` otherwise.
    """
    if not (big_a > 0.0 and big_b >= 0.0 and big_c >= 0.0):
        raise ValueError(f"need A > 0, B >= 0, C >= 0, got {big_a}, {big_b}, {big_c}")
    if not (0.0 <= v0 <= v1 < terminal_speed(big_a, big_b, big_c)):
        raise ValueError(f"need 0 <= v0 <= v1 < terminal speed, got v0={v0}, v1={v1}")
    if big_c > 0.0:
        d = math.sqrt(big_b * big_b + 4.0 * big_a * big_c)
        u0 = (2.0 * big_c * v0 + big_b) / d
        u1 = (2.0 * big_c * v1 + big_b) / d
        return 2.0 / d * (math.atanh(u1) - math.atanh(u0))
    if big_b > 0.0:
        return math.log((big_a - big_b * v0) / (big_a - big_b * v1)) / big_b
    return (v1 - v0) / big_a


def speed_at_time_analytic(
    t: float, big_a: float, big_b: float, big_c: float, v0: float = 0.0
) -> float:
    """Speed [m/s] at time ``t`` [s] from ``v0`` under ``dv/dt = A - B v - C v^2`` (C > 0)."""
    d = math.sqrt(big_b * big_b + 4.0 * big_a * big_c)
    phi0 = math.atanh((2.0 * big_c * v0 + big_b) / d)
    return (d * math.tanh(d * t / 2.0 + phi0) - big_b) / (2.0 * big_c)


def _log_cosh(z: float) -> float:
    """``ln(cosh(z))`` without overflow."""
    z = abs(z)
    return z + math.log1p(math.exp(-2.0 * z)) - math.log(2.0)


def distance_at_time_analytic(
    t: float, big_a: float, big_b: float, big_c: float, v0: float = 0.0
) -> float:
    """Distance [m] run in time ``t`` [s] from ``v0`` under ``dv/dt = A - B v - C v^2`` (C > 0)."""
    d = math.sqrt(big_b * big_b + 4.0 * big_a * big_c)
    phi0 = math.atanh((2.0 * big_c * v0 + big_b) / d)
    return (_log_cosh(d * t / 2.0 + phi0) - _log_cosh(phi0)) / big_c - big_b * t / (2.0 * big_c)


def time_to_speed_constant_power(
    v0: float, v1: float, power_w: float, effective_mass_kg: float
) -> float:
    """Time [s] from ``v0`` to ``v1`` [m/s] at constant power [W] with no resistance."""
    return effective_mass_kg * (v1 * v1 - v0 * v0) / (2.0 * power_w)
