"""Discrete quasi-sliding-mode control with a combined reaching law (paper 002).

The paper's formulas were lost in extraction; docs/paper-002-qsmc.md derives them.
Summary of what this kernel computes, keeping the paper's names (``c, eps, q, zeta, T``):

Design model (paper eq. 1 with the delay replaced by its Pade approximant, eq. 6)::

    dx/dt = v,   dv/dt = a + d,   a = exp(-sigma s)/(tau s + 1) [u]
    exp(-sigma s) ~ (lam - s)/(lam + s),  lam = 2/sigma

Realised with two actuator states: ``dz/dt = lam (u - z)`` (so the Pade output is
``2 z - u``) and ``tau da/dt = 2 z - u - a``. The coordinates::

    Y1 = x + h v + sigma tau a + sigma^2/2 z,   Y2 = v + tau a + sigma z,   h = sigma + tau

obey ``dY1/dt = Y2 + h d``, ``dY2/dt = u + d`` exactly: the lag and the Pade delay
disappear and the paper's double integrator ``Y(k+1) = A Y(k) + B u(k) + d(k)`` remains
(``A = [[1, T], [0, 1]]``, ``B = [T^2/2, T]``). ``Y`` is, for slowly varying commands,
the position and speed the train will have ``h`` seconds from now. The reference is
mapped the same way by a second copy of the actuator model driven by the reference
acceleration ``a_r``, so the predicted error ``E = Y_r - Y`` obeys::

    E(k+1) = A E(k) - B delta(k) + B_D (D_r(k) - d(k)),   delta = u - a_r
    B_D = [h T + T^2/2, T],   D_r = a_r - a_m,r   (reference acceleration not yet delivered)

Switching function ``s = c E1 + E2`` (``Ce = [c 1]``, paper eq. 8 on ``E``). Solving
``s(k+1) = s(k) - T rho(k)`` for ``u(k)`` gives the control law::

    u = a_r + [c E2 + (1 + c h + c T/2)(D_r - d_hat) + rho] / (1 + c T/2)
    rho = eps sat(s/Delta) + q s       while phi > zeta   (exponential reaching law)
    rho = eps phi sat(s/Delta)         once  phi <= zeta  (variable-speed reaching law)
    phi = |E1| + |E2|                  (1-norm of the predicted error)

clamped into the output limits. With ``sigma = tau = 0`` (``h = 0``, ``D_r = 0``) it is
the paper's law on the plain double integrator. ``d_hat`` is an optional estimate of
``d`` from the one-step prediction error of ``E2`` (first-order filter, time constant
``tau_d``; ``inf`` switches it off): the paper's "feedback through F^-1" that cancels a
persistent disturbance.
"""

from __future__ import annotations

import math

import numpy as np

from railpilot.control.base import (
    Controller,
    check_dt,
    check_flag,
    check_limits,
    check_number,
)
from railpilot.jit import njit

# params layout
(
    P_C,  # sliding surface slope c [1/s]
    P_EPS,  # reaching-law switching gain eps [m/s^2]
    P_Q,  # exponential reaching-law gain q [1/s]
    P_ZETA,  # switch-over threshold zeta on phi [m + m/s]
    P_DELTA,  # boundary layer Delta [m/s]; 0 = sgn
    P_T,  # design control period T [s]
    P_SIGMA,  # the controller's model of the brake delay sigma [s]
    P_TAU,  # the controller's model of the brake lag tau [s]
    P_TAU_D,  # disturbance estimate time constant tau_d [s]; inf = no estimate
    P_D_MAX,  # bound on |d_hat| [m/s^2]
    P_LO,  # output limits [m/s^2]
    P_HI,
    P_KEEP_Q,  # 1 = keep the linear term q s in the variable-speed phase, 0 = paper's law
) = range(13)
N_PARAMS = 13

# state layout
(
    S_AM,  # model's delivered acceleration a_m for the controller's own command [m/s^2]
    S_ZM,  # model's Pade state z_m for the own command [m/s^2]
    S_AR,  # the same two for the reference acceleration
    S_ZR,
    S_DHAT,  # disturbance estimate d_hat [m/s^2]
    S_E2_PRED,  # E2 predicted for the next step (estimator innovation) [m/s]
    S_HAS_PREV,  # 1 once a step has been taken
    S_S,  # switching function s [m/s]
    S_PHI,  # phi = |E1| + |E2|
    S_LAW,  # 0 = exponential, 1 = variable-speed reaching law
    S_UEQ,  # equivalent part of u [m/s^2] (a_r + c E2 + deficit - d_hat terms)
    S_USW,  # reaching (switching) part of u [m/s^2]
    S_E1,  # predicted position error E1 [m]
    S_E2,  # predicted speed error E2 [m/s]
    S_FACTORS_DT,  # the control period the actuator model's factors below are for [s]
    S_EZ,  # exp(-2 dt / sigma)
    S_EA,  # exp(-dt / tau)
    S_MIX,  # (ez - ea) / (1 - 2 tau / sigma)
) = range(18)
N_STATE = 18

