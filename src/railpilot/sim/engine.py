"""The fixed-step simulator: train + line + brake + controller + reference.

The simulator owns time. Everything that runs per step is one Numba kernel,
:func:`run_kernel`, reading one typed description of the run (sim/layout.py) and
calling the controller's and the brake's compiled steps it is handed (their
registries, control/registry.py and brakes/registry.py), so the same compiled code runs
one scenario (with a recorder) or a batch of many (metrics only, in parallel; see
railpilot.sim.batch). The public entry point is railpilot.sim.run.simulate.

Per step ``k`` (``t = k dt``):

1. every ``control_every`` steps the controller sees the *measured* position and
   speed (odometry with its errors, speed noise and quantisation; exact if the
   realism effects are off), the reference and the ATO's resistance model, and returns
   a commanded acceleration ``u`` [m/s^2], held until its next update (the ATO cycle);
   the ATO clamps it and quantises it to notches if the brake has them;
2. the brake's step turns ``u`` into electric and air brake forces, e.g. the EP blended
   brake (paper 000: a force demand through the load-weighed mass, brakes/ep_blend.py)
   or paper 002's brake (``uc = F^-1(u)`` through the static map ``F(uc) = -a_max uc``,
   a first-order lag ``tau`` and a transport delay ``sigma``, brakes/lag_delay_brake.py);
3. adhesion limits the brake force at the rail (a slide delivers a fraction of it and
   the wheels turn slower than the train, fooling odometry);
4. the train moves: ``m (1 + gamma) a = D - B - R_davis - R_line``; the acceleration is
   constant over the step, so position is advanced exactly and a stop inside a step
   lands where ``v^2 / (2 a)`` says.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

from railpilot.interp import interp_at
from railpilot.jit import njit
from railpilot.sim.layout import (
    A_A0,
    A_A1,
    A_A2,
    A_GRADE_FF,
    A_MASS,
    A_MEFF_LW,
    A_PREVIEW,
    A_STOP_M,
    A_UMAX,
    A_UMIN,
    A_UPOWER,
    A_V_CO,
    B_N_BUFFER,
    B_N_STATE,
    C_A,
    C_BRAKE_PREV,
    C_E_ELEC,
    C_E_FRIC,
    C_E_TRAC,
    C_E_TRAC_AIR,
    C_FAILED_CALL,
    C_HAS_MOVED,
    C_MAX_DECEL,
    C_MAX_JERK,
    C_MAX_VERR,
    C_MAX_XERR,
    C_MOVING,
    C_N_MOVING,
    C_N_RECORDS,
    C_N_UPDATES,
    C_NEXT_BALISE,
    C_NEXT_RECORD,
    C_NEXT_UPDATE,
    C_RAFF,
    C_RV,
    C_RX,
    C_SLIDE_T,
    C_SLIDING,
    C_STEPS_RUN,
    C_STOP_T,
    C_SUM_VERR2,
    C_U,
    C_V,
    C_V_MAX,
    C_VERR_CO,
    C_X,
    C_X_ODO,
    D_CONST_N,
    N_CARRY,
    R_ADHESION,
    R_NOTCHES,
    R_SLIDE_RATIO,
    R_SLIDE_SLIP,
    R_SPEED_RES,
    R_WHEEL_SCALE,
    T_A0,
    T_A1,
    T_A2,
    T_BRAKE_GAIN,
    T_LENGTH,
    T_MASS,
    T_MEFF,
    T_V0,
    T_X0,
    RunInputs,
    RunState,
)
from railpilot.units import G_MPS2, KMH_PER_MPS
from railpilot.vehicle import profile, resistance

# The two resistance laws the loop evaluates every step, compiled from their one source
# (vehicle/profile.py, vehicle/resistance.py) to be inlined into the loop: a call to a
# separately compiled function passes its arrays with reference counting on every step,
# which cost a third of the loop's time. The arithmetic is the same, so are the results.
mean_specific_resistance = njit(inline="always")(profile.mean_specific_resistance.py_func)
davis_specific_resistance = njit(inline="always")(resistance._davis_specific_resistance)

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
    M_ODO_ERR,
    M_SLIDE_T,
    M_E_TRACTION,
    M_MAX_SPEED,
    M_STEPS,
    M_E_TRAC_AIR,
    M_NO_COMMAND_T,
) = range(20)
N_METRICS = 20
N_CHANNELS = 12

G = G_MPS2  # the one value of g (units.py)


@njit(inline="always")
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
def fresh_state(inp: RunInputs) -> RunState:
    """The state of a run before its first step: the train where the scenario puts it,
    private copies of the controller's and the brake's parameters and state (a step may
    change its parameters, e.g. the PID's limits follow the ATO's clamp; a batch shares
    the inputs between runs running in parallel, and the compiled steps get their arrays
    with reference counts, which a row shared with other threads would contend on every
    step)."""
    c = np.zeros(N_CARRY)
    train = inp.train.p
    x = train[T_X0]
    v = train[T_V0]
    c[C_X] = x
    c[C_V] = v
    c[C_X_ODO] = x
    c[C_MOVING] = 1.0
    c[C_STOP_T] = np.nan
    c[C_VERR_CO] = np.nan
    c[C_V_MAX] = v
    c[C_HAS_MOVED] = 1.0 if v > 0.0 else 0.0
    balises = inp.realism.balises
    next_balise = 0
    while next_balise < balises.shape[0] and balises[next_balise] <= x:
        next_balise += 1
    c[C_NEXT_BALISE] = next_balise
    c[C_RX] = inp.reference.x[0]
    c[C_RV] = inp.reference.v[0]
    c[C_RAFF] = inp.reference.a_ff[0]
    return RunState(
        c,
        inp.controller.p.copy(),
        inp.controller.s0.copy(),
        inp.brake.p.copy(),
        np.zeros(int(inp.brake.sizes[B_N_STATE])),
        np.zeros(int(inp.brake.sizes[B_N_BUFFER])),
    )


@njit(cache=True)
def run_kernel(
    inp: RunInputs,
    ctrl_step: Any,
    brake_step: Any,
    record: np.ndarray,
    record_every: int,
    metrics: np.ndarray,
    run: RunState,
    k_stop: int,
) -> None:
    """Run one scenario from where ``run`` is up to step ``k_stop``; fill ``metrics`` and,
    if it has rows, ``record``.

    ``inp`` is the run's description (sim/layout.py); ``run`` its state
    (:func:`fresh_state` for a run from the start), carried from one call to the next, so
    a run can stop at a step, have its reference or its controller's parameters changed,
    and go on (sim/stepper.py); a run in one call ends at ``inp.sim.n_steps``.
    ``ctrl_step`` is the controller's compiled step and ``brake_step`` the brake's, with
    the signatures of control/base.py and brakes/base.py (the entries of their registries,
    or a user's compiled controller): the loop calls what it is given, nothing else.
    ``inp`` is never changed, so a batch can share it.
    """
    n_steps = inp.sim.n_steps
    dt = inp.sim.dt
    control_every = inp.sim.control_every
    train = inp.train.p
    brake_p = run.brake_p
    line_edges = inp.line.edges
    line_values = inp.line.values
    line_cumulative = inp.line.cumulative
    length_m = train[T_LENGTH]
    dist = inp.disturbance
    ref_x = inp.reference.x
    ref_v = inp.reference.v
    ref_a = inp.reference.a
    ref_a_ff = inp.reference.a_ff
    dist_ref = inp.reference.by_distance
    ato = inp.ato.p
    real = inp.realism.p
    speed_noise = inp.realism.speed_noise
    balises = inp.realism.balises
    ctrl_s = run.ctrl_s
    ctrl_p = run.ctrl_p
    brake_s = run.brake_s
    brake_buf = run.brake_buf
    m_eff = train[T_MEFF]
    mass = train[T_MASS]
    c = run.c
    k_start = int(c[C_STEPS_RUN])
    x = c[C_X]
    v = c[C_V]
    x_odo = c[C_X_ODO]
    a = c[C_A]
    brake_prev = c[C_BRAKE_PREV]
    u = c[C_U]
    moving = c[C_MOVING] > 0.5
    sliding = c[C_SLIDING] > 0.5
    stop_t = c[C_STOP_T]
    max_verr = c[C_MAX_VERR]
    sum_verr2 = c[C_SUM_VERR2]
    n_moving = int(c[C_N_MOVING])
    verr_co = c[C_VERR_CO]
    max_decel = c[C_MAX_DECEL]
    max_jerk = c[C_MAX_JERK]
    max_xerr = c[C_MAX_XERR]
    e_elec = c[C_E_ELEC]
    e_fric = c[C_E_FRIC]
    e_trac = c[C_E_TRAC]
    e_trac_air = c[C_E_TRAC_AIR]
    v_max = c[C_V_MAX]
    # a train that starts at rest is held there until its traction overcomes resistance;
    # only a train that has moved can come to its final stop
    has_moved = c[C_HAS_MOVED] > 0.5
    slide_t = c[C_SLIDE_T]
    no_command_t = np.nan
    n_rec = record.shape[0]
    ctrl_dt = dt * control_every
    next_balise = int(c[C_NEXT_BALISE])
    adhesion_n = real[R_ADHESION] * mass * G
    notches = real[R_NOTCHES]
    by_distance = dist_ref.shape[1] > 0
    # constants of the run, read once (the loop below is the hot path of a Monte Carlo)
    brake_gain = train[T_BRAKE_GAIN]
    wheel_factor = 1.0 + real[R_WHEEL_SCALE]
    slide_keep = 1.0 - real[R_SLIDE_SLIP]
    slide_ratio = real[R_SLIDE_RATIO]
    speed_res = real[R_SPEED_RES]
    u_min = ato[A_UMIN]
    u_max = ato[A_UMAX]
    v_co = ato[A_V_CO]
    grade_ff = ato[A_GRADE_FF] > 0.0
    preview_s = ato[A_PREVIEW]
    upower = ato[A_UPOWER]
    ato_a0 = ato[A_A0]
    ato_a1 = ato[A_A1]
    ato_a2 = ato[A_A2]
    ato_mass = ato[A_MASS]
    m_eff_lw = ato[A_MEFF_LW]
    a0 = train[T_A0]
    a1 = train[T_A1]
    a2 = train[T_A2]
    const_n = dist.p[D_CONST_N]
    # a Monte Carlo run (nothing recorded) ends at the stop: nothing that follows changes
    # a metric (the train is at rest and never moves again)
    stop_at_rest = n_rec == 0
    steps_run = int(c[C_STEPS_RUN])
    # counters instead of k % period (an integer modulo every step is slow)
    next_update = int(c[C_NEXT_UPDATE])
    n_updates = int(c[C_N_UPDATES])
    next_record = int(c[C_NEXT_RECORD])
    n_records = int(c[C_N_RECORDS])
    rx = c[C_RX]
    rv = c[C_RV]
    raff = c[C_RAFF]
    for k in range(k_start, min(n_steps, k_stop)):
        t = k * dt
        # the state at time t, recorded with this step's command and forces
        x_t = x
        v_t = v
        x_odo_t = x_odo
        if moving:
            # speed error against what the ATO tracks: the curve at the true position
            # for a distance-based reference, the curve at time t otherwise
            v_goal = interp_at(x, dist_ref[0], dist_ref[1]) if by_distance else ref_v[k]
            verr = v - v_goal
            if abs(verr) > max_verr:
                max_verr = abs(verr)
            xerr = abs(x - ref_x[k])
            if xerr > max_xerr:
                max_xerr = xerr
            sum_verr2 += verr * verr
            n_moving += 1
            if np.isnan(verr_co) and v <= v_co:
                verr_co = abs(verr)
        # --- controller (ATO cycle), on measured signals
        if k == next_update:
            next_update += control_every
            update_index = n_updates  # k // control_every
            n_updates += 1
            wheel_v = v * slide_keep if sliding else v
            v_meas = wheel_v * wheel_factor
            if speed_noise.shape[0] > 0:
                v_meas += speed_noise[update_index]
            if speed_res > 0.0:
                v_meas = np.round(v_meas / speed_res) * speed_res
            # where the ATO looks: the measured position, or ahead of it by what its
            # brake takes to act (ato.preview_s)
            x_look = x_odo + abs(v_meas) * preview_s if preview_s > 0.0 else x_odo
            if by_distance:
                # re-planned on distance to go: where the train is, not where it was due
                rx = x_odo
                rv = interp_at(x_odo, dist_ref[0], dist_ref[1])
                raff = interp_at(x_odo, dist_ref[0], dist_ref[2])
            else:
                rx = ref_x[k]
                rv = ref_v[k]
                raff = ref_a_ff[k]
            # the traction the drive can give at this speed (constant force, then power)
            u_hi = u_max
            if u_max > 0.0 and upower < u_max * abs(v_meas):
                u_hi = upower / abs(v_meas)
            v_kmh_m = abs(v_meas) * KMH_PER_MPS
            # the ATO's own resistance model, as a deceleration [m/s^2]
            w_model: float = davis_specific_resistance(v_kmh_m, ato_a0, ato_a1, ato_a2)
            if grade_ff:
                # an ATO that knows the line adds its gradients and curves where it
                # believes the train is (or will be: ato.preview_s)
                w_model += mean_specific_resistance(
                    line_edges, line_cumulative, line_values, x_look, length_m, 1.0
                )
            r_model = w_model * G / 1000.0 * ato_mass / m_eff_lw
            u = ctrl_step(
                ctrl_p,
                ctrl_s,
                rx,
                rv,
                raff,
                x_odo,
                v_meas,
                r_model,
                u_min,
                u_hi,
                ctrl_dt,
            )
            if u != u:
                # the controller gave no number (a user's step that returned NaN or
                # raised, control/user.py; a built-in's under NaN parameters): the run
                # stops here and the caller names it (sim/run.py check_commands)
                no_command_t = t
                c[C_FAILED_CALL] = rx
                c[C_FAILED_CALL + 1] = rv
                c[C_FAILED_CALL + 2] = raff
                c[C_FAILED_CALL + 3] = x_odo
                c[C_FAILED_CALL + 4] = v_meas
                c[C_FAILED_CALL + 5] = r_model
                c[C_FAILED_CALL + 6] = u_min
                c[C_FAILED_CALL + 7] = u_hi
                c[C_FAILED_CALL + 8] = ctrl_dt
                break
            u = min(max(u, u_min), u_hi)
            if notches > 0.0:
                # brake commands in notches: the nearest one to the wanted command
                step = -u_min / notches
                u = np.round(u / step) * step
        # --- brake
        e_n, air_n, demand = brake_step(brake_p, brake_s, brake_buf, u, v, t, dt, m_eff_lw, m_eff)
        air_n *= brake_gain
        if moving:
            brake_n = e_n + air_n
            sliding = False
            if adhesion_n > 0.0 and brake_n > adhesion_n:
                # slide: the wheel-rail contact gives only part of the peak adhesion
                scale = adhesion_n * slide_ratio / brake_n
                e_n *= scale
                air_n *= scale
                brake_n = e_n + air_n
                sliding = True
                slide_t += dt
            v_kmh = v * KMH_PER_MPS
            resist = (
                (
                    davis_specific_resistance(v_kmh, a0, a1, a2)
                    + mean_specific_resistance(
                        line_edges, line_cumulative, line_values, x, length_m, 1.0
                    )
                )
                * mass
                * G
                / 1000.0
            )
            outside = _disturbance(
                x,
                k,
                const_n,
                dist.region_start,
                dist.region_end,
                dist.region_force,
                dist.random_n,
            )
            a = (outside - brake_n - resist) / m_eff
            v_next = v + a * dt
            x_before = x
            # the step's trapezoid: its speeds' sum and how long it moved [s] (0: held)
            speed_sum = 0.0
            span = 0.0
            if v_next <= 0.0 and a < 0.0 and not has_moved:
                # at rest and nothing pulls hard enough yet: held (brakes, adhesion)
                a = 0.0
            elif v_next <= 0.0 and a < 0.0:
                h = v / (-a)
                x += v * h / 2.0
                speed_sum, span = v, h
                v = 0.0
                moving = False
                stop_t = t + h
            else:
                speed_sum, span = v + v_next, dt
                x += speed_sum * dt / 2.0
                v = v_next
                if v > 0.0:
                    has_moved = True
                if v > v_max:
                    v_max = v
            if span > 0.0:
                # the forces' work over the step's distance. Electric braking (regeneration)
                # and traction apart: the actuator's electric force is negative when it
                # pulls. Traction pulling against the air brake: the force the two cancel
                # (a long train's air brake releases over a minute; what traction spends
                # meanwhile heats the shoes)
                e_elec += max(e_n, 0.0) * speed_sum * span / 2.0
                e_trac += max(-e_n, 0.0) * speed_sum * span / 2.0
                e_fric += air_n * speed_sum * span / 2.0
                e_trac_air += min(max(-e_n, 0.0), max(air_n, 0.0)) * speed_sum * span / 2.0
            # odometry: wheel revolutions times the (mis-)calibrated circumference
            travelled = x - x_before
            if sliding:
                travelled *= slide_keep
            x_odo += travelled * wheel_factor
            while next_balise < balises.shape[0] and balises[next_balise] <= x:
                x_odo = balises[next_balise] + (x - balises[next_balise])
                next_balise += 1
            if a < 0.0 and -a > max_decel:
                max_decel = -a
            # jerk of the brake's deceleration: what the jerk limit and comfort govern
            # (a step in an outside force is not the brake's doing)
            brake_decel = brake_n / m_eff
            if k > 0 and moving:
                jerk = abs(brake_decel - brake_prev) / dt
                if jerk > max_jerk:
                    max_jerk = jerk
            brake_prev = brake_decel
        else:
            a = 0.0
        if n_rec > 0 and k == next_record:
            next_record += record_every
            r = n_records
            n_records += 1
            if r < n_rec:
                record[r, 0] = t
                record[r, 1] = x_t
                record[r, 2] = v_t
                record[r, 3] = a
                record[r, 4] = rx if by_distance else ref_x[k]
                record[r, 5] = rv if by_distance else ref_v[k]
                record[r, 6] = raff if by_distance else ref_a[k]
                record[r, 7] = u
                record[r, 8] = demand
                record[r, 9] = e_n
                record[r, 10] = air_n
                record[r, 11] = x_odo_t
        steps_run = k + 1
        if stop_at_rest and not moving:
            break
    c[C_X] = x
    c[C_V] = v
    c[C_X_ODO] = x_odo
    c[C_A] = a
    c[C_BRAKE_PREV] = brake_prev
    c[C_U] = u
    c[C_MOVING] = 1.0 if moving else 0.0
    c[C_SLIDING] = 1.0 if sliding else 0.0
    c[C_STOP_T] = stop_t
    c[C_MAX_VERR] = max_verr
    c[C_SUM_VERR2] = sum_verr2
    c[C_N_MOVING] = n_moving
    c[C_VERR_CO] = verr_co
    c[C_MAX_DECEL] = max_decel
    c[C_MAX_JERK] = max_jerk
    c[C_MAX_XERR] = max_xerr
    c[C_E_ELEC] = e_elec
    c[C_E_FRIC] = e_fric
    c[C_E_TRAC] = e_trac
    c[C_E_TRAC_AIR] = e_trac_air
    c[C_V_MAX] = v_max
    c[C_HAS_MOVED] = 1.0 if has_moved else 0.0
    c[C_SLIDE_T] = slide_t
    c[C_NEXT_BALISE] = next_balise
    c[C_NEXT_UPDATE] = next_update
    c[C_N_UPDATES] = n_updates
    c[C_NEXT_RECORD] = next_record
    c[C_N_RECORDS] = n_records
    c[C_RX] = rx
    c[C_RV] = rv
    c[C_RAFF] = raff
    c[C_STEPS_RUN] = steps_run
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
    metrics[M_ODO_ERR] = x_odo - x
    metrics[M_SLIDE_T] = slide_t
    metrics[M_E_TRACTION] = e_trac
    metrics[M_MAX_SPEED] = v_max
    metrics[M_STEPS] = steps_run
    metrics[M_E_TRAC_AIR] = e_trac_air
    metrics[M_NO_COMMAND_T] = no_command_t


def keep_going_if_the_cache_cannot_save(dispatcher: Any) -> None:
    """Let a compiled loop run when Numba cannot write its cache index.

    The loop takes compiled functions as arguments (the controller's and the brake's
    steps). Numba stores such specialisations in its on-disk cache, and a step keeps its
    identity from one process to the next (railpilot/jit_identity.py); but an index may
    still hold entries for steps this process does not have (those of a module since
    edited, which get another identity), and Numba cannot write the index again once the
    function objects it unpickled for them are gone (``ReferenceError``). The code
    compiled in this process is correct either way, so the save is skipped and the
    process runs on (that specialisation is compiled again by the next process).
    """
    cache = dispatcher._cache
    save = cache.save_overload

    def save_overload(sig: Any, data: Any) -> None:
        with contextlib.suppress(ReferenceError):
            save(sig, data)

    cache.save_overload = save_overload


keep_going_if_the_cache_cannot_save(run_kernel)
