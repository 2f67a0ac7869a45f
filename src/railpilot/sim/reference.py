"""Target braking curves to a stop point: reference position, speed, acceleration.

A curve is a sequence of phases of constant jerk starting from the braking point,
so position, speed and acceleration are exact piecewise polynomials of time and
the stop point is where the speed reaches zero. Two shapes:

* :func:`constant_deceleration` -- ``a = -decel`` until standstill (paper 002); the
  stop point is ``start + v0^2 / (2 decel)``.
* :func:`smooth_stop` -- the non-linear curve of paper 000's fig. 4 as an ATO would
  draw it: deceleration ramps in at a comfort jerk, holds, eases to a lower final
  deceleration for the approach, and eases to zero exactly at the stop point.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from railpilot.errors import ConfigError
from railpilot.vehicle.train import MAX_SPEED_KMH, MAX_SPEED_MPS

#: Longest coast before the braking point [s]: the longest run (``sim.duration_s``); the
#: knots square it (``h**2``), which overflows floats far beyond
MAX_COAST_S = 86_400.0


@dataclass(frozen=True)
class BrakingCurve:
    """Reference trajectory built of constant-jerk phases.

    Attributes
    ----------
    start_m, v0_mps, a0_mps2
        Position [m], speed [m/s] and acceleration [m/s^2] at t = 0.
    durations_s, jerks_mps3
        The phases: each lasts ``durations_s[i]`` with jerk ``jerks_mps3[i]``.
    jumps_mps2
        Optional step in acceleration at the start of each phase (a constant
        deceleration that starts at once); empty = none.
    """

    start_m: float
    v0_mps: float
    a0_mps2: float
    durations_s: tuple[float, ...]
    jerks_mps3: tuple[float, ...]
    jumps_mps2: tuple[float, ...] = ()

    def _knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Time, position, speed at the start of every phase and the end, and the
        acceleration at the start of every phase (after its jump) and the end."""
        jumps = self.jumps_mps2 or (0.0,) * len(self.durations_s)
        t = [0.0]
        x = [self.start_m]
        v = [self.v0_mps]
        a = [self.a0_mps2 + jumps[0]]
        for i, (h, j) in enumerate(zip(self.durations_s, self.jerks_mps3, strict=True)):
            x.append(x[-1] + v[-1] * h + a[-1] * h**2 / 2 + j * h**3 / 6)
            v.append(v[-1] + a[-1] * h + j * h**2 / 2)
            nxt = jumps[i + 1] if i + 1 < len(jumps) else 0.0
            a.append(a[-1] + j * h + nxt)
            t.append(t[-1] + h)
        return np.array(t), np.array(x), np.array(v), np.array(a)

    @property
    def duration_s(self) -> float:
        """Time from the braking point to standstill [s]."""
        return float(sum(self.durations_s))

    @property
    def stop_m(self) -> float:
        """Position where the reference comes to rest [m]."""
        return float(self._knots()[1][-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Reference ``(position [m], speed [m/s], acceleration [m/s^2])`` at times ``t`` [s].

        After the end of the curve the reference rests at the stop point.
        """
        t = np.asarray(t, dtype=float)
        tk, xk, vk, ak = self._knots()
        jerks = np.append(np.asarray(self.jerks_mps3, dtype=float), 0.0)
        idx = np.clip(np.searchsorted(tk, t, side="right") - 1, 0, len(tk) - 1)
        h = np.clip(t - tk[idx], 0.0, None)
        j = jerks[idx]
        at_rest = idx == len(tk) - 1
        a0 = np.where(at_rest, 0.0, ak[idx])
        x = xk[idx] + vk[idx] * h + a0 * h**2 / 2 + j * h**3 / 6
        v = vk[idx] + a0 * h + j * h**2 / 2
        a = a0 + j * h
        x = np.where(at_rest, xk[-1], x)
        v = np.where(at_rest, 0.0, v)
        a = np.where(at_rest, 0.0, a)
        return x, v, a

    def speed_at_position(self, position_m: np.ndarray, samples: int = 4001) -> np.ndarray:
        """Target speed [m/s] as a function of position [m] (the speed-distance curve)."""
        t = np.linspace(0.0, self.duration_s, samples)
        x, v, _ = self.sample(t)
        return np.interp(position_m, x, v, left=self.v0_mps, right=0.0)


def constant_deceleration(
    v0_mps: float, decel_mps2: float, start_m: float = 0.0, coast_s: float = 0.0
) -> BrakingCurve:
    """Brake at a constant ``decel_mps2`` [m/s^2, > 0] from ``v0_mps`` [m/s] to rest.

    The braking point is ``start_m``; with ``coast_s`` the curve first runs that long
    at ``v0`` before it (so a delayed brake can be commanded ahead of the point).
    The stop point is ``start_m + v0^2 / (2 decel)``.
    """
    _check_positive("reference.v0", v0_mps)
    _check_speed("reference.v0", v0_mps)
    _check_positive("reference.decel", decel_mps2)
    _check_coast(coast_s)
    if coast_s == 0.0:
        return BrakingCurve(start_m, v0_mps, -decel_mps2, (v0_mps / decel_mps2,), (0.0,))
    # coasting, then a jump to full deceleration at the braking point
    return BrakingCurve(
        start_m - v0_mps * coast_s,
        v0_mps,
        0.0,
        (coast_s, v0_mps / decel_mps2),
        (0.0, 0.0),
        (0.0, -decel_mps2),
    )


def smooth_stop(
    v0_mps: float,
    decel_mps2: float,
    jerk_mps3: float,
    final_decel_mps2: float,
    final_phase_speed_mps: float,
    start_m: float = 0.0,
    coast_s: float = 0.0,
    ease_out: bool = False,
) -> BrakingCurve:
    """A jerk-limited non-linear braking curve (paper 000's target curve).

    Phases: an optional coast of ``coast_s`` at ``v0`` before the braking point (so a
    delayed brake can be commanded ahead of it); deceleration ramps from 0 to
    ``decel`` at ``jerk``; constant ``decel``; eases to ``final_decel`` at ``jerk``;
    constant ``final_decel`` from ``final_phase_speed`` down to standstill, or, with
    ``ease_out``, easing to 0 at ``jerk`` exactly as the speed reaches 0.

    Parameters
    ----------
    v0_mps
        Initial braking speed [m/s].
    decel_mps2, final_decel_mps2
        Main and final deceleration [m/s^2], ``0 < final <= decel``.
    jerk_mps3
        Comfort jerk limit [m/s^3] for every transition.
    final_phase_speed_mps
        Speed [m/s] at which the constant final deceleration starts.
    start_m
        Braking point [m]: where the deceleration starts to ramp in.
    coast_s
        Time [s] the curve runs at ``v0`` before the braking point.
    ease_out
        End with deceleration easing to zero (softer, but the last second of the
        stop then depends on the brake's lag); default: stop at ``final_decel``.
    """
    for name, value in (
        ("reference.v0", v0_mps),
        ("reference.decel", decel_mps2),
        ("reference.jerk", jerk_mps3),
        ("reference.final_decel", final_decel_mps2),
        ("reference.final_phase_speed", final_phase_speed_mps),
    ):
        _check_positive(name, value)
    _check_speed("reference.v0", v0_mps)
    if final_decel_mps2 > decel_mps2:
        raise ConfigError(
            "reference.final_decel",
            final_decel_mps2,
            f"a deceleration <= reference.decel ({decel_mps2})",
        )
    a, af, j = decel_mps2, final_decel_mps2, jerk_mps3
    loss_in = a * a / (2 * j)
    loss_ease = (a + af) / 2 * (a - af) / j
    loss_out = af * af / (2 * j) if ease_out else 0.0
    if final_phase_speed_mps <= loss_out:
        raise ConfigError(
            "reference.final_phase_speed",
            final_phase_speed_mps,
            f"a speed > {loss_out:.4g} m/s (what the final ease-out loses)",
        )
    t_final = (final_phase_speed_mps - loss_out) / af
    t_main = (v0_mps - loss_in - loss_ease - final_phase_speed_mps) / a
    if t_main < 0:
        raise ConfigError(
            "reference.v0",
            v0_mps,
            "a speed high enough for the phases (raise v0 or lower the jerk/final_phase_speed)",
        )
    _check_coast(coast_s)
    durations = [coast_s, a / j, t_main, (a - af) / j, t_final]
    jerks = [0.0, -j, 0.0, j, 0.0]
    if ease_out:
        durations.append(af / j)
        jerks.append(j)
    return BrakingCurve(start_m - v0_mps * coast_s, v0_mps, 0.0, tuple(durations), tuple(jerks))


def _check_positive(name: str, value: float) -> None:
    if not (np.isfinite(value) and value > 0):
        raise ConfigError(name, value, "a finite number > 0")


def _check_speed(name: str, value: float) -> None:
    # bounded: v0 squares into the knots' positions (overflow far beyond any train)
    if not value <= MAX_SPEED_MPS:
        raise ConfigError(
            name, value, f"a speed > 0 and <= {MAX_SPEED_MPS:.4g} m/s ({MAX_SPEED_KMH:g} km/h)"
        )


def _check_coast(coast_s: float) -> None:
    if not (np.isfinite(coast_s) and 0 <= coast_s <= MAX_COAST_S):
        raise ConfigError("reference.coast_s", coast_s, f"a time in [0, {MAX_COAST_S:g}] s")
