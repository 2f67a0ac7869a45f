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
