"""One train of a whole-line run: the onboard intelligent driving system and the
simulation core, station to station through its timetable (docs/line-run.md).

A :class:`TrainDriver` is what :class:`~railpilot.cosim.link_sim.LinkSim` asks where a
train is (its ``Mover``) and what hears the train's link events. It drives each station
pair as ``railpilot drive`` does (onboard/drive.py): the most restrictive speed profile
of the static limits, the TSRs the link delivered (extended by the train's length) and
the red signals the train knows of (each a target stop a safety distance before it);
the planned curve for the section's running time; the simulation core (sim/stepper.py,
the brake pipe, the locomotive's drive and the precise-stop ATO) tracking it. When what
the train knows changes, it re-plans from where it is for the time that remains, as
``drive`` does at its events; here the events are the link's and the signals'.

What the train knows of red signals comes two ways:

* the **target point** the ground sends over the radio (paper 001, 2.4): the nearest
  signal ahead held at red, however far; the advised driver plans to it;
* the **cab signal** (:meth:`TrainDriver.cab_signal`): the aspect of the signals a few
  blocks ahead, from the track circuits, with no radio. A heavy-haul locomotive's train
  control (LKJ) has it; it is why a train in a radio dead zone never passes a red signal.

The advised train reports its planned curve to the ground (link ``PlannedCurve``, when its
predicted running time moves: onboard/report.py): the time run on the section and the
time still needed, which is its plan's time to go to where the plan ends, and the rest of
the section at the pace of its running time, if the plan ends short (a red signal, a
failure). The ground may answer with new running times for the sections ahead
(``RunningTimes``, ground/online_retimer.py): each section departed after that is planned for
the ground's time, and the one being run is planned again for it.

``advised=False`` is a baseline driver (docs/line-run.md, "The baseline"): no planned
curve and no target points from the ground (the cab signal only); TSRs are obeyed as
orders. Which baseline is ``human``: None the minimum-time driver (the fastest run to the
static limits less the margin, braking late); a :class:`~railpilot.cosim.human_driver.
HumanDriving` the human driver of cosim/human_driver.py (its margin, coasting habits and
braking cycles), who acts on a changed TSR or aspect its reaction time late.

Time: the driver works in seconds since the start of the run (``t``); the link speaks
epoch seconds (``epoch_s + t``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Literal, get_args

import numpy as np

from railpilot.control.pstop import PredictiveStop
from railpilot.errors import ConfigError
from railpilot.ground.targets import is_clear
from railpilot.line.model import UP, RailLine
from railpilot.link.events import (
    AppliedTsr,
    Event,
    MessageReceived,
    TargetPointReceived,
    TsrApplied,
    TsrCancelled,
    TsrExpired,
)
from railpilot.link.messages import PlannedCurve as CurveReport
from railpilot.link.messages import RunningTimes, TargetPoint, TargetReason, TravelDirection
from railpilot.onboard.consist_drive import ConsistDrive
from railpilot.onboard.drive import (
    ARRIVED_WITHIN_M,
    DEFAULT_MARGIN_KMH,
    StationRoute,
    TrainPreset,
    follow_plan,
    plan_follower,
    station_route,
    stop_controller,
    train_preset,
)
from railpilot.onboard.mrsp import Mrsp, TargetStop, direction_sign, most_restrictive_profile
from railpilot.onboard.planner import SpeedPlan, fastest
from railpilot.onboard.report import PlannedCurveReporter, remaining_time_s
from railpilot.onboard.target_point import safety_distance_m
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.stepper import Stepper

from .human_driver import HumanDriving, human_curve

#: who drives a line run's trains: the advised driving system, or one of the baselines
#: (docs/line-run.md, "The baseline")
DriverKind = Literal["advised", "minimum-time", "human"]
DRIVERS: tuple[DriverKind, ...] = get_args(DriverKind)
#: the baselines, in the order the KPI object gives them
BASELINES: tuple[DriverKind, ...] = ("minimum-time", "human")
#: the simulation core's step [s] (the ATO's control period is its own)
DEFAULT_DT_S = 0.1
#: target ids the driver gives the stops it makes itself (the link's are below 2^32)
CAB_SIGNAL_ID = 0
FAILURE_STOP_ID = 2**32
#: a train at rest this close short of a stop it knows of is held there [m] (farther:
#: nothing holds it, it goes on)
HELD_WITHIN_M = 10.0
#: the onboard powers up, and the train is placed at its origin, this long before its
#: first departure [s]
POWER_ON_LEAD_S = 120.0
#: the simulation core keeps a row a second (its cheap calling convention; the rows
#: themselves are not used)
RECORD_EVERY_S = 1.0
#: what the link asks where the train is, it is told as of the last whole second: the
#: onboard's odometry as its 1 s control cycle sampled it (one call into the core per
#: second and train, not one per frame)
ODOMETRY_CYCLE_S = 1.0


@lru_cache(maxsize=512)
def shared_route(
    line: RailLine,
    preset_name: str,
    from_id: int,
    to_id: int,
    margin: float,
    model: str = "point-mass",
) -> StationRoute:
    """One station pair's route, shared by every train of that kind and ``model`` (its
    line tables are cached on it)."""
    preset = train_preset(preset_name)
    return station_route(line, preset, from_id, to_id, margin, (), (), 0.0, model)


@lru_cache(maxsize=512)
def _controller(
    line: RailLine, preset_name: str, from_id: int, to_id: int, margin: float, dt_s: float
) -> PredictiveStop:
    """The precise-stop controller of a station pair, its line profile to the station
    (every stepper takes its own copy of the parameters; target stops retarget it)."""
    route = shared_route(line, preset_name, from_id, to_id, margin)
    return stop_controller(route.preset, route.vehicle_line, route.length_m, dt_s)


@lru_cache(maxsize=512)
def fastest_run(
    line: RailLine, preset_name: str, from_id: int, to_id: int, margin: float
) -> SpeedPlan:
    """The fastest run the onboard can plan between two stations (no TSR, no target
    point): distance from the departure stop and speed."""
    route = shared_route(line, preset_name, from_id, to_id, margin)
    _, sec = route.section_from(route.mrsp_at(0.0), 0.0, 0.0)
    return fastest(route.preset.driving, sec)


@lru_cache(maxsize=1024)
def planned_run(
    line: RailLine,
    preset_name: str,
    from_id: int,
    to_id: int,
    margin: float,
    running_time_s: float,
) -> SpeedPlan:
    """The plan the driving system departs on between two stations for ``running_time_s``
    [s] when nothing restricts it (no TSR, no target point): distance from the departure
    stop and speed."""
    route = shared_route(line, preset_name, from_id, to_id, margin)
    end_s, sec = route.section_from(route.mrsp_at(0.0), 0.0, 0.0)
    return route.plan_to(end_s, sec, running_time_s, 0.0)


@lru_cache(maxsize=512)
def planned_running_time_s(
    line: RailLine, preset_name: str, from_id: int, to_id: int, margin: float, supplement: float
) -> float:
    """The timetable's running time of a station pair [s]: the fastest run the onboard can
    plan (:func:`fastest_run`) plus ``supplement``, rounded up to 10 s (the rule of the
    shipped timetable, line/data/heavy_haul_timetable.toml)."""
    quickest = fastest_run(line, preset_name, from_id, to_id, margin).running_time_s
    return 10.0 * math.ceil(quickest * (1.0 + supplement) / 10.0)


@dataclass(frozen=True)
class Stop:
    """A station of a train's timetable, with its planned arrival and departure [s since
    the start of the run] (``nan``: none, at the origin and the destination)."""

    station: int
    arrival_s: float
    departure_s: float


@dataclass(frozen=True)
class Service:
    """One train's timetable: who it is and where and when it stops."""

    train_id: int
    number: str
    kind: str  # a shipped train (onboard/shipped_trains.py)
    stops: tuple[Stop, ...]
    min_dwell_s: float = 60.0

    @property
    def direction(self) -> TravelDirection:
        return UP if self.stops[-1].station > self.stops[0].station else TravelDirection.DOWN

    @property
    def power_on_s(self) -> float:
        """When the onboard powers up and the train is placed at its origin [s since the
        start of the run]."""
        return max(self.stops[0].departure_s - POWER_ON_LEAD_S, 0.0)


