"""Predictive precise stop: feed-forward, speed feedback and a disturbance observer while
tracking; a stop predicted by the controller's own brake model while stopping.

Why a controller of our own: a heavy-haul train's brake acts seconds
late and builds up over seconds more, and its mass is uncertain by tens of per cent. A
tracking controller that stops by following the speed curve stops where its tracking
error leaves it; on a 4 s delay and a 6 s lag that is metres to tens of metres. This one
asks, every control period, *where will the train stop* if it holds a command, and
picks the command that makes that the stop point (a shooting method on the controller's
model, as the Japanese TASC systems predict the stop). Docs: docs/precise-stop.md.

The controller's model (its knowledge of the train, not gains)
--------------------------------------------------------------
* the brake's response to its own commands, in two paths, each a transport delay and a
  lag realised as in paper 002's QSMC by a Pade delay and a first-order lag
  (:func:`railpilot.control.qsmc._actuator_apply`, one implementation of that model):
  a fast path ``sigma_track, tau_track`` for traction and for braking up to
  ``fast_limit`` (which may fall with speed), and the slow path ``sigma, tau`` for the
  braking beyond it, as a locomotive's brake manager blends regeneration first (traction
  and regeneration answer in a second, a long train's air brake in a minute). With
  ``fast_limit = 0`` (default) all braking goes through ``sigma, tau``;
* the running resistance as the ATO gives it (``resist_mps2``), held over the prediction.

Law
---
Tracking (far from the stop, or while the reference is not braking to it)::

    u = a_r + r - d_hat + k_v (v_r - v)

Stopping (latched once the reference decelerates to the stop point, ``a_r < -a_on`` and
``v_r^2 >= -a_r (stop_m - x_r)``, at the latest onset: when braking at the stop
deceleration ``b`` from now on, build-up included, would no longer stop short of
``stop_m``; or, behind a time-based reference's position, as soon as tracking brakes
harder than the stop needs):
the command ``u`` that, held from now on, brings the model train to rest at ``stop_m``::

    x_stop(u) = stop_m,   x_stop: predicted with the brake model's states, the
                          resistance r and the disturbance estimate d_hat held

found by bisection (``x_stop`` falls monotonically as ``u`` falls); ``u`` is clamped into
the limits when no command in them can stop there (all brake, or release).

Disturbance observer (both phases): the model predicts the speed one control period
ahead from the delivered acceleration of its brake model; the difference from the next
measurement is filtered into ``d_hat`` [m/s^2] with time constant ``T_obs``. It absorbs
what the model lacks: a mass or brake-efficiency error, a gradient the ATO does not know,
the resistance's speed dependence.

Gains: ``k_v = speed_gain / h`` and ``T_obs = observer_gain * h`` with ``h`` the horizon
(delay + lag) of the path that acts: the fast one while tracking (if it brakes at all),
the slow one while stopping. Two dimensionless numbers, the same for every train (no
retuning per train); the train's brake model sets the time scale.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from railpilot.control.base import Controller, check_dt, check_limits, check_number, check_pair
from railpilot.control.qsmc import _actuator_advance, _actuator_apply, _actuator_factors
from railpilot.errors import shown
from railpilot.interp import interp_at
from railpilot.jit import njit

# params layout
(
    P_STOP,  # stop point [m] in the reference's coordinate (nan: tracking only)
    P_SIGMA,  # model of the slow path's delay [s] (the brake's, if it has one path)
    P_TAU,  # and lag [s]
    P_SIGMA_REL,  # the slow path's delay when it releases [s]
    P_TAU_REL,  # and lag [s]
    P_SIGMA_T,  # model of the fast path's delay (traction, regeneration) [s]
    P_TAU_T,  # and lag [s]
    P_GAIN_V,  # speed feedback gain times the model's horizon, k_v h
    P_GAIN_OBS,  # observer time constant over the model's horizon, T_obs / h
    P_D_MAX,  # bound on |d_hat| [m/s^2]
    P_A_ON,  # deceleration the reference must ask for before stopping starts [m/s^2]
    P_STOP_DECEL,  # deceleration the stop is braked with [m/s^2] (0: the reference's)
    P_FAST_LIMIT,  # braking the fast path gives [m/s^2] (0: all braking is slow)
    P_FAST_FULL,  # speed [m/s] at and above which it gives all of it
    P_FAST_ZERO,  # speed [m/s] at and below which it gives none
    P_LO,  # output limits [m/s^2]
    P_HI,
    P_DAVIS0,  # the controller's running-resistance model c0 + c1 v + c2 v^2 [m/s^2],
    P_DAVIS1,  # v in m/s, for the prediction (with the line profile below)
    P_DAVIS2,
    P_N_LINE,  # knots of the line profile: positions, then resistances [m/s^2], follow
) = range(21)
N_PARAMS = 21

# state layout
(
    S_A,  # brake model, fast path: delivered acceleration [m/s^2]
    S_Z,  # and Pade state [m/s^2]
    S_AS,  # slow path: delivered acceleration [m/s^2]
    S_ZS,  # and Pade state [m/s^2]
    S_DHAT,  # disturbance estimate [m/s^2]
    S_V_PRED,  # speed predicted for the next update [m/s]
    S_HAS_PREV,  # 1 once an update has been made
    S_STOPPING,  # 1 once the stop law has taken over (latched)
    S_X_STOP,  # predicted stop position with the command sent [m]
    S_U_TRACK,  # the tracking law's command of the last update [m/s^2]
    S_U_STOP,  # the stop law's command of the last update [m/s^2] (nan: not evaluated)
) = range(11)
N_STATE = 11

#: the prediction's step is the model's horizon over this, at least a control period
_PREDICTION_STEPS_PER_HORIZON = 16.0
#: and at least this many steps to rest braking at the stop deceleration
_PREDICTION_STEPS_TO_STOP = 10.0
#: and it predicts at most this many steps (a command that never stops the train)
_MAX_PREDICTION_STEPS = 6000
#: bisection iterations for the stop command (interval / 2^24: micro-m/s^2)
_BISECTIONS = 24
#: "never stops" [m]
_FAR = 1.0e12


@njit(cache=True)
def fast_path_limit(params: np.ndarray, v: float) -> float:
    """Braking [m/s^2] the fast path gives at speed ``v`` [m/s]: ``fast_limit`` above
    ``fast_full_mps``, linearly less down to 0 at ``fast_zero_mps`` (the regenerative
    brake handed over to the air brake, or fading)."""
    limit = params[P_FAST_LIMIT]
    full = params[P_FAST_FULL]
    zero = params[P_FAST_ZERO]
    if limit <= 0.0 or v >= full:
        return limit
    if v <= zero:
        return 0.0
    return limit * (v - zero) / (full - zero)


@njit(cache=True)
def _split(params: np.ndarray, u: float, v: float) -> tuple[float, float]:
    """``u`` [m/s^2] into the fast path's part (traction, braking up to its limit) and the
    slow path's (the braking beyond)."""
    fast = max(u, -fast_path_limit(params, v))
    return fast, u - fast


