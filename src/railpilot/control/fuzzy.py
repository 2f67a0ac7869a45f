"""Mamdani fuzzy control (paper 003 section 3.2) and fuzzy adaptive PI (section 3.3).

Inference engine
----------------
Two inputs, one output, triangular membership functions, ``min`` for AND and for the
implication (clipping), ``max`` to aggregate, centroid defuzzification on a discretised
output universe. The centroid is the exact centroid of the piecewise-linear
interpolant of the aggregated membership on the grid -- the same quantity
``skfuzzy.defuzz(x, mf, "centroid")`` computes -- so our result and scikit-fuzzy's agree
to rounding (tests/control/test_fuzzy.py checks 2,000 seeded random inputs).

A fuzzy system is packed into one float64 array (:func:`pack_fis`) so the Numba kernels
stay allocation-free: ``[n1, n2, n_out, n_grid, in1 (a, b, c) x n1, in2 (a, b, c) x n2,
rules (n1 x n2, output-set index), grid (n_grid), table (n_out x n_grid)]``; ``table``
holds each output set's membership sampled on the grid.

Controllers
-----------
Inputs are the torque error ``e = setpoint - measurement`` and its rate ``ce`` (the
backward difference through a first-order filter of time constant ``ce_filter_s``: the
chopper ripple would otherwise swamp it), divided by the scaling factors ``e_scale`` and
``ce_scale`` and clipped to the normalised universe ``[-1, 1]``.

* :class:`FuzzyController`: sets NB/NS/PS/PB on ``[-1, 1]`` for ``e``, ``ce`` and the
  output, paper Table 1 rules; the output times ``u_scale`` is the command.
* :class:`FuzzyPI`: the same inputs give ``dKp`` and ``dKi`` from paper Tables 2-3
  (sets S/M/B on ``[0, 1]``, times ``kp_span`` / ``ki_span``); ``Kp = Kp1 + dKp``,
  ``Ki = Ki1 + dKi`` (eq. 30-31) with ``Kp1, Ki1`` the base gains, and the PI law is
  :func:`railpilot.control.pid.pid_step` (one PID implementation in the package).
  ``Kp1, Ki1`` are the tuned base values, not the previous sample's gains: every
  correction in Tables 2-3 is >= 0, so accumulating them sample by sample would make the
  gains grow without bound.

In the eddy-brake loop (railpilot.eddy.simulate) the command of every torque controller
is the rate of change of the coil-current reference [A/s].
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from railpilot.control.base import Controller, check_count, check_dt, check_limits, check_number
from railpilot.control.pid import (
    MODE_CLAMP,
    P_HI,
    P_KD,
    P_KI,
    P_KP,
    P_LO,
    P_MODE,
    P_TF,
    S_I,
    S_P,
    pid_step,
)
from railpilot.control.pid import (
    N_PARAMS as PID_N_PARAMS,
)
from railpilot.control.pid import (
    N_STATE as PID_N_STATE,
)
from railpilot.jit import njit

# ---------------------------------------------------------------------------
# Linguistic sets and the paper's rule tables
# ---------------------------------------------------------------------------

#: Input and output sets of the fuzzy controller, in universe order.
SETS4: tuple[str, ...] = ("NB", "NS", "PS", "PB")
#: Output sets of the adaptive-PI corrections.
SETS3: tuple[str, ...] = ("S", "M", "B")

#: Paper Table 1: rows e (NB..PB), columns ce (NB..PB), entry = reference-current change.
RULES_FUZZY: tuple[tuple[str, ...], ...] = (
    ("NB", "NB", "NB", "NB"),
    ("NB", "NS", "NS", "NS"),
    ("NS", "PS", "PS", "PB"),
    ("PB", "PB", "PB", "PB"),
)
#: Paper Table 2: dKp.
RULES_DKP: tuple[tuple[str, ...], ...] = (
    ("S", "S", "M", "S"),
    ("S", "M", "S", "S"),
    ("M", "M", "B", "B"),
    ("B", "B", "B", "B"),
)
#: Paper Table 3: dKi.
RULES_DKI: tuple[tuple[str, ...], ...] = (
    ("B", "M", "S", "S"),
    ("M", "S", "S", "S"),
    ("S", "M", "M", "B"),
    ("S", "M", "B", "B"),
)


def triangles(lo: float, hi: float, n: int) -> np.ndarray:
    """``n`` evenly spaced triangles covering ``[lo, hi]`` (a Ruspini partition).

    Row ``k`` is ``(a, b, c)``: feet ``a, c`` and peak ``b``; the end sets have their peak
    on the universe edge (a right-angled triangle), so every point of the universe has
    memberships summing to 1.
    """
    peaks = np.linspace(lo, hi, n)
    step = peaks[1] - peaks[0]
    abc = np.empty((n, 3))
    abc[:, 0] = np.maximum(peaks - step, lo)
    abc[:, 1] = peaks
    abc[:, 2] = np.minimum(peaks + step, hi)
    return abc


def rule_indices(rules: tuple[tuple[str, ...], ...], out_sets: tuple[str, ...]) -> np.ndarray:
    """Rule table of set names -> array of output-set indices."""
    return np.array([[out_sets.index(name) for name in row] for row in rules], dtype=np.float64)


@njit(cache=True)
def trimf(x: float, a: float, b: float, c: float) -> float:
    """Triangular membership (feet ``a``, ``c``, peak ``b``); ``a == b`` or ``b == c`` allowed."""
    if x < a or x > c:
        return 0.0
    if x <= b:
        if b == a:
            return 1.0
        return (x - a) / (b - a)
    if c == b:
        return 1.0
    return (c - x) / (c - b)


#: most points of the discretised output universe (every update sums over all of them)
MAX_N_GRID = 10_000


def pack_fis(
    in1_abc: np.ndarray,
    in2_abc: np.ndarray,
    rules: np.ndarray,
    out_abc: np.ndarray,
    out_lo: float,
    out_hi: float,
    n_grid: int,
) -> np.ndarray:
    """Pack a two-input Mamdani system into one float64 array (layout in module doc)."""
    n1, n2, n_out = len(in1_abc), len(in2_abc), len(out_abc)
    if rules.shape != (n1, n2):
        raise ValueError(f"rules shape {rules.shape} != ({n1}, {n2})")
    n_grid = check_count("n_grid", n_grid, 3, MAX_N_GRID)
    grid = np.linspace(out_lo, out_hi, n_grid)
    table = np.array([[trimf(y, *abc) for y in grid] for abc in out_abc])
    return np.concatenate(
        [
            np.array([n1, n2, n_out, n_grid], dtype=np.float64),
            np.asarray(in1_abc, dtype=np.float64).ravel(),
            np.asarray(in2_abc, dtype=np.float64).ravel(),
            rules.ravel().astype(np.float64),
            grid,
            table.ravel(),
        ]
    )


@njit(cache=True)
def fis_eval(fis: np.ndarray, x1: float, x2: float, strength: np.ndarray) -> float:
    """Mamdani inference + centroid of the packed system ``fis`` at ``(x1, x2)``.

    ``strength`` is caller-provided scratch of length >= n_out (no allocation here).
    Returns 0 if no rule fires (cannot happen for inputs inside Ruspini partitions).
    """
    n1 = int(fis[0])
    n2 = int(fis[1])
    n_out = int(fis[2])
    n_grid = int(fis[3])
    o_in1 = 4
    o_in2 = o_in1 + 3 * n1
    o_rules = o_in2 + 3 * n2
    o_grid = o_rules + n1 * n2
    o_table = o_grid + n_grid
    for k in range(n_out):
        strength[k] = 0.0
    # firing strength of each output set: max over its rules of min(mu1, mu2)
    for i in range(n1):
        mu1 = trimf(x1, fis[o_in1 + 3 * i], fis[o_in1 + 3 * i + 1], fis[o_in1 + 3 * i + 2])
        if mu1 <= 0.0:
            continue
        for j in range(n2):
            mu2 = trimf(x2, fis[o_in2 + 3 * j], fis[o_in2 + 3 * j + 1], fis[o_in2 + 3 * j + 2])
            w = min(mu1, mu2)
            k = int(fis[o_rules + i * n2 + j])
            if w > strength[k]:
                strength[k] = w
    # aggregate (max of clipped sets) and integrate the piecewise-linear result exactly
    area = 0.0
    moment = 0.0
    y_prev = 0.0
    x_prev = 0.0
    for g in range(n_grid):
        m = 0.0
        for k in range(n_out):
            s = strength[k]
            if s > 0.0:
                t = fis[o_table + k * n_grid + g]
                v = s if s < t else t
                if v > m:
                    m = v
        x = fis[o_grid + g]
        if g > 0:
            h = x - x_prev
            area += 0.5 * h * (y_prev + m)
            moment += h / 6.0 * (x_prev * (2.0 * y_prev + m) + x * (y_prev + 2.0 * m))
        x_prev = x
        y_prev = m
    if area <= 0.0:
        return 0.0
    return moment / area


@njit(cache=True)
def _clip1(x: float) -> float:
    if x > 1.0:
        return 1.0
    if x < -1.0:
        return -1.0
    return x


@njit(cache=True)
def _error_and_rate(
    params: np.ndarray, state: np.ndarray, setpoint: float, measurement: float, dt: float
) -> tuple[float, float]:
    """Torque error and its filtered rate; updates the shared input-stage state."""
    e = setpoint - measurement
    raw = (e - state[S_PREV_E]) / dt if state[S_HAS_PREV] > 0.5 else 0.0
    tau = params[F_TAU_CE]
    ce = (tau * state[S_CE] + dt * raw) / (tau + dt)
    state[S_PREV_E] = e
    state[S_CE] = ce
    state[S_HAS_PREV] = 1.0
    state[S_E] = e
    return e, ce


# shared header of both fuzzy controllers' params
F_E_SCALE, F_CE_SCALE, F_TAU_CE, F_OUT_SCALE, F_LO, F_HI = range(6)
# FuzzyPI adds
F_KP1, F_KI1, F_KI_SPAN, F_FIS2_OFF = 6, 7, 8, 9
F_FIS_OFF = 10  # first packed FIS starts here
# shared state layout
S_PREV_E, S_CE, S_HAS_PREV, S_E, S_OUT, S_Y1, S_Y2 = range(7)
S_SCRATCH = 7  # 8 slots of scratch for fis_eval
S_PID = 15  # FuzzyPI: live PID params (9) then PID state (8)
N_FUZZY_STATE = S_PID + PID_N_PARAMS + PID_N_STATE


@njit(cache=True)
def fuzzy_step(
    params: np.ndarray, state: np.ndarray, setpoint: float, measurement: float, dt: float
) -> float:
    """One update of the Mamdani fuzzy controller; returns the limited command."""
    e, ce = _error_and_rate(params, state, setpoint, measurement, dt)
    x1 = _clip1(e / params[F_E_SCALE])
    x2 = _clip1(ce / params[F_CE_SCALE])
    y = fis_eval(params[F_FIS_OFF:], x1, x2, state[S_SCRATCH : S_SCRATCH + 8])
    out = min(max(params[F_OUT_SCALE] * y, params[F_LO]), params[F_HI])
    state[S_Y1] = y
    state[S_OUT] = out
    return out


@njit(cache=True)
def fuzzy_pi_step(
    params: np.ndarray, state: np.ndarray, setpoint: float, measurement: float, dt: float
) -> float:
    """One update of the fuzzy adaptive PI; returns the limited command (eq. 30-31)."""
    e, ce = _error_and_rate(params, state, setpoint, measurement, dt)
    x1 = _clip1(e / params[F_E_SCALE])
    x2 = _clip1(ce / params[F_CE_SCALE])
    scratch = state[S_SCRATCH : S_SCRATCH + 8]
    y_kp = fis_eval(params[F_FIS_OFF:], x1, x2, scratch)
    y_ki = fis_eval(params[int(params[F_FIS2_OFF]) :], x1, x2, scratch)
    pid_params = state[S_PID : S_PID + PID_N_PARAMS]
    pid_state = state[S_PID + PID_N_PARAMS : S_PID + PID_N_PARAMS + PID_N_STATE]
    pid_params[P_KP] = params[F_KP1] + params[F_OUT_SCALE] * y_kp
    pid_params[P_KI] = params[F_KI1] + params[F_KI_SPAN] * y_ki
    out = pid_step(pid_params, pid_state, setpoint, measurement, dt)
    state[S_Y1] = y_kp
    state[S_Y2] = y_ki
    state[S_OUT] = out
    return out


class _FuzzyBase(Controller):
    """Shared input stage (error, filtered error rate, scaling) of both fuzzy controllers."""

    n_grid: int

    def reset(self) -> None:
        keep = self.state[S_PID : S_PID + PID_N_PARAMS].copy()
        self.state[:] = 0.0
        self.state[S_PID : S_PID + PID_N_PARAMS] = keep

    @property
    def output_limits(self) -> tuple[float, float]:
        return float(self.params[F_LO]), float(self.params[F_HI])

    def _header(
        self,
        e_scale: float,
        ce_scale: float,
        ce_filter_s: float,
        out_scale: float,
        output_limits: tuple[float | None, float | None],
    ) -> np.ndarray:
        """The shared head of ``params``; ``out_scale`` checked by the caller."""
        low, high = check_limits(output_limits)
        head = np.zeros(F_FIS_OFF)
        head[F_E_SCALE] = check_number("e_scale", e_scale, positive=True)
        head[F_CE_SCALE] = check_number("ce_scale", ce_scale, positive=True)
        head[F_TAU_CE] = check_number("ce_filter_s", ce_filter_s, minimum=0.0, unit="s")
        head[F_OUT_SCALE] = out_scale
        head[F_LO] = low
        head[F_HI] = high
        return head


class FuzzyController(_FuzzyBase):
    """Mamdani fuzzy torque controller (paper 003 section 3.2, Table 1).

    Parameters
    ----------
    e_scale
        Error [input unit] that maps to the universe edge (``e/e_scale`` clipped to +-1).
    ce_scale
        Error rate [input unit/s] that maps to the universe edge.
    u_scale
        Command per unit of defuzzified output [output unit]; the largest command is
        ``7/9 u_scale`` (centroid of a fully fired end set).
    ce_filter_s
        Time constant of the error-rate filter [s].
    n_grid
        Points of the discretised output universe for the centroid.
    output_limits
        ``(low, high)`` on the command; ``None`` = unbounded.
    """

    name: ClassVar[str] = "fuzzy"

    def __init__(
        self,
        e_scale: float,
        ce_scale: float,
        u_scale: float,
        *,
        ce_filter_s: float = 0.01,
        n_grid: int = 51,
        output_limits: tuple[float | None, float | None] = (None, None),
    ) -> None:
        u_scale = check_number("u_scale", u_scale, positive=True)
        head = self._header(e_scale, ce_scale, ce_filter_s, u_scale, output_limits)
        n_grid = check_count("n_grid", n_grid, 3, MAX_N_GRID)
        sets = triangles(-1.0, 1.0, 4)
        self.fis = pack_fis(sets, sets, rule_indices(RULES_FUZZY, SETS4), sets, -1.0, 1.0, n_grid)
        self.n_grid = n_grid
        self.params = np.concatenate([head, self.fis])
        self.state = np.zeros(N_FUZZY_STATE)

    def update(self, setpoint: float, measurement: float, dt: float) -> float:
        """Return the command for this sample; ``dt`` [s] since the previous one."""
        return float(
            fuzzy_step(self.params, self.state, float(setpoint), float(measurement), check_dt(dt))
        )

    @property
    def components(self) -> dict[str, float]:
        return {
            "e": float(self.state[S_E]),
            "ce": float(self.state[S_CE]),
            "y": float(self.state[S_Y1]),
            "u": float(self.state[S_OUT]),
        }


class FuzzyPI(_FuzzyBase):
    """Fuzzy adaptive PI (paper 003 section 3.3, Tables 2-3, eq. 30-31).

    Parameters
    ----------
    kp1, ki1
        Base gains ``Kp1`` [out/in], ``Ki1`` [out/(in s)].
    kp_span, ki_span
        Largest corrections: ``dKp = kp_span * y_kp``, ``dKi = ki_span * y_ki`` with
        ``y`` the defuzzified S/M/B output on ``[0, 1]`` (so ``y`` ranges over
        ``[1/6, 5/6]`` -- the centroids of the fully fired S and B sets).
    e_scale, ce_scale, ce_filter_s, n_grid, output_limits
        As for :class:`FuzzyController`.
    """

    name: ClassVar[str] = "fuzzy_pi"

    def __init__(
        self,
        kp1: float,
        ki1: float,
        kp_span: float,
        ki_span: float,
        e_scale: float,
        ce_scale: float,
        *,
        ce_filter_s: float = 0.01,
        n_grid: int = 51,
        output_limits: tuple[float | None, float | None] = (None, None),
    ) -> None:
        kp1 = check_number("kp1", kp1, minimum=0.0)
        ki1 = check_number("ki1", ki1, minimum=0.0)
        kp_span = check_number("kp_span", kp_span, minimum=0.0)
        ki_span = check_number("ki_span", ki_span, minimum=0.0)
        head = self._header(e_scale, ce_scale, ce_filter_s, kp_span, output_limits)
        n_grid = check_count("n_grid", n_grid, 3, MAX_N_GRID)
        head[F_KP1] = kp1
        head[F_KI1] = ki1
        head[F_KI_SPAN] = ki_span
        in_sets = triangles(-1.0, 1.0, 4)
        out_sets = triangles(0.0, 1.0, 3)
        self.fis_kp = pack_fis(
            in_sets, in_sets, rule_indices(RULES_DKP, SETS3), out_sets, 0.0, 1.0, n_grid
        )
        self.fis_ki = pack_fis(
            in_sets, in_sets, rule_indices(RULES_DKI, SETS3), out_sets, 0.0, 1.0, n_grid
        )
        head[F_FIS2_OFF] = F_FIS_OFF + self.fis_kp.size
        self.n_grid = n_grid
        self.params = np.concatenate([head, self.fis_kp, self.fis_ki])
        self.state = np.zeros(N_FUZZY_STATE)
        pid_params = self.state[S_PID : S_PID + PID_N_PARAMS]
        pid_params[P_KP] = kp1
        pid_params[P_KI] = ki1
        pid_params[P_KD] = 0.0
        pid_params[P_TF] = 0.0
        pid_params[P_LO] = head[F_LO]
        pid_params[P_HI] = head[F_HI]
        pid_params[P_MODE] = MODE_CLAMP

    def update(self, setpoint: float, measurement: float, dt: float) -> float:
        """Return the command for this sample; ``dt`` [s] since the previous one."""
        return float(
            fuzzy_pi_step(
                self.params, self.state, float(setpoint), float(measurement), check_dt(dt)
            )
        )

    @property
    def components(self) -> dict[str, float]:
        pid_state = self.state[S_PID + PID_N_PARAMS :]
        return {
            "e": float(self.state[S_E]),
            "ce": float(self.state[S_CE]),
            "kp": float(self.state[S_PID + P_KP]),
            "ki": float(self.state[S_PID + P_KI]),
            "p": float(pid_state[S_P]),
            "i": float(pid_state[S_I]),
            "u": float(self.state[S_OUT]),
        }
