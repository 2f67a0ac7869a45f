"""The ground's re-timing in a line run: the timetables it holds and the sections' curves
(ground/online_retimer.py; docs/line-run.md "Re-timing in the loop").

The ground of a line run holds every train's timetable, as a dispatch centre holds the
day's plan, and asks the onboard planner for a section's energy-time curve
(ground/energy.py) the first time a re-timing needs it: the same route the train drives
(the static limits, the scenario's margin), sampled at the fastest run, 3 to 30 % slower,
and the timetable's own running time. One curve per train kind, station pair and planned
time, shared by every run of the process.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

from railpilot.ground.energy import section_energy
from railpilot.ground.online_retimer import OnlineRetimer, SectionCurve, TimetabledTrain, timetabled
from railpilot.line.model import RailLine
from railpilot.onboard.drive import train_preset

from .driver import Service
from .scenario import LineScenario


@lru_cache(maxsize=1024)
def section_curve(
    line: RailLine, preset_name: str, from_id: int, to_id: int, margin_kmh: float, planned_s: float
) -> SectionCurve:
    """The fastest run and the energy-time curve of one station pair for one train kind."""
    energy = section_energy(
        line,
        train_preset(preset_name),
        from_id,
        to_id,
        extra_times_s=(planned_s,),
        margin_kmh=margin_kmh,
    )
    return SectionCurve(energy.fastest_s, energy.curve)


def ground_timetable(line: RailLine, service: Service, epoch_s: float) -> TimetabledTrain:
    """``service``'s timetable on the ground's clock [s since the epoch]."""
    stops = service.stops
    direction = service.direction
    return timetabled(
        service.train_id,
        (s.station for s in stops),
        (line.station(s.station).stop_m(direction) for s in stops),
        (epoch_s + s.departure_s for s in stops[:-1]),
        (epoch_s + s.arrival_s for s in stops[1:]),
        service.min_dwell_s,
    )


def retimer_factory(
    scenario: LineScenario, log: list[dict[str, object]] | None = None
) -> Callable[[], OnlineRetimer] | None:
    """What makes the ground's retimer of ``scenario`` (one per ground process: a restart
    makes a new one), or None if the scenario does not re-time. Every re-timing of every
    retimer made is appended to ``log``."""
    settings = scenario.retiming
    if settings is None:
        return None
    services = {s.train_id: s for s in scenario.services}
    trains = {i: ground_timetable(scenario.line, s, scenario.epoch_s) for i, s in services.items()}

    def curves(train_id: int, from_id: int, to_id: int) -> SectionCurve:
        t = trains[train_id]
        j = t.section_of[(from_id, to_id)]
        planned = round(t.arrivals_s[j] - t.departures_s[j], 3)  # one cache entry per time
        kind = services[train_id].kind
        return section_curve(scenario.line, kind, from_id, to_id, scenario.margin_kmh, planned)

    def make() -> OnlineRetimer:
        return OnlineRetimer(trains, curves, settings, log if log is not None else [])

    return make