LAW_EXPONENTIAL = 0.0
LAW_VARIABLE_SPEED = 1.0


@njit(cache=True)
def _actuator_factors(sigma: float, tau: float, dt: float) -> tuple[float, float, float]:
    """``(ez, ea, mix)`` of :func:`_actuator_advance` for ``dt`` (the exponentials, computed
    once per control period rather than twice per update)."""
    if sigma > 0.0:
        lam = 2.0 / sigma
        ez = math.exp(-lam * dt)
    else:
        lam = math.inf
        ez = 0.0
    if tau <= 0.0:
        return ez, 0.0, 0.0
    ea = math.exp(-dt / tau)
    if sigma <= 0.0:
        return ez, ea, 0.0
    # particular part driven by 2 z0 exp(-lam t) / tau; (ez - ea)/(1 - lam tau) has a
    # removable singularity at lam tau = 1, where it tends to (dt / tau) ea
    g = 1.0 - lam * tau
    mix = (ez - ea) / g if abs(g) > 1e-6 else (dt / tau) * ea
    return ez, ea, mix


@njit(cache=True)
def _actuator_apply(
    a: float, z: float, u: float, sigma: float, tau: float, ez: float, ea: float, mix: float
) -> tuple[float, float]:
    """One step of the Pade + lag model with the factors of :func:`_actuator_factors`."""
    z0 = z - u
    a0 = a - u
    if tau <= 0.0:
        # no lag: a is the Pade output 2 z - u
        z1 = z0 * ez
        return u + 2.0 * z1, u + z1
    if sigma <= 0.0:
        return u + a0 * ea, u
    return u + a0 * ea + 2.0 * z0 * mix, u + z0 * ez


@njit(cache=True)
def _actuator_advance(
    a: float, z: float, u: float, sigma: float, tau: float, dt: float
) -> tuple[float, float]:
    """Advance the Pade + lag model ``(a, z)`` exactly over ``dt`` with ``u`` held.

    ``dz/dt = lam (u - z)``, ``tau da/dt = 2 z - u - a``; in deviations from the steady
    state ``a = z = u`` this is triangular, so the solution is two exponentials.
    """
    ez, ea, mix = _actuator_factors(sigma, tau, dt)
    return _actuator_apply(a, z, u, sigma, tau, ez, ea, mix)


