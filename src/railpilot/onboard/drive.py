"""One station pair driven under the onboard system: MRSP, TSR checks, plan, simulation.

The pieces of the onboard application put together for a train on a line
(``railpilot drive``): the most restrictive speed profile of the line's static limits, the
TSRs (extended by the train's length) and the target points (each moved back by the
safety distance); the paper's TSR check for each restriction ahead; the energy-efficient
planned curve for the running time; and the simulation core driving the train along the
planned curve (the ATO tracking it by distance). No files and no printing: the command
line (commands/drive.py) does that.

Coordinates: km-post metres for everything the line and the link speak (MRSP, TSRs,
targets); the planner and the simulator run in the train's own coordinate, metres from the
departure stop in the direction of travel (``mrsp.travelled_m``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.control.pstop import PredictiveStop, retarget
from railpilot.errors import ConfigError
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import TargetPoint, TargetReason, TravelDirection, TsrSet
from railpilot.onboard.advice_list import advice_along
from railpilot.onboard.braking import BrakingTrain, TsrCheck, tsr_check
from railpilot.onboard.consist_drive import CONSIST_METRICS, ConsistDrive
from railpilot.onboard.mrsp import (
    FloatArray,
    Mrsp,
    SpeedProfile,
    TargetStop,
    apply_tsr,
    km_post_m,
    most_restrictive_profile,
    train_span_m,
    travelled_m,
)
from railpilot.onboard.planner import (
    DEFAULT_STEP_M,
    DrivingTrain,
    SectionGrid,
    SpeedPlan,
    fastest,
    plan,
    section,
    target_stop_net,
)
from railpilot.onboard.shipped_trains import SHIPPED_TRAINS
from railpilot.onboard.supervision import SupervisionCurve, supervision_curve
from railpilot.onboard.target_point import safety_distance_m
from railpilot.scenario.consist_file import consist_preset
from railpilot.scenario.model import ATOModel, ControllerSpec, Scenario, SimSettings
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.result import SimResult
from railpilot.sim.stepper import Stepper
from railpilot.units import G_MPS2, KMH_PER_MPS, kmh_to_mps, mps_to_kmh
from railpilot.vehicle.consist import Consist
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import ResistanceTable, elevation_table, mean_specific_resistance
from railpilot.vehicle.traction import Locomotive
from railpilot.vehicle.train import Train

#: the trains that can follow the plan: the point mass, or every vehicle of the consist
MODELS = ("point-mass", "consist")
#: the consist model's longest step [s]: its driver's cycle, and its electric drive's lag
#: (1 s) resolved
CONSIST_MAX_DT_S = 0.05
#: the running-time supplement over the fastest run when none is given
DEFAULT_SUPPLEMENT = 0.10
#: the onboard aims this far short of a target stop [m]: the heavy-haul precise stop's
#: tolerance, so it never ends beyond the end of authority
TARGET_STOP_MARGIN_M = 2.0
#: a train at rest this close to its stop point has arrived [m]; farther, the drive failed
#: (the line runs use the same rule)
ARRIVED_WITHIN_M = 50.0
#: the plan keeps this far below the MRSP [km/h], room for the ATO's tracking error (a
#: production ATO's target speed sits below the permitted speed the same way)
DEFAULT_MARGIN_KMH = 5.0


@dataclass(frozen=True)
class TrainPreset:
    """A train the command line can name: its physics and its speed-limit category.

    ``consist``: the vehicles it is made of (vehicle/consist.py), from which ``train``,
    the point mass the planner and the fast model use, is derived.
    """

    name: str
    category: str
    train: Train
    brake: LocomotiveDrive
    consist: Consist | None = None

    @property
    def braking(self) -> BrakingTrain:
        return BrakingTrain(self.train, self.brake.locomotive, self.brake.air)

    @property
    def driving(self) -> DrivingTrain:
        return DrivingTrain(self.train, self.brake.locomotive)


def hauling(consist: Consist) -> Locomotive:
    """The locomotives of ``consist`` as the one drive the planner and the point mass see:
    the lead alone, or, with distributed power (the remotes take the lead's notch by
    radio, docs/consist.md), every unit's force and power summed, so the 20,000 t train
    is planned with both its HXD1s."""
    units = [consist.vehicles[int(i)].locomotive for i in consist.locomotive_indices()]
    lead = units[0]
    assert lead is not None  # a consist's first vehicle is its lead locomotive
    if len(units) == 1:
        return lead
    drives = [u for u in units if u is not None]
    return dataclasses.replace(
        lead,
        name=" + ".join(u.name for u in drives),
        mass_kg=sum(u.mass_kg for u in drives),
        length_m=sum(u.length_m for u in drives),
        traction=dataclasses.replace(
            lead.traction,
            max_force_n=sum(u.traction.max_force_n for u in drives),
            max_power_w=sum(u.traction.max_power_w for u in drives),
        ),
        regen=dataclasses.replace(
            lead.regen,
            max_force_n=sum(u.regen.max_force_n for u in drives),
            max_power_w=sum(u.regen.max_power_w for u in drives),
        ),
    )


def preset_of_consist(name: str, category: str, consist: Consist) -> TrainPreset:
    """A heavy-haul preset from its consist: the point mass the consist derives, hauled by
    its lead locomotive's drive, with the brake pipe's full service at the consist's own
    brake force (its ``max_service_decel_mps2``).

    Without a handover from regeneration to air (the example scenario's 50 km/h): the
    precise-stop controller leads the air brake itself, and regeneration to its own fade
    stops the sections closer to their times and returns more energy (docs/precise-stop.md).
    """
    train = consist.point_mass_train()
    brake = LocomotiveDrive(
        locomotive=hauling(consist),
        traction_lag_s=1.0,
        air=BrakePipeBrake(max_decel_mps2=train.max_service_decel_mps2),
        handover_kmh=0.0,
    )
    return TrainPreset(name, category, train, brake, consist)


def heavy_haul_loaded() -> TrainPreset:
    """The 10,000 t coal train: one HXD1 and 105 loaded C80 wagons (docs/consist.md)."""
    return train_preset("heavy-haul-loaded")


def heavy_haul_empty() -> TrainPreset:
    """The same train returning empty: one HXD1 and 105 C80 wagons at their tare; the
    heavy-haul line's ``freight_empty`` limits."""
    return train_preset("heavy-haul-empty")


def train_preset(name: str) -> TrainPreset:
    shipped = SHIPPED_TRAINS.get(name)
    if shipped is None:
        raise ConfigError("--train", name, f"one of {', '.join(SHIPPED_TRAINS)}")
    return preset_of_consist(name, shipped.category, consist_preset(shipped.consist))


@dataclass(frozen=True)
class TsrRequest:
    """A TSR as the command line gives it: km-post range [m] and limit [m/s], received by
    the onboard ``set_s`` [s] after the run's time origin (0: known at departure)."""

    start_m: float
    end_m: float
    limit_mps: float
    set_s: float = 0.0


@dataclass(frozen=True)
class TargetRequest:
    """A signal held at red at km post ``signal_m`` [m]: a target point the onboard
    receives ``set_s`` [s] after the run's time origin and that clears at ``clear_s``
    (the train ahead has moved on; ``inf``: never)."""

    signal_m: float
    set_s: float = 0.0
    clear_s: float = math.inf

    def active(self, t_s: float) -> bool:
        return self.set_s <= t_s < self.clear_s


@dataclass(frozen=True)
class Replan:
    """The onboard re-planned at ``time_s`` [s, from the departure] at ``from_m`` [m from
    the departure stop] because ``reason``; ``plan`` in metres from ``from_m``."""

    time_s: float
    from_m: float
    reason: str
    plan: SpeedPlan


@dataclass(frozen=True)
class DriveOutcome:
    """Everything one drive produced (the command line prints and plots it)."""

    from_station: int
    to_station: int
    direction: TravelDirection
    departure_m: float
    arrival_m: float
    mrsp: Mrsp
    static: SpeedProfile
    plan: SpeedPlan
    result: SimResult
    tsr_checks: tuple[dict[str, Any], ...]
    train_length_m: float
    supervision: tuple[SupervisionCurve, ...] = ()
    #: the MRSP in force from each time [s from the departure] on (the first from 0)
    mrsp_timeline: tuple[tuple[float, Mrsp], ...] = ()
    #: the signals held at red, and when (each target point set, then cleared)
    target_requests: tuple[TargetRequest, ...] = ()
    replans: tuple[Replan, ...] = ()
    #: the TSRs as given (not extended; each known to the onboard from its ``set_s``)
    tsr_requests: tuple[TsrRequest, ...] = ()
    #: the departure on the clock of the TSRs' and target points' times [s]
    start_time_s: float = 0.0

    @property
    def target_signals_m(self) -> tuple[float, ...]:
        """Km posts [m] of the signals held at red."""
        return tuple(r.signal_m for r in self.target_requests)

    @property
    def targets(self) -> tuple[TargetStop, ...]:
        """The target stops (each red signal moved back by its safety distance)."""
        return self.mrsp.targets

    def km_post(self, travelled: np.ndarray) -> np.ndarray:
        """Km-post positions [m] of distances [m] from the departure stop."""
        return km_post_m(travelled, self.direction, self.departure_m)

    def summary(self) -> dict[str, Any]:
        """The command's JSON object (docs/onboard.md, "railpilot drive")."""
        r = self.result
        x = self.km_post(r["position_m"])
        v = r["speed_mps"]
        # the time of each sample on the clock of the TSRs and target points
        t = r["time_s"] + self.start_time_s
        limit = whole_train_limit_mps(
            self.static, self.tsr_requests, t, x, self.direction, self.train_length_m
        )
        moving = v > 0
        over = np.where(moving, v - limit, -np.inf)
        passed = 0
        for request in self.target_requests:
            held = (t >= request.set_s) & (t < request.clear_s)
            beyond = travelled_m(x, self.direction, request.signal_m) > 0.0
            # the head went past the signal while it was held, between two samples (not:
            # it was past already when the target point came, or when the section began)
            crossed = np.zeros_like(beyond)
            crossed[1:] = beyond[1:] & ~beyond[:-1]
            passed += int(np.any(held & crossed))
        metrics = r.metrics
        s_run = r["position_m"]
        above = np.zeros(s_run.shape, dtype=bool)
        for curve in self.supervision:
            # a curve supervises the approach to its target, not what lies beyond it
            approach = s_run <= curve.target_m
            above |= moving & approach & (v > curve.permitted_speed_mps(s_run) + 1e-6)
        metrics_out = {
            "supervision_curves": len(self.supervision),
            "above_intervention_s": float(
                np.sum(np.diff(r["time_s"], append=r["time_s"][-1])[above])
            ),
        }
        return metrics_out | {
            "direction": "up" if self.direction == UP else "down",
            "from_km": self.departure_m / 1000.0,
            "to_km": self.arrival_m / 1000.0,
            "running_time_s": metrics["running_time_s"],
            "planned_running_time_s": self.plan.running_time_s,
            "requested_running_time_s": self.plan.requested_time_s,
            "plan_strategy": self.plan.strategy,
            "stop_error_m": metrics["stop_error_m"],
            "energy_traction_kwh": metrics["energy_traction_kwh"],
            "energy_regenerated_kwh": metrics["energy_regenerated_kwh"],
            "energy_traction_against_air_kwh": metrics["energy_traction_against_air_kwh"],
            "planned_energy_traction_kwh": self.plan.energy_traction_kwh,
            "planned_energy_regenerated_kwh": self.plan.energy_regenerated_kwh,
            "max_speed_kmh": metrics["max_speed_kmh"],
            "max_overspeed_kmh": max(0.0, float(mps_to_kmh(np.max(over)))),
            "model": r.meta.get("model", "point-mass"),
            **{key: metrics[key] for key in CONSIST_METRICS if key in metrics},
            "target_points_passed": passed,
            "tsr_checks": list(self.tsr_checks),
            "replans": [
                {
                    "time_s": p.time_s,
                    "at_km": km_post_m(p.from_m, self.direction, self.departure_m).item() / 1000.0,
                    "reason": p.reason,
                }
                for p in self.replans
            ],
            "advice": [i.as_dict() for i in advice_along(r, self.km_post)],
        }


def whole_train_limit_mps(
    static: SpeedProfile,
    tsrs: tuple[TsrRequest, ...],
    time_s: npt.ArrayLike,
    head_m: npt.ArrayLike,
    direction: TravelDirection,
    length_m: float,
) -> FloatArray:
    """The speed [m/s] the whole train may run at, for each sample of its head's km post
    ``head_m`` [m] at ``time_s`` [s, the TSRs' clock] (vectorised).

    The lowest static limit anywhere between its tail and its head
    (:meth:`SpeedProfile.lowest_along`: a limit rises only when the tail has left the
    lower one), and the lowest limit of the TSRs the onboard knew at that time (from
    their ``set_s``) whose zone, *as given*, the train overlaps (edges included).

    Not the MRSP at the head and at the tail, as before: the MRSP carries each TSR
    extended by a train length on its exit side, so the tail looked up in it is held to
    the TSR for a train length after it has left the zone (a false overspeed as the
    train speeds up again), and its static limits are not extended, so the head looked
    up in it misses a tail still in a lower limit.
    """
    t = np.asarray(time_s, dtype=float)
    low, high = train_span_m(head_m, direction, length_m)
    limit = static.lowest_along(low, high)
    for tsr in tsrs:
        zone_low, zone_high = sorted((tsr.start_m, tsr.end_m))
        under = (t >= tsr.set_s) & (low <= zone_high) & (high >= zone_low)
        limit = np.where(under, np.minimum(limit, tsr.limit_mps), limit)
    return limit


def check_reachable(
    route: StationRoute, sec: SectionGrid, quickest: SpeedPlan, from_station: int, to_station: int
) -> None:
    """A station the train can reach: its fastest run comes to rest nowhere short of the
    stop. A train that cannot climb a grade of the section (a loaded heavy-haul train
    with one locomotive on a steep climb) is refused before anything runs, naming where it
    stalls and the forces: the line's and its running resistance there against the most
    its locomotive pulls."""
    v = quickest.speed_mps
    at_rest = np.flatnonzero(v[1:-1] <= 0.0)
    if at_rest.size == 0:
        return
    i = int(at_rest[0]) + 1
    train, loco = route.preset.train, route.preset.brake.locomotive
    weight_kn = train.mass_kg * G_MPS2 / 1000.0
    resisting_kn = (float(sec.line_w[i]) + train.davis_a0) * weight_kn / 1000.0
    where = float(km_post_m(quickest.s_m[i], route.direction, route.departure_m)) / 1000.0
    raise ConfigError(
        f"section {from_station} -> {to_station}",
        f"{route.preset.name} stalls at km {where:.3f}",
        f"a section the train can run: there the line under it and its running resistance "
        f"hold it back with {resisting_kn:,.0f} kN ({float(sec.line_w[i]):+.1f} per mille "
        f"of the line), its locomotive pulls at most {loco.traction.max_force_n / 1000.0:,.0f} kN",
    )


def drive(
    line: RailLine,
    preset: TrainPreset,
    from_station: int,
    to_station: int,
    *,
    running_time_s: float | None = None,
    tsrs: tuple[TsrRequest, ...] = (),
    targets: tuple[TargetRequest, ...] = (),
    margin_kmh: float = DEFAULT_MARGIN_KMH,
    dt_s: float = 0.1,
    start_time_s: float = 0.0,
    model: str = "point-mass",
) -> DriveOutcome:
    """Plan and drive ``preset`` from station ``from_station`` to ``to_station`` (ids).

    ``running_time_s`` None: the fastest run plus 10 %. ``tsrs`` and ``targets``: the
    restrictions and the signals held at red (target points; the stop moved back by the
    safety distance at the line speed), each known to the onboard from its ``set_s``;
    ``start_time_s``: the departure on the same clock [s]. What the onboard receives
    while running makes it re-plan from where the train is for the time that remains (and
    check a TSR there, as the paper does); a target point that clears lets it go on.
    ``margin_kmh``: the plan's ceiling is ``max(C - margin, C / 2)`` of the whole-train
    MRSP ``C``. ``model``: the train that follows the plan, ``"point-mass"`` (the
    simulation core with the precise-stop controller) or ``"consist"`` (every vehicle a
    mass, the freight air brake along the train: onboard/consist_drive.py; at most a
    0.05 s step).
    """
    if model not in MODELS:
        raise ConfigError("--model", model, f"one of {', '.join(MODELS)}")
    if model == "consist" and preset.consist is None:
        raise ConfigError("--model", model, f"point-mass: {preset.name} has no consist")
    route = station_route(
        line, preset, from_station, to_station, margin_kmh, tsrs, targets, start_time_s, model
    )
    direction, departure = route.direction, route.departure_m
    mrsp = route.mrsp_at(0.0)
    end_s, quickest_sec = route.section_from(mrsp, 0.0, 0.0)
    quickest = route.fastest_to(end_s, quickest_sec)
    check_reachable(route, quickest_sec, quickest, from_station, to_station)
    # the running time is the station pair's; a plan to a target stop gets its share
    target_time = (
        quickest.running_time_s * (1.0 + DEFAULT_SUPPLEMENT) * route.length_m / end_s
        if running_time_s is None
        else float(running_time_s)
    )
    planned = route.plan_to(end_s, quickest_sec, target_time, 0.0)
    known = route.tsrs_at(0.0)
    checks = [
        _tsr_check(preset, route.table, planned, tsr, direction, departure)
        for tsr in known
        if route.entry_ahead(tsr, 0.0)
    ]
    duration_s = max(900.0, 2.5 * planned.running_time_s)
    stepper = plan_follower(
        preset, route.vehicle_line, planned, end_s, dt_s, duration_s, model=model
    )
    timeline = [(0.0, mrsp)]
    replans: list[Replan] = []
    for t_event in route.event_times():
        stepper.advance_to(t_event)
        arrived = stepper.at_rest and end_s >= route.length_m
        if arrived or stepper.time_s >= duration_s:
            break  # what comes later concerns the next section
        new = route.mrsp_at(t_event)
        if new == timeline[-1][1]:
            continue
        s_now, v_now = stepper.position_m, stepper.speed_mps
        now_known = route.tsrs_at(t_event)
        received = [t for t in now_known if t not in known]
        known = now_known
        timeline.append((t_event, new))
        next_end_s = route.next_stop_s(new, s_now)
        if next_end_s - s_now < 50.0:
            continue  # stopped at (or just before) that stop already
        end_s, sec = route.section_from(new, s_now, v_now)
        remaining = max(target_time - t_event, 1.0)
        again = route.plan_to(end_s, sec, remaining, s_now)
        reason = _what_changed(timeline[-2][1], new, bool(received))
        replans.append(Replan(t_event, s_now, reason, again))
        for tsr in (t for t in received if route.entry_ahead(t, s_now)):
            # the paper's check where the train is when the TSR arrives
            checks.append(
                _tsr_check_now(preset, route.table, tsr, direction, departure, s_now, v_now)
            )
        follow_plan(stepper, PlannedProfile(again.s_m + s_now, again.speed_mps), end_s)
        if stepper.at_rest:
            stepper.restart()
    stepper.run_to_end()
    final_mrsp = timeline[-1][1]
    curves = _supervision(preset, route.table, final_mrsp, direction, departure, end_s)
    return DriveOutcome(
        from_station,
        to_station,
        direction,
        departure,
        km_post_m(end_s, direction, departure).item(),
        final_mrsp,
        route.static,
        planned,
        stepper.result(),
        tuple(checks),
        preset.train.length_m,
        curves,
        tuple(timeline),
        tuple(targets),
        tuple(replans),
        tuple(tsrs),
        start_time_s,
    )


def departure_section(
    line: RailLine,
    preset: TrainPreset,
    from_station: int,
    to_station: int,
    margin_kmh: float = DEFAULT_MARGIN_KMH,
) -> SectionGrid:
    """The planner's section of a station pair as the train departs with no TSR or target
    point: the whole-train MRSP of the static limits less the margin (the ground asks the
    planner for its energy-time curves with it, ground/energy.py)."""
    route = station_route(line, preset, from_station, to_station, margin_kmh, (), (), 0.0)
    return route.section_from(route.mrsp_at(0.0), 0.0, 0.0)[1]


def station_route(
    line: RailLine,
    preset: TrainPreset,
    from_station: int,
    to_station: int,
    margin_kmh: float,
    tsrs: tuple[TsrRequest, ...],
    targets: tuple[TargetRequest, ...],
    start_time_s: float,
    model: str = "point-mass",
) -> StationRoute:
    """The route of one station pair, planned for the train ``model`` names."""
    if not (math.isfinite(margin_kmh) and 0 <= margin_kmh <= 50):
        raise ConfigError("--margin", margin_kmh, "a margin in [0, 50] km/h")
    start = line.station(from_station)
    end = line.station(to_station)
    direction = UP if end.centre_m > start.centre_m else DOWN
    if end.id == start.id:
        raise ConfigError("--to", to_station, "a station other than --from")
    departure, arrival = start.stop_m(direction), end.stop_m(direction)
    return StationRoute(
        line,
        preset,
        direction,
        departure,
        float(travelled_m(arrival, direction, departure)),
        kmh_to_mps(margin_kmh),
        tsrs,
        targets,
        start_time_s,
        station_stop_net(preset, model),
    )


def station_stop_net(preset: TrainPreset, model: str) -> float:
    """The least net deceleration [m/s^2] of a plan's stop at the station, for the train
    that follows the plan. The consist's driver stops at the planning brake's deceleration
    net of the line, its air brake adding what a descent takes away
    (onboard/consist_drive.py), and its plan brakes so: at the planning brake's force less
    the descent, the empty train's stop on 12 per mille would be 2 km at 0.01 m/s^2,
    longer than its least application lets it brake. The point mass's precise stop
    tracks the planning brake's force however the line falls (0: no floor); a floor there
    put the shipped line's sections on descents 0.7 points further from their running
    times."""
    return preset.driving.brake_mps2 if model == "consist" else 0.0


def _what_changed(before: Mrsp, after: Mrsp, tsr_received: bool) -> str:
    """Why the onboard re-planned, in words for the log and the summary."""
    reasons = []
    if tsr_received:
        reasons.append("TSR received")
    before_ids = {t.target_id for t in before.targets}
    after_ids = {t.target_id for t in after.targets}
    if after_ids - before_ids:
        reasons.append("target point set")
    if before_ids - after_ids:
        reasons.append("target point cleared")
    return ", ".join(reasons) or "restrictions changed"


@dataclass(frozen=True)
class StationRoute:
    """One station pair as the onboard sees it: the line, the train, what it is told."""

    line: RailLine
    preset: TrainPreset
    direction: TravelDirection
    departure_m: float
    length_m: float
    margin_mps: float
    tsrs: tuple[TsrRequest, ...]
    targets: tuple[TargetRequest, ...]
    start_time_s: float
    #: the least net deceleration [m/s^2] of the plan's stop at the station
    station_stop_net_mps2: float = 0.0

    @cached_property
    def static(self) -> SpeedProfile:
        return SpeedProfile(*self.line.static_limit(self.preset.category, self.direction))

    @cached_property
    def vehicle_line(self) -> Line:
        return train_line(self.line, self.preset.category, self.direction, self.departure_m)

    @cached_property
    def table(self) -> ResistanceTable:
        return elevation_table(self.vehicle_line)

    def event_times(self) -> list[float]:
        """When what the onboard knows changes [s from this departure], after it."""
        times = {t.set_s for t in self.tsrs}
        for target in self.targets:
            times |= {target.set_s, target.clear_s}
        return sorted(
            t - self.start_time_s for t in times if math.isfinite(t) and t > self.start_time_s
        )

    def tsrs_at(self, t_s: float) -> tuple[AppliedTsr, ...]:
        """The TSRs the onboard knows ``t_s`` [s] after departing, as it applies them."""
        now = t_s + self.start_time_s
        train = self.preset.train
        return tuple(
            apply_tsr(
                TsrSet(i + 1, t.start_m, t.end_m, t.limit_mps, 0.0, 4.0e9),
                train.length_m,
                self.direction,
            )
            for i, t in enumerate(self.tsrs)
            if t.set_s <= now
        )

    def mrsp_at(self, t_s: float) -> Mrsp:
        """The MRSP of what the onboard knows ``t_s`` [s] after departing."""
        now = t_s + self.start_time_s
        train = self.preset.train
        static = self.static
        line_speed = float(np.max(static.speeds_mps[np.isfinite(static.speeds_mps)]))
        safety = float(safety_distance_m(line_speed, train.max_service_decel_mps2))
        stops = tuple(
            TargetStop.from_target_point(
                TargetPoint(i + 1, target.signal_m, TargetReason.TRAIN_AHEAD),
                safety,
                self.direction,
            )
            for i, target in enumerate(self.targets)
            if target.active(now)
        )
        return most_restrictive_profile(static, self.tsrs_at(t_s), stops, direction=self.direction)

    def section_from(self, mrsp: Mrsp, s0: float, v0: float) -> tuple[float, SectionGrid]:
        """The planner's section from ``s0`` [m from the departure] at ``v0`` [m/s] to the
        arrival stop or the first target stop before it, and where that end is."""
        end_s = self.next_stop_s(mrsp, s0)
        edges, ceiling = _whole_train_ceiling(
            mrsp, self.direction, self.departure_m, s0, end_s, self.preset
        )
        ceiling = np.maximum(ceiling - self.margin_mps, ceiling / 2.0)
        length = max(end_s - s0, 3.0 * DEFAULT_STEP_M)
        sec = section(
            length,
            (edges - s0, ceiling),
            self.table,
            start_m=s0,
            train_length_m=self.preset.train.length_m,
            initial_speed_mps=v0,
        )
        return end_s, sec

    def entry_ahead(self, tsr: AppliedTsr, s0: float) -> bool:
        """Does the train meet the restriction's zone between ``s0`` [m from the departure]
        and the arrival (a TSR behind it or beyond the station is not this section's)?"""
        entry_m = tsr.zone_start_m if self.direction == UP else tsr.zone_end_m
        exit_m = tsr.zone_end_m if self.direction == UP else tsr.zone_start_m
        entry_s = float(travelled_m(entry_m, self.direction, self.departure_m))
        exit_s = float(travelled_m(exit_m, self.direction, self.departure_m))
        return exit_s > s0 and entry_s < self.length_m

    def next_stop_s(self, mrsp: Mrsp, s0: float) -> float:
        """Where the train is to stop next [m from the departure]: the arrival, or the
        first target stop ahead of ``s0``, aimed short of the end of authority by the
        stop's tolerance (a precise stop lands within it either side)."""
        end_s = self.length_m
        for stop in mrsp.targets:
            s = float(travelled_m(stop.position_m, self.direction, self.departure_m))
            s -= TARGET_STOP_MARGIN_M
            if s0 < s < end_s:
                end_s = s
        return end_s

    def plan_to(self, end_s: float, sec: SectionGrid, time_s: float, s0: float) -> SpeedPlan:
        """The plan of ``sec``: for ``time_s`` if it ends at the arrival; to a target stop,
        for that stop's share of the time by distance (the target may clear)."""
        share = (end_s - s0) / max(self.length_m - s0, 1e-9)
        return plan(
            self.preset.driving,
            sec,
            max(time_s * min(share, 1.0), 1.0),
            self.stop_net_mps2(end_s),
        )

    def fastest_to(self, end_s: float, sec: SectionGrid) -> SpeedPlan:
        """The fastest run of ``sec`` to its stop at ``end_s`` [m from the departure]
        (the baseline driver's), braked to a target stop as :meth:`plan_to` brakes."""
        return fastest(self.preset.driving, sec, self.stop_net_mps2(end_s))

    def stop_net_mps2(self, end_s: float) -> float:
        """The least net deceleration [m/s^2] of a plan's stop at ``end_s`` [m from the
        departure]: a target stop short of the station's (a red signal ahead) is braked
        at ``target_stop_net`` however the line falls; the station's at
        ``station_stop_net_mps2`` (:func:`station_stop_net`)."""
        if end_s < self.length_m:
            return target_stop_net(self.preset.driving)
        return self.station_stop_net_mps2


def _supervision(
    preset: TrainPreset,
    table: ResistanceTable,
    mrsp: Mrsp,
    direction: TravelDirection,
    departure_m: float,
    end_s: float,
) -> tuple[SupervisionCurve, ...]:
    """The full-service supervision curve of every decrease of the MRSP on the section.

    In the train's coordinate (metres from the departure stop); the stop at ``end_s``
    included (a decrease to 0).
    """
    curves = []
    for decrease in mrsp.decreases():
        target_s = float(travelled_m(decrease.position_m, direction, departure_m))
        if 0.0 < target_s <= end_s + TARGET_STOP_MARGIN_M + 1e-6:
            curves.append(supervision_curve(preset.braking, table, target_s, decrease.to_mps))
    return tuple(curves)


def _whole_train_ceiling(
    mrsp: Mrsp,
    direction: TravelDirection,
    departure_m: float,
    start_s: float,
    end_s: float,
    preset: TrainPreset,
) -> tuple[np.ndarray, np.ndarray]:
    """The planner's ceiling: at each head position the lowest MRSP under the whole train.

    The MRSP carries the TSRs' train-length extension already; the static limits it does
    not (they hold where they are), so the head may not speed up until the tail has left a
    lower limit. On a 10 m grid: ``min`` of the MRSP over ``[s - L, s]``.
    """
    step = 10.0
    n = max(math.ceil((end_s - start_s) / step), 2)
    grid = np.linspace(start_s, end_s, n + 1)
    mids = 0.5 * (grid[:-1] + grid[1:])
    speeds = mrsp.at(km_post_m(mids, direction, departure_m))
    cell = (end_s - start_s) / n
    window = max(math.ceil(preset.train.length_m / cell), 1)
    if start_s > 0.0:
        # re-planned on the move: the tail still occupies the line behind the head
        behind_s = start_s - cell * (np.arange(window, 0, -1) - 0.5)
        behind = mrsp.at(km_post_m(behind_s, direction, departure_m))
    else:
        behind = np.full(window, speeds[0])  # at the departure stop, in the station
    padded = np.concatenate([behind, speeds])
    lowest = np.lib.stride_tricks.sliding_window_view(padded, window + 1).min(axis=1)
    return grid, lowest[: speeds.size]


def train_line(
    line: RailLine, category: str, direction: TravelDirection, departure_m: float
) -> Line:
    """The line in the train's coordinate with the departure stop at 0."""
    whole = line.to_vehicle_line(category, direction)
    offset = float(line.distance_along(departure_m, direction))

    def shift(segments: tuple[Segment, ...]) -> tuple[Segment, ...]:
        return tuple(
            Segment(s.start_m - offset, s.end_m - offset, s.value)
            for s in segments
            if s.end_m - offset > -5_000.0
        )

    return Line(gradients=shift(whole.gradients), curves=shift(whole.curves))


def _tsr_check_now(
    preset: TrainPreset,
    table: ResistanceTable,
    tsr: AppliedTsr,
    direction: TravelDirection,
    departure_m: float,
    s_m: float,
    v_mps: float,
) -> dict[str, Any]:
    """The paper's check for a TSR received mid-run: from where the train is, at its speed."""
    entry_m = tsr.zone_start_m if direction == UP else tsr.zone_end_m
    entry_s = float(travelled_m(entry_m, direction, departure_m))
    out: dict[str, Any] = {
        "session": tsr.session,
        "start_km": tsr.start_m / 1000.0,
        "end_km": tsr.end_m / 1000.0,
        "limit_kmh": float(mps_to_kmh(tsr.limit_mps)),
        "checked_at_km": float(km_post_m(s_m, direction, departure_m)) / 1000.0,
        "speed_kmh": float(mps_to_kmh(v_mps)),
    }
    if entry_s <= s_m or v_mps <= tsr.limit_mps:
        # in it already, or slow enough: nothing to brake for
        out.update({"regen_sufficient": True, "air_brake_from_km": None, "feasible": True})
        return out
    check = tsr_check(preset.braking, table, s_m, v_mps, entry_s, tsr.limit_mps)
    return out | _check_fields(check, direction, departure_m)


def _check_fields(
    check: TsrCheck, direction: TravelDirection, departure_m: float
) -> dict[str, Any]:
    air = (
        None
        if check.air_brake_from_m is None
        else float(km_post_m(check.air_brake_from_m, direction, departure_m)) / 1000.0
    )
    return {
        "distance_m": check.distance_m,
        "regen_distance_m": None if math.isinf(check.regen_distance_m) else check.regen_distance_m,
        "regen_sufficient": check.regen_sufficient,
        "air_brake_from_km": air,
        "feasible": check.feasible,
    }


def _tsr_check(
    preset: TrainPreset,
    table: ResistanceTable,
    planned: SpeedPlan,
    tsr: AppliedTsr,
    direction: TravelDirection,
    departure_m: float,
) -> dict[str, Any]:
    """The paper's check for one restriction, 3 km before it (or from the departure).

    As if the restriction were received there: the plan's speed at that point, the
    distance to the restriction's entry (its zone, train length included, as the train
    meets it).
    """
    entry_m = tsr.zone_start_m if direction == UP else tsr.zone_end_m
    entry_s = float(travelled_m(entry_m, direction, departure_m))
    s, v = planned.s_m, planned.speed_mps
    check: TsrCheck | None = None
    at_s = 0.0
    if entry_s > 0.0:
        at_s = max(entry_s - 3_000.0, 0.0)
        speed = float(np.interp(at_s, s, v))
        check = tsr_check(preset.braking, table, at_s, speed, entry_s, tsr.limit_mps)
    out: dict[str, Any] = {
        "session": tsr.session,
        "start_km": tsr.start_m / 1000.0,
        "end_km": tsr.end_m / 1000.0,
        "limit_kmh": float(mps_to_kmh(tsr.limit_mps)),
        "checked_at_km": float(km_post_m(at_s, direction, departure_m)) / 1000.0,
    }
    if check is None:
        out.update({"regen_sufficient": True, "air_brake_from_km": None, "feasible": True})
        return out
    out["speed_kmh"] = float(mps_to_kmh(float(np.interp(at_s, s, v))))
    return out | _check_fields(check, direction, departure_m)


def plan_follower(
    preset: TrainPreset,
    vehicle_line: Line,
    curve: SpeedPlan,
    end_s: float,
    dt_s: float,
    duration_s: float,
    *,
    model: str,
    controller: PredictiveStop | None = None,
    record_every_s: float | None = None,
) -> Stepper | ConsistDrive:
    """The train that follows ``curve`` to its stop at ``end_s`` [m from the departure]:
    the consist with its driver (``model`` ``"consist"``, at most a CONSIST_MAX_DT_S step),
    or the point mass tracked by the precise-stop controller (``controller``: one of this
    train and line to retarget, e.g. a cached one; else one is made for the stop).
    ``record_every_s``: how often the run is recorded (None: the point mass every step,
    the consist every second)."""
    if model == "consist":
        if preset.consist is None:
            raise ConfigError("--model", model, f"point-mass: {preset.name} has no consist")
        return ConsistDrive(
            preset.consist,
            vehicle_line,
            PlannedProfile(curve.s_m, curve.speed_mps),
            end_s,
            min(dt_s, CONSIST_MAX_DT_S),
            duration_s,
            station_stop_net(preset, model),
            record_every_s=1.0 if record_every_s is None else record_every_s,
        )
    record_every = 1 if record_every_s is None else round(record_every_s / dt_s)
    scenario = drive_scenario(preset, vehicle_line, curve, dt_s, duration_s, record_every)
    if controller is None:
        return Stepper(scenario, stop_controller(preset, vehicle_line, end_s, dt_s))
    stepper = Stepper(scenario, controller)
    retarget(stepper.controller_params, stepper.controller_state, end_s)
    return stepper


def follow_plan(stepper: Stepper | ConsistDrive, profile: PlannedProfile, end_s: float) -> None:
    """A new plan from here for a running train (:func:`plan_follower`'s): ``profile`` to
    a stop at ``end_s`` [m from the departure]."""
    if isinstance(stepper, ConsistDrive):
        stepper.follow(profile, end_s)
    else:
        stepper.replace_reference(profile)
        retarget(stepper.controller_params, stepper.controller_state, end_s)


def drive_scenario(
    preset: TrainPreset,
    vehicle_line: Line,
    planned: SpeedPlan,
    dt_s: float,
    duration_s: float | None = None,
    record_every: int = 1,
) -> Scenario:
    """The simulation core driving the planned curve: the ATO tracks it by distance with
    the precise-stop controller (control/pstop.py) and stops at its end."""
    return Scenario(
        name="drive",
        train=preset.train,
        line=vehicle_line,
        brake=preset.brake,
        reference=PlannedProfile(planned.s_m, planned.speed_mps),
        ato=ATOModel(
            reference="distance",
            gradient_feedforward=True,
            # the plan's acceleration is fed forward by the fast path's lead (traction and
            # regeneration); the controller leads its air brake itself
            brake_delay_s=0.0,
            brake_lag_s=preset.brake.traction_lag_s,
        ),
        controller=ControllerSpec(name="pstop"),
        # room for a wait at a target point and the plans after it
        sim=SimSettings(
            dt_s=dt_s,
            duration_s=duration_s or max(900.0, 2.5 * planned.running_time_s),
            record_every=record_every,
        ),
    )


def stop_controller(
    preset: TrainPreset, vehicle_line: Line, stop_m: float, control_period_s: float
) -> PredictiveStop:
    """The precise-stop controller with this train's models (its one set of gains).

    Fast path: traction and regeneration (the drive's lag), braking up to the regenerative
    envelope, handed over to the air brake below the handover speed; slow path: the whole
    train's air brake, application and release (brakes/brake_pipe.py ``train_lead_s``,
    ``train_release_lead_s``); the resistance model the ATO uses (Davis and the line's
    gradients and curves averaged over the train, every 20 m) for the prediction.
    """
    train = preset.train
    brake = preset.brake
    air_delay_s, air_lag_s = brake.train_lead_s(train.length_m)
    release_delay_s, release_lag_s = brake.air.train_release_lead_s(train.length_m)
    regen = brake.locomotive.regen
    handover_mps = kmh_to_mps(brake.handover_kmh)
    handed_over = handover_mps > regen.fade_below_mps
    # N/kN -> m/s^2 on the effective mass, as the ATO's feed-forward (sim/engine.py)
    per_n_per_kn = G_MPS2 / 1000.0 / (1.0 + train.rotating_mass_factor)
    table = elevation_table(vehicle_line)
    grid = np.arange(-train.length_m, stop_m + 1_000.0, 20.0)
    line = per_n_per_kn * np.array(
        [
            mean_specific_resistance(
                table.edges_m, table.cumulative, table.values_n_per_kn, x, train.length_m, 1.0
            )
            for x in grid
        ]
    )
    return PredictiveStop(
        air_delay_s,
        air_lag_s,
        stop_m=stop_m,
        sigma_release=release_delay_s,
        tau_release=release_lag_s,
        sigma_track=control_period_s / 2.0,
        tau_track=brake.traction_lag_s,
        stop_decel=preset.driving.brake_mps2,
        fast_limit=regen.max_force_n / train.effective_mass_kg,
        fast_full_mps=handover_mps if handed_over else regen.fade_below_mps,
        fast_zero_mps=regen.fade_below_mps if handed_over else 0.0,
        davis_mps2=(
            train.davis_a0 * per_n_per_kn,
            train.davis_a1 * KMH_PER_MPS * per_n_per_kn,
            train.davis_a2 * KMH_PER_MPS**2 * per_n_per_kn,
        ),
        line_profile=(grid, line),
        output_limits=(-train.max_service_decel_mps2, train.max_service_decel_mps2),
    )
