"""Freight air brake along the train: brake pipe, direct-release distributors, recharge,
emergency and distributed power.

A train of ``n`` vehicles at known distances from the head. Each vehicle is one cell of
the brake pipe; each braked vehicle has a distributor (control valve), an auxiliary
reservoir (AR), a brake cylinder (BC) and optionally an emergency reservoir (ER). One or
more driver's brake valves (the lead locomotive's, and each distributed-power remote's)
hold the pipe at their vehicle at the equalizing-reservoir pressure the caller commands,
or vent it in emergency. Model, numbers, sources and validation: docs/freight-air-brake.md.

Pipe (all pressures gauge [kPa]; air quantities in "pipe metres x kPa", the pipe's
cross-section cancelling out)::

    l_i dp_i/dt = sum_links k (p_j - p_i)              flow along the pipe, k = D / dx
                + G (p_er - p_i)                       a driver's brake valve at cell i
                - a (dA_i/dt) - e (dE_i/dt)            reservoirs charging from the pipe
                - quick-service and emergency venting  (local, at each distributor)

``D`` and ``G`` are the pipe diffusivity and the valve's venting speed of
brakes/brake_pipe.py (calibrated there against the ETCS conversion model). A change the
valve makes travels as a front at the propagation speed (service, emergency or release):
a link of the pipe carries flow only between two cells the same front has reached (the
cells' *phase*: released, applied, emergency), so nothing reaches a vehicle before
``distance / speed``, and behind the front the reduction follows with the pipe's flow.
With several valves each vehicle is reached first by the nearest one.

Distributor, direct release (Chinese 120, AAR ABD)::

    start      A - p > s_app, or an application front arrives at a charged distributor
               (quick service: the local pipe is vented to A0 - q)
    apply      A -> max(min(p, A0 - q), A_eq) with lag T_a;  C += rho (-dA)
    release    p > A + s_rel: C -> 0 with lag T_r; then A charges from the pipe
    emergency  an emergency front: local pipe vented to 0; AR (+ ER) -> BC in two stages

with ``rho = V_AR / V_BC`` (isothermal mass balance, gauge pressures:
``V_AR dA + V_BC dC = 0``) and ``A_eq = A - (A - C) / (1 + rho)`` the equalization.
Graduated release (UIC type): the BC follows ``rho (p_ref - p)`` both ways.

The kernel :func:`freight_air_step` advances the state by ``dt`` in substeps. Each substep
(1) lets the valves launch fronts, (2) gives each cell a front that has arrived by its
start, (3) checks the distributors' thresholds, (4) advances the pipe's flow, the valves'
hold and the reservoirs' charging together by backward Euler (one tridiagonal solve,
Thomas algorithm; a link between cells of different phases has no coupling), (5)
advances each vehicle's venting and cylinder exactly (first-order relaxations), and (6)
starts a release or an application whose threshold the vehicle crossed during the
substep at the interpolated moment of the crossing. The substep rule:

    h = min(max(h_min, g (t - t_event)), h_max),   split at the next front arrival

with ``t_event`` the latest launch or arrival of a front or start of an application
(``h_min`` = 1 ms, ``g`` = 0.2, ``h_max`` = 50 ms: MIN_SUBSTEP_S, SUBSTEP_GROWTH,
MAX_SUBSTEP_S). A front joining a cell to the pipe, a valve's new command or a quick
service starts a fast exchange (a cell's diffusion time ``l^2 / D`` is ~7 ms for a 12 m
wagon, the valve's ``l / G`` ~0.1 s): the short substeps resolve it; as it fades the
substep grows to 50 ms, where backward Euler is stable and accurate to a fraction of a kPa
(docs/freight-air-brake.md: validation against a fine explicit solution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from railpilot.brakes.brake_pipe import (
    APPLICATION_WAVE_MPS,
    NOMINAL_TIMES_S,
    PIPE_DIFFUSIVITY_M2PS,
    RELEASE_WAVE_MPS,
    VALVE_FLOW_MPS,
    application_lag_s,
    release_lag_s,
)
from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.jit import njit

# --- phases of a pipe cell (the type of the newest front that reached it) and modes of a
# distributor ------------------------------------------------------------------------------
PH_RELEASE, PH_APPLY, PH_EMERGENCY = 0, 1, 2
MODE_RELEASED, MODE_APPLIED, MODE_EMERGENCY = 0, 1, 2

# --- params layout: a header, then per-vehicle blocks of n, then the valves ----------------
(
    P_N,  # vehicles
    P_NV,  # driver's brake valves
    P_H_MAX,  # longest substep [s] (MAX_SUBSTEP_S)
    P_REF,  # charged pipe pressure = graduated-release reference [kPa]
    P_RHO,  # V_AR / V_BC
    P_EPS,  # V_ER / V_BC
    P_AR_M,  # AR volume in pipe metres [m]
    P_G,  # valve venting speed [m/s]
    P_C_REL,  # release front speed [m/s]
    P_C_APP,  # service front speed [m/s]
    P_C_EM,  # emergency front speed [m/s]
    P_S_APP,  # application sensitivity [kPa]
    P_S_REL,  # release sensitivity [kPa]
    P_QS_DEPTH,  # quick service: the local pipe vented this far below the AR [kPa]
    P_TAU_APP,  # AR -> BC lag [s]
    P_TAU_REL,  # BC exhaust lag [s]
    P_TAU_CH,  # AR / ER charging choke lag [s]
    P_TAU_QS,  # quick-service venting lag [s]
    P_QS_S,  # longest quick-service venting [s]
    P_TAU_EV,  # emergency venting lag [s]
    P_TAU_E1,  # emergency BC first stage lag [s]
    P_TAU_E2,  # emergency BC second stage lag [s]
    P_E_STAGE,  # BC pressure ending the first emergency stage [kPa]
    P_H_MIN,  # shortest substep, at a front's launch or arrival or an application [s]
    P_H_GROWTH,  # the substep's growth with the time since then [s/s]
) = range(25)
P_HEAD = 25
#: per-vehicle blocks after the header: position [m], pipe length [m], conductance of the
#: link to the next vehicle [m/s] (0 for the last), 1 if direct release, 1 if braked
PB_X, PB_ELL, PB_K, PB_DIRECT, PB_BRAKE = range(5)
P_BLOCKS = 5
#: fronts remembered per valve (a ring)
N_FRONTS = 8

# --- state layout: time, then per-vehicle blocks of n, then per-valve data -----------------
ST_T = 0
ST_HEAD = 1
(
    SB_BP,  # pipe [kPa]
    SB_AR,  # auxiliary reservoir [kPa]
    SB_BC,  # brake cylinder [kPa]
    SB_ER,  # emergency reservoir [kPa]
    SB_MODE,  # distributor mode
    SB_A0,  # AR at the start of the application [kPa]
    SB_TRIG,  # time the application started [s]
    SB_PHASE,  # type of the newest front that reached the cell
    SB_LAUNCH,  # launch time of that front [s]
    SB_ARRIVE,  # time that front reached the cell [s]
) = range(10)
S_BLOCKS = 10
#: per valve: its mode (the type of its newest front) and the number of fronts launched;
#: then N_FRONTS launch times and N_FRONTS types per valve
SV_MODE, SV_COUNT = range(2)

#: bounds of the configuration
MAX_PRESSURE_KPA = 1200.0
MAX_SPEED_MPS = 400.0  # a pressure front does not outrun sound (~340 m/s)
MAX_TIME_S = 600.0
MAX_VEHICLES = 2000
#: pipe length of a vehicle alone in the train [m] (only for a one-vehicle train)
SINGLE_VEHICLE_M = 14.0
#: a front never launched
NEVER = -1.0e30
#: the kernel's substep rule (module docstring): shortest [s], at a front's launch or
#: arrival or an application's start (the pipe's fast exchange then lasts a few ms); growth
#: with the time since [s/s]; longest [s] (the consist run's step: one solve per step
#: while nothing changes fast)
MIN_SUBSTEP_S = 0.001
SUBSTEP_GROWTH = 0.2
MAX_SUBSTEP_S = 0.05
#: a front reaching a vehicle within this of a substep's start counts as arrived [s]
ARRIVAL_TOL_S = 1e-9
#: the local lags whose factors exp(-h / T) a substep uses (scratch of the state)
AL_APP, AL_REL, AL_QS, AL_EV, AL_E1, AL_E2 = range(6)
N_ALPHAS = 6
#: the state's scratch after the valve data (no meaning between calls): per-vehicle blocks
#: (the pipe solve's upper diagonal, which reservoirs charge, each distributor's margin to
#: its threshold at the substep's start), then the lags' factors
(SC_UPPER, SC_CHARGING, SC_MARGIN) = range(3)
SC_BLOCKS = 3


@dataclass(frozen=True)
class FreightAirBrake:
    """Parameters of the freight air brake (module docstring); defaults: Chinese 120-type
    heavy-haul practice. Sources and status of each: docs/freight-air-brake.md.

    Attributes
    ----------
    charged_kpa
        Charged brake-pipe pressure [kPa] (600; the Chinese settings are 500 and 600).
    min_reduction_kpa
        Minimum service reduction [kPa] (50): the least first reduction a driver makes at
        the brake valve (a driving rule; the consist run refuses a smaller one).
    quick_service_kpa
        How far below its AR's pressure at the start of an application a distributor's
        quick service vents the local pipe [kPa] (25, assumed): the least application
        ``rho q`` of a charged distributor. Above the application sensitivity, and no
        more than it plus the release sensitivity, so that the pipe settling back behind
        a small reduction never releases the brake it applied (an AR drained by the quick
        service to ``A0 - q`` stays within ``s_rel`` of a pipe at ``A0 - s_app``).
    ar_to_bc_ratio
        ``rho = V_AR / V_BC`` (2.5: BC = 2.5 x reduction, full service 170 kPa -> 420-430
        kPa at 600 kPa).
    er_to_bc_ratio
        ``V_ER / V_BC`` (0: the 120 valve has no emergency reservoir; 3.5 for AAR ABD,
        which gives the published emergency BC ~20 % above full service).
    ar_volume_l
        AR volume [l] (40, assumed); with the pipe's bore it sets how much air the pipe
        must carry to recharge.
    pipe_bore_m
        Inner diameter of the brake pipe [m] (0.032, assumed).
    application_sensitivity_kpa, release_sensitivity_kpa
        Pipe below the AR [kPa] that starts an application (10, assumed); pipe above the
        AR that releases (20, assumed).
    service_wave_mps, emergency_wave_mps, release_wave_mps
        Front speeds [m/s]: 250, 280 (published range 250-280 m/s) and 150 (assumed), as
        brakes/brake_pipe.py.
    valve_flow_mps, pipe_diffusivity_m2ps
        ``G`` [m/s] and ``D`` [m^2/s] of brakes/brake_pipe.py (calibrated to ETCS).
    application_time_s
        Time [s] for a BC to reach 95 % of a step of the AR target (24 s, UIC G).
    release_time_s
        Time [s] for a BC to vent 3.8 -> 0.4 bar (52.5 s, UIC G).
    charge_lag_s
        Time constant [s] of the AR (and ER) charging choke (20 s, assumed).
    quick_service_lag_s, quick_service_max_s
        Quick-service venting lag [s] (0.5) and its longest duration [s] (2), assumed.
    emergency_vent_lag_s
        Lag [s] of the emergency vent at each vehicle (0.2, assumed).
    emergency_stage_kpa, emergency_lag1_s, emergency_lag2_s
        The 120's two-stage emergency build-up: fast (lag 1 s, assumed) up to 135 kPa
        (published 120-150 kPa), then slow (lag 6 s, assumed).
    """

    charged_kpa: float = 600.0
    min_reduction_kpa: float = 50.0
    quick_service_kpa: float = 25.0
    ar_to_bc_ratio: float = 2.5
    er_to_bc_ratio: float = 0.0
    ar_volume_l: float = 40.0
    pipe_bore_m: float = 0.032
    application_sensitivity_kpa: float = 10.0
    release_sensitivity_kpa: float = 20.0
    service_wave_mps: float = APPLICATION_WAVE_MPS
    emergency_wave_mps: float = 280.0
    release_wave_mps: float = RELEASE_WAVE_MPS
    valve_flow_mps: float = VALVE_FLOW_MPS
    pipe_diffusivity_m2ps: float = PIPE_DIFFUSIVITY_M2PS
    application_time_s: float = NOMINAL_TIMES_S["G"][0]
    release_time_s: float = NOMINAL_TIMES_S["G"][1]
    charge_lag_s: float = 20.0
    quick_service_lag_s: float = 0.5
    quick_service_max_s: float = 2.0
    emergency_vent_lag_s: float = 0.2
    emergency_stage_kpa: float = 135.0
    emergency_lag1_s: float = 1.0
    emergency_lag2_s: float = 6.0

    def __post_init__(self) -> None:
        positive_times = (
            "application_time_s",
            "release_time_s",
            "charge_lag_s",
            "quick_service_lag_s",
            "quick_service_max_s",
            "emergency_vent_lag_s",
            "emergency_lag1_s",
            "emergency_lag2_s",
        )
        for name in positive_times:
            check_number(
                f"air.{name}",
                getattr(self, name),
                positive=True,
                maximum=MAX_TIME_S,
                allowed=f"a number in (0, {MAX_TIME_S:g}] s",
                error=ConfigError,
            )
        for name in ("service_wave_mps", "emergency_wave_mps", "release_wave_mps"):
            check_number(
                f"air.{name}",
                getattr(self, name),
                positive=True,
                maximum=MAX_SPEED_MPS,
                allowed=f"a speed in (0, {MAX_SPEED_MPS:g}] m/s",
                error=ConfigError,
            )
        for name in ("valve_flow_mps", "pipe_diffusivity_m2ps", "ar_to_bc_ratio"):
            check_number(f"air.{name}", getattr(self, name), positive=True, error=ConfigError)
        check_number(
            "air.charged_kpa",
            self.charged_kpa,
            positive=True,
            maximum=MAX_PRESSURE_KPA,
            allowed=f"a pressure in (0, {MAX_PRESSURE_KPA:g}] kPa",
            error=ConfigError,
        )
        check_number("air.er_to_bc_ratio", self.er_to_bc_ratio, minimum=0.0, error=ConfigError)
        check_number("air.ar_volume_l", self.ar_volume_l, positive=True, error=ConfigError)
        check_number(
            "air.pipe_bore_m",
            self.pipe_bore_m,
            positive=True,
            maximum=0.1,
            allowed="a diameter in (0, 0.1] m",
            error=ConfigError,
        )
        full = self.charged_kpa / (1.0 + self.ar_to_bc_ratio)
        check_number(
            "air.min_reduction_kpa",
            self.min_reduction_kpa,
            positive=True,
            maximum=full,
            allowed=f"a reduction in (0, {full:.4g}] kPa (the full-service reduction)",
            error=ConfigError,
        )
        for name in ("application_sensitivity_kpa", "release_sensitivity_kpa"):
            check_number(
                f"air.{name}",
                getattr(self, name),
                positive=True,
                maximum=self.min_reduction_kpa,
                allowed=f"a pressure in (0, {self.min_reduction_kpa:g}] kPa (the minimum "
                "reduction)",
                error=ConfigError,
            )
        s_app, s_rel = self.application_sensitivity_kpa, self.release_sensitivity_kpa
        check_number(
            "air.quick_service_kpa",
            self.quick_service_kpa,
            minimum=s_app,
            maximum=min(s_app + s_rel, self.min_reduction_kpa),
            allowed=f"a depth in [{s_app:g}, {min(s_app + s_rel, self.min_reduction_kpa):g}] "
            "kPa (the application sensitivity, to the least of it plus the release "
            "sensitivity and the minimum reduction)",
            error=ConfigError,
        )
        check_number(
            "air.emergency_stage_kpa",
            self.emergency_stage_kpa,
            minimum=0.0,
            maximum=self.charged_kpa,
            allowed=f"a pressure in [0, {self.charged_kpa:g}] kPa",
            error=ConfigError,
        )

    @classmethod
    def aar_abd(cls, **changes: float) -> FreightAirBrake:
        """An AAR ABD/ABDX-type equipment: 90 psi (620.5 kPa) pipe, an emergency reservoir
        (``V_ER / V_BC = 3.5``, which gives the published emergency BC 20 % above full
        service), a 7 psi (48 kPa) minimum reduction; the rest as the defaults."""
        base = cls(
            charged_kpa=620.5,
            min_reduction_kpa=48.0,
            er_to_bc_ratio=3.5,
            emergency_stage_kpa=0.0,
        )
        return replace(base, **changes)

    def full_service_reduction_kpa(self) -> float:
        """Reduction [kPa] at which a fully charged AR equalizes with its BC:
        ``p_0 / (1 + rho)``."""
        return self.charged_kpa / (1.0 + self.ar_to_bc_ratio)

    def full_service_bc_kpa(self) -> float:
        """BC pressure [kPa] of a full-service application from a fully charged AR:
        ``rho p_0 / (1 + rho)`` (the reference of the brake force)."""
        return self.ar_to_bc_ratio * self.charged_kpa / (1.0 + self.ar_to_bc_ratio)

    def emergency_bc_kpa(self) -> float:
        """BC pressure [kPa] of an emergency application from fully charged AR and ER."""
        return float(emergency_bc_kpa(self, self.charged_kpa, self.charged_kpa))

    def ar_pipe_m(self) -> float:
        """The AR's volume as a length of brake pipe [m]."""
        area = math.pi * self.pipe_bore_m**2 / 4.0
        return self.ar_volume_l * 1e-3 / area