@njit(cache=True)
def qsmc_step(
    params: np.ndarray,
    state: np.ndarray,
    ref_x: float,
    ref_v: float,
    ref_a: float,
    x: float,
    v: float,
    dt: float,
) -> float:
    """One QSMC update; mutates ``state`` and returns ``u`` [m/s^2] (negative = braking).

    ``ref_x, ref_v, ref_a``: reference position [m], speed [m/s] and acceleration
    [m/s^2] at this control instant (not advanced: the controller predicts itself);
    ``x, v``: measured position and speed; ``dt``: control period [s].
    """
    c = params[P_C]
    eps = params[P_EPS]
    q = params[P_Q]
    zeta = params[P_ZETA]
    delta_bl = params[P_DELTA]
    sigma = params[P_SIGMA]
    tau = params[P_TAU]
    h = sigma + tau
    am = state[S_AM]
    zm = state[S_ZM]
    ar = state[S_AR]
    zr = state[S_ZR]

    # predicted error E = Y_r - Y in the delay-free coordinates
    da = ar - am
    dz = zr - zm
    e1 = (ref_x - x) + h * (ref_v - v) + sigma * tau * da + 0.5 * sigma * sigma * dz
    e2 = (ref_v - v) + tau * da + sigma * dz

    # disturbance estimate from the one-step prediction error of E2 (-T (d - d_hat))
    d_hat = state[S_DHAT]
    if state[S_HAS_PREV] > 0.5:
        innovation = e2 - state[S_E2_PRED]
        d_hat = d_hat - innovation / (params[P_TAU_D] + dt)
        d_max = params[P_D_MAX]
        d_hat = min(max(d_hat, -d_max), d_max)

    s = c * e1 + e2
    phi = abs(e1) + abs(e2)
    if delta_bl > 0.0:
        sat = s / delta_bl
        if sat > 1.0:
            sat = 1.0
        elif sat < -1.0:
            sat = -1.0
    else:
        sat = 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
    if phi > zeta:
        rho = eps * sat + q * s
        law = LAW_EXPONENTIAL
    else:
        # the paper's variable-speed law; with a boundary layer its gain eps phi / Delta
        # vanishes as phi -> 0, so by default the linear part q s is kept (see docs)
        rho = eps * phi * sat + params[P_KEEP_Q] * q * s
        law = LAW_VARIABLE_SPEED

    # reference acceleration the model has not delivered yet; without a lag the model's
    # output is algebraic in its input (2 z - a_r, or a_r itself with no delay either)
    if tau > 0.0:
        deficit = ref_a - ar
    elif sigma > 0.0:
        deficit = 2.0 * (ref_a - zr)
    else:
        deficit = 0.0
    # solve s(k+1) = s(k) - T rho for u (Ce B = T (1 + c T / 2))
    cb = 1.0 + 0.5 * c * dt
    u_eq = ref_a + (c * e2 + (1.0 + c * h + 0.5 * c * dt) * (deficit - d_hat)) / cb
    u_sw = rho / cb
    u = u_eq + u_sw
    u_out = min(max(u, params[P_LO]), params[P_HI])

    # what E2 should be next step if the model is right and d = d_hat
    state[S_E2_PRED] = e2 - dt * (u_out - ref_a) + dt * (deficit - d_hat)
    # actuator models see what was actually sent (anti-windup for free)
    if state[S_FACTORS_DT] != dt:
        state[S_EZ], state[S_EA], state[S_MIX] = _actuator_factors(sigma, tau, dt)
        state[S_FACTORS_DT] = dt
    ez, ea, mix = state[S_EZ], state[S_EA], state[S_MIX]
    am, zm = _actuator_apply(am, zm, u_out, sigma, tau, ez, ea, mix)
    ar, zr = _actuator_apply(ar, zr, ref_a, sigma, tau, ez, ea, mix)
    state[S_AM] = am
    state[S_ZM] = zm
    state[S_AR] = ar
    state[S_ZR] = zr
    state[S_DHAT] = d_hat
    state[S_HAS_PREV] = 1.0
    state[S_S] = s
    state[S_PHI] = phi
    state[S_LAW] = law
    state[S_UEQ] = u_eq
    state[S_USW] = u_sw
    state[S_E1] = e1
    state[S_E2] = e2
    return u_out


