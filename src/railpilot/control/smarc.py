"""Sliding-mode adaptive robust controller (SMARC), paper 000 section 2.2.

The paper's equations are partly garbled (eq. 10 prints ``s = x1 + c x2``; eq. 15
runs the two estimates together). This is the sound version docs/paper-000-smarc-ep.md
derives, keeping the paper's names (``c, ks, alpha, eta, gamma, theta``):

Model seen by the controller (eq. 8 normalised by the nominal mass)::

    theta1 * dv/dt = u + theta2

``u`` is the commanded acceleration [m/s^2] (negative = braking), ``theta1`` the
ratio of true to nominal inertia (load, rotating mass, brake-effort error) and
``theta2`` [m/s^2] the lumped unmodelled acceleration (resistance error, gradient,
outside disturbance). Tracking errors (eq. 9) and the sliding surface::

    e1 = x - xd,   e2 = v - vd,   s = e2 + c e1          [m/s]

Control law (eq. 14 with the model-compensation term its derivation needs)::

    u = theta1_hat (ad - c e2) - theta2_hat - ks (1 + alpha |s|) s - eta sat(s / phi)

Adaptive law (eq. 15, one line per parameter), with projection into
``[theta_min, theta_max]`` (eq. 12)::

    d theta1_hat / dt = -gamma1 s (ad - c e2)
    d theta2_hat / dt =  gamma2 s

With ``V = theta1 s^2 / 2 + sum (theta_i_hat - theta_i)^2 / (2 gamma_i)`` (eq. 16),
``dV/dt = -ks (1 + alpha |s|) s^2 - eta s sat(s/phi) <= 0``. The boundary layer
``phi`` replaces ``sgn`` to stop chattering (the paper's "boundary layer").
"""

from __future__ import annotations

import numpy as np

from railpilot.control.base import Controller, check_dt, check_limits, check_number, check_pair
from railpilot.jit import njit

(
    P_C,
    P_KS,
    P_ALPHA,
    P_ETA,
    P_PHI,
    P_GAMMA1,
    P_GAMMA2,
    P_TH1_MIN,
    P_TH1_MAX,
    P_TH2_MIN,
    P_TH2_MAX,
    P_TH1_0,
    P_TH2_0,
    P_LO,
    P_HI,
) = range(15)
N_PARAMS = 15
S_TH1, S_TH2, S_S, S_UEQ, S_UREACH, S_UROB = range(6)
N_STATE = 6


@njit(cache=True)
def smarc_step(
    params: np.ndarray,
    state: np.ndarray,
    ref_x: float,
    ref_v: float,
    ref_a: float,
    x: float,
    v: float,
    dt: float,
) -> float:
    """One SMARC update; mutates ``state`` (estimates) and returns ``u`` [m/s^2]."""
    c = params[P_C]
    e1 = x - ref_x
    e2 = v - ref_v
    s = e2 + c * e1
    phi = params[P_PHI]
    sat = s / phi if phi > 0.0 else (1.0 if s > 0 else (-1.0 if s < 0 else 0.0))
    if sat > 1.0:
        sat = 1.0
    elif sat < -1.0:
        sat = -1.0
    regressor = ref_a - c * e2
    u_eq = state[S_TH1] * regressor - state[S_TH2]
    u_reach = -params[P_KS] * (1.0 + params[P_ALPHA] * abs(s)) * s
    u_rob = -params[P_ETA] * sat
    u = u_eq + u_reach + u_rob
    lo = params[P_LO]
    hi = params[P_HI]
    u_out = min(max(u, lo), hi)
    # adaptive laws with projection (eq. 12, 15)
    th1 = state[S_TH1] - params[P_GAMMA1] * s * regressor * dt
    th2 = state[S_TH2] + params[P_GAMMA2] * s * dt
    state[S_TH1] = min(max(th1, params[P_TH1_MIN]), params[P_TH1_MAX])
    state[S_TH2] = min(max(th2, params[P_TH2_MIN]), params[P_TH2_MAX])
    state[S_S] = s
    state[S_UEQ] = u_eq
    state[S_UREACH] = u_reach
    state[S_UROB] = u_rob
    return u_out


