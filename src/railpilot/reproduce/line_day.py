"""A short day on the heavy-haul line, advised against the baseline.

The day of ``examples/line_short_day.toml`` (three loaded trains and an empty one, the
file's dispatcher operations and failures, a radio dead zone and a lossy radio) is
co-simulated twice (:func:`railpilot.cosim.line_run.run_line`): with the advised driving
system (the planned energy-efficient curve, the ground's target points, the ground's
re-timing) and with the baseline (the fastest run to the static limits, the cab signal
only, the fixed plan). The two run side by side in two processes; a third run, advised
and without the file's first train failure, then gives what that failure cost each train
(cosim/knock_on.py).

The section says in one sentence what the baseline is, and shows paper 001's KPIs of
both runs (``LineResult.kpis()``) with which way each is better, every train's
conformity, delay and energy, the failure's knock-on delays, the link's statistics, the
time-distance graph of plan against run and the energy per train. Every number comes from
the KPIs of the runs.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from railpilot.cosim.knock_on import summary as knock_on_summary
from railpilot.cosim.kpis import (
    BASELINE_DEFINITIONS,
    KPIS,
    ON_TIME_TOLERANCE_MIN,
    better_phrase,
    dig,
    safety_kpis,
    safety_phrase,
)
from railpilot.cosim.scenario import LineScenario
from railpilot.reproduce.base import Reproduction, Table, find_example

SCENARIO_FILE = "line_short_day.toml"
TIME_DISTANCE_PNG = "line_day_time_distance.png"
ENERGY_PNG = "line_day_energy.png"
#: a stand this long [s] away from the train's stops gets a sentence: the KPIs count red
#: signal stops but not how long a train stood, nor a stand for another reason
LONG_STAND_S = 300.0
#: a train this much further from the timetable end to end [percentage points] with advice
#: than without is named in a finding
CONFORMITY_GAP_PCT = 1.0
#: at rest below this speed [m/s]
AT_REST_MPS = 0.05
#: a head this close to one of the train's stop points [m] is at a station
AT_STOP_M = 100.0
#: a failure this long [s] before a stand began is its cause (the braking to a stand)
FAILURE_BRAKING_S = 300.0


def scenario_path() -> Path:
    """``examples/line_short_day.toml`` of the source checkout."""
    return find_example(SCENARIO_FILE)


@dataclass
class DayRun:
    """What the section keeps of one run: its KPIs and what the time-distance graph
    draws. A :class:`~railpilot.cosim.line_run.LineResult` cannot come back from a worker:
    its drivers hold the onboard's MRSP, which refuses to be rebuilt by unpickling."""

    kpis: dict[str, Any]
    trace: dict[int, np.ndarray]
    events: list[dict[str, Any]]


def drive_day(
    path: str, advised: bool, until_s: float | None = None, without: int | None = None
) -> DayRun:
    """One run of the scenario file at ``path`` (in a worker: it reads the file itself),
    ``without`` its event of that number if given."""
    from railpilot.cosim.knock_on import without_event
    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_line_scenario

    scenario = load_line_scenario(path)
    if without is not None:
        scenario = without_event(scenario, without)
    result = run_line(scenario, advised=advised, until_s=until_s)
    return DayRun(result.kpis(), result.trace, result.events)


def drive_all(
    path: Path, until_s: float | None = None, failure: int | None = None
) -> tuple[DayRun, DayRun, DayRun | None]:
    """The advised run and the baseline's side by side in two fresh processes, then (if
    ``failure`` is an event's number) the advised run without that event."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(2, mp_context=context) as pool:
        advised = pool.submit(drive_day, str(path), True, until_s)
        baseline = pool.submit(drive_day, str(path), False, until_s)
        without = None
        if failure is not None:
            without = pool.submit(drive_day, str(path), True, until_s, failure)
        return advised.result(), baseline.result(), None if without is None else without.result()


def knock_on_finding(out: dict[str, Any]) -> str:
    own = next(r for r in out["trains"].values() if r["own"])
    return (
        f"{own['number']}'s failure cost it {own['arrival_delay_s']['knock_on']} s at its last "
        f"stop, and the other trains {out['knock_on_others_s']} s in all (the day without it, "
        "same seed)."
    )


def first_failure(scenario: LineScenario) -> int | None:
    """The number (1-based) of the scenario's first train failure, if it has one."""
    from railpilot.cosim.knock_on import own_train

    found = (k for k, e in enumerate(scenario.events, 1) if own_train(e) is not None)
    return next(found, None)


