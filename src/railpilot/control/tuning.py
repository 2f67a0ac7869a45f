"""Documented tuning rules, so no gain in railpilot is picked by hand.

SIMC (Skogestad, "Simple analytic rules for model reduction and PID controller
tuning", J. Process Control 13 (2003) 291-309), integrating process with lag::

    G(s) = k exp(-theta s) / (s (T s + 1))

Series PID: ``Kc = 1 / (k (tau_c + theta))``, ``tau_I = 4 (tau_c + theta)``,
``tau_D = T``, with the closed-loop time constant ``tau_c = theta`` (Skogestad's
"tight control" choice). Converted here to the parallel form our PID uses.

For a speed loop the process from commanded acceleration to speed is exactly such
an integrator (``k = 1``) behind the brake's delay and lag.
"""

from __future__ import annotations

import math
from typing import Any


def simc_pid_integrating(
    k: float, theta_s: float, lag_s: float, tau_c_s: float | None = None
) -> dict[str, float]:
    """SIMC PID for ``k exp(-theta s) / (s (lag s + 1))`` in parallel form.

    Returns ``{"kp", "ki", "kd", "derivative_filter_s"}``; the derivative filter is a
    tenth of the derivative time, the usual choice.
    """
    tau_c = theta_s if tau_c_s is None else tau_c_s
    kc = 1.0 / (k * (tau_c + theta_s))
    tau_i = 4.0 * (tau_c + theta_s)
    tau_d = lag_s
    factor = 1.0 + tau_d / tau_i  # series -> parallel
    kp = kc * factor
    ti = tau_i * factor
    td = tau_d / factor
    return {"kp": kp, "ki": kp / ti, "kd": kp * td, "derivative_filter_s": td / 10.0}


def tracking_position_gain(
    theta_s: float, lag_s: float, tau_c_s: float, factor: float = 1.0
) -> float:
    """Outer position-loop gain [1/s] of the tracking PID: ``factor / (theta + T + tau_c)``.

    The position loop must be slower than the speed loop it drives, whose response
    time is about ``theta + T + tau_c`` (delay, lag and SIMC's closed-loop time
    constant); its gain is a fraction ``factor`` of the inverse of that time
    (railpilot.reproduce.tune_smarc_ep picks the fraction).
    """
    return factor / (theta_s + lag_s + tau_c_s)


def smarc_from_simc(
    k: float, theta_s: float, lag_s: float, tau_c_s: float | None = None
) -> dict[str, float]:
    """SMARC surface and reaching gains by the SIMC PI rule.

    Near ``s = 0`` SMARC's linear feedback is ``-(ks + c) e2 - ks c e1`` (the
    ``-c e2`` inside the equivalent control adds ``c`` to the speed gain): a PI on
    speed, P on speed and I on position, with no derivative. A PI cannot cancel the
    brake's lag the way SIMC's derivative does, so SIMC's PI rule counts the lag as
    extra delay (``theta_eff = theta + T``): ``Kc = 1 / (k (tau_c + theta_eff))``,
    ``tau_I = 4 (tau_c + theta_eff)``, ``tau_c = theta_eff``. Then ``c = 1 / tau_I``
    and ``ks = Kc - c``. What SMARC adds on top (adaptation, robust term, the
    ``alpha |s|`` gain) is what the comparison measures.
    """
    theta_eff = theta_s + lag_s
    tau_c = theta_eff if tau_c_s is None else tau_c_s
    kc = 1.0 / (k * (tau_c + theta_eff))
    c = 1.0 / (4.0 * (tau_c + theta_eff))
    return {"ks": kc - c, "c": c}