@njit(cache=True)
def _model_resistance(params: np.ndarray, n_line: int, x: float, v: float) -> float:
    """The controller's model of the resistance [m/s^2] at ``x`` [m] and ``v`` [m/s]."""
    r = params[P_DAVIS0] + v * (params[P_DAVIS1] + v * params[P_DAVIS2])
    if n_line > 0:
        r += interp_at(x, params[N_PARAMS : N_PARAMS + n_line], params[N_PARAMS + n_line :])
    return r


@njit(cache=True)
def predicted_stop_m(
    params: np.ndarray,
    x: float,
    v: float,
    model: np.ndarray,
    u: float,
    net_mps2: float,
    step_s: float,
    beyond_m: float = math.inf,
) -> float:
    """Where the model train comes to rest holding command ``u`` [m] (``_FAR`` if never);
    or, once it is past ``beyond_m`` [m], where it is then (a position > ``beyond_m``: the
    stop would be farther still).

    ``model``: the brake model's state ``(a_fast, z_fast, a_slow, z_slow)``;
    ``net_mps2``: what acts besides the brake now (``d_hat - r``); held, or, with a line
    profile, changed by the model's resistance ahead. The two paths are
    advanced exactly per step (their inputs held over it); the train with the trapezoid
    of their delivered acceleration, and the last step ends where ``v^2 / (2 a)`` says.

    ``beyond_m``: the stop law only asks whether the stop falls beyond its point (about
    27 predictions every control period while stopping; the onset test one every period
    from far out). A prediction that has passed the point has its answer, and a command
    that never stops the train need not be followed for its 6,000 steps. The answers
    are the same as the whole prediction's, to the bit.
    """
    if v <= 0.0:
        return x
    n_line = int(params[P_N_LINE])
    r_start = _model_resistance(params, n_line, x, v)
    t_sigma, t_tau = params[P_SIGMA_T], params[P_TAU_T]
    s_sigma, s_tau = params[P_SIGMA], params[P_TAU]
    r_sigma, r_tau = params[P_SIGMA_REL], params[P_TAU_REL]
    fez, fea, fmix = _actuator_factors(t_sigma, t_tau, step_s)
    sez, sea, smix = _actuator_factors(s_sigma, s_tau, step_s)
    rez, rea, rmix = _actuator_factors(r_sigma, r_tau, step_s)
    a_f, z_f, a_s, z_s = model[0], model[1], model[2], model[3]
    for _ in range(_MAX_PREDICTION_STEPS):
        u_fast, u_slow = _split(params, u, v)
        a_f_next, z_f = _actuator_apply(a_f, z_f, u_fast, t_sigma, t_tau, fez, fea, fmix)
        if u_slow > a_s:  # releasing
            a_s_next, z_s = _actuator_apply(a_s, z_s, u_slow, r_sigma, r_tau, rez, rea, rmix)
        else:
            a_s_next, z_s = _actuator_apply(a_s, z_s, u_slow, s_sigma, s_tau, sez, sea, smix)
        acc = 0.5 * (a_f + a_f_next + a_s + a_s_next) + net_mps2
        # how the resistance changes ahead (gradients, speed) on top of what acts now
        acc -= _model_resistance(params, n_line, x + 0.5 * v * step_s, v) - r_start
        a_f, a_s = a_f_next, a_s_next
        v_next = v + acc * step_s
        if v_next <= 0.0:
            return x + v * v / (-2.0 * acc)
        x += 0.5 * (v + v_next) * step_s
        v = v_next
        if x > beyond_m:
            return x
    return _FAR