def knock_on_table(out: dict[str, Any]) -> Table:
    """What the failure cost each train: the advised day with it and without it."""
    rows = []
    for row in out["trains"].values():
        delay, energy = row["arrival_delay_s"], row["energy_kwh"]
        name = row["number"] + (" (failed)" if row["own"] else "")
        rows.append(
            [name, _dash(delay["with"]), _dash(delay["without"]), _dash(delay["knock_on"]),
             energy["knock_on"]]
        )  # fmt: skip
    own = next(r["number"] for r in out["trains"].values() if r["own"])
    return Table(
        f"What {own}'s failure cost each train: the advised day with it and without it",
        ["train", "arrival delay with [s]", "without [s]", "knock-on [s]", "net energy [kWh]"],
        rows,
        note="Arrival delay at the last stop the train reached on both days, against the "
        "timetable; knock-on = with - without (the failed train's own: its primary delay). "
        "The same seed; a train the failure does not reach differs by exactly 0 "
        "(railpilot line knock-on, docs/line-run.md).",
    )


@dataclass
class Stand:
    """A train at rest away from its stops (``LONG_STAND_S`` or longer)."""

    train_id: int
    number: str
    from_s: float
    until_s: float
    km: float

    @property
    def minutes(self) -> float:
        return (self.until_s - self.from_s) / 60.0


def long_stands(scenario: LineScenario, trace: dict[int, np.ndarray]) -> list[Stand]:
    """Every stand of ``LONG_STAND_S`` or more away from the train's stops, from the
    trackside's samples (``LineResult.trace``: t [s], head km post [m], speed [m/s])."""
    stands = []
    line = scenario.line
    for service in scenario.services:
        rows = trace.get(service.train_id, np.empty((0, 3)))
        stops = np.array([line.station(s.station).stop_m(service.direction) for s in service.stops])
        at_rest = rows[rows[:, 2] < AT_REST_MPS]
        if not len(at_rest):
            continue
        # a new stand wherever a sample is missing (the train moved in between)
        breaks = np.flatnonzero(np.diff(at_rest[:, 0]) > 1.5) + 1
        for part in np.split(at_rest, breaks):
            head = float(part[0, 1])
            duration = float(part[-1, 0] - part[0, 0])
            if duration >= LONG_STAND_S and np.min(np.abs(stops - head)) > AT_STOP_M:
                stands.append(
                    Stand(
                        service.train_id,
                        service.number,
                        float(part[0, 0]),
                        float(part[-1, 0]),
                        head / 1000.0,
                    )
                )
    return stands


def _why(stand: Stand, events: list[dict[str, Any]]) -> str:
    """What the events say about a stand: a failure of the train just before it, or a TSR
    whose end is the stand's end."""
    for event in events:
        if (
            event.get("train") == stand.train_id
            and stand.from_s - FAILURE_BRAKING_S <= event["t_s"] <= stand.until_s
        ):
            return f", after its failure at {event['t_s'] / 3600:.2f} h"
        tsr = event.get("tsr")
        if tsr is not None and abs(tsr["until_s"] - stand.until_s) <= 2.0:
            return (
                f", until the TSR at km {tsr['start_km']:.1f}-{tsr['end_km']:.1f} "
                f"({tsr['limit_kmh']:g} km/h) expired"
            )
    return ""