# --- closed forms (tests, docs) ------------------------------------------------------------


def arrival_time_s(
    positions_m: np.ndarray,
    valve_vehicles: np.ndarray,
    speed_mps: float,
    launch_s: np.ndarray | float = 0.0,
) -> np.ndarray:
    """When a front launched at each valve at ``launch_s`` [s] first reaches each vehicle [s]:
    ``min_j (launch_j + |x_i - x_vj| / c)``, the nearest valve's."""
    x = np.asarray(positions_m, dtype=float)
    valves = np.asarray(valve_vehicles, dtype=np.int64)
    launch = np.broadcast_to(np.asarray(launch_s, dtype=float), valves.shape)
    times = launch[np.newaxis, :] + np.abs(x[:, np.newaxis] - x[valves][np.newaxis, :]) / speed_mps
    return np.asarray(times.min(axis=1))


def equalization_bc_kpa(
    ar_kpa: np.ndarray | float, bc_kpa: np.ndarray | float = 0.0, ratio: float = 2.5
) -> np.ndarray:
    """BC pressure [kPa] when an AR at ``ar_kpa`` has given air to its BC (at ``bc_kpa``)
    until the two are equal: ``C + rho (A - C) / (1 + rho)`` (mass balance)."""
    a = np.asarray(ar_kpa, dtype=float)
    c = np.asarray(bc_kpa, dtype=float)
    return np.asarray(c + ratio * np.maximum(a - c, 0.0) / (1.0 + ratio))