@njit(cache=True)
def _stop_command(
    params: np.ndarray,
    x: float,
    v: float,
    model: np.ndarray,
    net_mps2: float,
    step_s: float,
    lo: float,
    hi: float,
) -> float:
    """The held command that stops the model train at the stop point (bisection in [lo, hi])."""
    stop_m = params[P_STOP]
    if predicted_stop_m(params, x, v, model, lo, net_mps2, step_s, stop_m) >= stop_m:
        return lo  # even full braking overruns: all of it
    if predicted_stop_m(params, x, v, model, hi, net_mps2, step_s, stop_m) <= stop_m:
        return hi  # even the least braking stops short: release (or pull)
    low, high = lo, hi
    for _ in range(_BISECTIONS):
        mid = 0.5 * (low + high)
        if predicted_stop_m(params, x, v, model, mid, net_mps2, step_s, stop_m) > stop_m:
            high = mid
        else:
            low = mid
    return 0.5 * (low + high)


@njit(cache=True)
def pstop_step(
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
    """One update (the step of control/base.py); mutates ``state``, returns ``u`` [m/s^2]."""
    lo = max(params[P_LO], u_min)
    hi = min(params[P_HI], u_max)
    stopping = state[S_STOPPING] > 0.5
    t_sigma, t_tau = params[P_SIGMA_T], params[P_TAU_T]
    s_sigma, s_tau = params[P_SIGMA], params[P_TAU]
    model = state[S_A : S_ZS + 1]

    # gains scale with the horizon of the model in use: h = sigma + tau of the path that
    # acts (the fast one while tracking with one, the slow one while stopping)
    tracking_fast = params[P_FAST_LIMIT] > 0.0
    if stopping or not tracking_fast:
        horizon = max(s_sigma + s_tau, dt)
    else:
        horizon = max(t_sigma + t_tau, dt)
    # disturbance observer: last update's one-period speed prediction against this one
    d_hat = state[S_DHAT]
    if state[S_HAS_PREV] > 0.5:
        d_hat += (v - state[S_V_PRED]) / (params[P_GAIN_OBS] * horizon + dt)
        d_max = params[P_D_MAX]
        d_hat = min(max(d_hat, -d_max), d_max)

    u_track = ref_a + resist_mps2 - d_hat + params[P_GAIN_V] / horizon * (ref_v - v)
    u = u_track
    u_stop = math.nan
    net = d_hat - resist_mps2
    # at least a control period and a sixteenth of the horizon, and few enough steps for
    # a gentle stop (3,000 steps at 0.05 m/s^2) to fit in the prediction
    step = max(dt, (s_sigma + s_tau) / _PREDICTION_STEPS_PER_HORIZON, v / 150.0)
    if not math.isnan(params[P_STOP]) and v > 0.0:
        # the reference decelerates, and to this stop: its mean deceleration to the point
        # is at least half its present one (not a braking to a limit far before it)
        reference_brakes = ref_a < -params[P_A_ON]
        braking_to_stop = reference_brakes and ref_v * ref_v >= -ref_a * (params[P_STOP] - ref_x)
        # the deceleration the stop is braked with: the one given, or the reference's
        given_decel = params[P_STOP_DECEL] > 0.0
        b = params[P_STOP_DECEL] if given_decel else max(-ref_a, 0.0)
        if 0.0 < b <= params[P_FAST_LIMIT]:
            # a stop regeneration brakes alone: the air stays off until regeneration
            # fades, and the fade decides where the train comes to rest. The prediction
            # must see it: a sixteenth of an empty train's 61 s air horizon is 3.8 s, its
            # last 5 km/h in four steps (it stopped 0.26-0.32 m beyond the point). Finer
            # below 3.8 m/s only, where the fade is (docs/precise-stop.md)
            step = max(min(step, v / (_PREDICTION_STEPS_TO_STOP * b)), dt)
        if not stopping:
            # time to brake for the stop? At the latest onset: when braking at the stop
            # deceleration from now on (the build-up included) would no longer stop short
            # of the point, as a driver brakes. With a given stop deceleration (a planned
            # curve's, which knows nothing of the air brake's build-up) that is looked for
            # ahead of the reference's own braking, within reach of the point
            if given_decel:
                slack = max(b - max(net, 0.0), 0.01)
                reach = v * v / (2.0 * slack) + 2.0 * v * (s_sigma + s_tau)
                look = params[P_STOP] - x <= 1.5 * reach
            else:
                look = braking_to_stop
            if look:
                u_onset = min(max(-b - net, lo), hi)
                stop_m = params[P_STOP]
                stopping = (
                    predicted_stop_m(params, x, v, model, u_onset, net, step, stop_m) >= stop_m
                )
            if not stopping and braking_to_stop and x < ref_x:
                # behind a time-based reference's position: tracking its speed brakes the
                # train to rest short of the point if it brakes harder than the stop needs
                stopping = u_track <= _stop_command(params, x, v, model, net, step, lo, hi)
        if stopping:
            u_stop = _stop_command(params, x, v, model, net, step, lo, hi)
            u = u_stop
            # the speed one slow-path horizon from now, braking at the stop deceleration:
            # the regeneration the fast path still gives then bounds what needs no lead
            v_later = max(v - b * (s_sigma + s_tau), 0.0)
            air_off = model[2] > -1e-6
            if u_stop > 0.0 or (air_off and u_track > u_stop >= -fast_path_limit(params, v_later)):
                # Nothing slow to lead: the stop needs pull (a light train climbing to its
                # stop), or only the braking regeneration gives at once, now and an air
                # horizon from now, with the air brake off. The held command is
                # ill-conditioned there: near the balance of pull and gradient the train
                # creeps for minutes, and where the gradient eases the stop jumps from
                # short to far beyond; and a held brake that the gradient and the
                # resistance do most of coasts the train to its stop at walking pace as
                # they fall with speed (an empty train 11-13 % late on the climbs). Follow
                # the planned curve, which brakes to the point at its rate, on time
                # (docs/precise-stop.md, "Climbing to a stop")
                u = u_track
            elif u_track < u and reference_brakes and not braking_to_stop:
                # the reference brakes for a lower limit before the stop (a station's
                # throat, a TSR), harder than the held stop command: the command that
                # lands the train at the stop knows nothing of the limit on the way
                # (an empty train 11.7 km/h over a 45 km/h throat). Brake as tracking asks
                u = u_track
    u_out = min(max(u, lo), hi)

    x_stop = math.nan
    if stopping:
        x_stop = predicted_stop_m(params, x, v, model, u_out, net, step)
    # the model sees what was sent; the speed it predicts for the next update
    u_fast, u_slow = _split(params, u_out, v)
    a_f, z_f = _actuator_advance(model[0], model[1], u_fast, t_sigma, t_tau, dt)
    if u_slow > model[2]:  # releasing
        a_s, z_s = _actuator_advance(
            model[2], model[3], u_slow, params[P_SIGMA_REL], params[P_TAU_REL], dt
        )
    else:
        a_s, z_s = _actuator_advance(model[2], model[3], u_slow, s_sigma, s_tau, dt)
    delivered = 0.5 * (model[0] + a_f + model[2] + a_s)
    state[S_V_PRED] = v + dt * (delivered + net)
    state[S_A] = a_f
    state[S_Z] = z_f
    state[S_AS] = a_s
    state[S_ZS] = z_s
    state[S_DHAT] = d_hat
    state[S_HAS_PREV] = 1.0
    state[S_STOPPING] = 1.0 if stopping else 0.0
    state[S_U_TRACK] = u_track
    state[S_U_STOP] = u_stop
    state[S_X_STOP] = x_stop
    return u_out


class PredictiveStop(Controller):
    """Precise-stop controller: tracking with an observer, then a predicted stop.

    Parameters
    ----------
    sigma, tau
        The controller's model of the (slow) brake's delay and lag [s].
    stop_m
        The stop point [m], in the reference's coordinate; ``nan`` = tracking only (the
        simulator sets it from the scenario's reference).
    sigma_release, tau_release
        The slow path's delay and lag [s] while it releases (a long train's brake pipe
        refills more slowly than it vents); default: ``sigma, tau``.
    sigma_track, tau_track
        The model of the fast path [s]: traction, and braking up to ``fast_limit``;
        default: ``sigma, tau``.
    speed_gain
        ``k_v h`` (dimensionless): the speed feedback gain times the horizon ``h = sigma +
        tau`` of the model in use.
    observer_gain
        ``T_obs / h`` (dimensionless): the observer's time constant over the horizon.
    d_max
        Bound on ``|d_hat|`` [m/s^2].
    a_on
        The reference must decelerate by more than this [m/s^2] before the stop law may
        take over.
    stop_decel
        The deceleration [m/s^2] the stop is braked with (a planned curve's braking); 0
        (default): the reference's deceleration when it starts decelerating.
    fast_limit
        Braking [m/s^2] the fast path (``sigma_track, tau_track``) gives, as a brake
        manager blends regeneration first: what is asked beyond it goes through the slow
        model (the air brake). 0 (default): all braking is slow, traction fast.
    fast_full_mps, fast_zero_mps
        The fast path's braking is ``fast_limit`` at and above ``fast_full_mps`` [m/s],
        falling linearly to 0 at ``fast_zero_mps`` (a handover to the air brake, or the
        regenerative brake's fade).
    davis_mps2, line_profile
        The controller's resistance model for its prediction: ``c0 + c1 v + c2 v^2``
        [m/s^2, v in m/s] plus the line's gradient and curve resistance [m/s^2] at the
        head, ``(positions [m], values [m/s^2])`` (interpolated; held beyond the ends).
        The prediction starts from the resistance the ATO gives now and adds how the model
        changes ahead (with speed; with a profile, a descent ending before the station).
        Python only (a scenario file's ``[controller.pstop]`` takes numbers).
    output_limits
        Limits on ``u`` [m/s^2].
    """

    name = "pstop"

    def __init__(
        self,
        sigma: float,
        tau: float,
        *,
        stop_m: float = float("nan"),
        sigma_track: float | None = None,
        tau_track: float | None = None,
        sigma_release: float | None = None,
        tau_release: float | None = None,
        speed_gain: float = 0.5,
        observer_gain: float = 2.0,
        d_max: float = 0.3,
        a_on: float = 0.02,
        stop_decel: float = 0.0,
        fast_limit: float = 0.0,
        fast_full_mps: float = 0.0,
        fast_zero_mps: float = 0.0,
        davis_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0),
        line_profile: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        output_limits: tuple[float | None, float | None] = (None, None),
    ) -> None:
        low, high = check_limits(output_limits)
        sigma = check_number("sigma", sigma, minimum=0.0, unit="s")
        tau = check_number("tau", tau, minimum=0.0, unit="s")
        # None: the slow path's
        sigma_track = sigma if sigma_track is None else _seconds("sigma_track", sigma_track)
        tau_track = tau if tau_track is None else _seconds("tau_track", tau_track)
        sigma_release = sigma if sigma_release is None else _seconds("sigma_release", sigma_release)
        tau_release = tau if tau_release is None else _seconds("tau_release", tau_release)
        d_max = check_number("d_max", d_max, minimum=0.0, unit="m/s^2")
        a_on = check_number("a_on", a_on, minimum=0.0, unit="m/s^2")
        stop_decel = check_number("stop_decel", stop_decel, minimum=0.0, unit="m/s^2")
        fast_limit = check_number("fast_limit", fast_limit, minimum=0.0, unit="m/s^2")
        fast_full_mps = check_number("fast_full_mps", fast_full_mps, minimum=0.0, unit="m/s")
        fast_zero_mps = check_number("fast_zero_mps", fast_zero_mps, minimum=0.0, unit="m/s")
        speed_gain = check_number("speed_gain", speed_gain, positive=True)
        observer_gain = check_number("observer_gain", observer_gain, positive=True)
        if not fast_zero_mps <= fast_full_mps:
            raise ValueError(
                f"fast_zero_mps = {fast_zero_mps!r} is not allowed with fast_full_mps = "
                f"{fast_full_mps!r}: expected fast_zero_mps <= fast_full_mps"
            )
        stop_m = check_number("stop_m", stop_m, unit="m", allow_nan=True)
        line_x, line_r = _line_profile(line_profile)
        davis = [
            check_number(f"davis_mps2[{i}]", c)
            for i, c in enumerate(
                check_pair("davis_mps2", davis_mps2, 3, "three finite numbers (c0, c1, c2) [m/s^2]")
            )
        ]
        self.params = np.zeros(N_PARAMS + 2 * line_x.size)
        self.params[P_DAVIS0 : P_DAVIS2 + 1] = davis
        self.params[P_N_LINE] = line_x.size
        self.params[N_PARAMS : N_PARAMS + line_x.size] = line_x
        self.params[N_PARAMS + line_x.size :] = line_r
        self.params[P_STOP] = stop_m
        self.params[P_SIGMA] = sigma
        self.params[P_TAU] = tau
        self.params[P_SIGMA_T] = sigma_track
        self.params[P_TAU_T] = tau_track
        self.params[P_SIGMA_REL] = sigma_release
        self.params[P_TAU_REL] = tau_release
        self.params[P_GAIN_V] = speed_gain
        self.params[P_GAIN_OBS] = observer_gain
        self.params[P_D_MAX] = d_max
        self.params[P_A_ON] = a_on
        self.params[P_STOP_DECEL] = stop_decel
        self.params[P_FAST_LIMIT] = fast_limit
        self.params[P_FAST_FULL] = fast_full_mps
        self.params[P_FAST_ZERO] = fast_zero_mps
        self.params[P_LO] = low
        self.params[P_HI] = high
        self.state = np.zeros(N_STATE)
        self.reset()

    def reset(self) -> None:
        """Brake released in the model, no estimate, not stopping."""
        self.state[:] = 0.0
        self.state[S_U_STOP] = math.nan
        self.state[S_X_STOP] = math.nan

    def update(
        self,
        reference: tuple[float, float, float],
        measurement: tuple[float, float],
        dt: float,
        resist_mps2: float = 0.0,
    ) -> float:
        """``reference = (x_r [m], v_r [m/s], a_r [m/s^2])``, ``measurement = (x, v)``."""
        dt = check_dt(dt)
        xr, vr, ar = reference
        x, v = measurement
        return float(
            pstop_step(
                self.params,
                self.state,
                float(xr),
                float(vr),
                float(ar),
                float(x),
                float(v),
                float(resist_mps2),
                -math.inf,
                math.inf,
                dt,
            )
        )

    @property
    def components(self) -> dict[str, float]:
        return {
            "d_hat": float(self.state[S_DHAT]),
            "stopping": float(self.state[S_STOPPING]),
            "u_track": float(self.state[S_U_TRACK]),
            "u_stop": float(self.state[S_U_STOP]),
            "predicted_stop_m": float(self.state[S_X_STOP]),
        }

    @property
    def output_limits(self) -> tuple[float, float]:
        return float(self.params[P_LO]), float(self.params[P_HI])