def _stands_sentence(label: str, stands: list[Stand], events: list[dict[str, Any]]) -> str:
    if not stands:
        return f"{label}: no train stood {LONG_STAND_S / 60:.0f} min or more away from a station."
    parts = [
        f"{s.number} {s.minutes:.0f} min at km {s.km:.1f} "
        f"({s.from_s / 3600:.2f}-{s.until_s / 3600:.2f} h{_why(s, events)})"
        for s in stands
    ]
    return (
        f"{label}: stands of {LONG_STAND_S / 60:.0f} min or more away from a station: "
        + "; ".join(parts)
        + "."
    )


def _dash(value: Any) -> Any:
    """A missing KPI (a train that never arrived) as a dash, not "None"."""
    return "-" if value is None else value


def _whole(value: float | None) -> int | None:
    """kWh and seconds to the unit: the tables print floats to 4 digits (1.044e+04)."""
    return None if value is None else round(value)


def _difference(a: Any, b: Any) -> Any:
    if isinstance(a, int) and isinstance(b, int):
        return a - b
    if isinstance(a, int | float) and isinstance(b, int | float):
        return round(a - b, 3)
    return "-"


def _finished(kpis: dict[str, Any]) -> int:
    return sum(1 for t in kpis["trains"].values() if t["finished"])


def _total(kpis: dict[str, Any], key: str) -> int:
    """A per-train energy summed over the trains [kWh]."""
    return round(sum(t[key] for t in kpis["trains"].values()))


def baseline_sentence() -> str:
    """What the section's baseline is, in one sentence."""
    return f"The baseline is {BASELINE_DEFINITIONS['minimum-time']}."


def kpi_table(advised: dict[str, Any], baseline: dict[str, Any], note: str = "") -> Table:
    """The two runs side by side: every figure of the KPIs set against the baseline and
    of the safety KPIs (cosim/kpis.py), then what the trains add up to; each row says
    which way is better (a count of what the runs did, such as the re-timings, none)."""
    rows: list[list[Any]] = []

    def row(name: str, a: Any, b: Any, better: str | None) -> None:
        rows.append([name, _dash(a), _dash(b), _difference(a, b), better_phrase(better)])

    for kpi in KPIS:
        if not (kpi.against_baseline or kpi.safety):
            continue
        for figure in kpi.figures:
            a, b = dig(advised, kpi.path(figure)), dig(baseline, kpi.path(figure))
            if figure.unit == "kWh":
                a, b = _whole(a), _whole(b)
            row(figure.title, a, b, figure.better)
    # traction drawn costs energy; regeneration returned gives it back
    row(
        "traction drawn [kWh]",
        _total(advised, "energy_traction_kwh"),
        _total(baseline, "energy_traction_kwh"),
        "lower",
    )
    row(
        "regeneration returned [kWh]",
        _total(advised, "energy_regenerated_kwh"),
        _total(baseline, "energy_regenerated_kwh"),
        "higher",
    )
    row("trains finished", _finished(advised), _finished(baseline), "higher")
    ra, rb = advised.get("retiming"), baseline.get("retiming")
    if ra is not None and rb is not None:
        # the baseline runs the fixed plan: these count what the advised run did
        row("re-timings by the ground", ra["runs"], rb["runs"], None)
        row("running-time messages sent", ra["messages_sent"], rb["messages_sent"], None)
    if "ground_restarts" in advised and "ground_restarts" in baseline:
        restarts = len(advised["ground_restarts"]), len(baseline["ground_restarts"])
        row("ground restarts", *restarts, None)
    return Table(
        f"{advised['scenario']}: paper 001's KPIs, advised against the baseline",
        ["KPI", "advised", "baseline", "advised - baseline", "better"],
        rows,
        note=f"{baseline_sentence()} {note}".strip(),
    )


