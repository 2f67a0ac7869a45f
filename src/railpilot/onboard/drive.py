"""One station pair driven under the onboard system: MRSP, TSR checks, plan, simulation.

The pieces of the onboard application put together for a train on a line (issue 10 item 9,
``railpilot drive``): the most restrictive speed profile of the line's static limits, the
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

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from railpilot.brakes.brake_pipe import BrakePipeBrake
from railpilot.brakes.locomotive_drive import LocomotiveDrive
from railpilot.errors import ConfigError
from railpilot.line.model import DOWN, UP, RailLine
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import TargetPoint, TargetReason, TravelDirection, TsrSet
from railpilot.onboard.braking import BrakingTrain, TsrCheck, tsr_check
from railpilot.onboard.mrsp import (
    Mrsp,
    SpeedProfile,
    TargetStop,
    apply_tsr,
    km_post_m,
    most_restrictive_profile,
    travelled_m,
)
from railpilot.onboard.planner import DrivingTrain, PlannedCurve, fastest, plan, section
from railpilot.onboard.supervision import SupervisionCurve, supervision_curve
from railpilot.onboard.target_point import safety_distance_m
from railpilot.scenario.model import ATOModel, ControllerSpec, Scenario, SimSettings
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.result import SimResult
from railpilot.sim.run import simulate
from railpilot.units import kmh_to_mps, mps_to_kmh
from railpilot.vehicle.line import Line, Segment
from railpilot.vehicle.profile import ResistanceTable, elevation_table
from railpilot.vehicle.traction import hxd1_locomotive
from railpilot.vehicle.train import Train

#: the running-time supplement over the fastest run when none is given
DEFAULT_SUPPLEMENT = 0.10
#: the plan keeps this far below the MRSP [km/h], room for the ATO's tracking error (a
#: production ATO's target speed sits below the permitted speed the same way)
DEFAULT_MARGIN_KMH = 5.0


@dataclass(frozen=True)
class TrainPreset:
    """A train the command line can name: its physics and its speed-limit category."""

    name: str
    category: str
    train: Train
    brake: LocomotiveDrive

    @property
    def braking(self) -> BrakingTrain:
        return BrakingTrain(self.train, self.brake.locomotive, self.brake.air)

    @property
    def driving(self) -> DrivingTrain:
        return DrivingTrain(self.train, self.brake.locomotive)


def heavy_haul_loaded() -> TrainPreset:
    """The 10,000 t, 1,600 m train of examples/heavy_haul_run.toml (one HXD1, brake pipe G)."""
    train = Train(
        mass_kg=10_000e3,
        rotating_mass_factor=0.06,
        length_m=1600.0,
        davis_a0=0.92,
        davis_a1=0.0048,
        davis_a2=0.000125,
        max_service_decel_mps2=0.5,
    )
    brake = LocomotiveDrive(
        locomotive=hxd1_locomotive(),
        traction_lag_s=1.0,
        air=BrakePipeBrake(max_decel_mps2=0.5),
        handover_kmh=50.0,
    )
    return TrainPreset("heavy-haul-loaded", "freight_loaded", train, brake)


#: the trains ``railpilot drive --train`` knows
TRAINS = {"heavy-haul-loaded": heavy_haul_loaded}


def train_preset(name: str) -> TrainPreset:
    factory = TRAINS.get(name)
    if factory is None:
        raise ConfigError("--train", name, f"one of {', '.join(TRAINS)}")
    return factory()


@dataclass(frozen=True)
class TsrRequest:
    """A TSR as the command line gives it: km-post range [m] and limit [m/s]."""

    start_m: float
    end_m: float
    limit_mps: float


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
    target_signals_m: tuple[float, ...]
    plan: PlannedCurve
    result: SimResult
    tsr_checks: tuple[dict[str, Any], ...]
    train_length_m: float
    supervision: tuple[SupervisionCurve, ...] = ()

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
        head_limit = self.mrsp.at(x)
        tail = x - (1.0 if self.direction == UP else -1.0) * self.train_length_m
        tail_limit = self.mrsp.at(tail)
        moving = v > 0
        head_over = np.where(moving, v - head_limit, -np.inf)
        tail_over = np.where(moving, v - tail_limit, -np.inf)
        passed = sum(
            1
            for signal in self.target_signals_m
            if np.any(travelled_m(x, self.direction, signal) > 0.0)
        )
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
            "planned_energy_traction_kwh": self.plan.energy_traction_kwh,
            "planned_energy_regenerated_kwh": self.plan.energy_regenerated_kwh,
            "max_speed_kmh": metrics["max_speed_kmh"],
            "max_overspeed_kmh": {
                "head": max(0.0, float(mps_to_kmh(np.max(head_over)))),
                "tail": max(0.0, float(mps_to_kmh(np.max(tail_over)))),
            },
            "target_points_passed": passed,
            "tsr_checks": list(self.tsr_checks),
        }


def drive(
    line: RailLine,
    preset: TrainPreset,
    from_station: int,
    to_station: int,
    *,
    running_time_s: float | None = None,
    tsrs: tuple[TsrRequest, ...] = (),
    targets_m: tuple[float, ...] = (),
    margin_kmh: float = DEFAULT_MARGIN_KMH,
    dt_s: float = 0.1,
) -> DriveOutcome:
    """Plan and drive ``preset`` from station ``from_station`` to ``to_station`` (ids).

    ``running_time_s`` None: the fastest run plus 10 %. ``tsrs``: restrictions in force for
    the whole run; ``targets_m``: km posts [m] of signals held at red (target points), the
    stop moved back by the safety distance at the line speed. ``margin_kmh``: the plan's
    ceiling is ``max(C - margin, C / 2)`` of the whole-train MRSP ``C``.
    """
    if not (math.isfinite(margin_kmh) and 0 <= margin_kmh <= 50):
        raise ConfigError("--margin", margin_kmh, "a margin in [0, 50] km/h")
    start = line.station(from_station)
    end = line.station(to_station)
    direction = UP if end.centre_m > start.centre_m else DOWN
    if end.id == start.id:
        raise ConfigError("--to", to_station, "a station other than --from")
    departure, arrival = start.stop_m(direction), end.stop_m(direction)
    length_m = float(travelled_m(arrival, direction, departure))
    static = SpeedProfile(*line.static_limit(preset.category, direction))
    applied = tuple(
        apply_tsr(
            TsrSet(i + 1, t.start_m, t.end_m, t.limit_mps, 0.0, 4.0e9),
            preset.train.length_m,
            direction,
        )
        for i, t in enumerate(tsrs)
    )
    line_speed = float(np.max(static.speeds_mps[np.isfinite(static.speeds_mps)]))
    stops = tuple(
        TargetStop.from_target_point(
            TargetPoint(i + 1, signal, TargetReason.TRAIN_AHEAD),
            float(safety_distance_m(line_speed, preset.train.max_service_decel_mps2)),
            direction,
        )
        for i, signal in enumerate(targets_m)
    )
    mrsp = most_restrictive_profile(static, applied, stops, direction=direction)
    # the planner's ceiling in the train's coordinate, from the departure to the arrival
    # stop or the first target stop before it
    end_s = length_m
    for stop in mrsp.targets:
        s = float(travelled_m(stop.position_m, direction, departure))
        if 0.0 < s < end_s:
            end_s = s
    edges_s, ceiling = _whole_train_ceiling(mrsp, direction, departure, end_s, preset)
    ceiling = np.maximum(ceiling - kmh_to_mps(margin_kmh), ceiling / 2.0)
    vehicle_line = train_line(line, preset.category, direction, departure)
    table = elevation_table(vehicle_line)
    sec = section(end_s, (edges_s, ceiling), table, train_length_m=preset.train.length_m)
    quickest = fastest(preset.driving, sec)
    target_time = (
        quickest.running_time_s * (1.0 + DEFAULT_SUPPLEMENT)
        if running_time_s is None
        else float(running_time_s)
    )
    planned = plan(preset.driving, sec, target_time)
    checks = tuple(_tsr_check(preset, table, planned, tsr, direction, departure) for tsr in applied)
    curves = _supervision(preset, table, mrsp, direction, departure, end_s)
    result = _simulate(preset, vehicle_line, planned, dt_s)
    return DriveOutcome(
        from_station,
        to_station,
        direction,
        departure,
        km_post_m(end_s, direction, departure).item(),
        mrsp,
        static,
        tuple(float(t) for t in targets_m),
        planned,
        result,
        checks,
        preset.train.length_m,
        curves,
    )


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
        if 0.0 < target_s <= end_s + 1e-6:
            curves.append(
                supervision_curve(preset.braking, table, min(target_s, end_s), decrease.to_mps)
            )
    return tuple(curves)


def _whole_train_ceiling(
    mrsp: Mrsp, direction: TravelDirection, departure_m: float, end_s: float, preset: TrainPreset
) -> tuple[np.ndarray, np.ndarray]:
    """The planner's ceiling: at each head position the lowest MRSP under the whole train.

    The MRSP carries the TSRs' train-length extension already; the static limits it does
    not (they hold where they are), so the head may not speed up until the tail has left a
    lower limit. On a 10 m grid: ``min`` of the MRSP over ``[s - L, s]``.
    """
    step = 10.0
    n = max(math.ceil(end_s / step), 2)
    grid = np.linspace(0.0, end_s, n + 1)
    mids = 0.5 * (grid[:-1] + grid[1:])
    speeds = mrsp.at(km_post_m(mids, direction, departure_m))
    window = max(math.ceil(preset.train.length_m / (end_s / n)), 1)
    padded = np.concatenate([np.full(window, speeds[0]), speeds])
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


def _tsr_check(
    preset: TrainPreset,
    table: ResistanceTable,
    planned: PlannedCurve,
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
    air = (
        None
        if check.air_brake_from_m is None
        else float(km_post_m(check.air_brake_from_m, direction, departure_m)) / 1000.0
    )
    out.update(
        {
            "speed_kmh": float(mps_to_kmh(float(np.interp(at_s, s, v)))),
            "distance_m": check.distance_m,
            "regen_distance_m": None
            if math.isinf(check.regen_distance_m)
            else check.regen_distance_m,
            "regen_sufficient": check.regen_sufficient,
            "air_brake_from_km": air,
            "feasible": check.feasible,
        }
    )
    return out


def _simulate(
    preset: TrainPreset, vehicle_line: Line, planned: PlannedCurve, dt_s: float
) -> SimResult:
    """The simulation core driving the planned curve (ATO by distance, PID)."""
    reference = PlannedProfile(planned.s_m, planned.speed_mps)
    scenario = Scenario(
        name="drive",
        train=preset.train,
        line=vehicle_line,
        brake=preset.brake,
        reference=reference,
        ato=ATOModel(reference="distance", gradient_feedforward=True, preview_s=30.0),
        controller=ControllerSpec(name="pid"),
        sim=SimSettings(dt_s=dt_s, duration_s=max(600.0, 1.6 * planned.running_time_s)),
    )
    return simulate(scenario)
