"""First-order lag plus transport delay: ``Y(s)/U(s) = exp(-delay s) / (lag s + 1)``.

Paper 000 eq. 4 (brake cylinder pressure) and paper 002 eq. 1 (brake system).

Two discretisations of one model, both for a command held constant over each step
(zero-order hold, as a digital controller delivers it):

``exact``
    A ring buffer holds past commands, so the delay is exact. A delay that is not a
    whole number of steps is exact too: within a step the delayed command switches
    from one held value to the next at the fraction ``f`` of the step, and the lag is
    advanced exactly over each part (``exp(-h/lag)``).
``pade``
    The delay is replaced by its Pade approximant of the chosen order (what paper 002
    does for its design model), the resulting rational transfer function is realised
    in state space and discretised by zero-order hold. It is a model error against
    ``exact``; :func:`pade_difference` measures it.
"""

from __future__ import annotations

from math import factorial
from typing import Literal

import numpy as np
from scipy.linalg import expm

from railpilot.checks import check_count, check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit

#: longest delay line the exact method builds (80 MB of float64)
MAX_DELAY_STEPS = 10_000_000
#: highest order of Pade approximant :class:`LagDelay` builds: a state space of this
#: order; beyond about ten its discretisation loses its digits (nan for a short delay)
MAX_PADE_ORDER = 10

# params layout of the exact kernel
E_ALPHA_F, E_ALPHA_REST, E_N, E_FRAC, E_LEN = range(5)