def train_table(advised: dict[str, Any], baseline: dict[str, Any]) -> Table:
    """Every train's end-to-end conformity, arrival delay and net energy in both runs."""
    rows = []
    for train_id in sorted(advised["trains"], key=int):
        a, b = advised["trains"][train_id], baseline["trains"][train_id]
        rows.append(
            [
                a["number"],
                a["kind"],
                f"{a['sections_run']}/{a['sections_planned']}",
                f"{b['sections_run']}/{b['sections_planned']}",
                _dash(a["conformity_pct"]["end_to_end"]),
                _dash(b["conformity_pct"]["end_to_end"]),
                _dash(_whole(a["arrival_delay_s"])),
                _dash(_whole(b["arrival_delay_s"])),
                _whole(a["energy_kwh"]),
                _whole(b["energy_kwh"]),
            ]
        )
    return Table(
        "Per train: advised (adv) and baseline (base)",
        [
            "train",
            "kind",
            "sections adv",
            "sections base",
            "end-to-end conf. adv [%]",
            "base [%]",
            "arrival delay adv [s]",
            "base [s]",
            "net energy adv [kWh]",
            "base [kWh]",
        ],
        rows,
        note="Conformity: (actual - planned) / planned running time from the origin's "
        "departure to the last arrival; delay: the last arrival against the timetable's; "
        "net energy: traction drawn less regeneration returned, over the sections run.",
    )


def _counter_names(*counters: dict[str, Any]) -> list[str]:
    """Every counter any of the endpoints has, in the order the first one lists them."""
    names: list[str] = []
    for c in counters:
        names += [k for k in c if k != "rejected" and k not in names]
    return names


def link_table(advised: dict[str, Any], baseline: dict[str, Any]) -> Table:
    """The link's statistics of both runs (``LinkSim.link_report``): the endpoints'
    counters, the rejections by check, and the radio's packets."""
    la, lb = advised["link"], baseline["link"]
    ends = (la["ground"], la["onboard"], lb["ground"], lb["onboard"])
    rows: list[list[Any]] = []
    for name in _counter_names(*ends):
        rows.append([name.replace("_", " "), *(e.get(name, 0) for e in ends)])
    checks = sorted({check for e in ends for check in e.get("rejected", {})})
    for check in checks:
        rows.append([f"rejected: {check}", *(e.get("rejected", {}).get(check, 0) for e in ends)])
    for name in sorted(set(la["channel"]) | set(lb["channel"]), key=_channel_order):
        label = f"radio: {name.replace('lost_', 'lost, ').replace('_', ' ')}"
        rows.append([label, la["channel"].get(name, 0), "", lb["channel"].get(name, 0), ""])
    for name in ("connects", "link_failures"):
        rows.append([f"sessions: {name.replace('_', ' ')}", la[name], "", lb[name], ""])
    return Table(
        "The link: counters of the ground's and the trains' endpoints (all trains summed) "
        "and of the radio (both directions)",
        ["counter", "advised: ground", "onboard", "baseline: ground", "onboard"],
        rows,
        note="Radio rows and sessions are one count per run (first column of the run).",
    )


def _channel_order(name: str) -> tuple[int, str]:
    # packets, delivered, then the losses by cause
    return ({"packets": 0, "delivered": 1}.get(name, 2), name)


