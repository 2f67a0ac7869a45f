"""What one event of a line run cost each train: the day with it against the day without.

A train that fails and stands ten minutes delays itself (its primary delay) and the trains
held behind it, and those behind them (the knock-on, or secondary, delay); a TSR slows every
train that meets it. The co-simulation is deterministic, so the cost of event ``k`` is
measured directly: the scenario is run twice with the same seed, once as written and once
without that event, and each train's arrival delays and energy are compared
(``railpilot line knock-on SCENARIO K``).

What the difference holds besides the event: the radio draws its latencies and losses from
one stream per train (cosim/channel.py). A train the event does not reach sends the same
packets at the same times and draws the same, so its difference is exactly 0 (K101 and
E201 on the short day). A train it does reach sends other packets from then on and draws
other luck with them: with frame loss, its difference holds that too (a lost packet's
timeout, a replan a second later: seconds, against the minutes of a failure).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from railpilot.errors import ConfigError

from .line_run import LineResult, run_line
from .scenario import LineScenario, ScenarioEvent, TrainFailure


@dataclass(frozen=True)
class KnockOn:
    """The day with event ``index`` (1-based, in the file's order) and without it."""

    scenario: LineScenario
    index: int
    with_event: LineResult
    without_event: LineResult

    def summary(self) -> dict[str, Any]:
        """:func:`summary` of the two days' KPIs."""
        return summary(self.scenario, self.index, self.with_event.kpis(), self.without_event.kpis())


def without_event(scenario: LineScenario, index: int) -> LineScenario:
    """``scenario`` without its event ``index`` (1-based, the file's order)."""
    count = len(scenario.events)
    if type(index) is not int or not 1 <= index <= count:
        allowed = f"an event number 1..{count}" if count else "a scenario with events (none)"
        raise ConfigError("event", index, allowed)
    return scenario.with_(events=scenario.events[: index - 1] + scenario.events[index:])


def knock_on(scenario: LineScenario, index: int, *, seed: int | None = None) -> KnockOn:
    """Run ``scenario`` with and without its event ``index`` (1-based, the file's order),
    both with the same seed (the file's unless ``seed``), advised."""
    rest = without_event(scenario, index)
    return KnockOn(scenario, index, run_line(scenario, seed=seed), run_line(rest, seed=seed))


def own_train(event: ScenarioEvent) -> int | None:
    """The train ``event`` happens to (a failure's), if it is one train's."""
    return event.action.train_id if isinstance(event.action, TrainFailure) else None


def summary(
    scenario: LineScenario,
    index: int,
    with_kpis: dict[str, Any],
    without_kpis: dict[str, Any],
) -> dict[str, Any]:
    """One JSON-ready object from the KPIs of the day with event ``index`` and of the day
    without it (``LineResult.kpis()``): the event, and per train its arrival delay at the
    last stop it reached on both days, with and without the event [s], and the difference
    (+: the event made it later); the difference at every stop of its timetable (None
    where a day did not reach it); its net energy's difference [kWh] (over the sections
    each day ran); then the sums over the trains other than the event's own."""
    event = scenario.events[index - 1]
    own = own_train(event)
    trains: dict[str, Any] = {}
    secondary = secondary_late = 0.0
    for key in sorted(with_kpis["trains"], key=int):
        a, b = with_kpis["trains"][key], without_kpis["trains"][key]
        pairs = list(zip(a["arrival_delays_s"], b["arrival_delays_s"], strict=True))
        stations = [_difference(x, y) for x, y in pairs]
        # the last stop both days reached (a day cut short may not reach the last one)
        both = [(x, y) for x, y in pairs if x is not None and y is not None]
        last = both[-1] if both else (None, None)
        delay = _difference(*last)
        trains[key] = {
            "number": a["number"],
            "own": int(key) == own,
            "arrival_delay_s": {"with": last[0], "without": last[1], "knock_on": delay},
            "knock_on_by_station_s": stations,
            "energy_kwh": {
                "with": a["energy_kwh"],
                "without": b["energy_kwh"],
                "knock_on": round(a["energy_kwh"] - b["energy_kwh"], 1),
            },
        }
        if int(key) != own and delay is not None:
            secondary += delay
            secondary_late += max(delay, 0.0)
    return {
        "scenario": scenario.name,
        "seed": with_kpis["seed"],
        "event": {"index": index, "at_s": event.at_s, "label": event.label},
        "own_train": own,
        "trains": trains,
        "knock_on_others_s": round(secondary, 1),
        "knock_on_others_late_s": round(secondary_late, 1),
    }


def _difference(with_s: float | None, without_s: float | None) -> float | None:
    if with_s is None or without_s is None:
        return None  # not reached in one of the two days
    return round(with_s - without_s, 1)