class SMARC(Controller):
    """Sliding-mode adaptive robust tracking controller.

    Parameters
    ----------
    c
        Sliding surface slope [1/s]: on ``s = 0`` the position error decays as ``exp(-c t)``.
    ks
        Reaching-law gain [1/s].
    alpha
        Extra reaching gain per unit ``|s|`` [s/m].
    eta
        Robust (switching) term amplitude [m/s^2].
    phi
        Boundary layer width [m/s] of ``sat(s/phi)``; 0 = pure ``sgn``.
    gamma
        ``(gamma1, gamma2)`` adaptation gains.
    theta_bounds
        ``((theta1_min, theta1_max), (theta2_min, theta2_max))`` projection bounds.
    theta0
        Initial estimates ``(theta1, theta2)``.
    output_limits
        Limits on ``u`` [m/s^2].
    """

    name = "smarc"

    def __init__(
        self,
        c: float = 0.4,
        ks: float = 1.0,
        alpha: float = 0.0,
        eta: float = 0.05,
        phi: float = 0.05,
        gamma: tuple[float, float] = (0.05, 0.05),
        theta_bounds: tuple[tuple[float, float], tuple[float, float]] = ((0.7, 1.5), (-0.3, 0.3)),
        theta0: tuple[float, float] = (1.0, 0.0),
        output_limits: tuple[float | None, float | None] = (None, None),
    ) -> None:
        low, high = check_limits(output_limits)
        c = check_number("c", c, minimum=0.0, unit="1/s")
        ks = check_number("ks", ks, minimum=0.0, unit="1/s")
        alpha = check_number("alpha", alpha, minimum=0.0, unit="s/m")
        eta = check_number("eta", eta, minimum=0.0, unit="m/s^2")
        phi = check_number("phi", phi, minimum=0.0, unit="m/s")
        gamma1, gamma2 = (
            check_number(f"gamma{i + 1}", g, minimum=0.0)
            for i, g in enumerate(check_pair("gamma", gamma, what="a pair of numbers"))
        )
        theta0_1, theta0_2 = (
            check_number(f"theta0[{i}]", t, unit="m/s^2" if i else "")
            for i, t in enumerate(check_pair("theta0", theta0, what="a pair of numbers"))
        )
        bounds = []
        for i, pair in enumerate(
            check_pair("theta_bounds", theta_bounds, what="a pair of (min, max) pairs")
        ):
            name = f"theta_bounds[{i}]"
            lo_b, hi_b = (
                check_number(f"{name}[{j}]", b)
                for j, b in enumerate(check_pair(name, pair, what="a pair (min, max)"))
            )
            if not lo_b <= hi_b:
                raise ValueError(
                    f"{name} = {(lo_b, hi_b)!r} is not allowed: expected (min, max) with min <= max"
                )
            bounds.append((lo_b, hi_b))
        for i, (theta, (lo_b, hi_b)) in enumerate(zip((theta0_1, theta0_2), bounds, strict=True)):
            if not lo_b <= theta <= hi_b:
                raise ValueError(
                    f"theta0[{i}] = {theta!r} is not allowed: expected a value inside "
                    f"theta_bounds[{i}] = {(lo_b, hi_b)!r}"
                )
        self.params = np.array(
            [
                c,
                ks,
                alpha,
                eta,
                phi,
                gamma1,
                gamma2,
                bounds[0][0],
                bounds[0][1],
                bounds[1][0],
                bounds[1][1],
                theta0_1,
                theta0_2,
                low,
                high,
            ],
            dtype=float,
        )
        self.state = np.zeros(N_STATE)
        self.reset()

    def reset(self) -> None:
        self.state[:] = 0.0
        self.state[S_TH1] = self.params[P_TH1_0]
        self.state[S_TH2] = self.params[P_TH2_0]

    def update(
        self, reference: tuple[float, float, float], measurement: tuple[float, float], dt: float
    ) -> float:
        """``reference = (x_d [m], v_d [m/s], a_d [m/s^2])``, ``measurement = (x, v)``."""
        dt = check_dt(dt)
        xd, vd, ad = reference
        x, v = measurement
        return float(
            smarc_step(
                self.params,
                self.state,
                float(xd),
                float(vd),
                float(ad),
                float(x),
                float(v),
                dt,
            )
        )

    @property
    def components(self) -> dict[str, float]:
        return {
            "s": float(self.state[S_S]),
            "theta1_hat": float(self.state[S_TH1]),
            "theta2_hat": float(self.state[S_TH2]),
            "u_equivalent": float(self.state[S_UEQ]),
            "u_reaching": float(self.state[S_UREACH]),
            "u_robust": float(self.state[S_UROB]),
        }


@njit(cache=True)
def smarc_ato_step(
    params: np.ndarray,
    state: np.ndarray,
    ref_x: float,
    ref_v: float,
    ref_a: float,
    x: float,
    v: float,
    resist_mps2: float,
    u_min: float,
    u_max: float,
    dt: float,
) -> float:
    """:func:`smarc_step` in the simulator (the step of control/base.py): the ATO adds its
    resistance model as a feed-forward; the clamp is the ATO's (``u_min``, ``u_max``)."""
    return smarc_step(params, state, ref_x, ref_v, ref_a, x, v, dt) + resist_mps2