def retarget(params: np.ndarray, state: np.ndarray, stop_m: float) -> None:
    """A new stop point for a running controller (its ``params`` and ``state`` arrays): the
    stop law starts over, tracking until the new stop's onset (the onboard re-planned: a
    target point set or cleared)."""
    params[P_STOP] = stop_m
    state[S_STOPPING] = 0.0
    state[S_U_STOP] = math.nan
    state[S_X_STOP] = math.nan


def _seconds(name: str, value: object) -> float:
    """A delay or lag [s] of the brake model: a finite number >= 0."""
    return check_number(name, value, minimum=0.0, unit="s")


def _line_profile(
    profile: tuple[npt.ArrayLike, npt.ArrayLike] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(positions, values)`` as arrays; a ValueError naming ``line_profile`` if they are
    not two equally long finite sequences with strictly increasing positions."""
    if profile is None:
        return np.zeros(0), np.zeros(0)
    try:
        xs, rs = (np.asarray(part, dtype=float) for part in check_pair("line_profile", profile))
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(
            f"line_profile = {shown(profile)} is not allowed: expected (positions, values)"
        ) from exc
    ok = (
        xs.ndim == 1
        and xs.shape == rs.shape
        and xs.size >= 2
        and np.all(np.isfinite(xs))
        and np.all(np.isfinite(rs))
        and np.all(np.diff(xs) > 0)
    )
    if not ok:
        raise ValueError(
            f"line_profile = {shown(profile)} is not allowed: expected two equally long finite "
            "sequences (at least 2 knots) with strictly increasing positions"
        )
    return xs, rs


pstop_ato_step = pstop_step
