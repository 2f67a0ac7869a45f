"""A whole line in simulated time: trains, ground and radio together, and what it gives
(paper 001's KPIs; docs/line-run.md).

:func:`run_line` puts a scenario's trains (:class:`~railpilot.cosim.driver.TrainDriver`,
the onboard driving system and the simulation core) and the ground (the dispatch core and
its link endpoints) into one :class:`~railpilot.cosim.link_sim.LinkSim`, plays the
scenario's events, and watches the line from the trackside once a second: where every
train is, the signals' aspects (the cab signal each train sees), and every TSR and red
signal against what the trains do. The KPIs come from what was watched, not from what
the trains or the ground believe.

The KPIs (paper 001's and the operator's) are one table, cosim/kpis.py; a result's
:meth:`LineResult.kpis` is its KPI object.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railpilot.errors import ConfigError, RunFailed
from railpilot.ground.assembly import GroundParts
from railpilot.ground.store import AuditEntry, Snapshot, Store
from railpilot.link import GroundConfig, KeyStore, OnboardConfig
from railpilot.link.keys import seeded_test_keys as loadtest_keys
from railpilot.units import hms

from .driver import DRIVERS, DriverKind, SectionRun, Service, TrainDriver
from .human_driver import DEFAULT_HUMAN, HumanDriving
from .kpis import ON_TIME_WITHIN_MIN, kpi_object, punctuality
from .link_sim import LinkSim, SimTrain
from .retimer_factory import retimer_factory
from .scenario import GroundRestart, LineScenario, ScenarioEvent, TrainFailure
from .stall import DEFAULT_STALL_S, StallWatch, Standing, TrainAt
from .trackside import Trackside, TrainSeen, TrainShape, static_overspeeds

#: how often the trackside looks [s] (the link's cycle)
WATCH_S = 1.0
#: a dispatcher's operation that finds the ground down is tried again this much later [s]
RETRY_WHILE_DOWN_S = 10.0
#: the keys of a dispatcher's operation's answer that are times on the ground's clock [s
#: since its epoch] (ground/dispatch.py: a TSR set answers when it holds)
GROUND_CLOCK_KEYS = frozenset({"valid_from_s", "valid_until_s"})

__all__ = [
    "ON_TIME_WITHIN_MIN",
    "LineResult",
    "LiveRunInfo",
    "Overspeed",
    "SignalPassedAtRed",
    "TrainRun",
    "TsrViolation",
    "line_keys",
    "line_train",
    "punctuality",
    "run_line",
]


@dataclass(frozen=True)
class TsrViolation:
    """A train faster than a TSR's limit in its stretch during its validity, as the
    trackside saw it first for this (train, TSR) pair (trackside.py)."""

    train: int
    #: the TSR's session
    session: int
    #: when [s since the run's start]
    t_s: float
    #: which ends of the train were in the stretch: "head", "tail"
    at: list[str]
    speed_kmh: float
    limit_kmh: float


@dataclass(frozen=True)
class SignalPassedAtRed:
    """A signal a train's head passed while another train held the block beyond (a
    target point passed; trackside.py)."""

    train: int
    #: when [s since the run's start]
    t_s: float
    #: the signal's km post [km]
    signal_km: float
    #: the block beyond it and the trains that held it
    block: str
    held_by: list[int]


@dataclass(frozen=True)
class Overspeed:
    """A spell in which a moving train was faster than the static limit along it
    (trackside.py ``static_overspeeds``): its first and last look and its worst look
    [s since the run's start], where the head was then [km], the speed, the limit and the
    excess [km/h]."""

    train: int
    from_s: float
    to_s: float
    t_s: float
    head_km: float
    speed_kmh: float
    limit_kmh: float
    excess_kmh: float


@dataclass(frozen=True)
class LiveRunInfo:
    """What a live run (cosim/live.py) adds to its result: its time scale [simulated s
    per wall-clock s] and what the dashboard's screenshot gave (None: none asked for)."""

    speedup: float
    screenshot: dict[str, Any] | None


@dataclass
class TrainRun:
    """A train as the KPIs read it: its timetable, the sections it ran, whether it reached
    its destination, how often it stopped at red and how many re-timings changed its plan.

    A co-simulated train's (:meth:`of` its driver at the end of the run) or a live train's
    report (cosim/live.py). Plain data: a result holds no simulation core, so it pickles
    (a sweep's worker sends its result back) and a study can keep many of them.
    """

    service: Service
    sections: list[SectionRun]
    finished: bool
    red_signal_stops: int
    running_times_received: int
    #: the running times the ground sent [s] by station pair (its last for each)
    running_times: dict[tuple[int, int], float] = field(default_factory=dict)

    def arrival_delays_s(self, end_s: float) -> list[float | None]:
        """Each arrival at a stop of the timetable, in order, that the train made or
        that was due by ``end_s`` [s since the start of the run]: how late it came [s,
        negative: early], or None for one due that it had not made by then (a train held
        up, or failed, is late, not left out)."""
        delays: list[float | None] = []
        for k, stop in enumerate(self.service.stops[1:]):
            section = self.sections[k] if k < len(self.sections) else None
            if section is not None and math.isfinite(section.arrival_s):
                delays.append(section.arrival_s - section.planned_arrival_s)
            elif stop.arrival_s <= end_s:
                delays.append(None)
        return delays

    @classmethod
    def of(cls, driver: TrainDriver) -> TrainRun:
        """What ``driver`` ran, copied (the driver and its core can then go)."""
        return cls(
            driver.service,
            list(driver.sections),
            driver.finished,
            driver.red_signal_stops,
            driver.running_times_received,
            dict(driver.running_times),
        )


@dataclass
class LineResult:
    """One run of a line scenario: the drivers (their sections), the trackside's samples,
    the link's counters, and the KPIs (:meth:`kpis`)."""

    scenario: LineScenario
    seed: int
    #: who drove: ``"advised"``, ``"minimum-time"`` or ``"human"``
    driver: DriverKind
    drivers: Mapping[int, TrainRun]
    trace: dict[int, np.ndarray]  # train id -> rows (t [s], km post [m], speed [m/s])
    tsr_violations: list[TsrViolation]
    signals_passed_at_red: list[SignalPassedAtRed]
    #: spells above the static limits (trackside.py ``static_overspeeds``)
    overspeeds: list[Overspeed]
    link: dict[str, Any]
    tsr_applied: dict[int, dict[int, int]]  # train -> session -> times applied
    wall_s: float
    events: list[dict[str, Any]] = field(default_factory=list)
    #: the ground's restarts (LinkSim.restarts)
    restarts: list[dict[str, Any]] = field(default_factory=list)
    #: the ground's store at the end of the run: its audit log and what it holds
    audit_log: list[AuditEntry] = field(default_factory=list)
    ground_store: Snapshot | None = None
    #: the TSR sessions each train's onboard holds at the end of the run
    onboard_tsrs: dict[int, list[int]] = field(default_factory=dict)
    #: where the run stopped [s since its start] (None: the scenario's end)
    end_s: float | None = None
    #: a live run's (cosim/live.py): its time scale and the dashboard's screenshot
    live: LiveRunInfo | None = None
    #: the ground's re-timings (ground/online_retimer.py ``OnlineRetimer.log``)
    retiming: list[dict[str, Any]] = field(default_factory=list)

    @property
    def advised(self) -> bool:
        """Driven by the advised driving system (not a baseline)."""
        return self.driver == "advised"

    @property
    def sim_s(self) -> float:
        """Simulated time run [s]: the scenario's duration, or ``until_s`` if shorter."""
        return self.end_s if self.end_s is not None else self.scenario.duration_s

    def retimings(self) -> list[dict[str, Any]]:
        """The ground's re-timings with their times on the run's clock, as every other
        time of the results (``retiming`` keeps the ground's log as it is, on its own
        clock, ``scenario.epoch_s`` on)."""
        epoch = self.scenario.epoch_s
        return [{**e, "t_s": e["t_s"] - epoch} for e in self.retiming]

    def events_on_run_clock(self) -> list[dict[str, Any]]:
        """The scenario's events as played, with the times of the ground's answers on the
        run's clock, as every other time of the results (``events`` keeps each answer as
        the ground gave it: a TSR's ``valid_from_s``/``valid_until_s`` on its own clock,
        ``scenario.epoch_s`` on)."""
        epoch = self.scenario.epoch_s
        played = []
        for entry in self.events:
            answer = entry.get("result")
            if answer is not None:
                answer = {
                    key: value - epoch if key in GROUND_CLOCK_KEYS and value is not None else value
                    for key, value in answer.items()
                }
                entry = {**entry, "result": answer}
            played.append(entry)
        return played

    def kpis(
        self, baseline: LineResult | None = None, human: LineResult | None = None
    ) -> dict[str, Any]:
        """The KPI object of ``railpilot line simulate --json`` (cosim/kpis.py), the
        figures of the minimum-time ``baseline`` and of the ``human`` one beside it if
        given."""
        return kpi_object(self, baseline, human)


def line_train(
    scenario: LineScenario,
    service: Service,
    advised: bool,
    human: HumanDriving | None = None,
) -> tuple[TrainDriver, OnboardConfig]:
    """One train of ``scenario``: its driver (powered on, and placed at its origin, at
    ``service.power_on_s``; a baseline's driven by ``human`` if given) and its onboard
    unit's link configuration."""
    power_on = service.power_on_s
    driver = TrainDriver(
        scenario.line,
        service,
        scenario.epoch_s,
        power_on,
        advised=advised,
        margin_kmh=scenario.margin_kmh,
        model=scenario.train_model,
        human=human,
    )
    config = OnboardConfig(
        train_id=service.train_id,
        ground_id=1,
        train_number=service.number,
        loco_number=f"HXD1{service.train_id % 10000:04d}",
        driver_id=service.train_id,
        train_length_m=driver.preset.train.length_m,
    )
    return driver, config


def line_keys(scenario: LineScenario, seed: int) -> KeyStore:
    """The trains' link keys of a run (derived from its seed, as the load test's)."""
    ids = [s.train_id for s in scenario.services]
    return loadtest_keys(seed, range(min(ids), max(ids) + 1))


def run_line(
    scenario: LineScenario,
    *,
    seed: int | None = None,
    advised: bool = True,
    until_s: float | None = None,
    on_watch: Callable[[LinkSim, float], None] | None = None,
    driver: DriverKind | None = None,
    human: HumanDriving = DEFAULT_HUMAN,
    stall_after_s: float = DEFAULT_STALL_S,
) -> LineResult:
    """Run ``scenario`` (its seed unless ``seed``) to its end (or ``until_s``) with the
    ``driver``: ``"advised"`` (the driving system), ``"minimum-time"`` or ``"human"``
    (the baselines, docs/line-run.md; the human driver's habits ``human``). Without
    ``driver``, ``advised`` chooses: True the driving system, False the minimum-time
    baseline. A run whose trains stand still for ``stall_after_s`` [s] with nothing
    holding them ends with :class:`~railpilot.errors.RunFailed` (cosim/stall.py)."""
    if driver is None:
        driver = "advised" if advised else "minimum-time"
    elif driver not in DRIVERS:
        raise ConfigError("driver", driver, f"one of {', '.join(DRIVERS)}")
    elif not advised and driver == "advised":
        raise ConfigError("advised", advised, "True (or no driver) with driver='advised'")
    advised = driver == "advised"
    human_driver = human if driver == "human" else None
    seed = scenario.seed if seed is None else seed
    line = scenario.line
    epoch = scenario.epoch_s
    drivers: dict[int, TrainDriver] = {}
    trains = []
    for service in scenario.services:
        train, config = line_train(scenario, service, advised, human_driver)
        drivers[service.train_id] = train
        trains.append(
            SimTrain(config, train, train.power_on_s, train.on_event, train.planned_curve_report)
        )
    keys = line_keys(scenario, seed)
    # the ground keeps its TSRs, deliveries and audit log in a store, as the live ground
    # does (in memory: it outlives the simulated ground process, not this one)
    store = Store(":memory:", synchronous="NORMAL")
    # the baseline has no re-timing: the fixed plan
    retimings: list[dict[str, Any]] = []
    retimer = retimer_factory(scenario, retimings) if advised else None
    ground = GroundParts(
        GroundConfig(ground_id=1, timers=trains[0].config.timers), line, keys, store, retimer
    )
    sim = LinkSim.over(ground, trains, scenario.channel, seed=seed, start_s=epoch)
    watch = _Watch(sim, drivers, on_watch, stall_after_s)
    events: list[dict[str, Any]] = []
    for event in scenario.events:
        sim.call_at(event.at_s, _event_action(sim, drivers, watch, event, events))
    sim.call_at(WATCH_S, watch)
    started = time.perf_counter()
    end = scenario.duration_s if until_s is None else min(until_s, scenario.duration_s)
    sim.run_until(end)
    wall = time.perf_counter() - started
    audit_log, snapshot = store.audit_log(), store.load()
    store.close()
    traces = watch.trackside.traces()
    return LineResult(
        scenario,
        seed,
        driver,
        {i: TrainRun.of(driver) for i, driver in drivers.items()},
        traces,
        [TsrViolation(**seen) for seen in watch.trackside.tsr_violations],
        [SignalPassedAtRed(**seen) for seen in watch.trackside.passed_at_red],
        [
            Overspeed(**spell)
            for spell in static_overspeeds(scenario.line, traces, watch.trackside.trains)
        ],
        sim.link_report(),
        {i: dict(s.tsr_applied) for i, s in sim.stats.items()},
        wall,
        events,
        sim.restarts,
        audit_log,
        snapshot,
        {i: sorted(endpoint.active_tsrs) for i, endpoint in sim.onboard.items()},
        end,
        retiming=retimings,
    )


def _event_action(
    sim: LinkSim,
    drivers: dict[int, TrainDriver],
    watch: _Watch,
    event: ScenarioEvent,
    log: list[dict[str, Any]],
) -> Callable[[], None]:
    def act() -> None:
        t = sim.now_s - sim.start_s
        action = event.action
        entry: dict[str, Any] = {"t_s": t, "event": event.label}
        if isinstance(action, TrainFailure):
            driver = drivers[action.train_id]
            driver.fail(t)
            sim.call_at(t + action.stand_s, lambda: driver.recover(sim.now_s - sim.start_s))
            entry["train"] = action.train_id
        elif isinstance(action, GroundRestart):
            sim.restart_ground(action.down_s)
            entry["down_s"] = action.down_s
        elif not sim.ground_up:
            # the dispatcher's operation waits for the ground to be back
            sim.call_at(t + RETRY_WHILE_DOWN_S, act)
            return
        else:
            outcome = sim.operate(action, "scenario")
            entry["result"] = outcome.result
            tsr = watch.trackside.dispatched(action, outcome.result, sim.now_s, sim.start_s)
            if tsr is not None:
                entry["tsr"] = tsr
        log.append(entry)

    return act


def _stalled_message(standing: list[Standing], t: float, stall_s: float) -> str:
    trains = ", ".join(
        f"train {s.train_id} at km {s.head_m / 1000.0:.3f} since {hms(s.since_s)}" for s in standing
    )
    return (
        f"the run stands still at {hms(t)} (h:mm:ss from its start): {trains}; each has "
        f"stood {stall_s / 60.0:g} min or more where neither its timetable nor a scenario "
        "event holds it (trains holding one another's block sections, or a train stopped "
        "short of its station)"
    )


class _Watch:
    """The co-simulation's trackside: once a second, every train's true position from its
    driver, handed to the :class:`~railpilot.cosim.trackside.Trackside` at one instant;
    its cab views back to the drivers; a train at its destination retired from the link."""

    def __init__(
        self,
        sim: LinkSim,
        drivers: dict[int, TrainDriver],
        on_watch: Callable[[LinkSim, float], None] | None,
        stall_s: float = DEFAULT_STALL_S,
    ) -> None:
        self.sim = sim
        self.drivers = drivers
        self.on_watch = on_watch
        self.stalls = StallWatch(stall_s)
        self.trackside = Trackside(
            sim.line,
            {
                i: TrainShape(d.direction, d.preset.train.length_m, d.preset.category)
                for i, d in drivers.items()
            },
        )
        self._retired: set[int] = set()

    def __call__(self) -> None:
        sim = self.sim
        t = sim.now_s - sim.start_s
        seen: dict[int, TrainSeen] = {}
        for train_id, driver in self.drivers.items():
            if train_id in self._retired or t < driver.power_on_s:
                continue
            head, speed = driver.at(t)
            if driver.finished:
                # arrived at its destination: it leaves the line and the ground
                self._retired.add(train_id)
                sim.retire(train_id)
                continue
            seen[train_id] = TrainSeen(head, speed, driver.next_stop_m())
        for train_id, view in self.trackside.look(t, sim.now_s, seen).items():
            self.drivers[train_id].cab_signal(view.red_signal_m, view.sight_m, t)
        standing = self.stalls.look(
            t,
            {
                i: TrainAt(at.head_m, self.drivers[i].direction, self.drivers[i].due_to_move(t))
                for i, at in seen.items()
            },
        )
        if standing:
            raise RunFailed(_stalled_message(standing, t, self.stalls.stall_s))
        if self.on_watch is not None:
            self.on_watch(sim, t)
        sim.call_at(t + WATCH_S, self)
