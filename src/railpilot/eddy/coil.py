"""Excitation chain of paper 003 section 2.4-2.5: hysteresis current controller,
DC chopper and the brake coil as an R-L circuit.

* The torque controller outputs the *reference-current change* as a rate ``u`` [A/s];
  the current reference integrates it, ``I_ref <- clip(I_ref + u dt, 0, I_max)``
  (:func:`reference_step`), and may not lead or lag the coil current by more than
  ``reference_lead_a``. Both clips are the anti-windup of the torque loop.
* The hysteresis controller (:func:`hysteresis_step`) closes the chopper switch when
  ``I_ref - I > +band`` and opens it when ``I_ref - I < -band`` (paper: band 0.1 A);
  inside the band it keeps its last command. It also opens the switch whenever the
  current is at the limit (the chopper's over-current protection).
* The chopper (:func:`coil_step`) applies the supply voltage ``U`` when the switch is
  closed; when it is open the coil free-wheels through the diode (``-U_fw``, default 0 V)
  and the diode blocks reverse current, so ``I >= 0``.
* The coil is ``L dI/dt = V - R I``, advanced with its exact solution for a constant
  voltage over the step, so the step size does not affect its accuracy.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit

# packed layout of the coil parameters used by the compiled loop
C_R, C_L, C_U, C_IMAX, C_UFW, C_BAND, C_LEAD = range(7)
N_COIL = 7


@dataclass(frozen=True)
class CoilParams:
    """Brake coil, chopper supply and hysteresis band.

    Attributes
    ----------
    resistance_ohm
        Coil resistance ``R`` [Ohm].
    inductance_h
        Coil inductance ``L`` [H] (time constant ``L/R``).
    supply_voltage_v
        DC-link voltage the chopper switches onto the coil ``U`` [V].
    current_limit_a
        Largest coil current the chopper allows ``I_max`` [A]; must be below ``U/R``.
    freewheel_voltage_v
        Forward drop of the free-wheel diode [V] (>= 0; 0 = ideal diode).
    hysteresis_band_a
        Half-width of the hysteresis band [A] (paper: 0.1 A).
    reference_lead_a
        Largest distance [A] the current reference may lead or lag the coil current
        (``inf`` = no limit). Anti-windup of the torque loop: while the coil cannot
        follow (supply-voltage limit) the reference waits for it instead of running
        ahead and forcing an overshoot. Must be > ``hysteresis_band_a``.
    """

    resistance_ohm: float = 0.6
    inductance_h: float = 0.15
    supply_voltage_v: float = 300.0
    current_limit_a: float = 425.0
    freewheel_voltage_v: float = 0.0
    hysteresis_band_a: float = 0.1
    reference_lead_a: float = 1.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            check_number(
                f"coil.{name}",
                value,
                minimum=0.0,
                positive=name != "freewheel_voltage_v",
                allow_inf=name == "reference_lead_a",  # inf: the reference unlimited
                error=ConfigError,
            )
        if not self.reference_lead_a > self.hysteresis_band_a:
            raise ConfigError(
                "coil.reference_lead_a",
                self.reference_lead_a,
                f"a current > hysteresis_band_a = {self.hysteresis_band_a} A (or inf)",
            )
        ceiling = self.supply_voltage_v / self.resistance_ohm
        if self.current_limit_a >= ceiling:
            raise ConfigError(
                "coil.current_limit_a",
                self.current_limit_a,
                f"a current below supply_voltage_v / resistance_ohm = {ceiling:.6g} A "
                "(the chopper could never reach it)",
            )

    @property
    def time_constant_s(self) -> float:
        """``L / R`` [s]."""
        return self.inductance_h / self.resistance_ohm

    def packed(self) -> np.ndarray:
        """The float64 array the compiled kernels take (layout ``C_*``)."""
        out = np.zeros(N_COIL)
        out[C_R] = self.resistance_ohm
        out[C_L] = self.inductance_h
        out[C_U] = self.supply_voltage_v
        out[C_IMAX] = self.current_limit_a
        out[C_UFW] = self.freewheel_voltage_v
        out[C_BAND] = self.hysteresis_band_a
        out[C_LEAD] = self.reference_lead_a
        return out

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@njit(cache=True)
def reference_step(
    current_ref_a: float,
    rate_a_per_s: float,
    current_a: float,
    lead_a: float,
    limit_a: float,
    dt: float,
) -> float:
    """Integrate the reference-current change rate [A/s]; keep the result within
    ``current_a +- lead_a`` and within ``[0, limit_a]``."""
    ref = current_ref_a + rate_a_per_s * dt
    if ref > current_a + lead_a:
        ref = current_a + lead_a
    elif ref < current_a - lead_a:
        ref = current_a - lead_a
    if ref < 0.0:
        return 0.0
    if ref > limit_a:
        return limit_a
    return ref


@njit(cache=True)
def hysteresis_step(
    current_ref_a: float, current_a: float, switch_on: bool, band_a: float, limit_a: float
) -> bool:
    """Chopper switch command of the hysteresis current controller (paper section 2.4)."""
    if current_a >= limit_a:
        return False
    error = current_ref_a - current_a
    if error > band_a:
        return True
    if error < -band_a:
        return False
    return switch_on


@njit(cache=True)
def coil_step(current_a: float, switch_on: bool, coil: np.ndarray, decay: float) -> float:
    """Coil current [A] one step later; ``decay = exp(-R dt / L)`` (exact R-L solution).

    Switch closed: ``V = U``. Switch open: the coil free-wheels, ``V = -U_fw``, and the
    diode stops the current at zero.
    """
    r = coil[C_R]
    volts = coil[C_U] if switch_on else -coil[C_UFW]
    i_inf = volts / r
    nxt = i_inf + (current_a - i_inf) * decay
    if nxt < 0.0:
        return 0.0
    return nxt


def coil_decay(coil: CoilParams, dt: float) -> float:
    """``exp(-R dt / L)`` for :func:`coil_step`."""
    return float(np.exp(-coil.resistance_ohm * dt / coil.inductance_h))


def coil_current_response_a(
    coil: CoilParams, voltage_v: float, initial_current_a: float, time_s: np.ndarray
) -> np.ndarray:
    """Analytic R-L current [A] under a constant voltage: ``V/R + (I0 - V/R) e^(-t R/L)``."""
    i_inf = voltage_v / coil.resistance_ohm
    return i_inf + (initial_current_a - i_inf) * np.exp(-np.asarray(time_s) / coil.time_constant_s)