def findings(advised: dict[str, Any], baseline: dict[str, Any]) -> list[str]:
    """Short sentences computed from the two runs' KPIs, after the baseline's own."""
    out = [baseline_sentence()]
    ea, eb = advised["energy_kwh"], baseline["energy_kwh"]
    lower = "lower" if ea <= eb else "higher"
    share = f" ({abs(ea - eb) / eb:.1%} of the baseline's)" if eb > 0 else ""
    # net energy below zero: the loaded trains run downhill and return more than they draw
    sign = " (below zero: more returned by regeneration than drawn)" if min(ea, eb) < 0 else ""
    traction = _total(advised, "energy_traction_kwh") - _total(baseline, "energy_traction_kwh")
    regenerated = _total(advised, "energy_regenerated_kwh") - _total(
        baseline, "energy_regenerated_kwh"
    )
    out.append(
        f"Net energy{sign}: {ea:.0f} kWh advised, {eb:.0f} kWh baseline; the advised run's is "
        f"{abs(ea - eb):.0f} kWh {lower}{share}: {abs(traction)} kWh "
        f"{'less' if traction <= 0 else 'more'} traction drawn, {abs(regenerated)} kWh "
        f"{'more' if regenerated >= 0 else 'less'} regeneration returned."
    )
    ca, cb = advised["conformity_pct"], baseline["conformity_pct"]
    if ca["mean_end_to_end"] is not None and cb["mean_end_to_end"] is not None:
        out.append(
            f"Running-time conformity end to end: {ca['mean_end_to_end']:+.2f} % advised "
            f"against {cb['mean_end_to_end']:+.2f} % baseline (mean |section| "
            f"{ca['mean_abs_section']:.2f} % against {cb['mean_abs_section']:.2f} %)."
        )
    further = [
        f"{a['number']} ({a_e2e:+.1f} % against {b_e2e:+.1f} %)"
        for train_id, a in sorted(advised["trains"].items(), key=lambda item: int(item[0]))
        if (a_e2e := a["conformity_pct"]["end_to_end"]) is not None
        and (b_e2e := baseline["trains"][train_id]["conformity_pct"]["end_to_end"]) is not None
        and abs(a_e2e) > abs(b_e2e) + CONFORMITY_GAP_PCT
    ]
    if further:
        points = "point" if CONFORMITY_GAP_PCT == 1 else "points"
        out.append(
            "Further from the timetable with advice than without (end to end, by more than "
            f"{CONFORMITY_GAP_PCT:g} percentage {points}): " + ", ".join(further) + "."
        )
    n = len(advised["trains"])
    fa, fb = _finished(advised), _finished(baseline)
    out.append(
        f"Trains at their destination by the end of the day: {fa} of {n} advised, "
        f"{fb} of {n} baseline."
    )
    safety = [k.name for k in safety_kpis()]
    if all(kpis[k] == 0 for kpis in (advised, baseline) for k in safety):
        out.append(f"No {safety_phrase()}, in either run.")
    else:
        counts = ", ".join(
            f"{k.replace('_', ' ')} {advised[k]} advised / {baseline[k]} baseline" for k in safety
        )
        out.append(f"Safety KPIs not all zero: {counts}.")
    out.append(
        f"Red-signal stops: {advised['red_signal_stops']} advised, "
        f"{baseline['red_signal_stops']} baseline."
    )
    out.append(punctuality_finding(advised["punctuality"], baseline["punctuality"]))
    retiming = advised.get("retiming")
    if retiming is not None and retiming["runs"]:
        trains = ", ".join(
            advised["trains"][str(i)]["number"] for i in retiming["trains_sent_times"]
        )
        out.append(
            f"The ground re-timed {retiming['runs']} times "
            f"({retiming['fallbacks']} by the fallback) and sent new running times "
            f"{retiming['messages_sent']} times, to {trains}; the baseline runs the fixed plan."
        )
    for restart in advised.get("ground_restarts", []):
        up = restart.get("up_at_s")
        out.append(
            f"The ground was killed at {restart['down_at_s'] / 3600:.2f} h and "
            + ("did not come back." if up is None else f"restarted at {up / 3600:.2f} h.")
        )
    link, radio = advised["link"], advised["link"]["channel"]
    if radio.get("packets"):
        lost = radio["packets"] - radio["delivered"]
        out.append(
            f"Advised run's link: the radio lost {lost} of {radio['packets']} packets "
            f"({lost / radio['packets']:.1%}); {link['link_failures']} link failures, "
            f"{link['connects']} connects; the ground resent {link['ground']['resends']} "
            f"frames, the trains {link['onboard']['resends']}."
        )
    return out


