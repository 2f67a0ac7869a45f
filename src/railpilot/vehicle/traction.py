"""Tractive-effort and regenerative-brake envelopes of an electric locomotive, and its energy chain.

Two envelopes bound what the drive can put on the rail, both the textbook shape of an
inverter-fed asynchronous drive (constant force up to the base speed, then constant power):

* traction ``F_T,max(v) = min(F_T0, P_T / |v|)``, zero above the locomotive's maximum speed;
* electric (regenerative) brake ``F_E,max(v) = min(F_E0, P_E / |v|) * min(1, |v| / v_fade)``,
  the same shape faded linearly to zero below ``v_fade`` (regeneration fades near standstill:
  the motor's back-EMF, and with it the power it can return, goes to zero with speed).

Each law is written twice, with the same arithmetic in the same order so that the two agree
to the last bit (tests/vehicle/test_traction.py checks it):

* a Numba ``@njit`` scalar function (:func:`traction_force_max`, :func:`regen_force_max`),
  float64 in, float64 out, for the simulation kernel;
* a vectorised NumPy function (:func:`traction_force_envelope_n`,
  :func:`regen_force_envelope_n`) for everything else; the dataclasses call these.

:func:`hxd1_locomotive` gives the HXD1 heavy-haul locomotive; which of its numbers are
published and which are our assumptions is said at each constant and in
docs/heavy-haul-vehicle.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import kmh_to_mps, kn_to_n, tonne_to_kg
from railpilot.vehicle.train import _non_negative, _positive

# --- the HXD1 (DJ4), CSR Zhuzhou / Siemens, Bo'Bo'+Bo'Bo' --------------------------------
# Published figures: the class's Wikipedia page ("China Railways HXD1", infobox, and the
# references it cites), seen through the search tool; the loco-info.com page agrees on 9.6 MW
# and on the 25 t ballasted axle load. See docs/heavy-haul-vehicle.md.

#: Starting tractive effort [N]. Published: 760 kN ballasted to 25 t axle load (200 t);
#: 700 kN (adhesion 0.39) at 23 t (184 t).
HXD1_MAX_TRACTIVE_FORCE_N = kn_to_n(760.0)
#: Continuous power [W], taken at the wheel rim. Published: 9.6 MW. That it is wheel power
#: follows from the published continuous effort 494 kN at 70 km/h (9.6 MW / 19.44 m/s).
HXD1_POWER_W = 9.6e6
#: Maximum speed [m/s]. Published: 120 km/h.
HXD1_MAX_SPEED_MPS = kmh_to_mps(120.0)
#: Maximum electric brake force [N]. Published: 461 kN.
HXD1_MAX_REGEN_FORCE_N = kn_to_n(461.0)
#: Electric brake power [W]. Published: "9.6 MW maximum", and the published continuous
#: brake force 461 kN at 75 km/h falling to 288 kN at 120 km/h is that power exactly.
HXD1_REGEN_POWER_W = 9.6e6
#: Speed [m/s] below which the electric brake fades linearly to zero. ASSUMPTION (10 km/h):
#: no published figure found; asynchronous-drive regeneration typically fades out below
#: 5-10 km/h, and the air brake has to finish every stop.
HXD1_REGEN_FADE_BELOW_MPS = kmh_to_mps(10.0)
#: Locomotive mass [kg]. Published: 184 t, 200 t ballasted (the 760 kN configuration).
HXD1_MASS_KG = tonne_to_kg(200.0)
#: Length over couplers [m]. Published: 35.222 m (two sections).
HXD1_LENGTH_M = 35.222
#: Driven axles. Published: 8 (Bo'Bo'+Bo'Bo').
HXD1_AXLES = 8

#: Efficiency of the traction chain, catenary -> wheel [-]. ASSUMPTION: transformer (~0.96)
#: x four-quadrant converter and inverter (~0.97 each) x asynchronous motor (~0.95) x gear
#: (~0.98) ~ 0.85; auxiliaries not included.
TRACTION_EFFICIENCY = 0.85
#: Efficiency of regeneration, wheel -> catenary [-]. ASSUMPTION: the same chain run
#: backwards, less at the part loads of braking and with some of the returned energy taken by
#: auxiliaries: 0.80.
REGEN_EFFICIENCY = 0.80


def _efficiency(name: str, value: object) -> None:
    check_number(
        name,
        value,
        positive=True,
        maximum=1.0,
        allowed="an efficiency in (0, 1]",
        error=ConfigError,
    )


# --- the laws: Numba scalar twins --------------------------------------------------------


@njit(cache=True)
def traction_force_max(
    v: float, max_force_n: float, max_power_w: float, max_speed_mps: float = math.inf
) -> float:
    """Maximum tractive effort [N] at speed ``v`` [m/s] (Numba scalar).

    ``min(max_force_n [N], max_power_w [W] / |v|)``, and 0 above ``max_speed_mps`` [m/s]
    (the drive cuts traction at overspeed). At ``v = 0`` it is the starting effort.
    The same arithmetic as :func:`traction_force_envelope_n`.
    """
    speed = abs(v)
    if speed > max_speed_mps:
        return 0.0
    if max_force_n * speed <= max_power_w:
        return max_force_n
    return max_power_w / speed


@njit(cache=True)
def regen_force_max(
    v: float, max_force_n: float, max_power_w: float, fade_below_mps: float
) -> float:
    """Maximum electric (regenerative) brake force [N] at speed ``v`` [m/s] (Numba scalar).

    ``min(max_force_n [N], max_power_w [W] / |v|)``, times ``|v| / fade_below_mps`` below
    ``fade_below_mps`` [m/s] (0 there: no fade). A positive number; the caller applies it
    against the motion. The same arithmetic as :func:`regen_force_envelope_n`.
    """
    speed = abs(v)
    force = max_force_n if max_force_n * speed <= max_power_w else max_power_w / speed
    if speed < fade_below_mps:
        force = force * (speed / fade_below_mps)
    return force


# --- the laws: vectorised ----------------------------------------------------------------


def _constant_force_constant_power(
    speed: np.ndarray, max_force_n: float, max_power_w: float
) -> np.ndarray:
    """``min(F0, P / speed)`` for ``speed >= 0``, dividing only where power limits."""
    force_limited = max_force_n * speed <= max_power_w
    power_limited = np.divide(
        max_power_w, speed, out=np.full(speed.shape, float(max_force_n)), where=~force_limited
    )
    return np.where(force_limited, max_force_n, power_limited)


def traction_force_envelope_n(
    speed_mps: npt.ArrayLike,
    max_force_n: float,
    max_power_w: float,
    max_speed_mps: float = math.inf,
) -> np.ndarray:
    """Maximum tractive effort [N] of a constant-force / constant-power drive.

    Parameters
    ----------
    speed_mps
        Train speed [m/s]; the sign is ignored.
    max_force_n
        Starting tractive effort ``F_T0`` [N], available up to the base speed.
    max_power_w
        Power at the wheel ``P_T`` [W], the limit above the base speed ``P_T / F_T0``.
    max_speed_mps
        Maximum speed [m/s]; above it the force is 0.

    Returns
    -------
    numpy.ndarray
        ``F_T,max`` [N], shaped like ``speed_mps`` (0-d for a scalar).

    Notes
    -----
    ``F_T,max(v) = min(F_T0, P_T / |v|)``: the inverter holds the motor current (torque) at
    its limit up to the base speed and the power at its limit above it, the usual tractive
    effort curve of an AC locomotive (e.g. Steimel, *Electric Traction -- Motive Power and
    Energy Supply*). Real curves often slope gently in the constant-force region
    (adhesion falls with speed); this envelope ignores that. :func:`traction_force_max` is
    the Numba twin.
    """
    speed = np.abs(np.asarray(speed_mps, dtype=float))
    force = _constant_force_constant_power(speed, max_force_n, max_power_w)
    return np.where(speed > max_speed_mps, 0.0, force)


def regen_force_envelope_n(
    speed_mps: npt.ArrayLike, max_force_n: float, max_power_w: float, fade_below_mps: float
) -> np.ndarray:
    """Maximum electric (regenerative) brake force [N] with a low-speed fade.

    Parameters
    ----------
    speed_mps
        Train speed [m/s]; the sign is ignored.
    max_force_n
        Maximum electric brake force ``F_E0`` [N].
    max_power_w
        Electric brake power at the wheel ``P_E`` [W].
    fade_below_mps
        Fade speed ``v_fade`` [m/s]; below it the force falls linearly to 0 at standstill
        (0: no fade).

    Returns
    -------
    numpy.ndarray
        ``F_E,max`` [N] >= 0, shaped like ``speed_mps`` (0-d for a scalar).

    Notes
    -----
    ``F_E,max(v) = min(F_E0, P_E / |v|) * min(1, |v| / v_fade)``. Constant force, then
    constant power, as in traction (the drive runs the same limits as a generator); the
    linear fade stands for the loss of back-EMF near standstill, which leaves too little
    voltage to return power and hands the last of the stop to the air brake.
    :func:`regen_force_max` is the Numba twin.
    """
    speed = np.abs(np.asarray(speed_mps, dtype=float))
    force = _constant_force_constant_power(speed, max_force_n, max_power_w)
    fade = np.divide(speed, fade_below_mps, out=np.ones(speed.shape), where=speed < fade_below_mps)
    return np.where(speed < fade_below_mps, force * fade, force)


# --- the envelopes as objects ------------------------------------------------------------


@dataclass(frozen=True)
class TractionEnvelope:
    """Maximum tractive effort vs speed: constant force, then constant power.

    Attributes
    ----------
    max_force_n
        Starting tractive effort [N].
    max_power_w
        Power at the wheel [W].
    max_speed_mps
        Maximum speed [m/s] (``None``: unlimited); above it the envelope is 0.
    """

    max_force_n: float
    max_power_w: float
    max_speed_mps: float | None = None

    def __post_init__(self) -> None:
        _positive("locomotive.traction.max_force_n", self.max_force_n)
        _positive("locomotive.traction.max_power_w", self.max_power_w)
        if self.max_speed_mps is not None:
            _positive("locomotive.traction.max_speed_mps", self.max_speed_mps)

    @property
    def base_speed_mps(self) -> float:
        """Speed [m/s] where constant force gives way to constant power, ``P / F0``."""
        return self.max_power_w / self.max_force_n

    @property
    def speed_limit_mps(self) -> float:
        """``max_speed_mps`` [m/s], ``inf`` if unlimited (the kernel's argument)."""
        return math.inf if self.max_speed_mps is None else self.max_speed_mps

    def max_force(self, speed_mps: npt.ArrayLike) -> np.ndarray:
        """Available tractive effort [N] at ``speed_mps`` [m/s]."""
        return traction_force_envelope_n(
            speed_mps, self.max_force_n, self.max_power_w, self.speed_limit_mps
        )


@dataclass(frozen=True)
class RegenEnvelope:
    """Maximum electric (regenerative) brake force vs speed, faded out near standstill.

    Like :class:`railpilot.vehicle.train.ElectricBrakeCurve` plus the fade: constant force
    ``max_force_n`` [N], then constant power ``max_power_w`` [W], times ``v /
    fade_below_mps`` below ``fade_below_mps`` [m/s] (0: no fade).
    """

    max_force_n: float
    max_power_w: float
    fade_below_mps: float = 0.0

    def __post_init__(self) -> None:
        _non_negative("locomotive.regen.max_force_n", self.max_force_n)
        _non_negative("locomotive.regen.max_power_w", self.max_power_w)
        _non_negative("locomotive.regen.fade_below_mps", self.fade_below_mps)

    @property
    def base_speed_mps(self) -> float:
        """Speed [m/s] where constant force gives way to constant power, ``P / F0``."""
        return self.max_power_w / self.max_force_n if self.max_force_n > 0 else math.inf

    def max_force(self, speed_mps: npt.ArrayLike) -> np.ndarray:
        """Available electric brake force [N] (>= 0) at ``speed_mps`` [m/s]."""
        return regen_force_envelope_n(
            speed_mps, self.max_force_n, self.max_power_w, self.fade_below_mps
        )


@dataclass(frozen=True)
class Locomotive:
    """An electric locomotive: mass, length, envelopes and the efficiencies of its chain.

    Attributes
    ----------
    name
        Class name, e.g. ``"HXD1"``.
    mass_kg
        Service mass [kg] (part of the train mass, not added to it by this class).
    length_m
        Length over couplers [m].
    traction, regen
        Tractive-effort and electric-brake envelopes (whole locomotive, at the wheel).
    traction_efficiency
        Catenary -> wheel efficiency [-], see :func:`traction_energy_drawn_j`.
    regen_efficiency
        Wheel -> catenary efficiency [-], see :func:`regenerated_energy_returned_j`.
    """

    name: str
    mass_kg: float
    length_m: float
    traction: TractionEnvelope
    regen: RegenEnvelope
    traction_efficiency: float = TRACTION_EFFICIENCY
    regen_efficiency: float = REGEN_EFFICIENCY

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise ConfigError("locomotive.name", self.name, "a string")
        _positive("locomotive.mass_kg", self.mass_kg)
        _positive("locomotive.length_m", self.length_m)
        if not isinstance(self.traction, TractionEnvelope):
            raise ConfigError("locomotive.traction", self.traction, "a TractionEnvelope")
        if not isinstance(self.regen, RegenEnvelope):
            raise ConfigError("locomotive.regen", self.regen, "a RegenEnvelope")
        _efficiency("locomotive.traction_efficiency", self.traction_efficiency)
        _efficiency("locomotive.regen_efficiency", self.regen_efficiency)


def hxd1_locomotive() -> Locomotive:
    """The HXD1 8-axle heavy-haul electric locomotive (ballasted, 25 t axle load).

    Published: 760 kN starting effort, 9.6 MW, 120 km/h, 461 kN / 9.6 MW electric brake,
    200 t, 35.222 m. Assumed: the 10 km/h regeneration fade and both efficiencies. Sources
    and reasoning at the ``HXD1_*`` constants and in docs/heavy-haul-vehicle.md.
    """
    return Locomotive(
        name="HXD1",
        mass_kg=HXD1_MASS_KG,
        length_m=HXD1_LENGTH_M,
        traction=TractionEnvelope(
            max_force_n=HXD1_MAX_TRACTIVE_FORCE_N,
            max_power_w=HXD1_POWER_W,
            max_speed_mps=HXD1_MAX_SPEED_MPS,
        ),
        regen=RegenEnvelope(
            max_force_n=HXD1_MAX_REGEN_FORCE_N,
            max_power_w=HXD1_REGEN_POWER_W,
            fade_below_mps=HXD1_REGEN_FADE_BELOW_MPS,
        ),
    )


# --- energy accounting -------------------------------------------------------------------


def _check_energy(wheel_energy_j: npt.ArrayLike) -> np.ndarray:
    energy = np.asarray(wheel_energy_j, dtype=float)
    if not np.all(energy >= 0.0):
        raise ConfigError("wheel_energy_j", wheel_energy_j, "energies >= 0 [J] (magnitudes)")
    return energy


def traction_energy_drawn_j(
    wheel_energy_j: npt.ArrayLike, efficiency: float = TRACTION_EFFICIENCY
) -> np.ndarray:
    """Energy drawn from the catenary [J] to put ``wheel_energy_j`` [J] on the rail.

    Parameters
    ----------
    wheel_energy_j
        Traction work at the wheel ``E_T = integral(F_T v dt)`` over ``F_T > 0`` [J], >= 0.
    efficiency
        Catenary -> wheel efficiency ``eta_T`` [-] in (0, 1]; default
        :data:`TRACTION_EFFICIENCY` (0.85, an assumption).

    Returns
    -------
    numpy.ndarray
        ``E_T / eta_T`` [J].

    Notes
    -----
    A constant efficiency makes the conversion linear, so a kernel may integrate the wheel
    work and convert once at the end. Auxiliary power (blowers, compressors, cab) is not in
    it.
    """
    _efficiency("efficiency", efficiency)
    return _check_energy(wheel_energy_j) / efficiency


def regenerated_energy_returned_j(
    wheel_energy_j: npt.ArrayLike, efficiency: float = REGEN_EFFICIENCY
) -> np.ndarray:
    """Energy returned to the catenary [J] from ``wheel_energy_j`` [J] of electric braking.

    Parameters
    ----------
    wheel_energy_j
        Electric brake work at the wheel ``E_E = integral(F_E v dt)`` [J], >= 0.
    efficiency
        Wheel -> catenary efficiency ``eta_R`` [-] in (0, 1]; default
        :data:`REGEN_EFFICIENCY` (0.80, an assumption).

    Returns
    -------
    numpy.ndarray
        ``eta_R E_E`` [J].

    Notes
    -----
    Assumes a receptive catenary (another train or the substation takes every joule
    returned); on a non-receptive line the electric brake would be cut back, which is not
    modelled. The net energy drawn is
    ``traction_energy_drawn_j(E_T) - regenerated_energy_returned_j(E_E)``.
    """
    _efficiency("efficiency", efficiency)
    return _check_energy(wheel_energy_j) * efficiency