def qsmc_defaults(
    sigma_s: float, tau_s: float, control_period_s: float, *, eps_mps2: float = 0.05
) -> dict[str, float]:
    """QSMC parameters (paper 002) for a brake with delay ``sigma_s`` and lag ``tau_s``.

    Returns ``{"c", "eps", "q", "zeta", "Delta", "T", "sigma", "tau", "tau_d", "d_max"}``,
    the keyword arguments of :class:`railpilot.control.qsmc.QSMC` (the controller's model
    of the brake is the one given here).

    The rule. QSMC works on the predicted error ``E``, in which the modelled delay
    (first-order Pade) and lag have been removed, so what limits its speed is the model
    error: the Pade approximant of the delay, an uncertain delay and lag, and the
    control period. A first-order Pade approximant is good below ``omega = 1 / sigma``
    (phase error ``1 - 2 atan(1/2) = 0.073 rad``, 4.2 deg; a 25 % delay error adds
    0.25 rad there), so all closed-loop poles are placed at

    ``p = 1 / max(sigma, tau, 10 T)``  [1/s]

    (``tau`` and ``10 T`` take over when the delay is short: an uncertain lag, and a
    discrete loop whose poles stay well inside the unit circle, ``T p <= 0.1``).

    * ``c = p``: on the surface the position error decays as ``exp(-p t)``.
    * Inside the boundary layer the reaching law is linear with gain ``q + eps/Delta``;
      setting it to ``p`` too gives a double pole at ``-p`` (the critically damped PD
      ``E1'' + 2p E1' + p^2 E1 = 0``). It is shared equally, ``q = eps/Delta = p/2``,
      so that half of it (``q``) survives in the variable-speed phase.
    * ``eps = eps_mps2`` (0.05 m/s^2): the disturbance acceleration the switching term
      must dominate once ``d_hat`` has taken out the persistent part: the paper's
      random +/-2.3 % of 0.65 m/s^2 is 0.015 m/s^2, three times less.
      Quasi-sliding band with ``sgn``: ``2 T eps`` (0.001 m/s at T = 0.01 s).
    * ``Delta = eps / (p/2)``.
    * ``zeta = 1`` [m + m/s]: the variable-speed switching amplitude ``eps phi`` equals
      the exponential law's ``eps`` exactly at the switch, so only ``q s`` can jump
      (``|q s| <= q phi <= p/2``).
    * ``tau_d = 2 / p``: the disturbance estimate is twice as slow as the loop's
      poles (time constant ``1/p``), so the two do not fight.
    * ``d_max = 0.3`` m/s^2 (a 3 % gradient).

    Worked example, ``sigma = 1.2 s, tau = 0.5 s, T = 0.01 s``: ``p = 1/1.2 = 0.833/s``;
    ``c = 0.833``, ``q = 0.417`` (``1 - T q = 0.996 > 0``), ``Delta = 0.05/0.417 =
    0.12 m/s``, ``tau_d = 2.4 s``. Reaching time from ``s0 = 1 m/s`` to the layer with the
    exponential law: ``ln((q s0 + eps)/(q Delta + eps)) / q = ln(0.467/0.1)/0.417 = 3.7 s``.
    """
    for name, value in (("sigma_s", sigma_s), ("tau_s", tau_s)):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{name} = {value!r} is not allowed: expected a finite number >= 0")
    if not (math.isfinite(control_period_s) and control_period_s > 0):
        raise ValueError(
            f"control_period_s = {control_period_s!r} is not allowed: expected a number > 0"
        )
    if not (math.isfinite(eps_mps2) and eps_mps2 > 0):
        raise ValueError(f"eps_mps2 = {eps_mps2!r} is not allowed: expected a number > 0")
    p = 1.0 / max(sigma_s, tau_s, 10.0 * control_period_s)
    q = p / 2.0
    return {
        "c": p,
        "eps": eps_mps2,
        "q": q,
        "zeta": 1.0,
        "Delta": eps_mps2 / q,
        "T": control_period_s,
        "sigma": sigma_s,
        "tau": tau_s,
        "tau_d": 2.0 / p,
        "d_max": 0.3,
    }


# --- tuning defaults of the built-in controllers (control/registry.py) -------------------
# ``theta_s``: the ATO's brake delay plus half a control period (sim/run.tuning_model);
# ``lag_s``: the ATO's brake lag. The free factors are the winners of the grid search in
# railpilot/reproduce/tune_smarc_ep.py (same method and objective for both).


def pid_tuning_default(theta_s: float, lag_s: float, control_period_s: float) -> dict[str, Any]:
    """TrackingPID: SIMC with ``tau_c = theta``, back-calculation, position gain 0.75 x."""
    tau_c = 1.0 * theta_s
    return dict(
        simc_pid_integrating(1.0, theta_s, lag_s, tau_c_s=tau_c),
        anti_windup="backcalc",
        position_gain=tracking_position_gain(theta_s, lag_s, tau_c, factor=0.75),
    )


def smarc_tuning_default(theta_s: float, lag_s: float, control_period_s: float) -> dict[str, Any]:
    """SMARC from SIMC with ``tau_c = (theta + lag) / 2`` and the searched adaptation."""
    return dict(
        smarc_from_simc(1.0, theta_s, lag_s, tau_c_s=0.5 * (theta_s + lag_s)),
        alpha=1.0,
        eta=0.1,
        phi=0.05,
        gamma=(0.05, 0.05),
        theta_bounds=((0.7, 1.5), (-0.3, 0.3)),
    )


def qsmc_tuning_default(theta_s: float, lag_s: float, control_period_s: float) -> dict[str, Any]:
    """QSMC by :func:`qsmc_defaults`."""
    return dict(qsmc_defaults(theta_s, lag_s, control_period_s))


def pstop_tuning_default(theta_s: float, lag_s: float, control_period_s: float) -> dict[str, Any]:
    """PredictiveStop: the ATO's brake model is its model; its two gains are fixed
    dimensionless numbers (the constructor's defaults), the same for every train."""
    return dict(sigma=theta_s, tau=lag_s)