def service_bc_kpa(
    brake: FreightAirBrake,
    ar_start_kpa: np.ndarray | float,
    bp_kpa: np.ndarray | float,
    bc_start_kpa: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Settled BC pressure [kPa] of a direct-release distributor whose application started
    with its AR at ``ar_start_kpa`` and its BC at ``bc_start_kpa``, with the pipe now at
    ``bp_kpa``.

    The AR laps at the pipe, but at least the quick service's depth below its start, and not
    below equalization; the BC receives the air it gives: ``C = C0 + rho (A0 - A)``.
    """
    rho = brake.ar_to_bc_ratio
    a0 = np.asarray(ar_start_kpa, dtype=float)
    c0 = np.asarray(bc_start_kpa, dtype=float)
    lap = np.minimum(np.asarray(bp_kpa, dtype=float), a0 - brake.quick_service_kpa)
    a_eq = a0 - np.maximum(a0 - c0, 0.0) / (1.0 + rho)
    a_end = np.minimum(np.maximum(lap, a_eq), a0)
    return np.asarray(c0 + rho * (a0 - a_end))


def emergency_bc_kpa(
    brake: FreightAirBrake,
    ar_kpa: np.ndarray | float,
    er_kpa: np.ndarray | float,
    bc_kpa: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Settled BC pressure [kPa] of an emergency application: AR, ER and BC equalize,
    ``(rho A + e E + C) / (rho + e + 1)`` with ``e = V_ER / V_BC``."""
    rho, e = brake.ar_to_bc_ratio, brake.er_to_bc_ratio
    a = np.asarray(ar_kpa, dtype=float)
    er = np.asarray(er_kpa, dtype=float)
    c = np.asarray(bc_kpa, dtype=float)
    return np.asarray((rho * a + e * er + c) / (rho + e + 1.0))


# --- packing ---------------------------------------------------------------------------------


def _vehicle_arrays(
    positions_m: np.ndarray,
    valve_vehicles: np.ndarray,
    direct_release: np.ndarray,
    has_brake: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The caller's arrays, checked (ConfigError naming ``air.<argument>``)."""
    x = np.asarray(positions_m, dtype=float)
    if x.ndim != 1 or not 1 <= x.size <= MAX_VEHICLES:
        raise ConfigError("air.positions_m", x.shape, f"1 to {MAX_VEHICLES} positions")
    if not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0.0):
        raise ConfigError("air.positions_m", x, "finite positions, strictly increasing [m]")
    valves = np.asarray(valve_vehicles)
    if (
        valves.ndim != 1
        or valves.size == 0
        or valves.dtype.kind not in "iu"
        or np.any(valves < 0)
        or np.any(valves >= x.size)
        or np.unique(valves).size != valves.size
    ):
        raise ConfigError(
            "air.valve_vehicles", valve_vehicles, f"distinct integer indices in [0, {x.size})"
        )
    flags = []
    for name, value in (("direct_release", direct_release), ("has_brake", has_brake)):
        array = np.asarray(value)
        if array.shape != x.shape or array.dtype.kind not in "biu":
            raise ConfigError(f"air.{name}", value, f"{x.size} booleans, one per vehicle")
        flags.append(array.astype(bool))
    return x, valves.astype(np.int64), flags[0], flags[1]


def pack_freight_air(
    brake: FreightAirBrake,
    positions_m: np.ndarray,
    valve_vehicles: np.ndarray,
    direct_release: np.ndarray,
    has_brake: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's ``(params, state)``: the state charged and released at the brake's pipe
    pressure, at time 0.

    ``positions_m``: each vehicle's distance from the head [m], increasing;
    ``valve_vehicles``: int indices of the vehicles with a driver's brake valve (lead
    first); ``direct_release`` / ``has_brake``: per vehicle.
    """
    x, valves, direct, braked = _vehicle_arrays(
        positions_m, valve_vehicles, direct_release, has_brake
    )
    n, nv = x.size, valves.size
    # each vehicle's share of the pipe: half-way to its neighbours, the ends a full spacing
    if n == 1:
        ell = np.array([SINGLE_VEHICLE_M])
    else:
        gaps = np.diff(x)
        ell = np.empty(n)
        ell[1:-1] = (gaps[:-1] + gaps[1:]) / 2.0
        ell[0], ell[-1] = gaps[0], gaps[-1]
    k = np.zeros(n)
    if n > 1:
        k[:-1] = brake.pipe_diffusivity_m2ps / np.diff(x)
    p = np.zeros(P_HEAD + P_BLOCKS * n + nv)
    p[P_N], p[P_NV], p[P_H_MAX] = n, nv, MAX_SUBSTEP_S
    p[P_H_MIN], p[P_H_GROWTH] = MIN_SUBSTEP_S, SUBSTEP_GROWTH
    p[P_REF] = brake.charged_kpa
    p[P_RHO] = brake.ar_to_bc_ratio
    p[P_EPS] = brake.er_to_bc_ratio
    p[P_AR_M] = brake.ar_pipe_m()
    p[P_G] = brake.valve_flow_mps
    p[P_C_REL] = brake.release_wave_mps
    p[P_C_APP] = brake.service_wave_mps
    p[P_C_EM] = brake.emergency_wave_mps
    p[P_S_APP] = brake.application_sensitivity_kpa
    p[P_S_REL] = brake.release_sensitivity_kpa
    p[P_QS_DEPTH] = brake.quick_service_kpa
    p[P_TAU_APP] = application_lag_s(brake.application_time_s)
    p[P_TAU_REL] = release_lag_s(brake.release_time_s)
    p[P_TAU_CH] = brake.charge_lag_s
    p[P_TAU_QS] = brake.quick_service_lag_s
    p[P_QS_S] = brake.quick_service_max_s
    p[P_TAU_EV] = brake.emergency_vent_lag_s
    p[P_TAU_E1] = brake.emergency_lag1_s
    p[P_TAU_E2] = brake.emergency_lag2_s
    p[P_E_STAGE] = brake.emergency_stage_kpa
    for block, values in (
        (PB_X, x),
        (PB_ELL, ell),
        (PB_K, k),
        (PB_DIRECT, direct.astype(float)),
        (PB_BRAKE, braked.astype(float)),
    ):
        _block(p, P_HEAD, block, n)[:] = values
    p[P_HEAD + P_BLOCKS * n :] = valves
    s = np.zeros(_scratch_start(n, nv) + SC_BLOCKS * n + N_ALPHAS)
    for block in (SB_BP, SB_AR, SB_ER):
        _block(s, ST_HEAD, block, n)[:] = brake.charged_kpa
    for block in (SB_TRIG, SB_LAUNCH, SB_ARRIVE):
        _block(s, ST_HEAD, block, n)[:] = NEVER
    launches = ST_HEAD + S_BLOCKS * n + 2 * nv
    s[launches : launches + nv * N_FRONTS] = NEVER
    return p, s


# --- accessors (njit: usable inside another compiled function) -------------------------------


@njit(cache=True)
def _block(a: np.ndarray, start: int, k: int, n: int) -> np.ndarray:
    """The ``k``-th block of ``n`` floats from ``start`` in a packed array (a view)."""
    return a[start + k * n : start + (k + 1) * n]


@njit(cache=True)
def _state_block(params: np.ndarray, state: np.ndarray, block: int) -> np.ndarray:
    n = int(params[P_N])
    return _block(state, ST_HEAD, block, n)


@njit(cache=True)
def bp_kpa(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Each vehicle's brake-pipe pressure [kPa] (a view of ``state``)."""
    return _state_block(params, state, SB_BP)


@njit(cache=True)
def ar_kpa(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Each vehicle's auxiliary-reservoir pressure [kPa] (a view of ``state``)."""
    return _state_block(params, state, SB_AR)


@njit(cache=True)
def bc_kpa(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Each vehicle's brake-cylinder pressure [kPa] (a view; 0 for an unbraked vehicle)."""
    return _state_block(params, state, SB_BC)


@njit(cache=True)
def er_kpa_of(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Each vehicle's emergency-reservoir pressure [kPa] (a view of ``state``)."""
    return _state_block(params, state, SB_ER)


@njit(cache=True)
def front_arrival_s(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """When the newest front reached each vehicle [s] (a view; -1e30 if none has)."""
    return _state_block(params, state, SB_ARRIVE)


@njit(cache=True)
def application_start_s(params: np.ndarray, state: np.ndarray) -> np.ndarray:
    """When each distributor's latest application started [s] (a view; -1e30 if never)."""
    return _state_block(params, state, SB_TRIG)


def time_s(state: np.ndarray) -> float:
    """The state's time [s]."""
    return float(state[ST_T])


# --- the kernel -----------------------------------------------------------------------------


@njit(cache=True)
def _scratch_start(n: int, nv: int) -> int:
    """Index of the state's scratch (after the per-vehicle blocks and the valve data)."""
    return ST_HEAD + S_BLOCKS * n + nv * (2 + 2 * N_FRONTS)


@njit(cache=True)
def _relax(value: float, target: float, alpha: float) -> float:
    """A first-order lag held toward ``target`` over a part of a step (``alpha = exp(-h/T)``)."""
    return target + (value - target) * alpha


@njit(cache=True)
def _front_speed_mps(params: np.ndarray, kind: int) -> float:
    """Propagation speed [m/s] of a front of type ``kind`` (a phase)."""
    if kind == PH_EMERGENCY:
        return float(params[P_C_EM])
    if kind == PH_APPLY:
        return float(params[P_C_APP])
    return float(params[P_C_REL])


@njit(cache=True)
def _launch_fronts(
    params: np.ndarray, state: np.ndarray, er_kpa: np.ndarray, emergency: np.ndarray
) -> None:
    """Each valve launches a new front, at the state's time, when its command departs from
    the pipe at its cell (beyond a sensitivity) or its emergency flag is newly set."""
    n = int(params[P_N])
    nv = int(params[P_NV])
    t = state[ST_T]
    s_app = params[P_S_APP]
    s_rel = params[P_S_REL]
    bp = _block(state, ST_HEAD, SB_BP, n)
    vbase = ST_HEAD + S_BLOCKS * n
    fl0 = vbase + 2 * nv
    ft0 = fl0 + nv * N_FRONTS
    for j in range(nv):
        v = int(params[P_HEAD + P_BLOCKS * n + j])
        vm = int(state[vbase + 2 * j + SV_MODE])
        new_type = -1
        if emergency[j] > 0.5:
            if vm != PH_EMERGENCY:
                new_type = PH_EMERGENCY
        elif vm == PH_RELEASE:
            if er_kpa[j] < bp[v] - s_app:
                new_type = PH_APPLY
        elif er_kpa[j] > bp[v] + s_rel:
            new_type = PH_RELEASE
        if new_type >= 0:
            count = int(state[vbase + 2 * j + SV_COUNT])
            slot = count % N_FRONTS
            state[fl0 + j * N_FRONTS + slot] = t
            state[ft0 + j * N_FRONTS + slot] = new_type
            state[vbase + 2 * j + SV_COUNT] = count + 1
            state[vbase + 2 * j + SV_MODE] = new_type


@njit(cache=True)
def _fronts_travelling(params: np.ndarray, state: np.ndarray) -> bool:
    """Whether some front may still reach a vehicle, or reached one so recently that the
    substep is still growing after it: a front that reached the farthest vehicle from its
    valve longer ago was taken by every cell already (the substeps since were shorter)."""
    n = int(params[P_N])
    nv = int(params[P_NV])
    h_max = params[P_H_MAX]
    t_done = state[ST_T] - 2.0 * h_max - (h_max - params[P_H_MIN]) / params[P_H_GROWTH]
    x_first = params[P_HEAD + PB_X * n]
    x_last = params[P_HEAD + PB_X * n + n - 1]
    fl0 = ST_HEAD + S_BLOCKS * n + 2 * nv
    ft0 = fl0 + nv * N_FRONTS
    for j in range(nv):
        x_valve = params[P_HEAD + PB_X * n + int(params[P_HEAD + P_BLOCKS * n + j])]
        farthest = max(x_valve - x_first, x_last - x_valve)
        for f in range(N_FRONTS):
            t_launch = state[fl0 + j * N_FRONTS + f]
            kind = int(state[ft0 + j * N_FRONTS + f])
            if t_launch + farthest / _front_speed_mps(params, kind) > t_done:
                return True
    return False


@njit(cache=True)
def _reach_fronts(params: np.ndarray, state: np.ndarray) -> tuple[float, float]:
    """Each cell takes the type of the newest-launched front that has reached it by the
    state's time (within ARRIVAL_TOL_S); a braked vehicle reached by a service front while
    charged starts its application (quick service) at the front's arrival, one reached by
    an emergency front its emergency. Returns the earliest later arrival [s] that will
    change a cell (inf if none) and the latest arrival so far [s]."""
    n = int(params[P_N])
    nv = int(params[P_NV])
    t_cut = state[ST_T] + ARRIVAL_TOL_S
    rho = params[P_RHO]
    eps = params[P_EPS]
    s_app = params[P_S_APP]
    x = _block(params, P_HEAD, PB_X, n)
    braked = _block(params, P_HEAD, PB_BRAKE, n)
    valve_at = params[P_HEAD + P_BLOCKS * n : P_HEAD + P_BLOCKS * n + nv]
    base = ST_HEAD
    bp = _block(state, base, SB_BP, n)
    ar = _block(state, base, SB_AR, n)
    er = _block(state, base, SB_ER, n)
    mode = _block(state, base, SB_MODE, n)
    a0 = _block(state, base, SB_A0, n)
    trig = _block(state, base, SB_TRIG, n)
    phase = _block(state, base, SB_PHASE, n)
    launch = _block(state, base, SB_LAUNCH, n)
    arrive = _block(state, base, SB_ARRIVE, n)
    fl0 = base + S_BLOCKS * n + 2 * nv
    ft0 = fl0 + nv * N_FRONTS
    next_arrival = math.inf
    latest = NEVER
    for i in range(n):
        best_launch = launch[i]
        best_type = -1
        best_arrive = 0.0
        for j in range(nv):
            distance = abs(x[i] - x[int(valve_at[j])])
            for f in range(N_FRONTS):
                t_launch = state[fl0 + j * N_FRONTS + f]
                if t_launch <= best_launch:
                    continue
                kind = int(state[ft0 + j * N_FRONTS + f])
                t_arrive = t_launch + distance / _front_speed_mps(params, kind)
                if t_arrive <= t_cut:
                    best_launch = t_launch
                    best_type = kind
                    best_arrive = t_arrive
        if best_type >= 0:
            phase[i] = best_type
            launch[i] = best_launch
            arrive[i] = best_arrive
            if braked[i] > 0.5:
                if best_type == PH_EMERGENCY:
                    if mode[i] != MODE_EMERGENCY:
                        # AR and ER join to feed the BC
                        if eps > 0.0:
                            merged = (rho * ar[i] + eps * er[i]) / (rho + eps)
                            ar[i] = merged
                            er[i] = merged
                        mode[i] = MODE_EMERGENCY
                        trig[i] = best_arrive
                elif best_type == PH_APPLY and mode[i] == MODE_RELEASED and ar[i] + s_app >= bp[i]:
                    # quick service carried along by the front
                    mode[i] = MODE_APPLIED
                    a0[i] = ar[i]
                    trig[i] = best_arrive
        latest = max(latest, arrive[i])
        # the next front still to reach this cell, newer than the one it has
        for j in range(nv):
            distance = abs(x[i] - x[int(valve_at[j])])
            for f in range(N_FRONTS):
                t_launch = state[fl0 + j * N_FRONTS + f]
                if t_launch <= launch[i]:
                    continue
                kind = int(state[ft0 + j * N_FRONTS + f])
                t_arrive = t_launch + distance / _front_speed_mps(params, kind)
                if t_cut < t_arrive < next_arrival:
                    next_arrival = t_arrive
    return next_arrival, latest


@njit(cache=True)
def _distributor_thresholds(params: np.ndarray, state: np.ndarray) -> float:
    """Each distributor's own thresholds at the state's time: apply when the pipe is
    ``s_app`` below its AR, release when ``s_rel`` above (graduated release: near the
    charged pressure). Keeps each direct-release distributor's margin to the threshold it
    may cross next (released: ``A - p - s_app``; applied: ``p - A - s_rel``) for
    :func:`_crossings`. Returns the latest start of an application [s] (its quick service
    vents the pipe from then on)."""
    n = int(params[P_N])
    nv = int(params[P_NV])
    t = state[ST_T]
    ref = params[P_REF]
    s_app = params[P_S_APP]
    s_rel = params[P_S_REL]
    direct = _block(params, P_HEAD, PB_DIRECT, n)
    braked = _block(params, P_HEAD, PB_BRAKE, n)
    base = ST_HEAD
    bp = _block(state, base, SB_BP, n)
    ar = _block(state, base, SB_AR, n)
    mode = _block(state, base, SB_MODE, n)
    a0 = _block(state, base, SB_A0, n)
    trig = _block(state, base, SB_TRIG, n)
    phase = _block(state, base, SB_PHASE, n)
    scratch0 = _scratch_start(n, nv)
    margin = _block(state, scratch0, SC_MARGIN, n)
    latest = NEVER
    for i in range(n):
        if braked[i] < 0.5:
            continue
        if mode[i] == MODE_RELEASED:
            if ar[i] - bp[i] > s_app:
                mode[i] = MODE_APPLIED
                a0[i] = ar[i]
                trig[i] = t
        elif mode[i] == MODE_APPLIED:
            if direct[i] > 0.5:
                if bp[i] > ar[i] + s_rel:
                    mode[i] = MODE_RELEASED
            elif bp[i] > ref - s_app:
                mode[i] = MODE_RELEASED
        elif phase[i] != PH_EMERGENCY and bp[i] > ar[i] + s_rel:
            mode[i] = MODE_RELEASED
        if mode[i] == MODE_RELEASED:
            margin[i] = ar[i] - bp[i] - s_app
        elif mode[i] == MODE_APPLIED:
            margin[i] = bp[i] - ar[i] - s_rel
            latest = max(latest, trig[i])
    return latest


@njit(cache=True)
def _crossings(params: np.ndarray, state: np.ndarray, h: float) -> None:
    """The thresholds a direct-release distributor crossed during the substep of ``h``
    [s] that ends at the state's time, at the moment of the crossing (the margin
    interpolated linearly over the substep): a release vents the BC for the rest of the
    substep; an application starts there (its quick service vents the pipe for the rest
    of the substep)."""
    n = int(params[P_N])
    nv = int(params[P_NV])
    t_end = state[ST_T]
    s_app = params[P_S_APP]
    s_rel = params[P_S_REL]
    q_depth = params[P_QS_DEPTH]
    direct = _block(params, P_HEAD, PB_DIRECT, n)
    braked = _block(params, P_HEAD, PB_BRAKE, n)
    base = ST_HEAD
    bp = _block(state, base, SB_BP, n)
    ar = _block(state, base, SB_AR, n)
    bc = _block(state, base, SB_BC, n)
    mode = _block(state, base, SB_MODE, n)
    a0 = _block(state, base, SB_A0, n)
    trig = _block(state, base, SB_TRIG, n)
    scratch0 = _scratch_start(n, nv)
    margin = _block(state, scratch0, SC_MARGIN, n)
    for i in range(n):
        if braked[i] < 0.5 or direct[i] < 0.5:
            continue
        if mode[i] == MODE_RELEASED:
            after = ar[i] - bp[i] - s_app
            if after > 0.0:
                late = h * after / (after - min(margin[i], 0.0))
                mode[i] = MODE_APPLIED
                a0[i] = ar[i]
                trig[i] = t_end - late
                floor = a0[i] - q_depth
                if bp[i] > floor:
                    bp[i] = _relax(bp[i], floor, math.exp(-late / params[P_TAU_QS]))
        elif mode[i] == MODE_APPLIED:
            after = bp[i] - ar[i] - s_rel
            if after > 0.0:
                late = h * after / (after - min(margin[i], 0.0))
                mode[i] = MODE_RELEASED
                bc[i] *= math.exp(-late / params[P_TAU_REL])


@njit(cache=True)
def _pipe_flow(params: np.ndarray, state: np.ndarray, er_kpa: np.ndarray, h: float) -> None:
    """The pipe's flow, the valves' hold and the reservoirs' charging over ``h`` [s],
    backward Euler, as one linear system.

    For each cell, with ``w_i = h k_i`` between two cells of one phase (else 0)::

        (l_i + w_{i-1} + w_i + h G_i + c_i) p_i' - w_{i-1} p_{i-1}' - w_i p_{i+1}'
            = l_i p_i + h G_i p_ER + c_i A_i

    ``G_i = G`` at a valve's cell (unless it vents in emergency); a reservoir of ``a``
    pipe metres charging through its choke (lag ``T``) from a pipe above it adds
    ``c_i = a b / (1 + b)``, ``b = h / T``, and then ``A_i' = (A_i + b p_i') / (1 + b)``
    (the ER likewise). Tridiagonal and diagonally dominant: the Thomas algorithm, no
    pivoting, in place (the pipe block holds the eliminated right-hand side, the state's
    scratch the eliminated upper diagonal and which reservoirs charge).
    """
    n = int(params[P_N])
    nv = int(params[P_NV])
    g = params[P_G]
    rho = params[P_RHO]
    eps = params[P_EPS]
    a_m = params[P_AR_M]
    e_m = a_m * eps / rho
    b = h / params[P_TAU_CH]
    ell = _block(params, P_HEAD, PB_ELL, n)
    k = _block(params, P_HEAD, PB_K, n)
    direct = _block(params, P_HEAD, PB_DIRECT, n)
    braked = _block(params, P_HEAD, PB_BRAKE, n)
    bp = _block(state, ST_HEAD, SB_BP, n)
    ar = _block(state, ST_HEAD, SB_AR, n)
    er = _block(state, ST_HEAD, SB_ER, n)
    mode = _block(state, ST_HEAD, SB_MODE, n)
    phase = _block(state, ST_HEAD, SB_PHASE, n)
    vbase = ST_HEAD + S_BLOCKS * n
    scratch0 = _scratch_start(n, nv)
    upper = _block(state, scratch0, SC_UPPER, n)
    charging = _block(state, scratch0, SC_CHARGING, n)
    # the extra diagonal (in ``upper`` until the sweep overwrites it), its pressures folded
    # into the right-hand side as ``bp * l``; 1 = the AR charges, 2 = the ER, 3 = both
    c_ar = a_m * b / (1.0 + b)
    c_er = e_m * b / (1.0 + b)
    for i in range(n):
        extra = 0.0
        flags = 0.0
        if braked[i] > 0.5 and mode[i] != MODE_EMERGENCY:
            charges_ar = direct[i] < 0.5 or mode[i] == MODE_RELEASED
            if charges_ar and bp[i] > ar[i]:
                extra += c_ar
                bp[i] += c_ar * ar[i] / ell[i]
                flags += 1.0
            if eps > 0.0 and bp[i] > er[i]:
                extra += c_er
                bp[i] += c_er * er[i] / ell[i]
                flags += 2.0
        upper[i] = extra
        charging[i] = flags
    for j in range(nv):
        if int(state[vbase + 2 * j + SV_MODE]) != PH_EMERGENCY:
            v = int(params[P_HEAD + P_BLOCKS * n + j])
            upper[v] += h * g
            bp[v] += h * g * er_kpa[j] / ell[v]
    # forward sweep: bp becomes the eliminated right-hand side, upper the upper diagonal
    w_left = 0.0
    c_left = 0.0
    d_left = 0.0
    for i in range(n):
        w = h * k[i] if i < n - 1 and phase[i] == phase[i + 1] else 0.0
        denom = ell[i] + upper[i] + w + w_left * (1.0 + c_left)
        c_left = -w / denom
        d_left = (ell[i] * bp[i] + w_left * d_left) / denom
        upper[i] = c_left
        bp[i] = d_left
        w_left = w
    # back substitution, and the reservoirs that charged
    for i in range(n - 1, -1, -1):
        if i < n - 1:
            bp[i] -= upper[i] * bp[i + 1]
        flags = charging[i]
        if flags > 0.5:
            if flags != 2.0:
                ar[i] = (ar[i] + b * bp[i]) / (1.0 + b)
            if flags > 1.5:
                er[i] = (er[i] + b * bp[i]) / (1.0 + b)


@njit(cache=True)
def _local_exchanges(params: np.ndarray, state: np.ndarray, h: float, alphas: np.ndarray) -> None:
    """Each vehicle's own exchanges over ``h`` [s], each an exact first-order relaxation:
    emergency venting, the distributor's AR -> BC (and BC exhaust), quick service, the
    reservoirs charging from the pipe. ``alphas``: ``exp(-h / T)`` of the application,
    release, quick-service, emergency-vent and the two emergency lags (AL_* order)."""
    n = int(params[P_N])
    t = state[ST_T]
    ref = params[P_REF]
    rho = params[P_RHO]
    eps = params[P_EPS]
    q_depth = params[P_QS_DEPTH]
    qs_s = params[P_QS_S]
    tau_qs = params[P_TAU_QS]
    e_stage = params[P_E_STAGE]
    al_app = alphas[AL_APP]
    al_rel = alphas[AL_REL]
    al_qs = alphas[AL_QS]
    al_ev = alphas[AL_EV]
    al_e1 = alphas[AL_E1]
    al_e2 = alphas[AL_E2]
    direct = _block(params, P_HEAD, PB_DIRECT, n)
    braked = _block(params, P_HEAD, PB_BRAKE, n)
    base = ST_HEAD
    bp = _block(state, base, SB_BP, n)
    ar = _block(state, base, SB_AR, n)
    bc = _block(state, base, SB_BC, n)
    er = _block(state, base, SB_ER, n)
    mode = _block(state, base, SB_MODE, n)
    a0 = _block(state, base, SB_A0, n)
    trig = _block(state, base, SB_TRIG, n)
    phase = _block(state, base, SB_PHASE, n)
    for i in range(n):
        if phase[i] == PH_EMERGENCY:
            bp[i] = bp[i] * al_ev
        if braked[i] < 0.5:
            continue
        m = mode[i]
        if m == MODE_EMERGENCY:
            # the target is the mass balance (it stays put as the AR and ER feed the BC);
            # the first stage's lag up to C_stage, the second's after, switching within
            # the substep at the moment the BC passes C_stage
            target = (rho * ar[i] + eps * er[i] + bc[i]) / (rho + eps + 1.0)
            if bc[i] < target:
                if bc[i] >= e_stage:
                    new_bc = _relax(bc[i], target, al_e2)
                else:
                    new_bc = _relax(bc[i], target, al_e1)
                    if new_bc > e_stage:
                        t_stage = params[P_TAU_E1] * math.log((target - bc[i]) / (target - e_stage))
                        new_bc = _relax(e_stage, target, math.exp((t_stage - h) / params[P_TAU_E2]))
                given = (new_bc - bc[i]) / (rho + eps)
                bc[i] = new_bc
                ar[i] -= given
                if eps > 0.0:
                    er[i] -= given
            continue
        # quick service: vent the local pipe to its depth below the AR's start, for the
        # part of the substep before its longest duration ends
        if m == MODE_APPLIED:
            venting = min(h, trig[i] + qs_s - t)
            floor = a0[i] - q_depth
            if venting > 0.0 and bp[i] > floor:
                alpha = al_qs if venting >= h else math.exp(-venting / tau_qs)
                bp[i] = _relax(bp[i], floor, alpha)
        if direct[i] > 0.5:
            if m == MODE_APPLIED:
                lap = min(bp[i], a0[i] - q_depth)
                a_eq = ar[i] - max(ar[i] - bc[i], 0.0) / (1.0 + rho)
                target = max(lap, a_eq)
                if ar[i] > target:
                    new_ar = _relax(ar[i], target, al_app)
                    bc[i] += rho * (ar[i] - new_ar)
                    ar[i] = new_ar
            else:
                bc[i] = bc[i] * al_rel
        else:
            # graduated release: the BC follows rho (p_ref - p), above the threshold
            demand = ref - bp[i]
            want = rho * max(demand, q_depth) if m == MODE_APPLIED else 0.0
            if want > bc[i]:
                c_eq = bc[i] + rho * max(ar[i] - bc[i], 0.0) / (1.0 + rho)
                goal = min(want, c_eq)
                if goal > bc[i]:
                    new_bc = _relax(bc[i], goal, al_app)
                    ar[i] -= (new_bc - bc[i]) / rho
                    bc[i] = new_bc
            else:
                bc[i] = _relax(bc[i], want, al_rel)


@njit(cache=True)
def _fill_alphas(params: np.ndarray, h: float, alphas: np.ndarray) -> None:
    """``exp(-h / T)`` of the local lags (AL_* order) for a substep of ``h`` [s]."""
    alphas[AL_APP] = math.exp(-h / params[P_TAU_APP])
    alphas[AL_REL] = math.exp(-h / params[P_TAU_REL])
    alphas[AL_QS] = math.exp(-h / params[P_TAU_QS])
    alphas[AL_EV] = math.exp(-h / params[P_TAU_EV])
    alphas[AL_E1] = math.exp(-h / params[P_TAU_E1])
    alphas[AL_E2] = math.exp(-h / params[P_TAU_E2])


@njit(cache=True)
def freight_air_step(
    params: np.ndarray, state: np.ndarray, er_kpa: np.ndarray, emergency: np.ndarray, dt: float
) -> None:
    """Advance the freight air brake by ``dt`` [s] (module docstring).

    ``er_kpa[j]``: the pressure valve ``j`` holds its pipe at (the charged pressure:
    release and recharge; lower: a service reduction); ``emergency[j] > 0.5``: valve ``j``
    vents the pipe in emergency. Any ``dt``: the kernel substeps by its rule (module
    docstring), the last substep ending at ``t + dt``.
    """
    if dt <= 0.0:
        return
    n = int(params[P_N])
    nv = int(params[P_NV])
    h_min = params[P_H_MIN]
    h_max = params[P_H_MAX]
    growth = params[P_H_GROWTH]
    t_stop = state[ST_T] + dt
    scratch = _scratch_start(n, nv) + SC_BLOCKS * n
    alphas = state[scratch : scratch + N_ALPHAS]
    h_alphas = -1.0
    while True:
        _launch_fronts(params, state, er_kpa, emergency)
        t = state[ST_T]
        next_arrival = math.inf
        latest = NEVER
        if _fronts_travelling(params, state):
            next_arrival, latest = _reach_fronts(params, state)
        latest = max(latest, _distributor_thresholds(params, state))
        h_rule = min(max(h_min, growth * (t - latest)), h_max)
        # equal substeps of at most h_rule to the end of the step, or to the next arrival
        remaining = t_stop - t
        h = remaining / max(math.ceil(remaining / h_rule - 1e-9), 1)
        last = h >= remaining
        if next_arrival < t + h - ARRIVAL_TOL_S:
            h = next_arrival - t
            last = False
        _pipe_flow(params, state, er_kpa, h)
        if h != h_alphas:
            _fill_alphas(params, h, alphas)
            h_alphas = h
        _local_exchanges(params, state, h, alphas)
        state[ST_T] = t_stop if last else t + h
        _crossings(params, state, h)
        if last:
            break


# --- simulation helpers (tests, docs) -------------------------------------------------------


def simulate(
    params: np.ndarray,
    state: np.ndarray,
    er_kpa: np.ndarray,
    emergency: np.ndarray,
    duration_s: float,
    dt: float,
) -> dict[str, np.ndarray]:
    """Step the kernel for ``duration_s`` [s] with the commands held; returns the end time of
    each step and the pipe, AR and BC pressures after it (arrays ``(steps, n)``)."""
    steps = round(duration_s / dt)
    n = int(params[P_N])
    out: dict[str, np.ndarray] = {key: np.empty((steps, n)) for key in ("bp", "ar", "bc")}
    times = np.empty(steps)
    er_cmd = np.asarray(er_kpa, dtype=float)
    em_cmd = np.asarray(emergency, dtype=float)
    for step in range(steps):
        freight_air_step(params, state, er_cmd, em_cmd, dt)
        times[step] = state[ST_T]
        out["bp"][step] = bp_kpa(params, state)
        out["ar"][step] = ar_kpa(params, state)
        out["bc"][step] = bc_kpa(params, state)
    out["t"] = times
    return out


def recharge_time_s(
    brake: FreightAirBrake,
    positions_m: np.ndarray,
    valve_vehicles: np.ndarray,
    *,
    reduction_kpa: float | None = None,
    hold_s: float = 240.0,
    within_kpa: float = 10.0,
    max_s: float = 3600.0,
    dt: float = 0.05,
) -> float:
    """Time [s] from a release until every AR is within ``within_kpa`` of the charged
    pressure, after a service reduction of ``reduction_kpa`` (None: full service) held
    ``hold_s`` [s] by every valve (all direct release, all braked). ``inf`` if not within
    ``max_s``."""
    x = np.asarray(positions_m, dtype=float)
    ones = np.ones(x.size, dtype=bool)
    params, state = pack_freight_air(brake, x, np.asarray(valve_vehicles), ones, ones)
    nv = int(params[P_NV])
    depth = brake.full_service_reduction_kpa() if reduction_kpa is None else reduction_kpa
    calm = np.zeros(nv)
    simulate(params, state, np.full(nv, brake.charged_kpa - depth), calm, hold_s, dt)
    charged = np.full(nv, brake.charged_kpa)
    chunk = 5.0
    elapsed = 0.0
    while elapsed < max_s:
        steps = round(chunk / dt)
        for step in range(steps):
            freight_air_step(params, state, charged, calm, dt)
            if np.min(ar_kpa(params, state)) >= brake.charged_kpa - within_kpa:
                return elapsed + (step + 1) * dt
        elapsed += chunk
    return math.inf
