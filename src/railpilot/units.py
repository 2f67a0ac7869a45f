"""Every unit conversion in one place.

The core works in SI: metres, seconds, m/s, m/s^2, newtons, kilograms.
The papers use km/h, kN, N/kN (specific resistance per kN of train weight)
and km posts; those appear only at the edges and are converted here.
Every function takes a float or a NumPy array and returns the same kind.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np

Num = TypeVar("Num", float, np.ndarray)

#: Gravity used by the papers [m/s^2]. Paper 000 writes 0.0098 = g/1000 for the
#: N/kN -> m/s^2 factor and paper 003 uses g = 9.8; we follow them.
G_MPS2 = 9.8

KMH_PER_MPS = 3.6


def kmh_to_mps(speed_kmh: Num) -> Num:
    """Convert speed [km/h] to [m/s]."""
    return speed_kmh / KMH_PER_MPS


def mps_to_kmh(speed_mps: Num) -> Num:
    """Convert speed [m/s] to [km/h]."""
    return speed_mps * KMH_PER_MPS


def kn_to_n(force_kn: Num) -> Num:
    """Convert force [kN] to [N]."""
    return force_kn * 1000.0


def n_to_kn(force_n: Num) -> Num:
    """Convert force [N] to [kN]."""
    return force_n / 1000.0


def tonne_to_kg(mass_t: Num) -> Num:
    """Convert mass [t] to [kg]."""
    return mass_t * 1000.0


#: Largest km post a file may give, either sign [km]: as line files and the train-ground
#: link allow (line/model.py and link/messages.py MAX_POSITION_M); far beyond it positions
#: lose their metre resolution, and 1e308 km is no position at all (inf m)
MAX_KM_POST = 10_000.0


def km_post_to_m(km_post: Num) -> Num:
    """Convert a km post [km along the line] to a position [m]."""
    return km_post * 1000.0


def m_to_km_post(position_m: Num) -> Num:
    """Convert a position [m] to a km post [km]."""
    return position_m / 1000.0


def hms(duration_s: float) -> str:
    """``duration_s`` [s], rounded to the second, as ``h:mm:ss`` (a time from a run's
    start in messages a person reads)."""
    whole = round(duration_s)
    return f"{whole // 3600}:{whole % 3600 // 60:02d}:{whole % 60:02d}"


def specific_to_force_n(specific_n_per_kn: Num, mass_kg: float) -> Num:
    """Force [N] of a specific force [N/kN] on a train of ``mass_kg`` [kg].

    A specific resistance ``w`` newtons per kilonewton of train weight is a force
    of ``w * m * g / 1000`` newtons.
    """
    return specific_n_per_kn * (mass_kg * G_MPS2 / 1000.0)


def force_to_specific_n_per_kn(force_n: Num, mass_kg: float) -> Num:
    """Specific force [N/kN] of a force [N] on a train of ``mass_kg`` [kg]."""
    return force_n * (1000.0 / (mass_kg * G_MPS2))


def gradient_permille_to_specific(gradient_permille: Num) -> Num:
    """Gradient resistance [N/kN] of a gradient [per mille, positive uphill].

    One per mille adds 1 N/kN (small-angle approximation, sin ~ tan), the
    convention of Chinese and most European traction calculations.
    """
    return gradient_permille * 1.0


def curve_specific_resistance(radius_m: Num, coefficient: float = 600.0) -> Num:
    """Curve resistance [N/kN] of a curve of radius [m]: ``w_r = A / R``.

    ``A = 600`` is the standard-gauge coefficient of the Chinese traction rules
    (TB/T 1407); a straight track is radius ``inf`` and gives 0.
    """
    return coefficient / radius_m


RAD_S_PER_RPM = np.pi / 30.0


def rpm_to_rad_s(speed_rpm: Num) -> Num:
    """Convert a rotational speed [rev/min] to an angular speed [rad/s] (paper 003 eq. 22)."""
    return speed_rpm * RAD_S_PER_RPM


def rad_s_to_rpm(speed_rad_s: Num) -> Num:
    """Convert an angular speed [rad/s] to a rotational speed [rev/min]."""
    return speed_rad_s / RAD_S_PER_RPM


def wheel_angular_speed_rad_s(speed_mps: Num, wheel_diameter_m: float) -> Num:
    """Angular speed [rad/s] of a wheel (and its axle-mounted disc) rolling at ``speed_mps``.

    ``omega = v / (Dw / 2)``; with ``v`` in km/h and ``n`` in rev/min this is paper 003
    eq. 22-23 (``omega = pi n / 30``, ``v = 3 pi Dw n / 50``).
    """
    return speed_mps * (2.0 / wheel_diameter_m)


def wheel_speed_to_train_speed_mps(speed_rad_s: Num, wheel_diameter_m: float) -> Num:
    """Train speed [m/s] of a wheel turning at ``speed_rad_s`` [rad/s] without slip."""
    return speed_rad_s * (wheel_diameter_m / 2.0)
