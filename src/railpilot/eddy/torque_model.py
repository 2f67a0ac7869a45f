"""Analytic braking torque of the electromagnetic rotating eddy-current brake (paper 003, sec. 1).

Pure, vectorised functions of the coil current and the disc speed; SI units throughout
(``[A]``, ``[rad/s]``, ``[m/s]``, ``[N m]``). The derivation, re-done from the paper's
eq. 1-18 because the extracted eq. 7, 12, 16, 17, 19 and 24 lost radicals and factors of
pi, is in ``docs/paper-003-eddy-brake.md``; the short form is in :func:`eddy_torque_nm`.

Notes
-----
Disc of resistivity ``rho`` and relative permeability ``mu_r`` between two rows of
electromagnets; each pole projects a 40-degree annular sector (radii ``r1 < r2``,
``rc = (r1 + r2)/2``, ``dr = (r2 - r1)/2``) onto the disc; only the air-gap reluctance
counts; the eddy currents' own magneto-motive force ``ke * Ie`` opposes the coil's
``N I`` (eq. 10). With ``a = pi rc`` and the sector factors

    k1 = dr^2/2 - a dr + a^2 ln((dr + a)/a)        [m^2]   (eq. 20)
    k2 = dr - a ln((dr + a)/a)                     [m]     (eq. 21)

the gap flux density and the torque are (``wn = Np w`` the electrical angular speed)

    B = mu0 N I / (delta + pi ke rc k2 sqrt(mu0 wn / (rho mu_r)))            (eq. 15)
    M = S (2 sqrt(2) pi^2 / 9) k1 rc^2 B^2 Np^(3/2) w^(1/2) / sqrt(rho mu0 mu_r)

with ``S`` poles (sectors) in all. For ``S = 18`` and ``ke`` absorbing one factor pi this
is the printed eq. 19, ``M = 4 sqrt(2) pi k1 rc^2 mu0^(5/2) (mu_r rho)^(1/2) (N I)^2
Np^(3/2) w^(1/2) / (delta sqrt(rho mu0 mu_r) + k2 ke rc mu0 sqrt(Np w))^2``. Both sides of
the denominator are [m Ohm s^(1/2)], the quotient is [Ohm s A^2] = [J] = [N m].

Shape: ``M ~ sqrt(w)`` at low speed, ``M ~ 1/sqrt(w)`` at high speed, maximum where the
two denominator terms are equal (:func:`peak_torque_angular_speed_rad_s`); ``M ~ I^2``
(no saturation, assumption 4 of the paper).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.units import Num, wheel_angular_speed_rad_s

#: Vacuum permeability [H/m] as the paper uses it (4 pi 1e-7).
MU0_H_PER_M = 4.0e-7 * np.pi

#: Wheel diameter of paper 003 [m] (eq. 23, Dw = 845 mm).
WHEEL_DIAMETER_M = 0.845


@dataclass(frozen=True)
class EddyBrakeParams:
    """Geometry and materials of the brake (the paper gives none of them but ``Dw``).

    Default values are our choice (see docs/paper-003-eddy-brake.md): with them and a
    400 A coil-current limit the model holds 3500 N m down to about 16 km/h and
    4500 N m at 200 km/h, and peaks near 150 km/h at fixed current.

    Attributes
    ----------
    r_inner_m, r_outer_m
        Inner and outer radius of a pole's 40-degree sector on the disc [m].
    air_gap_m
        Air gap ``delta`` between pole face and disc [m].
    turns
        Coil turns ``N`` per pole.
    pole_pairs
        Pole pairs per disc side ``Np``; the disc carries ``4 Np`` pole sectors in all
        (``2 Np`` per side, both sides).
    resistivity_ohm_m
        Disc resistivity ``rho`` [Ohm m] (temperature-independent, assumption 1).
    relative_permeability
        Disc relative permeability ``mu_r`` [-].
    eddy_flux_factor
        ``ke`` [-]: fraction of the eddy current's r.m.s. value acting as reverse MMF.
    wheel_diameter_m
        Wheel diameter ``Dw`` [m]; the disc turns with the wheel.
    """

    r_inner_m: float = 0.13
    r_outer_m: float = 0.29
    air_gap_m: float = 0.004
    turns: float = 12.0
    pole_pairs: float = 4.0
    resistivity_ohm_m: float = 2.5e-7
    relative_permeability: float = 100.0
    eddy_flux_factor: float = 0.30
    wheel_diameter_m: float = WHEEL_DIAMETER_M

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            check_number(
                f"brake.{name}",
                value,
                positive=True,
                error=ConfigError,
            )
        if not self.r_outer_m > self.r_inner_m:
            raise ConfigError(
                "brake.r_outer_m", self.r_outer_m, f"a radius > r_inner_m = {self.r_inner_m}"
            )

    @property
    def mean_radius_m(self) -> float:
        """``rc = (r1 + r2) / 2`` [m]."""
        return 0.5 * (self.r_inner_m + self.r_outer_m)

    @property
    def half_width_m(self) -> float:
        """``dr = (r2 - r1) / 2`` [m]."""
        return 0.5 * (self.r_outer_m - self.r_inner_m)

    @property
    def sectors(self) -> float:
        """Number of pole sectors on the disc, both sides [-]."""
        return 4.0 * self.pole_pairs

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def sector_factors(r_inner_m: float, r_outer_m: float) -> tuple[float, float]:
    """Geometry factors ``(k1 [m^2], k2 [m])`` of a 40-degree pole sector (eq. 20-21).

    They come from integrating the ring currents (eq. 7) and powers (eq. 16) over the
    sector: ``k2 = int_0^dr r/(r + a) dr``, ``k1 = int_0^dr r^2/(r + a) dr``, ``a = pi rc``.
    Both are computed with ``log1p`` because for narrow sectors they are small
    differences of nearly equal numbers.
    """
    rc = 0.5 * (r_inner_m + r_outer_m)
    dr = 0.5 * (r_outer_m - r_inner_m)
    a = np.pi * rc
    log_term = np.log1p(dr / a)
    k2 = dr - a * log_term
    k1 = 0.5 * dr * dr - a * dr + a * a * log_term
    return float(k1), float(k2)


def skin_depth_m(resistivity_ohm_m: float, relative_permeability: float, omega_n: Num) -> Num:
    """Skin depth ``d' = sqrt(2 rho / (mu0 mu_r wn))`` [m] at electrical speed ``wn`` [rad/s]."""
    return np.sqrt(2.0 * resistivity_ohm_m / (MU0_H_PER_M * relative_permeability * omega_n))