@dataclass
class SectionRun:
    """What happened on one station pair (the KPIs are computed from these)."""

    from_station: int
    to_station: int
    planned_departure_s: float
    planned_arrival_s: float
    departure_s: float
    arrival_s: float = math.nan
    energy_traction_kwh: float = 0.0
    energy_regenerated_kwh: float = 0.0
    #: of the traction energy, what pulled against the air brake (sim/result.py)
    energy_traction_against_air_kwh: float = 0.0
    stops_at_red: int = 0
    replans: int = 0
    #: the running time the train planned the section for [s]: the timetable's, or the
    #: ground's re-timing (its last, if it came while the train ran the section)
    target_running_time_s: float = math.nan

    @property
    def planned_running_time_s(self) -> float:
        return self.planned_arrival_s - self.planned_departure_s

    @property
    def running_time_s(self) -> float:
        return self.arrival_s - self.departure_s


@dataclass
class _Running:
    """The section being driven: its route, the simulation core and the plan's time."""

    route: StationRoute
    stepper: Stepper | ConsistDrive
    t0: float  # the stepper's time 0 [s since the start of the run]
    running_time_s: float
    mrsp: Mrsp
    record: SectionRun
    stopped: bool = False  # at rest short of the station (a red signal, a failure)
    #: the plan tracked: its curve, where it starts and ends [m from the departure stop]
    #: (None: a stand, no plan)
    plan: tuple[SpeedPlan, float, float] | None = None


