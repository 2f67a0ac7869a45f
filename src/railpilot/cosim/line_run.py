"""A whole line in simulated time: trains, ground and radio together, and what it gives
(paper 001's KPIs; issue 12; docs/line-run.md).

:func:`run_line` puts a scenario's trains (:class:`~railpilot.cosim.driver.TrainDriver`,
the onboard driving system and the simulation core) and the ground (the dispatch core and
its link endpoints) into one :class:`~railpilot.cosim.link_sim.LinkSim`, plays the
scenario's events, and watches the line from the trackside once a second: where every
train is, the signals' aspects (the cab signal each train sees), and every TSR and red
signal against what the trains do. The KPIs come from what was watched, not from what
the trains or the ground believe.

KPIs (paper 001 tables 2 and 3; docs/line-run.md "KPIs"):

``conformity_pct``
    running-time conformity ``(actual - planned) / planned * 100`` per section and end to
    end (the origin's departure to the destination's arrival), per train and overall.
``energy_kwh``
    net traction energy (traction less regeneration) per train and in total;
    ``baseline_energy_kwh`` is the same day driven by the baseline (no advice, no
    re-timing: :func:`run_line` with ``advised=False``).
``energy_traction_against_air_kwh``
    of the traction energy drawn, what pulled against the air brake still applied (the
    smaller of the two forces while both act; a loaded train's air brake takes about a
    minute to release), per train and in total.
``red_signal_stops``
    the trains' stops at red signals (at rest short of the station).
``tsr_violations``
    (train, TSR) pairs where the head or the tail was in the restricted stretch, during
    its validity, faster than the limit, at any sample (every second).
``target_points_passed``
    signals a train's head passed while the block beyond was held by another train (at
    red), checked every second against the previous second's occupancy.
``overspeeds``
    spells (consecutive samples, every second) in which a moving train was faster than
    the line's static limit for its category anywhere between its tail and its head
    (trackside.py ``static_overspeeds``); ``max_overspeed_kmh`` the worst excess, per
    train and overall.
``link``
    the link's counters (frames, losses by cause, resends, timeouts, rejections by check).

Besides paper 001's, the operator's: ``punctuality`` (:func:`punctuality`), every arrival
at a timetabled stop against the timetable (not against a re-timing), per train
(``arrival_delays_s``) and as shares on time within 1, 3 and 5 minutes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from railpilot.ground.retime import STATUS_FALLBACK
from railpilot.ground.store import AuditEntry, Snapshot, Store
from railpilot.link import KeyStore, OnboardConfig
from railpilot.net.loadtest import loadtest_keys

from .driver import SectionRun, Service, TrainDriver
from .link_sim import LinkSim, SimTrain
from .retiming import retimer_factory
from .scenario import GroundRestart, LineScenario, ScenarioEvent, TrainFailure
from .trackside import Trackside, TrainSeen, TrainShape, static_overspeeds

#: how often the trackside looks [s] (the link's cycle)
WATCH_S = 1.0
#: the onboard powers up this long before its first departure [s]
POWER_ON_LEAD_S = 120.0
#: a dispatcher's operation that finds the ground down is tried again this much later [s]
RETRY_WHILE_DOWN_S = 10.0
#: the keys of a dispatcher's operation's answer that are times on the ground's clock [s
#: since its epoch] (ground/dispatch.py: a TSR set answers when it holds)
GROUND_CLOCK_KEYS = frozenset({"valid_from_s", "valid_until_s"})
#: punctuality: an arrival at most this many minutes after the timetable is on time (one
#: share each; an early arrival is on time)
ON_TIME_WITHIN_MIN = (1, 3, 5)


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
    advised: bool
    drivers: Mapping[int, TrainRun]
    trace: dict[int, np.ndarray]  # train id -> rows (t [s], km post [m], speed [m/s])
    tsr_violations: list[dict[str, Any]]
    signals_passed_at_red: list[dict[str, Any]]
    #: spells above the static limits (trackside.py ``static_overspeeds``)
    overspeeds: list[dict[str, Any]]
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
    live: dict[str, Any] | None = None
    #: the ground's re-timings (ground/retimer.py ``OnlineRetimer.log``)
    retiming: list[dict[str, Any]] = field(default_factory=list)

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

    def kpis(self, baseline: LineResult | None = None) -> dict[str, Any]:
        """The KPI object of ``railpilot line simulate --json`` (module docstring)."""
        trains: dict[str, Any] = {}
        all_sections: list[float] = []
        end_to_end: list[float] = []
        total_energy = against_air = 0.0
        all_delays: list[float | None] = []
        worst_excess: dict[int, float] = {}
        for spell in self.overspeeds:
            train = spell["train"]
            worst_excess[train] = max(worst_excess.get(train, 0.0), spell["excess_kmh"])
        for train_id, driver in sorted(self.drivers.items()):
            sections = driver.sections
            per_section = [
                _conformity(s.running_time_s, s.planned_running_time_s) for s in sections
            ]
            all_sections += per_section
            energy = sum(s.energy_traction_kwh - s.energy_regenerated_kwh for s in sections)
            total_energy += energy
            wasted = sum(s.energy_traction_against_air_kwh for s in sections)
            against_air += wasted
            delays = driver.arrival_delays_s(self.sim_s)
            all_delays += delays
            row: dict[str, Any] = {
                "number": driver.service.number,
                "kind": driver.service.kind,
                "sections_run": len(sections),
                "sections_planned": len(driver.service.stops) - 1,
                "finished": driver.finished,
                "conformity_pct": {
                    "sections": [round(c, 3) for c in per_section],
                    "end_to_end": None,
                },
                "energy_kwh": round(energy, 1),
                "energy_traction_kwh": round(sum(s.energy_traction_kwh for s in sections), 1),
                "energy_regenerated_kwh": round(sum(s.energy_regenerated_kwh for s in sections), 1),
                "energy_traction_against_air_kwh": round(wasted, 1),
                "red_signal_stops": driver.red_signal_stops,
                "max_overspeed_kmh": worst_excess.get(train_id, 0.0),
                "running_times_received": driver.running_times_received,
                "arrival_delay_s": None,
                "arrival_delays_s": [None if d is None else round(d, 1) for d in delays],
            }
            if sections:
                planned = sections[-1].planned_arrival_s - sections[0].planned_departure_s
                actual = sections[-1].arrival_s - sections[0].departure_s
                e2e = _conformity(actual, planned)
                end_to_end.append(e2e)
                row["conformity_pct"]["end_to_end"] = round(e2e, 3)
                row["arrival_delay_s"] = round(
                    sections[-1].arrival_s - sections[-1].planned_arrival_s, 1
                )
            trains[str(train_id)] = row
        out: dict[str, Any] = {
            "scenario": self.scenario.name,
            "seed": self.seed,
            "driver": "advised" if self.advised else "baseline",
            "train_model": self.scenario.train_model,
            "sim_s": self.sim_s,
            "trains": trains,
            "conformity_pct": {
                "mean_end_to_end": _mean(end_to_end),
                "mean_abs_section": _mean([abs(c) for c in all_sections]),
                "max_section": round(max(all_sections), 3) if all_sections else None,
            },
            "energy_kwh": round(total_energy, 1),
            "energy_traction_against_air_kwh": round(against_air, 1),
            "punctuality": punctuality(all_delays),
            "red_signal_stops": sum(d.red_signal_stops for d in self.drivers.values()),
            "tsr_violations": len(self.tsr_violations),
            "target_points_passed": len(self.signals_passed_at_red),
            "overspeeds": len(self.overspeeds),
            "max_overspeed_kmh": max(worst_excess.values(), default=0.0),
            "tsr_applied_twice": sum(
                1 for sessions in self.tsr_applied.values() for n in sessions.values() if n > 1
            ),
            "link": self.link,
            "retiming": _retiming_summary(self.retimings()),
            "ground_restarts": self.restarts,
            "wall_s": round(self.wall_s, 3),
            **({"live": self.live} if self.live is not None else {}),
            "realtime_factor": round(self.sim_s / self.wall_s, 1) if self.wall_s > 0 else None,
        }
        if baseline is not None:
            base = baseline.kpis()
            out["baseline_energy_kwh"] = base["energy_kwh"]
            out["baseline"] = {
                k: base[k]
                for k in (
                    "conformity_pct",
                    "energy_kwh",
                    "energy_traction_against_air_kwh",
                    "punctuality",
                    "red_signal_stops",
                    "tsr_violations",
                    "target_points_passed",
                    "overspeeds",
                    "max_overspeed_kmh",
                )
            }
        return out


def _retiming_summary(log: list[dict[str, Any]]) -> dict[str, Any]:
    """The ground's re-timings (``LineResult.retimings``): how many, how solved, who was
    sent new times, and what the solver expected (lateness at the destinations [s], fixed
    plan against re-timed)."""
    solved = [e for e in log if "lateness_s" in e]
    return {
        "runs": len(solved),
        "fallbacks": sum(1 for e in solved if e["status"] == STATUS_FALLBACK),
        "trains_sent_times": sorted({i for e in solved for i in e.get("sent_to", ())}),
        "messages_sent": sum(len(e.get("sent_to", ())) for e in solved),
        "log": [
            {
                "t_s": round(e["t_s"], 1),
                "trigger": e["trigger"],
                "status": e["status"],
                "trains": e["trains"],
                "sent_to": e.get("sent_to", []),
                "lateness_fixed_s": round(e["lateness_fixed_s"], 1),
                "lateness_s": round(e["lateness_s"], 1),
                "solve_ms": round(e["solve_ms"], 1),
            }
            for e in solved
        ],
    }


def punctuality(delays_s: list[float | None]) -> dict[str, Any]:
    """The operator's view of the arrivals (:meth:`TrainRun.arrival_delays_s`, None: due
    and not made): how many were due or made, how many not made, the share [%] on time
    within each of :data:`ON_TIME_WITHIN_MIN` minutes (one not made is not on time), and
    the mean and the largest delay [s] of those made (None where there are none)."""
    made = [d for d in delays_s if d is not None]
    out: dict[str, Any] = {"arrivals": len(delays_s), "not_made": len(delays_s) - len(made)}
    for minutes in ON_TIME_WITHIN_MIN:
        on_time = sum(1 for d in made if d <= 60.0 * minutes)
        out[f"within_{minutes}_min_pct"] = (
            round(100.0 * on_time / len(delays_s), 1) if delays_s else None
        )
    out["mean_delay_s"] = round(float(np.mean(made)), 1) if made else None
    out["max_delay_s"] = round(max(made), 1) if made else None
    return out


def _conformity(actual_s: float, planned_s: float) -> float:
    return (actual_s - planned_s) / planned_s * 100.0


def _mean(values: list[float]) -> float | None:
    return round(float(np.mean(values)), 3) if values else None


def line_train(
    scenario: LineScenario, service: Service, advised: bool
) -> tuple[TrainDriver, OnboardConfig]:
    """One train of ``scenario``: its driver (powered on ``POWER_ON_LEAD_S`` before its
    first departure) and its onboard unit's link configuration."""
    power_on = max(service.stops[0].departure_s - POWER_ON_LEAD_S, 0.0)
    driver = TrainDriver(
        scenario.line,
        service,
        scenario.epoch_s,
        power_on,
        advised=advised,
        margin_kmh=scenario.margin_kmh,
        model=scenario.train_model,
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
) -> LineResult:
    """Run ``scenario`` (its seed unless ``seed``) with the advised driving system, or the
    baseline (``advised=False``), to its end (or ``until_s``)."""
    seed = scenario.seed if seed is None else seed
    line = scenario.line
    epoch = scenario.epoch_s
    drivers: dict[int, TrainDriver] = {}
    trains = []
    for service in scenario.services:
        driver, config = line_train(scenario, service, advised)
        drivers[service.train_id] = driver
        trains.append(
            SimTrain(
                config, driver, driver.power_on_s, driver.on_event, driver.planned_curve_report
            )
        )
    keys = line_keys(scenario, seed)
    # the ground keeps its TSRs, deliveries and audit log in a store, as the live ground
    # does (in memory: it outlives the simulated ground process, not this one)
    store = Store(":memory:", synchronous="NORMAL")
    # the baseline has no re-timing: the fixed plan (issue 12 item 4)
    retimings: list[dict[str, Any]] = []
    retimer = retimer_factory(scenario, retimings) if advised else None
    sim = LinkSim(
        line, trains, scenario.channel, keys, seed=seed, start_s=epoch, store=store, retimer=retimer
    )
    watch = _Watch(sim, drivers, on_watch)
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
        advised,
        {i: TrainRun.of(driver) for i, driver in drivers.items()},
        traces,
        watch.trackside.tsr_violations,
        watch.trackside.passed_at_red,
        static_overspeeds(scenario.line, traces, watch.trackside.trains),
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


class _Watch:
    """The co-simulation's trackside: once a second, every train's true position from its
    driver, handed to the :class:`~railpilot.cosim.trackside.Trackside` at one instant;
    its cab views back to the drivers; a train at its destination retired from the link."""

    def __init__(
        self,
        sim: LinkSim,
        drivers: dict[int, TrainDriver],
        on_watch: Callable[[LinkSim, float], None] | None,
    ) -> None:
        self.sim = sim
        self.drivers = drivers
        self.on_watch = on_watch
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
        if self.on_watch is not None:
            self.on_watch(sim, t)
        sim.call_at(t + WATCH_S, self)