def punctuality_finding(pa: dict[str, Any], pb: dict[str, Any]) -> str:
    """The arrivals as a railway reports them: on time within the tolerance, the mean
    lateness with an early arrival as 0, the early arrivals apart, the signed mean."""
    minutes = ON_TIME_TOLERANCE_MIN
    on_time = f"within_{minutes}_min_pct"

    def early(p: dict[str, Any]) -> str:
        if not p["early_arrivals"]:
            return "none"
        return f"{p['early_arrivals']} (by {p['mean_earliness_s']} s on average)"

    return (
        f"Of {pa['arrivals']} arrivals, on time (at most {minutes} min late, an early one "
        f"on time): {_dash(pa[on_time])} % advised, {_dash(pb[on_time])} % baseline. "
        f"Mean lateness, an early arrival counted as 0: {_dash(pa['mean_lateness_s'])} s "
        f"advised, {_dash(pb['mean_lateness_s'])} s baseline; early arrivals: "
        f"{early(pa)} advised, {early(pb)} baseline; the signed mean delay, where early "
        f"minutes offset late ones: {_dash(pa['mean_delay_s'])} s advised, "
        f"{_dash(pb['mean_delay_s'])} s baseline."
    )


def run(out_dir: Path, until_s: float | None = None) -> Reproduction:
    """Run the day twice side by side (or up to ``until_s``, for a quick check) and build
    the section; write the time-distance graph and the energy per train."""
    from railpilot.cosim.scenario import load_line_scenario
    from railpilot.report.figure import save_figure
    from railpilot.report.line_plots import energy_by_train, plan_against_run

    out_dir.mkdir(parents=True, exist_ok=True)
    path = scenario_path()
    scenario = load_line_scenario(path)  # checked here: a bad file fails before the workers start
    started = time.perf_counter()
    failure = first_failure(scenario)
    advised, baseline, without = drive_all(path, until_s, failure)
    runs_s = time.perf_counter() - started
    figures = [
        save_figure(
            plan_against_run(scenario, advised.trace, advised.events, baseline.trace),
            out_dir / TIME_DISTANCE_PNG,
        ),
        save_figure(energy_by_train(advised.kpis, baseline.kpis), out_dir / ENERGY_PNG),
    ]
    wall = time.perf_counter() - started
    a, b = advised.kpis, baseline.kpis
    stands = {
        "advised": long_stands(scenario, advised.trace),
        "baseline": long_stands(scenario, baseline.trace),
    }
    # the KPIs' sim_s is the scenario's duration even for a run stopped at until_s
    simulated_s = a["sim_s"] if until_s is None else min(until_s, a["sim_s"])
    knock = None
    if failure is not None and without is not None:
        knock = knock_on_summary(scenario, failure, a, without.kpis)
    note = (
        f"{simulated_s / 3600:.2f} h simulated; the runs in two processes took "
        f"{runs_s:.1f} s of wall clock (the simulation itself: {a['wall_s']:.1f} s advised, "
        f"{b['wall_s']:.1f} s baseline), the whole section {wall:.1f} s."
    )
    payload = {
        "scenario": "line-day",
        "file": str(path),
        "until_s": until_s,
        "advised": a,
        "baseline": b,
        "long_stands": {
            which: [
                {"train": s.number, "from_s": s.from_s, "until_s": s.until_s, "km": s.km}
                for s in found
            ]
            for which, found in stands.items()
        },
        "knock_on": knock,
        "runs_wall_s": round(runs_s, 2),
        "wall_s": round(wall, 2),
        "files": [str(f) for f in figures],
    }
    return Reproduction(
        "line-day",
        "Paper 001 on a whole line: a short day, advised driving against the baseline",
        payload,
        [
            kpi_table(a, b, note),
            train_table(a, b),
            *([knock_on_table(knock)] if knock is not None else []),
            link_table(a, b),
        ],
        figures,
        [
            *findings(a, b),
            *([knock_on_finding(knock)] if knock is not None else []),
            _stands_sentence("Advised run", stands["advised"], advised.events),
            _stands_sentence("Baseline run", stands["baseline"], baseline.events),
        ],
    )