class QSMC(Controller):
    """Discrete quasi-sliding-mode tracking controller with the combined reaching law.

    Parameters (names as in paper 002; the rule for picking them is
    :func:`railpilot.control.tuning.qsmc_defaults`)
    ----------
    c
        Sliding surface slope [1/s], ``s = c E1 + E2``: on ``s = 0`` the predicted
        position error decays as ``exp(-c t)``.
    eps
        Switching gain [m/s^2] of both reaching laws (``eps > 0``).
    q
        Exponential reaching-law gain [1/s] (``q > 0``, ``1 - T q > 0``).
    zeta
        Switch-over threshold on ``phi = |E1| + |E2|`` [m + m/s]: exponential law while
        ``phi > zeta``, variable-speed law once ``phi <= zeta``.
    Delta
        Boundary layer [m/s] of ``sat(s / Delta)``; 0 = the ideal ``sgn``.
    T
        Design control period [s]. The kernel discretises with the ``dt`` it is given;
        ``T`` is what the parameter checks (``1 - T q > 0``) are made against.
    sigma, tau
        The controller's *model* of the brake's transport delay and lag [s] (may differ
        from the plant's). 0, 0 = the paper's plain double integrator.
    tau_d
        Time constant [s] of the disturbance estimate ``d_hat``; ``inf`` = no estimate.
    d_max
        Bound on ``|d_hat|`` [m/s^2].
    output_limits
        Limits on ``u`` [m/s^2], e.g. ``(-1.0, 0.0)`` for service braking only.
    keep_q
        Keep the linear term ``q s`` in the variable-speed phase (default). ``False`` is
        the paper's pure law ``s(k+1) = s(k) - T eps phi sat(s/Delta)``, whose gain
        vanishes inside the boundary layer as ``phi -> 0`` (docs/paper-002-qsmc.md).
    """

    name = "qsmc"

    def __init__(
        self,
        c: float,
        eps: float,
        q: float,
        zeta: float,
        Delta: float,
        T: float,
        *,
        sigma: float = 0.0,
        tau: float = 0.0,
        tau_d: float = float("inf"),
        d_max: float = 0.3,
        output_limits: tuple[float | None, float | None] = (None, None),
        keep_q: bool = True,
    ) -> None:
        low, high = check_limits(output_limits)
        c = check_number("c", c, positive=True, unit="1/s")
        eps = check_number("eps", eps, positive=True, unit="m/s^2")
        q = check_number("q", q, positive=True, unit="1/s")
        zeta = check_number("zeta", zeta, minimum=0.0, unit="m + m/s")
        Delta = check_number("Delta", Delta, minimum=0.0, unit="m/s")
        T = check_number("T", T, positive=True, unit="s")
        sigma = check_number("sigma", sigma, minimum=0.0, unit="s")
        tau = check_number("tau", tau, minimum=0.0, unit="s")
        d_max = check_number("d_max", d_max, minimum=0.0, unit="m/s^2")
        # inf allowed: no estimate
        tau_d = check_number("tau_d", tau_d, positive=True, unit="s", allow_inf=True)
        keep_q = check_flag("keep_q", keep_q)
        if not 1.0 - T * q > 0.0:
            raise ValueError(
                f"q = {q!r} is not allowed with T = {T!r}: expected 1 - T q > 0 (q < {1.0 / T:g})"
            )
        if Delta > 0.0 and not T * (q + eps / Delta) < 2.0:
            # inside the layer s(k+1) = (1 - T q - T eps / Delta) s must contract
            raise ValueError(
                f"Delta = {Delta!r} is not allowed with T = {T!r}, q = {q!r}, eps = {eps!r}: "
                f"expected T (q + eps / Delta) < 2 (Delta > {T * eps / (2.0 - T * q):g})"
            )
        self.params = np.zeros(N_PARAMS)
        self.params[P_C] = c
        self.params[P_EPS] = eps
        self.params[P_Q] = q
        self.params[P_ZETA] = zeta
        self.params[P_DELTA] = Delta
        self.params[P_T] = T
        self.params[P_SIGMA] = sigma
        self.params[P_TAU] = tau
        self.params[P_TAU_D] = tau_d
        self.params[P_D_MAX] = d_max
        self.params[P_LO] = low
        self.params[P_HI] = high
        self.params[P_KEEP_Q] = 1.0 if keep_q else 0.0
        self.state = np.zeros(N_STATE)
        self.reset()

    def reset(self) -> None:
        """Brake released and at rest in the model, no estimate, no history."""
        self.state[:] = 0.0

    def update(
        self, reference: tuple[float, float, float], measurement: tuple[float, float], dt: float
    ) -> float:
        """``reference = (x_r [m], v_r [m/s], a_r [m/s^2])``, ``measurement = (x, v)``.

        ``a_r`` is the reference acceleration at this instant, not advanced by the brake's
        delay: the controller's own model does the looking ahead.
        """
        dt = check_dt(dt)
        if not 1.0 - dt * self.params[P_Q] > 0.0:
            raise ValueError(
                f"dt = {dt!r} is not allowed with q = {float(self.params[P_Q])!r}: "
                "expected 1 - dt q > 0"
            )
        xr, vr, ar = reference
        x, v = measurement
        return float(
            qsmc_step(
                self.params,
                self.state,
                float(xr),
                float(vr),
                float(ar),
                float(x),
                float(v),
                dt,
            )
        )

    @property
    def components(self) -> dict[str, float]:
        return {
            "s": float(self.state[S_S]),
            "phi": float(self.state[S_PHI]),
            "law": float(self.state[S_LAW]),
            "u_equivalent": float(self.state[S_UEQ]),
            "u_switching": float(self.state[S_USW]),
            "d_hat": float(self.state[S_DHAT]),
            "e1": float(self.state[S_E1]),
            "e2": float(self.state[S_E2]),
        }

    @property
    def law(self) -> str:
        """Reaching law of the last update: ``"exponential"`` or ``"variable-speed"``."""
        return "variable-speed" if self.state[S_LAW] == LAW_VARIABLE_SPEED else "exponential"

    @property
    def output_limits(self) -> tuple[float, float]:
        return float(self.params[P_LO]), float(self.params[P_HI])


@njit(cache=True)
def qsmc_ato_step(
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
    """:func:`qsmc_step` in the simulator (the step of control/base.py): the ATO adds its
    resistance model as a feed-forward; the clamp is the ATO's (``u_min``, ``u_max``)."""
    return qsmc_step(params, state, ref_x, ref_v, ref_a, x, v, dt) + resist_mps2