def _reaction_length_m(omega_rad_s: Num, p: EddyBrakeParams) -> Num:
    """Eddy reaction term of eq. 15's denominator, ``pi ke rc k2 sqrt(mu0 wn/(rho mu_r))`` [m]."""
    _, k2 = sector_factors(p.r_inner_m, p.r_outer_m)
    omega_n = p.pole_pairs * np.abs(omega_rad_s)
    return (
        np.pi
        * p.eddy_flux_factor
        * p.mean_radius_m
        * k2
        * np.sqrt(MU0_H_PER_M * omega_n / (p.resistivity_ohm_m * p.relative_permeability))
    )


def gap_flux_density_t(current_a: Num, omega_rad_s: Num, p: EddyBrakeParams) -> Num:
    """Air-gap flux density ``B`` [T] at coil current [A] and disc speed [rad/s] (eq. 15).

    At standstill this is the plain gap field ``mu0 N I / delta``; the eddy currents'
    reaction lowers it as the disc speeds up.
    """
    return MU0_H_PER_M * p.turns * current_a / (p.air_gap_m + _reaction_length_m(omega_rad_s, p))


def eddy_torque_nm(current_a: Num, omega_rad_s: Num, p: EddyBrakeParams) -> Num:
    """Braking torque ``M`` [N m] at coil current [A] and disc angular speed [rad/s] (eq. 19).

    ``M = P / w`` (eq. 18) with ``P`` the time-mean eddy power of all ``S = 4 Np``
    sectors (eq. 17): ``M = S (2 sqrt(2) pi^2 / 9) k1 rc^2 B^2 Np^(3/2) w^(1/2) /
    sqrt(rho mu0 mu_r)``. Zero at standstill; even in the current (``M ~ I^2``); the
    brake always opposes motion, so ``|w|`` is used.
    """
    k1, _ = sector_factors(p.r_inner_m, p.r_outer_m)
    omega = np.abs(omega_rad_s)
    b = gap_flux_density_t(current_a, omega, p)
    rc = p.mean_radius_m
    coeff = (
        p.sectors
        * (2.0 * np.sqrt(2.0) * np.pi**2 / 9.0)
        * k1
        * rc
        * rc
        * p.pole_pairs**1.5
        / np.sqrt(p.resistivity_ohm_m * MU0_H_PER_M * p.relative_permeability)
    )
    return coeff * b * b * np.sqrt(omega)


def eddy_torque_at_speed_nm(current_a: Num, speed_mps: Num, p: EddyBrakeParams) -> Num:
    """Braking torque [N m] at coil current [A] and train speed [m/s] (eq. 24).

    The disc turns with the wheel: ``w = v / (Dw / 2)`` (eq. 22-23).
    """
    return eddy_torque_nm(current_a, wheel_angular_speed_rad_s(speed_mps, p.wheel_diameter_m), p)


def peak_torque_angular_speed_rad_s(p: EddyBrakeParams) -> float:
    """Disc speed [rad/s] of maximum torque at fixed current.

    ``M ~ x / (delta + beta x)^2`` with ``x = sqrt(w)`` peaks where ``beta x = delta``:
    the eddy reaction then halves the gap flux density.
    """
    beta = float(_reaction_length_m(1.0, p))  # reaction length per sqrt(rad/s)
    return (p.air_gap_m / beta) ** 2


def current_for_torque_a(torque_nm: Num, speed_mps: Num, p: EddyBrakeParams) -> Num:
    """Coil current [A] that gives ``torque_nm`` at ``speed_mps`` (inverse of eq. 24).

    Exact because ``M ~ I^2``; infinite at standstill, where the brake has no torque.
    """
    omega = wheel_angular_speed_rad_s(np.asarray(speed_mps, dtype=float), p.wheel_diameter_m)
    per_amp2 = eddy_torque_nm(np.ones_like(omega), omega, p)
    with np.errstate(divide="ignore"):
        out = np.sqrt(torque_nm / per_amp2)
    return out if isinstance(torque_nm, np.ndarray) or np.ndim(speed_mps) else float(out)  # type: ignore[return-value]
