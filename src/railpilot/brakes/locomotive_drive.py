"""The actuator of a locomotive-hauled heavy-haul train: traction, regeneration and air.

The ATO commands an acceleration ``u`` [m/s^2]: positive is traction, negative braking.
This brake model (the interface of brakes/base.py) turns it into the locomotive's electric
force (traction or regenerative brake, one signed force with one lag) and the train's
automatic air brake (brakes/brake_pipe.py), regeneration first. Model, blending rule and
assumptions: docs/locomotive-drive.md.

Model (``D = u m_eff,lw`` the force the ATO demands, ``B = -D`` when braking)::

    e*      = -min(D, F_T,max(v))        u > 0   traction (negative: propulsive)
            =  min(B, F_E,max(v))        u < 0   regeneration
            =  0                         u = 0
    e(k+1)  = clip(e* + (e(k) - e*) exp(-dt / T_e), -F_T,max(v), F_E,max(v))
    u_air   = -(B - e*) / m_eff,lw       u < 0   (0 otherwise): the rest, to the brake pipe
    F_air   = brake_pipe_ato_step(u_air)           the brake-pipe wave and cylinders

``F_T,max`` and ``F_E,max`` are the locomotive's tractive-effort and faded regenerative
envelopes (vehicle/traction.py), ``T_e`` the electric lag (``traction_lag_s``). ``e`` is in
the simulator's brake-force sign (positive retarding): the simulator computes ``a =
(outside - electric - air - resistance) / m_eff``, so a negative electric force accelerates
the train. Traction and regeneration are one force that passes through zero, never both.

Layout: ``params = [own floats (P_*), then the air brake's params from P_AIR0]``; ``state =
[e (ST_E), then the air brake's state from ST_AIR0]``; ``buffer`` is the air brake's.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from railpilot.brakes.base import PackContext
from railpilot.brakes.brake_pipe import BrakePipeBrake, brake_pipe_ato_step
from railpilot.checks import check_flag, check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.units import kmh_to_mps
from railpilot.vehicle.traction import (
    Locomotive,
    hxd1_locomotive,
    regen_force_max,
    traction_force_max,
)
from railpilot.vehicle.train import Train

# --- params layout -------------------------------------------------------------------------
#: exp(-dt / T_e) of the electric lag [-] (0: no lag)
P_ALPHA = 0
#: traction envelope: starting effort [N], power [W], maximum speed [m/s] (inf: none)
P_T_F0, P_T_POWER, P_T_VMAX = 1, 2, 3
#: regenerative envelope: maximum force [N], power [W], fade speed [m/s]
P_R_F0, P_R_POWER, P_R_FADE = 4, 5, 6
#: 1.0 if the regenerative brake is in use, 0.0 if every brake demand goes to the air
P_REGEN_ON = 7
#: the handover speed [m/s]: below it regeneration is handed over to the air brake (0: none)
P_HANDOVER = 8
#: the air brake's packed params start here (brakes/brake_pipe.py's layout)
P_AIR0 = 9
# --- state layout --------------------------------------------------------------------------
#: the delivered electric force [N], signed like a brake force (negative: traction)
ST_E = 0
#: the air brake's state starts here
ST_AIR0 = 1

#: ASSUMPTION: the electric force's first-order time constant [s]. No figure was found for
#: the HXD1; an inverter-fed drive sets its torque in well under a second, and the
#: locomotive's control ramps it, so 1 s stands for the whole chain.
TRACTION_LAG_S = 1.0
#: longest electric lag accepted [s] (a configuration error beyond it, not a drive)
MAX_LAG_S = 60.0


@dataclass(frozen=True)
class LocomotiveDrive:
    """Parameters of the locomotive drive (module docstring).

    Attributes
    ----------
    locomotive
        The locomotive: its traction and regenerative envelopes (whole locomotive, at the
        wheel). Default :func:`railpilot.vehicle.traction.hxd1_locomotive`. Its mass must be
        part of the run's ``train.mass_kg`` (it is not added).
    traction_lag_s
        Time constant ``T_e`` [s] of the electric force, traction and regeneration alike
        (first order, exact over each step); 0 = immediate. ASSUMED 1 s
        (:data:`TRACTION_LAG_S`).
    air
        The train's automatic air brake (brakes/brake_pipe.py), which covers what the
        regenerative brake cannot. Its ``max_decel_mps2`` is the full-service deceleration of
        the whole train.
    regen_enabled
        False: no regenerative brake (e.g. a non-receptive catenary); the air brake then
        covers every brake demand. Traction is unaffected.
    handover_kmh
        The brake manager's handover speed [km/h]: below it, the regenerative brake's share
        is scaled down linearly to nothing at its fade speed, and the air brake takes the
        rest, so a slow air brake is built up by the time regeneration fades. 0 (default):
        no handover, regeneration to its own fade (docs/locomotive-drive.md).
    """

    locomotive: Locomotive = field(default_factory=hxd1_locomotive)
    traction_lag_s: float = TRACTION_LAG_S
    air: BrakePipeBrake = field(default_factory=BrakePipeBrake)
    regen_enabled: bool = True
    handover_kmh: float = 0.0

    name: ClassVar[str] = "locomotive-drive"
    #: the regenerative brake fades by its envelope (``fade_below_mps``), not at a changeover
    #: speed the ATO must know of
    changeover_kmh: ClassVar[float] = 0.0

    def __post_init__(self) -> None:
        if not isinstance(self.locomotive, Locomotive):
            raise ConfigError(
                "brake.locomotive", self.locomotive, "a railpilot.vehicle.traction.Locomotive"
            )
        if not isinstance(self.air, BrakePipeBrake):
            raise ConfigError("brake.air", self.air, "a brake-pipe brake (BrakePipeBrake)")
        check_number(
            "brake.traction_lag_s",
            self.traction_lag_s,
            minimum=0.0,
            maximum=MAX_LAG_S,
            allowed=f"a number in [0, {MAX_LAG_S:g}] s",
            error=ConfigError,
        )
        check_flag(
            "brake.regen_enabled", self.regen_enabled, allowed="true or false", error=ConfigError
        )
        check_number(
            "brake.handover_kmh",
            self.handover_kmh,
            minimum=0.0,
            maximum=200.0,
            allowed="a speed in [0, 200] km/h",
            error=ConfigError,
        )

    @property
    def lead_s(self) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the air brake (its front: ``BrakePipeBrake.lead_s``).

        The air brake is the slow path the ATO must lead (seconds of wave and tens of
        seconds of cylinder filling against the electric force's ``traction_lag_s``).
        For the whole train use :meth:`train_lead_s`.
        """
        return self.air.lead_s

    def train_lead_s(self, train_length_m: float) -> tuple[float, float]:
        """``(delay, lag)`` [s] of the whole train's air brake (``BrakePipeBrake.train_lead_s``)."""
        return self.air.train_lead_s(train_length_m)

    def max_traction_accel_mps2(self, train: Train) -> float:
        """Largest traction acceleration [m/s^2]: starting effort / effective mass.

        ``F_T0 / (m (1 + gamma))`` with the train's true effective mass, resistance not
        deducted: the bound of the ATO's clamp (``u_max``). A command above the envelope at
        the current speed is not an error: the drive delivers the envelope.
        """
        return float(self.locomotive.traction.max_force_n / train.effective_mass_kg)

    def max_traction_power_accel_w_per_kg(self, train: Train) -> float:
        """Traction power per effective mass [W/kg]: the envelope's constant-power part.

        ``P_T / (m (1 + gamma))``: divided by the speed it is the largest traction
        acceleration above the base speed, so the ATO's clamp can follow the envelope
        (``u_max(v) = min(F_T0, P_T / v) / m_eff``) and its controller's anti-windup sees
        the saturation the drive really has.
        """
        return float(self.locomotive.traction.max_power_w / train.effective_mass_kg)

    def sizes(self, params: np.ndarray) -> tuple[int, int]:
        """Floats of state (the electric force, then the air brake's) and of history."""
        params = np.asarray(params, dtype=float)
        if params.ndim != 1 or params.size <= P_AIR0:
            raise ConfigError(
                "brake.params", params.shape, f"a locomotive-drive params array (> {P_AIR0})"
            )
        if not 0.0 <= params[P_ALPHA] <= 1.0:
            raise ConfigError("brake.params", params[P_ALPHA], "exp(-dt / T_e) in [0, 1]")
        try:
            n_state, n_buffer = self.air.sizes(params[P_AIR0:])
        except ConfigError as err:
            raise ConfigError("brake.air.params", err.value, err.allowed) from err
        return ST_AIR0 + n_state, n_buffer

    def pack(self, context: PackContext) -> np.ndarray:
        """The kernel's params for the context's step and train (brakes/base.py).

        The air brake is packed with the same context and appended from :data:`P_AIR0`.
        """
        dt = context.dt_s
        if not (np.isfinite(dt) and dt > 0):
            raise ConfigError("sim.dt_s", dt, "a finite number > 0 [s]")
        train = context.train
        if train.mass_kg < self.locomotive.mass_kg:
            raise ConfigError(
                "train.mass_kg",
                train.mass_kg,
                f"at least the locomotive's mass {self.locomotive.mass_kg:g} kg "
                f"({self.locomotive.mass_kg / 1000.0:g} t; the train's mass includes it)",
            )
        loco = self.locomotive
        own = np.zeros(P_AIR0)
        own[P_ALPHA] = np.exp(-dt / self.traction_lag_s) if self.traction_lag_s > 0 else 0.0
        own[P_T_F0] = loco.traction.max_force_n
        own[P_T_POWER] = loco.traction.max_power_w
        own[P_T_VMAX] = loco.traction.speed_limit_mps
        own[P_R_F0] = loco.regen.max_force_n
        own[P_R_POWER] = loco.regen.max_power_w
        own[P_R_FADE] = loco.regen.fade_below_mps
        own[P_REGEN_ON] = 1.0 if self.regen_enabled else 0.0
        own[P_HANDOVER] = kmh_to_mps(self.handover_kmh)
        return np.concatenate((own, self.air.pack(context)))

    # --- pure helpers (tests, docs, ATO tuning) ----------------------------------------------

    def electric_target_n(
        self, u_mps2: npt.ArrayLike, speed_mps: npt.ArrayLike, m_eff_lw_kg: float
    ) -> np.ndarray:
        """The electric force target ``e*`` [N] (signed: positive retarding).

        ``-min(u m_eff,lw, F_T,max(v))`` for ``u > 0``, ``min(-u m_eff,lw, F_E,max(v))`` for
        ``u < 0`` (0 without regeneration), 0 at ``u = 0``; the value the delivered force
        settles to under a held command at a held speed. Vectorised (broadcasts).
        """
        u = np.asarray(u_mps2, dtype=float)
        demand = u * m_eff_lw_kg
        traction = self.locomotive.traction.max_force(speed_mps)
        regen = self.locomotive.regen.max_force(speed_mps) * handover_share(
            speed_mps, kmh_to_mps(self.handover_kmh), self.locomotive.regen.fade_below_mps
        )
        if not self.regen_enabled:
            regen = np.zeros_like(regen)
        return np.asarray(
            np.where(
                u > 0.0,
                -np.minimum(demand, traction),
                np.where(u < 0.0, np.minimum(-demand, regen), 0.0),
            )
        )

    def steady_forces_n(
        self,
        u_mps2: npt.ArrayLike,
        speed_mps: npt.ArrayLike,
        m_eff_lw_kg: float,
        m_eff_kg: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(electric, air)`` [N] a held command settles to at a held speed.

        Electric: :meth:`electric_target_n`. Air (braking only): the rest of the demand,
        ``(B - e*) m_eff / m_eff,lw``, limited to full service ``a_max m_eff``: the brake
        manager turns the rest into a brake-pipe command with the weighed mass and the air
        brake acts on the true mass, so with exact load weighing ``electric + air = B``
        (until the air brake saturates).
        """
        u = np.asarray(u_mps2, dtype=float)
        electric = self.electric_target_n(u, speed_mps, m_eff_lw_kg)
        rest = np.where(u < 0.0, -u * m_eff_lw_kg - electric, 0.0)
        a_max = self.air.max_decel_mps2
        fraction = np.minimum(rest / (a_max * m_eff_lw_kg), 1.0)
        return electric, np.asarray(fraction * a_max * m_eff_kg)


@njit(cache=True)
def _handover_share(speed: float, handover_mps: float, fade_mps: float) -> float:
    if handover_mps <= fade_mps or speed >= handover_mps:
        return 1.0
    if speed <= fade_mps:
        return 0.0
    return (speed - fade_mps) / (handover_mps - fade_mps)


def handover_share(speed_mps: npt.ArrayLike, handover_mps: float, fade_mps: float) -> np.ndarray:
    """The regenerative brake's share [-] under the brake manager's handover.

    1 at and above ``handover_mps`` [m/s] (and always when it is not above the fade speed),
    falling linearly to 0 at ``fade_mps`` [m/s], 0 below. :func:`_handover_share` is the
    kernel's scalar twin.
    """
    v = np.abs(np.asarray(speed_mps, dtype=float))
    if handover_mps <= fade_mps:
        return np.ones_like(v)
    return np.asarray(np.clip((v - fade_mps) / (handover_mps - fade_mps), 0.0, 1.0))


def electric_step_response_n(
    t_s: npt.ArrayLike, target_n: float, lag_s: float, initial_n: float = 0.0
) -> np.ndarray:
    """Locomotive drive: the electric force [N] ``t_s`` [s] after its target steps.

    ``e(t) = e* + (e0 - e*) exp(-t / T_e)`` for a target ``target_n`` [N] held from ``t = 0``
    and a force ``initial_n`` [N] then, inside the envelope (the kernel clips to it). The
    kernel reproduces it at the end of each step to rounding (exact discretisation).
    """
    t = np.asarray(t_s, dtype=float)
    decay = np.exp(-t / lag_s) if lag_s > 0 else np.where(t > 0.0, 0.0, 1.0)
    return np.asarray(target_n + (initial_n - target_n) * decay)


@njit(cache=True)
def locomotive_drive_ato_step(
    p: np.ndarray,
    state: np.ndarray,
    buffer: np.ndarray,
    u: float,
    speed_mps: float,
    t: float,
    dt: float,
    m_eff_lw: float,
    m_eff: float,
) -> tuple[float, float, float]:
    """The locomotive drive in the simulator (the step of brakes/base.py).

    Returns ``(electric_n, air_n, demand_n)`` [N], all in the brake-force sign (positive
    retarding). ``electric_n`` is the locomotive's one electric force: NEGATIVE in traction
    (a propulsive force; the simulator's ``a = (outside - electric - air - resistance) /
    m_eff`` then accelerates the train), positive when regenerating. ``air_n`` >= 0 is the
    brake pipe's. ``demand_n = -u m_eff,lw`` is the force the ATO asked for (negative for
    traction, the braking demand ``B`` when braking).

    The electric force follows its target ``e*`` (module docstring) with the exact
    first-order lag ``exp(-dt / T_e)`` and is then clipped to the envelopes at the current
    speed, so it never exceeds them and passes continuously through zero between traction
    and regeneration. When braking, the brake pipe is commanded ``u_air = -(B - e*) /
    m_eff,lw``; the brake pipe acts with its ``a_max`` on the true ``m_eff``, so it settles
    to ``(B - e*) m_eff / m_eff,lw``: with exact load weighing electric + air = ``B``. The
    brake pipe is stepped every step (command 0 outside braking: it releases at its release
    rate) so that its command history stays whole. ``state``: all zeros is at rest.
    """
    demand = u * m_eff_lw
    t_max = traction_force_max(speed_mps, p[P_T_F0], p[P_T_POWER], p[P_T_VMAX])
    r_max = 0.0
    if p[P_REGEN_ON] > 0.0:
        r_max = regen_force_max(speed_mps, p[P_R_F0], p[P_R_POWER], p[P_R_FADE])
        r_max *= _handover_share(speed_mps, p[P_HANDOVER], p[P_R_FADE])
    u_air = 0.0
    if u > 0.0:
        target = -min(demand, t_max)
    elif u < 0.0:
        braking = -demand
        target = min(braking, r_max)
        u_air = -(braking - target) / m_eff_lw
    else:
        target = 0.0
    e = target + (state[ST_E] - target) * p[P_ALPHA]
    e = min(max(e, -t_max), r_max)
    state[ST_E] = e
    _, air_n, _ = brake_pipe_ato_step(
        p[P_AIR0:], state[ST_AIR0:], buffer, u_air, speed_mps, t, dt, m_eff_lw, m_eff
    )
    return e, air_n, -demand
