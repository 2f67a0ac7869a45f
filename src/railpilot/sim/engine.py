"""The fixed-step simulator: train + line + EP brake + controller + reference.

The simulator owns time. Everything that runs per step is one Numba kernel,
:func:`run_ep_kernel`, working on flat float64 arrays, so the same compiled code runs
one scenario (with a recorder) or a batch of many (metrics only, in parallel; see
railpilot.sim.batch). The public entry point is :func:`simulate`.

Per step ``k`` (``t = k dt``):

1. every ``control_every`` steps the controller sees the *measured* position and
   speed and the reference, and returns a commanded acceleration ``u`` [m/s^2],
   held until its next update (the ATO cycle);
2. the ATO turns ``u`` into a brake force demand with its load-weighed mass and its
   own resistance model (feed-forward), and the EP brake (brakes/ep_blend.py)
   delivers electric and air force;
3. the train moves: ``m (1 + gamma) a = -(E + A + R_davis + R_line) + D``, integrated
   exactly for the constant acceleration of the step (so a stop inside a step lands
   where ``v^2 / (2 a)`` says).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from railpilot.brakes.ep_blend import ep_brake_step
from railpilot.control.pid import pid_step, tracking_setpoint
from railpilot.control.smarc import smarc_step

KIND_PID = 0
KIND_SMARC = 1

# train params
T_MEFF, T_MASS, T_A0, T_A1, T_A2, T_X0, T_V0 = range(7)
N_TRAIN = 7
# ATO params: the controllers' side's view of the train
A_MEFF_LW, A_A0, A_A1, A_A2, A_MASS, A_UMIN, A_UMAX, A_STOP_M, A_V_CO = range(9)
N_ATO = 9
# metrics
(
    M_STOP_ERR,
    M_STOP_T,
    M_MAX_VERR,
    M_RMS_VERR,
    M_VERR_CO,
    M_MAX_DECEL,
    M_MAX_JERK,
    M_MAX_XERR,
    M_E_ELEC,
    M_E_FRIC,
    M_FINAL_X,
    M_FINAL_V,
    M_STOPPED,
) = range(13)
N_METRICS = 13
N_CHANNELS = 11

G = 9.8


@njit(cache=True)
def _step_lookup(edges: np.ndarray, values: np.ndarray, x: float) -> float:
    i = np.searchsorted(edges, x, side="right") - 1
    if i < 0 or i >= values.shape[0]:
        return 0.0
    return values[i]


@njit(cache=True)
def _disturbance(
    x: float,
    k: int,
    const_n: float,
    reg_start: np.ndarray,
    reg_end: np.ndarray,
    reg_force: np.ndarray,
    random_n: np.ndarray,
) -> float:
    f = const_n
    for i in range(reg_start.shape[0]):
        if reg_start[i] <= x < reg_end[i]:
            f += reg_force[i]
    if random_n.shape[0] > 0:
        f += random_n[k]
    return f


@njit(cache=True)
def run_ep_kernel(
    n_steps: int,
    dt: float,
    control_every: int,
    train: np.ndarray,
    brake_p: np.ndarray,
    brake_s: np.ndarray,
    brake_buf: np.ndarray,
    line_edges: np.ndarray,
    line_values: np.ndarray,
    dist_const: float,
    reg_start: np.ndarray,
    reg_end: np.ndarray,
    reg_force: np.ndarray,
    random_n: np.ndarray,
    ref_x: np.ndarray,
    ref_v: np.ndarray,
    ref_a: np.ndarray,
    ref_a_ff: np.ndarray,
    ato: np.ndarray,
    kind: int,
    ctrl_p: np.ndarray,
    ctrl_s: np.ndarray,
    speed_noise: np.ndarray,
    record: np.ndarray,
    record_every: int,
    metrics: np.ndarray,
) -> None:
    """Run one scenario for ``n_steps``; fill ``metrics`` and, if it has rows, ``record``.

    ``ref_*`` have ``n_steps + 1`` samples; ``ref_a_ff`` is the reference acceleration
    the feed-forward uses (shifted ahead by the ATO's model of the brake's lead).
    """
    m_eff = train[T_MEFF]
    mass = train[T_MASS]
    x = train[T_X0]
    v = train[T_V0]
    a = 0.0
    a_prev = 0.0
    u = 0.0
    moving = True
    stop_t = np.nan
    max_verr = 0.0
    sum_verr2 = 0.0
    n_moving = 0
    verr_co = np.nan
    max_decel = 0.0
    max_jerk = 0.0
    max_xerr = 0.0
    e_elec = 0.0
    e_fric = 0.0
    n_rec = record.shape[0]
    ctrl_dt = dt * control_every
    for k in range(n_steps):
        t = k * dt
        if moving:
            verr = v - ref_v[k]
            if abs(verr) > max_verr:
                max_verr = abs(verr)
            xerr = abs(x - ref_x[k])
            if xerr > max_xerr:
                max_xerr = xerr
            sum_verr2 += verr * verr
            n_moving += 1
            if np.isnan(verr_co) and v <= ato[A_V_CO]:
                verr_co = abs(verr)
        # --- controller (ATO cycle), on measured signals
        if k % control_every == 0:
            v_meas = v
            if speed_noise.shape[0] > 0:
                v_meas += speed_noise[k]
            v_kmh_m = abs(v_meas) * 3.6
            # the ATO's own resistance model, as a deceleration [m/s^2]
            r_model = (
                (ato[A_A0] + ato[A_A1] * v_kmh_m + ato[A_A2] * v_kmh_m * v_kmh_m)
                * G
                / 1000.0
                * ato[A_MASS]
                / ato[A_MEFF_LW]
            )
            if kind == KIND_PID:
                v_set = tracking_setpoint(ctrl_p, ref_x[k], ref_v[k], x)
                u = ref_a_ff[k] + r_model + pid_step(ctrl_p, ctrl_s, v_set, v_meas, ctrl_dt)
            else:
                u = (
                    smarc_step(ctrl_p, ctrl_s, ref_x[k], ref_v[k], ref_a_ff[k], x, v_meas, ctrl_dt)
                    + r_model
                )
            u = min(max(u, ato[A_UMIN]), ato[A_UMAX])
        demand = -u * ato[A_MEFF_LW] if u < 0.0 else 0.0
        # --- brake and train
        e_n, air_n = ep_brake_step(brake_p, brake_s, brake_buf, demand, v, t, dt)
        if moving:
            v_kmh = v * 3.6
            resist = (
                (
                    train[T_A0]
                    + train[T_A1] * v_kmh
                    + train[T_A2] * v_kmh * v_kmh
                    + _step_lookup(line_edges, line_values, x)
                )
                * mass
                * G
                / 1000.0
            )
            dist = _disturbance(x, k, dist_const, reg_start, reg_end, reg_force, random_n)
            a = (dist - e_n - air_n - resist) / m_eff
            v_next = v + a * dt
            if v_next <= 0.0 and a < 0.0:
                h = v / (-a)
                x += v * h / 2.0
                e_elec += e_n * v * h / 2.0
                e_fric += air_n * v * h / 2.0
                v = 0.0
                moving = False
                stop_t = t + h
            else:
                x += (v + v_next) * dt / 2.0
                e_elec += e_n * (v + v_next) * dt / 2.0
                e_fric += air_n * (v + v_next) * dt / 2.0
                v = v_next
            if a < 0.0 and -a > max_decel:
                max_decel = -a
            # jerk of the brake's deceleration: what the jerk limit and comfort govern
            # (a step in an outside force is not the brake's doing)
            brake_decel = (e_n + air_n) / m_eff
            if k > 0 and moving:
                jerk = abs(brake_decel - a_prev) / dt
                if jerk > max_jerk:
                    max_jerk = jerk
            a_prev = brake_decel
        else:
            a = 0.0
        if n_rec > 0 and k % record_every == 0:
            r = k // record_every
            if r < n_rec:
                record[r, 0] = t
                record[r, 1] = x
                record[r, 2] = v
                record[r, 3] = a
                record[r, 4] = ref_x[k]
                record[r, 5] = ref_v[k]
                record[r, 6] = ref_a[k]
                record[r, 7] = u
                record[r, 8] = demand
                record[r, 9] = e_n
                record[r, 10] = air_n
    metrics[M_STOP_ERR] = x - ato[A_STOP_M] if not moving else np.nan
    metrics[M_STOP_T] = stop_t
    metrics[M_MAX_VERR] = max_verr
    metrics[M_RMS_VERR] = np.sqrt(sum_verr2 / max(n_moving, 1))
    metrics[M_VERR_CO] = verr_co
    metrics[M_MAX_DECEL] = max_decel
    metrics[M_MAX_JERK] = max_jerk
    metrics[M_MAX_XERR] = max_xerr
    metrics[M_E_ELEC] = e_elec
    metrics[M_E_FRIC] = e_fric
    metrics[M_FINAL_X] = x
    metrics[M_FINAL_V] = v
    metrics[M_STOPPED] = 0.0 if moving else 1.0