def pade_coefficients(delay_s: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of the ``order``-th Pade approximant of ``exp(-delay s)``.

    Coefficients in descending powers of ``s`` (numpy.polyval order). From
    ``N(s) = sum_k (-1)^k c_k (delay s)^k``, ``D(s) = sum_k c_k (delay s)^k`` with
    ``c_k = (2n-k)! n! / ((2n)! k! (n-k)!)``; normalised so the leading denominator
    coefficient is 1 (as python-control's ``pade`` returns it).
    """
    if order < 1:
        raise ConfigError("pade_order", order, "an integer >= 1")
    n = order
    c = [
        factorial(2 * n - k) * factorial(n) / (factorial(2 * n) * factorial(k) * factorial(n - k))
        for k in range(n + 1)
    ]
    num = np.array([(-1) ** k * c[k] * delay_s**k for k in range(n + 1)])[::-1]
    den = np.array([c[k] * delay_s**k for k in range(n + 1)])[::-1]
    return num / den[0], den / den[0]


def _state_space(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, ...]:
    """Controllable canonical realisation of a proper ``num/den`` (den monic)."""
    n = len(den) - 1
    num = np.concatenate([np.zeros(len(den) - len(num)), num])
    d = num[0]
    b = num[1:] - d * den[1:]
    a_mat = np.zeros((n, n))
    a_mat[0, :] = -den[1:]
    if n > 1:
        a_mat[1:, :-1] = np.eye(n - 1)
    b_vec = np.zeros(n)
    b_vec[0] = 1.0
    return a_mat, b_vec, b.copy(), np.array(d)


@njit(cache=True)
def ring_back(slot: int, back: int, length: int) -> int:
    """The slot ``back`` places before ``slot`` in a ring of ``length`` (``back < length``).

    A comparison instead of ``%`` (Python's modulo, slow in a loop that runs every step of
    every Monte Carlo run).
    """
    j = slot - back
    return j + length if j < 0 else j


@njit(cache=True)
def ring_next(slot: int, length: int) -> int:
    """The slot after ``slot`` in a ring of ``length``."""
    slot += 1
    return 0 if slot == length else slot


@njit(cache=True)
def lag_delay_exact_step(
    params: np.ndarray, state: np.ndarray, buffer: np.ndarray, command: float
) -> float:
    """Advance the exact model one step with ``command`` held; return the new output.

    ``state = [output, write slot]``; ``buffer`` is a ring of ``n + 2`` slots of past
    commands (the slot advances by one each step; the delayed commands are read ``n`` and
    ``n + 1`` slots back). Ring arithmetic by comparison, not ``%``: this runs every
    simulation step of every Monte Carlo run.
    """
    length = int(params[E_LEN])
    n = int(params[E_N])
    i = int(state[1])
    buffer[i] = command
    current = buffer[ring_back(i, n, length)]
    previous = buffer[ring_back(i, n + 1, length)]
    y = state[0]
    if params[E_FRAC] > 0.0:
        # first the part of the step where the older command is still arriving
        y = previous + (y - previous) * params[E_ALPHA_F]
    y = current + (y - current) * params[E_ALPHA_REST]
    state[0] = y
    state[1] = ring_next(i, length)
    return y


@njit(cache=True)
def lti_step(
    a_d: np.ndarray, b_d: np.ndarray, c: np.ndarray, d: float, x: np.ndarray, command: float
) -> float:
    """``x <- A_d x + B_d u``; return ``C x + D u`` (discrete state space, in place)."""
    x[:] = a_d @ x + b_d * command
    return float(c @ x + d * command)


class LagDelay:
    """First-order lag [s] plus transport delay [s], stepped at a fixed ``dt`` [s].

    Parameters
    ----------
    lag_s
        Time constant ``T`` [s] (0 = pure delay).
    delay_s
        Transport delay [s] (0 = pure lag).
    dt
        Step [s].
    method
        ``"exact"`` (ring buffer, default) or ``"pade"``.
    pade_order
        Order of the Pade approximant for ``method="pade"``, 1 to :data:`MAX_PADE_ORDER`.
    initial
        Output and past commands before the first step (steady state), a finite number.
    """

    def __init__(
        self,
        lag_s: float,
        delay_s: float,
        dt: float,
        method: Literal["exact", "pade"] = "exact",
        pade_order: int = 1,
        initial: float = 0.0,
    ) -> None:
        self.lag_s = check_number("lag_s", lag_s, minimum=0.0, unit="s", error=ConfigError)
        self.delay_s = check_number("delay_s", delay_s, minimum=0.0, unit="s", error=ConfigError)
        self.dt = check_number("dt", dt, positive=True, unit="s", error=ConfigError)
        if not (isinstance(method, str) and method in ("exact", "pade")):
            raise ConfigError("method", method, "'exact' or 'pade'")
        self.method = method
        self.pade_order = check_count(
            "pade_order",
            pade_order,
            1,
            MAX_PADE_ORDER,
            allowed=f"an integer from 1 to {MAX_PADE_ORDER}",
            error=ConfigError,
        )
        self.initial = check_number("initial", initial, error=ConfigError)
        if method == "exact":
            steps = self.delay_s / self.dt
            if steps > MAX_DELAY_STEPS:
                raise ConfigError(
                    "delay_s", delay_s, f"at most {MAX_DELAY_STEPS:,} steps of dt = {dt} s"
                )
            self.params = exact_params(np.array([self.lag_s]), np.array([self.delay_s]), self.dt)[0]
        else:
            try:
                self._build_pade()
            except OverflowError:  # delay_s ** pade_order past a float's range
                raise ConfigError(
                    "delay_s",
                    delay_s,
                    f"a delay whose order-{self.pade_order} Pade coefficients a float holds",
                ) from None
        self.reset()

    def _build_pade(self) -> None:
        if self.delay_s > 0:
            num, den = pade_coefficients(self.delay_s, self.pade_order)
        else:
            num, den = np.array([1.0]), np.array([1.0])
        if self.lag_s > 0:
            den = np.polymul(den, np.array([1.0, 1.0 / self.lag_s]))
            num = num / self.lag_s
        a_c, b_c, c, d = _state_space(num, den)
        n = len(b_c)
        if n == 0:  # pure gain
            self._ad, self._bd = np.zeros((0, 0)), np.zeros(0)
        else:
            # zero-order-hold discretisation via the augmented matrix exponential
            aug = np.zeros((n + 1, n + 1))
            aug[:n, :n] = a_c
            aug[:n, n] = b_c
            phi = expm(aug * self.dt)
            self._ad, self._bd = phi[:n, :n].copy(), phi[:n, n].copy()
        self._c, self._d = c, float(d)
        self._a_c, self._b_c = a_c, b_c

    def reset(self) -> None:
        """Back to steady state at ``initial``."""
        if self.method == "exact":
            self.state = np.array([self.initial, 0.0])
            self.buffer = np.full(int(self.params[E_LEN]), self.initial)
        else:
            n = len(self._bd)
            # steady state x = -A^-1 B u for the initial command
            if n and self.initial != 0.0:
                self.x = -np.linalg.solve(self._a_c, self._b_c * self.initial)
            else:
                self.x = np.zeros(n)

    def step(self, command: float) -> float:
        """Hold ``command`` for one step; return the output at the end of the step."""
        if self.method == "exact":
            return float(lag_delay_exact_step(self.params, self.state, self.buffer, float(command)))
        return lti_step(self._ad, self._bd, self._c, self._d, self.x, float(command))

    def response(self, commands: np.ndarray) -> np.ndarray:
        """Outputs at the end of each step for a sequence of held commands."""
        return np.array([self.step(u) for u in np.asarray(commands, dtype=float)])


def exact_params(lag_s: np.ndarray, delay_s: np.ndarray, dt: float) -> np.ndarray:
    """The exact kernel's params (``E_*``), one row per ``(lag, delay)`` pair [s].

    The delay is ``n`` whole steps plus a fraction ``f`` of one (a fraction within 1e-9
    of a whole step is none); ``E_ALPHA_F = exp(-f dt / lag)``, ``E_ALPHA_REST =
    exp(-(1 - f) dt / lag)`` (0 for no lag). Vectorised: a Monte Carlo packs a whole
    chunk of sampled brakes at once (:meth:`LagDelayBrake.pack_many`), a single
    :class:`LagDelay` a chunk of one, so both get the same numbers.
    """
    lag_s = np.asarray(lag_s, dtype=float)
    steps = np.asarray(delay_s, dtype=float) / dt
    n = np.floor(steps + 1e-9)
    frac = np.where(np.abs(steps - np.round(steps)) > 1e-9, np.maximum(steps - n, 0.0), 0.0)
    params = np.zeros((steps.shape[0], 5))
    params[:, E_N] = n
    params[:, E_FRAC] = frac
    params[:, E_LEN] = n + 2
    params[:, E_ALPHA_F] = _decay(frac * dt, lag_s)
    params[:, E_ALPHA_REST] = _decay((1.0 - frac) * dt, lag_s)
    return params


def _decay(h: np.ndarray, lag_s: np.ndarray) -> np.ndarray:
    """``exp(-h / lag)``: how much of the old output survives ``h`` seconds (0 for no lag)."""
    no_lag = lag_s == 0.0
    return np.where(no_lag, 0.0, np.exp(-h / np.where(no_lag, 1.0, lag_s)))


def step_response_analytic(t: np.ndarray, lag_s: float, delay_s: float) -> np.ndarray:
    """Unit step response ``1 - exp(-(t - delay)/lag)`` for ``t >= delay``, else 0."""
    t = np.asarray(t, dtype=float)
    shifted = np.maximum(t - delay_s, 0.0)
    if lag_s == 0.0:
        return (t >= delay_s).astype(float)
    return np.where(t >= delay_s, 1.0 - np.exp(-shifted / lag_s), 0.0)


def pade_difference(
    lag_s: float, delay_s: float, dt: float, order: int, duration_s: float | None = None
) -> float:
    """Largest difference [fraction of the step] between the exact and Pade step responses."""
    duration = duration_s if duration_s is not None else 10.0 * (lag_s + delay_s) + dt
    n = int(np.ceil(duration / dt))
    u = np.ones(n)
    exact = LagDelay(lag_s, delay_s, dt).response(u)
    pade = LagDelay(lag_s, delay_s, dt, method="pade", pade_order=order).response(u)
    return float(np.max(np.abs(exact - pade)))