@dataclass
class TrainDriver:
    """One train through its timetable (module docstring). A ``Mover`` for LinkSim."""

    line: RailLine
    service: Service
    epoch_s: float
    #: when the onboard unit comes up [s since the start of the run]
    power_on_s: float
    advised: bool = True
    margin_kmh: float = DEFAULT_MARGIN_KMH
    dt_s: float = DEFAULT_DT_S
    #: what follows the plan: the point mass with the precise-stop ATO, or the consist
    model: str = "point-mass"
    #: the human driver's habits (module docstring): with ``advised=False``, the human
    #: baseline instead of the minimum-time one
    human: HumanDriving | None = None
    sections: list[SectionRun] = field(default_factory=list)
    #: red-signal stops (cab signal or target point), failure stands excluded
    red_signal_stops: int = 0
    #: the running times the ground sent [s] by station pair (its last for each)
    running_times: dict[tuple[int, int], float] = field(default_factory=dict)
    #: how many ``RunningTimes`` messages changed a running time it held (a message is
    #: sent again on every registration)
    running_times_received: int = 0

    def __post_init__(self) -> None:
        if self.human is not None and self.advised:
            raise ConfigError("human", self.human, "None for the advised driver")
        self.preset: TrainPreset = train_preset(self.service.kind)
        self.direction: TravelDirection = self.service.direction
        self._sign = direction_sign(self.direction)
        self._k = 0  # index of the stop the train is at or departs from
        self._running: _Running | None = None
        self.finished = False
        self.tsrs: dict[int, AppliedTsr] = {}
        self._target: TargetPoint | None = None
        self._cab_red_m: float | None = None
        self._cab_sight_m: float | None = None
        self._failure_m: float | None = None
        self._held = False  # at a stop whose way out is held
        self._released_s = -math.inf  # when it was last let go (its departure, if held)
        self._reporter = PlannedCurveReporter()
        #: when the human driver acts on what changed last (None: nothing to act on)
        self._react_at_s: float | None = None
        static = shared_route(self.line, self.service.kind, *self._pair(0), self.margin_kmh).static
        top = float(np.max(static.speeds_mps[np.isfinite(static.speeds_mps)]))
        self._safety_m = float(safety_distance_m(top, self.preset.train.max_service_decel_mps2))

    # ------------------------------------------------------------------ where it is

    @property
    def train_id(self) -> int:
        return self.service.train_id

    @property
    def on_line(self) -> bool:
        return not self.finished

    def state(self, elapsed_s: float) -> tuple[float, float]:
        """``(km post [m], speed [m/s])`` of the head ``elapsed_s`` after power-on, as the
        onboard's last control cycle measured it (``ODOMETRY_CYCLE_S``)."""
        return self.at(_last_cycle_s(self.power_on_s + elapsed_s))

    def at(self, t: float) -> tuple[float, float]:
        """``(km post [m], speed [m/s])`` of the head at ``t`` [s since the start]."""
        self.advance(t)
        return self.at_last()

    def at_last(self) -> tuple[float, float]:
        """``(km post [m], speed [m/s])`` as far as the train has been driven (no step)."""
        running = self._running
        if running is None:
            station = self.line.station(self.service.stops[self._k].station)
            return station.stop_m(self.direction), 0.0
        stepper = running.stepper
        # km_post_m's arithmetic on one float (asked for every train several times a second)
        head = running.route.departure_m + self._sign * stepper.position_m
        return float(head), stepper.speed_mps

    def due_to_move(self, t: float) -> bool:
        """Should the train be moving at ``t`` [s since the start] as far as its timetable
        and the scenario go: on the line, not before its departure from the stop it
        stands at, not stood by a failure. (A red signal ahead is the trackside's to say.)"""
        if self.finished or self._failure_m is not None:
            return False
        return self._running is not None or t >= self._departure_s()

    def next_stop_m(self) -> float:
        """Km post [m] of the station the train stops at next: the next one of its
        timetable, also while it stands at one (its exit signal is ahead of it), or its
        destination once there."""
        k = self._k + 1
        station = self.line.station(self.service.stops[min(k, len(self.service.stops) - 1)].station)
        return station.stop_m(self.direction)

    # ------------------------------------------------------------------ time goes on

    def advance(self, t: float) -> None:
        """Drive on to ``t`` [s since the start]: depart, run, arrive, as the timetable
        and the train allow; a human driver acts on what changed when its reaction time
        is up."""
        while self._react_at_s is not None and self._react_at_s <= t:
            react_at, self._react_at_s = self._react_at_s, None
            self.replan(react_at)
        self._drive_to(t)

    def _drive_to(self, t: float) -> None:
        while not self.finished:
            running = self._running
            if running is None:
                departure = self._departure_s()
                if t < departure or self._held:
                    return
                start = max(departure, self._released_s)
                if not self._depart(start):
                    # the way out is held (a failure): it departs when what it knows
                    # changes (replan) and lets it
                    self._held = True
                    return
                continue
            if running.stopped:
                running.stepper.advance_to(t - running.t0)  # standing
                return  # held at a red signal or a failure, until it clears
            stepper = running.stepper
            stepper.advance_to(t - running.t0)
            if not stepper.at_rest:
                if stepper.step >= stepper.n_steps:
                    raise ConfigError(
                        f"train {self.train_id}",
                        f"{running.record.from_station}->{running.record.to_station}",
                        "a section the simulation core finishes in its time",
                    )
                return
            to_go = running.route.length_m - stepper.position_m
            if to_go <= ARRIVED_WITHIN_M:
                self._arrive(running.t0 + stepper.stop_time_s)
                continue
            running.stopped = True
            running.record.stops_at_red += int(self._failure_m is None)
            self.red_signal_stops += int(self._failure_m is None)
            position = stepper.position_m
            if running.route.next_stop_s(running.mrsp, position) - position < HELD_WITHIN_M:
                return  # held at a red signal or a failure, until it clears (replan)
            # Nothing it knows holds it here: the red cleared while it was braking for it
            # and the air brake, still releasing, brought it to rest. It goes on now (it
            # waited for a change that had already come: 39 min in one baseline run).
            self._follow(running, running.t0 + stepper.stop_time_s)

    def _pair(self, k: int) -> tuple[int, int]:
        stops = self.service.stops
        return stops[k].station, stops[k + 1].station

    def _departure_s(self) -> float:
        """When the train leaves its stop: its timetable, and not before its minimum dwell
        after a late arrival."""
        stop = self.service.stops[self._k]
        if not self.sections:
            return stop.departure_s
        return max(stop.departure_s, self.sections[-1].arrival_s + self.service.min_dwell_s)

    def _depart(self, t: float) -> bool:
        """Leave the stop at ``t`` on a plan of what the train knows; False if it may not
        move at all (its way out is held)."""
        k = self._k
        from_id, to_id = self._pair(k)
        route = shared_route(
            self.line, self.service.kind, from_id, to_id, self.margin_kmh, self.model
        )
        stops = self.service.stops
        planned = self.running_times.get(
            (from_id, to_id), stops[k + 1].arrival_s - stops[k].departure_s
        )
        record = SectionRun(from_id, to_id, stops[k].departure_s, stops[k + 1].arrival_s, t)
        record.target_running_time_s = planned
        mrsp = self._mrsp(route, t)
        end_s, sec = route.section_from(mrsp, 0.0, 0.0)
        if not np.any(sec.ceiling_mps > 0.0):
            return False
        curve = self._curve(route, end_s, sec, planned, 0.0)
        stepper = plan_follower(
            self.preset,
            route.vehicle_line,
            curve,
            end_s,
            self.dt_s,
            3.0 * planned + 3_600.0,
            model=self.model,
            controller=_controller(
                self.line, self.service.kind, from_id, to_id, self.margin_kmh, self.dt_s
            ),
            record_every_s=RECORD_EVERY_S,
        )
        self._running = _Running(route, stepper, t, planned, mrsp, record, plan=(curve, 0.0, end_s))
        return True

    def _arrive(self, t: float) -> None:
        running = self._running
        assert running is not None
        record = running.record
        record.arrival_s = t
        metrics = running.stepper.result().metrics
        record.energy_traction_kwh += float(metrics["energy_traction_kwh"])
        record.energy_regenerated_kwh += float(metrics["energy_regenerated_kwh"])
        record.energy_traction_against_air_kwh += float(metrics["energy_traction_against_air_kwh"])
        self.sections.append(record)
        self._running = None
        self._k += 1
        if self._k >= len(self.service.stops) - 1:
            self.finished = True

    # ------------------------------------------------------------------ what it is told

    def on_event(self, event: Event, now_s: float) -> None:
        """An onboard event of the link (LinkSim's ``on_event``)."""
        t = now_s - self.epoch_s
        if isinstance(event, TsrApplied):
            self.tsrs[event.tsr.session] = event.tsr
        elif isinstance(event, TsrCancelled | TsrExpired):
            self.tsrs.pop(event.session, None)
        elif isinstance(event, TargetPointReceived) and self.advised:
            target = event.target
            self._target = None if is_clear(target, self.line) else target
        elif isinstance(event, MessageReceived) and isinstance(event.message, RunningTimes):
            self._new_running_times(event.message, t)
            return
        else:
            return
        self._notice(t)

    def _notice(self, t: float) -> None:
        """What the driver is told changed at ``t``: it plans again now, or, a human
        driver, its reaction time later (what it knows then)."""
        if self.human is None:
            self.replan(t)
            return
        self.advance(t)
        if self._react_at_s is None:
            self._react_at_s = t + self.human.reaction_s

    def _new_running_times(self, message: RunningTimes, t: float) -> None:
        """The ground re-timed the train: the sections ahead are planned for its times,
        and so is the one being run if the message has it (module docstring)."""
        new_times = {(t.from_station_id, t.to_station_id): t.running_time_s for t in message.times}
        if all(self.running_times.get(pair) == r for pair, r in new_times.items()):
            return  # the same again (sent on a registration)
        self.running_times_received += 1
        self.running_times.update(new_times)
        self.advance(t)
        running = self._running
        if running is None:
            return
        record = running.record
        new = self.running_times.get((record.from_station, record.to_station))
        if new is None or new == running.running_time_s:
            return
        running.running_time_s = record.target_running_time_s = new
        if not running.stopped:
            self._follow(running, t)

    # ------------------------------------------------------------------ what it tells

    def planned_curve_report(self, t: float) -> CurveReport | None:
        """The planned-curve report due at ``t`` (None: none due; the baseline sends
        none): the section run or just arrived from, the time run and the time its plan
        still needs (module docstring)."""
        if not self.advised:
            return None
        # as of the onboard's last control cycle, as its odometry (``state``): the core is
        # stepped once a second, not again at each report's instant
        seen = _last_cycle_s(t)
        self.advance(seen)
        running = self._running
        if running is not None:
            record = running.record
            elapsed = max(seen - record.departure_s, 0.0)
            remaining = self._remaining_s(running)
        elif self.sections:
            record = self.sections[-1]
            elapsed, remaining = record.running_time_s, 0.0
        else:
            return None  # not yet departed: the timetable stands
        return self._reporter.update(record.from_station, record.to_station, elapsed, remaining, t)

    @staticmethod
    def _remaining_s(running: _Running) -> float:
        position = running.stepper.position_m
        length = running.route.length_m
        pace = running.running_time_s / length  # [s/m]
        if running.plan is None:
            return (length - position) * pace
        curve, s0, end_s = running.plan
        to_go = remaining_time_s(curve, position - s0)
        return to_go + max(length - max(end_s, position), 0.0) * pace

    def cab_signal(self, red_signal_m: float | None, sight_m: float, t: float) -> None:
        """The aspect of the signals ahead from the track (module docstring): the km post
        of the red one within sight [m] or None, and of the last signal in sight [m].

        The track outranks the radio for the signals it shows: a target point whose
        signal the cab shows not at red is stale (its clear lost, the train in a dead
        zone) and no longer held.
        """
        before = self._stops_known()
        self._cab_red_m = red_signal_m
        self._cab_sight_m = sight_m
        if self._stops_known() != before:
            self._notice(t)

    def fail(self, t: float) -> None:
        """The train fails at ``t``: it brakes to a stand at a full-service stop."""
        pos, speed = self.at(t)
        decel = self.preset.train.max_service_decel_mps2
        ahead = speed * speed / decel + 10.0 * speed + 1.0
        sign = self._sign
        self._failure_m = pos + sign * ahead
        self.replan(t)

    def recover(self, t: float) -> None:
        """The failure is repaired at ``t``: the train goes on."""
        self._failure_m = None
        self.replan(t)

    def _in_sight(self, signal_m: float) -> bool:
        """Is the signal at ``signal_m`` [m] one the cab signal knows: in sight ahead, or
        behind the head (a target the ground set behind the train on its lagging view)?"""
        if self._cab_sight_m is None:
            return False
        head, _ = self.at_last()
        sign = self._sign
        return sign * (signal_m - head) <= sign * (self._cab_sight_m - head)

    def _stops_known(self) -> tuple[TargetStop, ...]:
        stops = []
        target = self._target
        if target is not None and not (
            self._in_sight(target.position_m) and target.position_m != self._cab_red_m
        ):
            stops.append(TargetStop.from_target_point(target, self._safety_m, self.direction))
        if self._cab_red_m is not None:
            cab = TargetPoint(CAB_SIGNAL_ID, self._cab_red_m, TargetReason.TRAIN_AHEAD)
            stops.append(TargetStop.from_target_point(cab, self._safety_m, self.direction))
        if self._failure_m is not None:
            stops.append(TargetStop(self._failure_m, FAILURE_STOP_ID))
        return tuple(stops)

    def _mrsp(self, route: StationRoute, t: float) -> Mrsp:
        now = self.epoch_s + t
        # obeyed from arrival until expiry, before its validity starts too: the safe side,
        # and nothing would re-plan the train at the start (its end: TsrExpired)
        tsrs = [tsr for tsr in self.tsrs.values() if now < tsr.valid_until_s]
        return most_restrictive_profile(
            route.static, tsrs, self._stops_known(), direction=self.direction
        )

    def _curve(
        self, route: StationRoute, end_s: float, sec: Any, time_s: float, s0: float
    ) -> SpeedPlan:
        if self.advised:
            return route.plan_to(end_s, sec, time_s, s0)
        if self.human is not None:
            preset = route.preset
            return human_curve(
                preset.driving,
                sec,
                self.human,
                planned_margin_mps=route.margin_mps,
                stop_net_mps2=route.stop_net_mps2(end_s),
                release_s=sum(preset.brake.air.train_release_lead_s(preset.train.length_m)),
            )
        return route.fastest_to(end_s, sec)

    def replan(self, t: float) -> None:
        """What the train knows changed at ``t``: plan again from where it is (as
        ``drive`` does at its events)."""
        self.advance(t)
        running = self._running
        if running is None:
            # at a station: the departure plans with what it knows then
            if self._held:
                self._held, self._released_s = False, t
            self.advance(t)
            return
        new = self._mrsp(running.route, t)
        if new == running.mrsp:
            return
        running.mrsp = new
        self._follow(running, t)

    def _follow(self, running: _Running, t: float) -> None:
        """Plan from where the train is at ``t`` to what its MRSP lets it reach, and track
        that (from rest: start again)."""
        stepper = running.stepper
        new = running.mrsp
        s_now, v_now = stepper.position_m, stepper.speed_mps
        route = running.route
        to_stop = route.next_stop_s(new, s_now) - s_now
        if to_stop <= 0.0:
            # past the point it stops at, in the last centimetres of a precise stop (it
            # lands within its tolerance either side): the stop in progress ends it, and
            # nothing is left to plan (it was planned, and the planner refused the
            # backward section: one 60-train day stopped there)
            return
        if to_stop < 1.0 and running.stopped:
            return  # held where it stands
        end_s, sec = route.section_from(new, s_now, v_now)
        profile = None
        if np.any(sec.ceiling_mps > 0.0):
            elapsed = t - running.record.departure_s
            remaining = max(running.running_time_s - elapsed, 1.0)
            curve = self._curve(route, end_s, sec, remaining, s_now)
            try:
                profile = PlannedProfile(curve.s_m + s_now, curve.speed_mps)
                running.plan = (curve, s_now, end_s)
            except ConfigError:
                # a plan that comes to rest short of its end (a train creeping onto a
                # stop just ahead): nothing to track but a stand
                profile = None
        if profile is None:
            # nothing ahead may be entered (a failure where it stands, a red signal it is
            # already past on the ground's lagging view): brake to a stand now
            if v_now <= 0.0:
                # at rest: it stands here. It may have been setting off on a plan made a
                # moment before (the exit signal turned red in the second it departed:
                # it went on to pass it at red, before this hold)
                stepper.hold()
                running.stopped = True
                running.plan = None
                return
            end_s, (s_stand, v_stand) = _stand_curve(
                s_now, v_now, self.preset.train.max_service_decel_mps2
            )
            profile = PlannedProfile(s_stand, v_stand)
            running.plan = None
        follow_plan(stepper, profile, end_s)
        running.record.replans += 1
        if running.stopped:
            stepper.restart()
            running.stopped = False


def _last_cycle_s(t: float) -> float:
    """The start of the onboard's control cycle that ``t`` [s] falls in (its odometry's
    sample, ``ODOMETRY_CYCLE_S``)."""
    return math.floor(t / ODOMETRY_CYCLE_S + 1e-9) * ODOMETRY_CYCLE_S


def _stand_curve(
    s_m: float, v_mps: float, decel_mps2: float
) -> tuple[float, tuple[np.ndarray, np.ndarray]]:
    """A braking curve from ``s_m`` at ``v_mps`` to a stand at ``decel_mps2`` [m/s^2] (half
    the full service: the train brakes firmly, not in emergency), and where it ends."""
    b = 0.5 * decel_mps2
    length = v_mps * v_mps / (2.0 * b)
    s = np.linspace(0.0, length, 64)
    v = np.sqrt(np.maximum(v_mps * v_mps - 2.0 * b * s, 0.0))
    v[-1] = 0.0
    return s_m + length, (s + s_m, v)
