"""The line run's KPIs, one entry each in one table (:data:`KPIS`; docs/line-run.md "KPIs").

A :class:`Kpi` says what a figure is called in the KPI object (``railpilot line simulate
--json``), its unit, how it is computed from a run (:class:`~railpilot.cosim.line_run.LineResult`),
whether it is a safety KPI that must be 0, whether it is set against the baseline, and how
a sweep of seeds aggregates it. Everything that shows KPIs iterates the table: the KPI
object (:func:`kpi_object`), the baseline comparison, the sweep's summary
(:func:`sweep_summary`) and its ``runs.csv``, the command line's text, and the report's
sections. Adding a KPI is one entry here (and, if it needs data a run does not keep yet,
the field that keeps it in line_run.py).

Paper 001's KPIs (tables 2 and 3):

``conformity_pct``
    running-time conformity ``(actual - planned) / planned * 100`` per section and end to
    end (the origin's departure to the destination's arrival), per train and overall.
``energy_kwh``
    net traction energy (traction less regeneration) per train and in total;
    ``baseline_energy_kwh`` is the same day driven by the minimum-time baseline (no
    advice, no re-timing: ``run_line`` with ``driver="minimum-time"``),
    ``human_baseline_energy_kwh`` by the human-driver baseline (``driver="human"``,
    cosim/human_driver.py).
``energy_traction_against_air_kwh``
    of the traction energy drawn, what pulled against the air brake still applied (the
    smaller of the two forces while both act; a loaded train's air brake takes about a
    minute to release), per train and in total.
``trains_not_arrived``
    trains due at their destination by the end of the run that had not arrived there;
    such a train's row has ``finished`` false and no end-to-end conformity or arrival delay
    (None), never a figure from the part of its way it made.
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
(``arrival_delays_s``), as shares on time within 1, 3 and 5 minutes, and as a railway
reports lateness (:func:`lateness`): the mean counting an early arrival as 0 (an early
train is not late, and its minutes ahead must not hide another's behind), the early
arrivals apart, and the signed mean beside them.

Each figure says which way is better (:attr:`Figure.better`): the report sets every row
of two runs side by side with it, and the command line's text says it on every line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from railpilot.ground.running_time_lp import STATUS_FALLBACK

if TYPE_CHECKING:
    from .line_run import LineResult, TrainRun

#: punctuality: an arrival at most this many minutes after the timetable is on time (one
#: share each; an early arrival is on time)
ON_TIME_WITHIN_MIN = (1, 3, 5)
#: the tolerance of the share on time that the command line's text states [min]
ON_TIME_TOLERANCE_MIN = 3
#: which way a figure is better: smaller, larger, or nearer 0 (a signed figure, where
#: early is no better than late)
LOWER, HIGHER, NEARER_ZERO = "lower", "higher", "nearer 0"
#: the quantiles a sweep gives of each swept figure, by name in its summary; NumPy's
#: ``linear`` method (Hyndman and Fan's definition 7: linear between order statistics)
SWEEP_QUANTILES = (("p5", 0.05), ("median", 0.5), ("p95", 0.95))
QUANTILE_METHOD: Final = "linear"
#: digits a sweep's quantiles and mean are rounded to
SWEEP_DIGITS = 4


@dataclass(frozen=True)
class Figure:
    """A number of a KPI that a table of KPIs shows as one row and a sweep may give the
    spread of: ``path`` into the KPI's value (``""`` the value itself, ``"a.b"`` a number
    inside it), its row's label and its unit."""

    path: str
    label: str
    unit: str = ""
    #: a sweep gives its spread (:func:`spread`)
    swept: bool = True
    #: which way is better: :data:`LOWER`, :data:`HIGHER` or :data:`NEARER_ZERO` (None: a
    #: count that is neither, such as the link's connects)
    better: str | None = LOWER
    #: a line of its own in the command line's text, after its KPI's
    text: bool = False

    @property
    def title(self) -> str:
        """The row's label with the unit: ``net energy [kWh]``."""
        return f"{self.label} [{self.unit}]" if self.unit else self.label

    @property
    def better_phrase(self) -> str:
        """``lower is better``; ``""`` for a figure with no better way."""
        return better_phrase(self.better)


def better_phrase(better: str | None) -> str:
    """How a table says which way is better: ``lower is better``."""
    return "" if better is None else f"{better} is better"


@dataclass(frozen=True)
class Kpi:
    """One entry of the KPI object of a line run.

    ``name`` is its key in the KPI object, ``of_run`` computes its value from a run.
    ``figures`` are its numbers that tables show, row by row, and that a sweep of seeds
    gives the spread of where ``Figure.swept`` (:func:`sweep_summary`: min, quantiles,
    max, mean, and the seeds of the extremes). ``count_runs_not_zero``: a sweep also
    counts the runs where it is not 0 (``runs_with_<name>``). ``safety``: a correct run
    has it 0. ``against_baseline``: given beside the baseline's in the KPI object, and
    one of the KPIs a report sets side by side. ``text``: its line in the command line's
    text output (None: not printed), of which ``better`` says which way is better.
    ``optional``: left out of the KPI object when None (a figure only some runs have).
    ``records``: for a KPI that counts what the trackside saw, the key under which a
    run's events document (cosim/export.py) lists each sighting, and how to get them from
    a run.
    """

    name: str
    label: str
    of_run: Callable[[LineResult], Any]
    figures: tuple[Figure, ...] = ()
    safety: bool = False
    against_baseline: bool = False
    count_runs_not_zero: bool = False
    text: Callable[[Any], str] | None = None
    better: str | None = LOWER
    optional: bool = False
    records: tuple[str, Callable[[LineResult], Sequence[Any]]] | None = None

    def path(self, figure: Figure) -> str:
        """The dotted path of one of its figures in the KPI object."""
        return self.name if figure.path == "" else f"{self.name}.{figure.path}"

    def swept(self) -> list[str]:
        """The dotted paths into the KPI object that a sweep gives the spread of."""
        return [self.path(f) for f in self.figures if f.swept]


# ---------------------------------------------------------------- computed from a run


def _trackside_count(name: str, label: str, records: str) -> Kpi:
    """A safety KPI that counts what the trackside saw: the run's ``records`` list (its
    events document lists each under that key), 0 in a correct run."""
    return Kpi(
        name,
        label,
        lambda r: len(getattr(r, records)),
        (Figure("", label),),
        safety=True,
        against_baseline=True,
        count_runs_not_zero=True,
        text=str,
        records=(records, lambda r: getattr(r, records)),
    )


def _conformity(actual_s: float, planned_s: float) -> float:
    return (actual_s - planned_s) / planned_s * 100.0


def _mean(values: list[float]) -> float | None:
    return round(float(np.mean(values)), 3) if values else None


def _trains(result: LineResult) -> list[tuple[int, TrainRun]]:
    return sorted(result.drivers.items())


def _net_energy_kwh(run: TrainRun) -> float:
    return sum(s.energy_traction_kwh - s.energy_regenerated_kwh for s in run.sections)


def _end_to_end(run: TrainRun) -> float | None:
    """A train's conformity from its origin's departure to its destination [%]; None for
    a train that has not arrived there (a share of its way is not its conformity)."""
    sections = run.sections
    if not sections or not run.finished:
        return None
    planned = sections[-1].planned_arrival_s - sections[0].planned_departure_s
    actual = sections[-1].arrival_s - sections[0].departure_s
    return _conformity(actual, planned)


def _worst_excess_kmh(result: LineResult) -> dict[int, float]:
    """Each overspeeding train's worst excess over the static limit [km/h]."""
    worst: dict[int, float] = {}
    for spell in result.overspeeds:
        worst[spell.train] = max(worst.get(spell.train, 0.0), spell.excess_kmh)
    return worst


def punctuality(delays_s: list[float | None]) -> dict[str, Any]:
    """The operator's view of the arrivals (``TrainRun.arrival_delays_s``, None: due
    and not made): how many were due or made, how many not made, the share [%] on time
    within each of :data:`ON_TIME_WITHIN_MIN` minutes (one not made is not on time), the
    signed mean and the largest delay [s] of those made (None where there are none), and
    :func:`lateness`'s figures of those made."""
    made = [d for d in delays_s if d is not None]
    out: dict[str, Any] = {"arrivals": len(delays_s), "not_made": len(delays_s) - len(made)}
    for minutes in ON_TIME_WITHIN_MIN:
        on_time = sum(1 for d in made if d <= 60.0 * minutes)
        out[f"within_{minutes}_min_pct"] = (
            round(100.0 * on_time / len(delays_s), 1) if delays_s else None
        )
    out["mean_delay_s"] = round(float(np.mean(made)), 1) if made else None
    out["max_delay_s"] = round(max(made), 1) if made else None
    out.update(lateness(made))
    return out


def lateness(made_s: list[float]) -> dict[str, Any]:
    """Lateness as a railway reports it, of the arrivals made (delays [s], negative
    early): the mean lateness counting an early arrival as 0 (``mean_lateness_s``), and
    the early arrivals apart: how many (``early_arrivals``) and how early on average
    (``mean_earliness_s`` [s], positive); None where there is nothing to average."""
    early = [-d for d in made_s if d < 0.0]
    return {
        "mean_lateness_s": (
            round(float(np.mean([max(d, 0.0) for d in made_s])), 1) if made_s else None
        ),
        "early_arrivals": len(early),
        "mean_earliness_s": round(float(np.mean(early)), 1) if early else None,
    }


def train_rows(result: LineResult) -> dict[str, dict[str, Any]]:
    """Each train's figures in the KPI object, by train id."""
    worst = _worst_excess_kmh(result)
    rows: dict[str, dict[str, Any]] = {}
    for train_id, run in _trains(result):
        sections = run.sections
        e2e = _end_to_end(run)
        delays = run.arrival_delays_s(result.sim_s)
        rows[str(train_id)] = {
            "number": run.service.number,
            "kind": run.service.kind,
            "sections_run": len(sections),
            "sections_planned": len(run.service.stops) - 1,
            "finished": run.finished,
            "conformity_pct": {
                "sections": [
                    round(_conformity(s.running_time_s, s.planned_running_time_s), 3)
                    for s in sections
                ],
                "end_to_end": None if e2e is None else round(e2e, 3),
            },
            "energy_kwh": round(_net_energy_kwh(run), 1),
            "energy_traction_kwh": round(sum(s.energy_traction_kwh for s in sections), 1),
            "energy_regenerated_kwh": round(sum(s.energy_regenerated_kwh for s in sections), 1),
            "energy_traction_against_air_kwh": round(
                sum(s.energy_traction_against_air_kwh for s in sections), 1
            ),
            "red_signal_stops": run.red_signal_stops,
            "max_overspeed_kmh": worst.get(train_id, 0.0),
            "running_times_received": run.running_times_received,
            # at its destination; None for a train that has not arrived there
            "arrival_delay_s": round(sections[-1].arrival_s - sections[-1].planned_arrival_s, 1)
            if run.finished
            else None,
            "arrival_delays_s": [None if d is None else round(d, 1) for d in delays],
        }
    return rows


def _conformity_kpi(result: LineResult) -> dict[str, Any]:
    all_sections: list[float] = []
    end_to_end: list[float] = []
    for _, run in _trains(result):
        all_sections += [
            _conformity(s.running_time_s, s.planned_running_time_s) for s in run.sections
        ]
        e2e = _end_to_end(run)
        if e2e is not None:
            end_to_end.append(e2e)
    return {
        "mean_end_to_end": _mean(end_to_end),
        "mean_abs_section": _mean([abs(c) for c in all_sections]),
        "max_section": round(max(all_sections), 3) if all_sections else None,
    }


def _energy_kpi(result: LineResult) -> float:
    total = 0.0
    for _, run in _trains(result):
        total += _net_energy_kwh(run)
    return round(total, 1)


def _against_air_kpi(result: LineResult) -> float:
    total = 0.0
    for _, run in _trains(result):
        total += sum(s.energy_traction_against_air_kwh for s in run.sections)
    return round(total, 1)


def _punctuality_kpi(result: LineResult) -> dict[str, Any]:
    delays: list[float | None] = []
    for _, run in _trains(result):
        delays += run.arrival_delays_s(result.sim_s)
    return punctuality(delays)


def _not_arrived(result: LineResult) -> int:
    """Trains due at their destination by the end of the run that had not arrived there
    (held up, failed or stopped short: each train's row says where it got to)."""
    return sum(
        1
        for _, run in _trains(result)
        if not run.finished and run.service.stops[-1].arrival_s <= result.sim_s
    )


def _tsr_applied_twice(result: LineResult) -> int:
    return sum(1 for sessions in result.tsr_applied.values() for n in sessions.values() if n > 1)


def retiming_summary(log: list[dict[str, Any]]) -> dict[str, Any]:
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


def _on_time_text(p: Mapping[str, Any]) -> str:
    """The punctuality KPI's line: the share on time within the stated tolerance."""
    if not p["arrivals"]:
        return "no arrival was due within the run"
    minutes = ON_TIME_TOLERANCE_MIN
    return (
        f"on time within {minutes} min: {p[f'within_{minutes}_min_pct']} % of {p['arrivals']}"
        + (" (none made)" if p["max_delay_s"] is None else "")
    )


# ---------------------------------------------------------------------------- the table

#: every entry of a run's KPI object after its trains, in the object's order
KPIS: tuple[Kpi, ...] = (
    Kpi(
        "conformity_pct",
        "conformity",
        _conformity_kpi,
        (
            Figure("mean_end_to_end", "end-to-end conformity, mean", "%", better=NEARER_ZERO),
            Figure("mean_abs_section", "|section conformity|, mean", "%"),
            Figure("max_section", "section conformity, max", "%", swept=False, better=NEARER_ZERO),
        ),
        against_baseline=True,
        better=NEARER_ZERO,
        text=lambda c: (
            "end to end: no train arrived"
            if c["mean_end_to_end"] is None
            else f"end to end, mean {c['mean_end_to_end']} %"
        ),
    ),
    Kpi(
        "energy_kwh",
        "net energy",
        _energy_kpi,
        (Figure("", "net energy", "kWh"),),
        against_baseline=True,
        text=lambda e: f"{e} kWh",
    ),
    Kpi(
        "energy_traction_against_air_kwh",
        "traction against the air brake",
        _against_air_kpi,
        (Figure("", "of the traction, against the air brake", "kWh"),),
        against_baseline=True,
    ),
    Kpi(
        "punctuality",
        "punctuality",
        _punctuality_kpi,
        (
            *(
                Figure(
                    f"within_{minutes}_min_pct",
                    f"punctuality: arrivals within {minutes} min of the timetable",
                    "%",
                    swept=minutes == 3,
                    better=HIGHER,
                )
                for minutes in ON_TIME_WITHIN_MIN
            ),
            Figure(
                "mean_lateness_s",
                "punctuality: lateness, mean (an early arrival as 0)",
                "s",
                text=True,
            ),
            Figure("early_arrivals", "punctuality: early arrivals", swept=False, text=True),
            Figure(
                "mean_earliness_s",
                "punctuality: how early the early arrivals came, mean",
                "s",
                swept=False,
                text=True,
            ),
            Figure(
                "mean_delay_s",
                "punctuality: arrival delay, signed mean (early negative)",
                "s",
                better=NEARER_ZERO,
                text=True,
            ),
            Figure("max_delay_s", "punctuality: arrival delay, largest", "s", text=True),
        ),
        against_baseline=True,
        text=_on_time_text,
        better=HIGHER,
    ),
    Kpi(
        "trains_not_arrived",
        "trains not arrived",
        _not_arrived,
        (Figure("", "trains due at their destination that had not arrived"),),
        against_baseline=True,
        text=str,
    ),
    Kpi(
        "red_signal_stops",
        "red signal stops",
        lambda r: sum(d.red_signal_stops for d in r.drivers.values()),
        (Figure("", "red signal stops"),),
        against_baseline=True,
        text=str,
    ),
    _trackside_count("tsr_violations", "TSR violations", "tsr_violations"),
    _trackside_count("target_points_passed", "target points passed", "signals_passed_at_red"),
    _trackside_count("overspeeds", "overspeeds above the static limits", "overspeeds"),
    Kpi(
        "max_overspeed_kmh",
        "worst overspeed",
        lambda r: max(_worst_excess_kmh(r).values(), default=0.0),
        (Figure("", "worst overspeed above the static limits", "km/h"),),
        against_baseline=True,
    ),
    Kpi(
        "tsr_applied_twice",
        "TSR applied twice",
        _tsr_applied_twice,
        (Figure("", "TSR applied twice"),),
        safety=True,
    ),
    Kpi(
        "link",
        "link",
        lambda r: r.link,
        (
            Figure("link_failures", "link failures"),
            Figure("connects", "link connects", better=None),
        ),
        text=lambda k: f"failures {k['link_failures']}, connects {k['connects']}",
        better=None,
    ),
    Kpi("retiming", "re-timings by the ground", lambda r: retiming_summary(r.retimings())),
    Kpi("ground_restarts", "ground restarts", lambda r: r.restarts),
    Kpi(
        "timetable_shifts_s",
        "trains moved later to clear timetable conflicts [s]",
        lambda r: {str(i): s for i, s in r.scenario.shifted_s.items()} or None,
        optional=True,
    ),
    Kpi("wall_s", "wall clock [s]", lambda r: round(r.wall_s, 3)),
    Kpi(
        "live",
        "live run",
        lambda r: None if r.live is None else asdict(r.live),
        optional=True,
    ),
    Kpi(
        "realtime_factor",
        "simulated seconds per wall-clock second",
        lambda r: round(r.sim_s / r.wall_s, 1) if r.wall_s > 0 else None,
        (Figure("", "simulated seconds per wall-clock second", better=HIGHER),),
    ),
)
#: the KPI whose baseline figure the KPI object also gives on top (``baseline_<name>``,
#: ``human_baseline_<name>``)
HEADLINE = "energy_kwh"
#: how the KPI object's ``driver`` names who drove a run, and the prefix of a baseline's
#: headline figure on top of the object, by driver (cosim/driver.py ``DRIVERS``)
DRIVER_LABELS = {"advised": "advised", "minimum-time": "baseline", "human": "human"}
HEADLINE_PREFIX = {"minimum-time": "baseline", "human": "human_baseline"}
#: how the command line's text names a baseline's figure beside the run's
TEXT_LABELS = {"minimum-time": "baseline", "human": "human baseline"}
#: each baseline in one sentence, by driver, for a reader of the text or the report
#: (docs/line-run.md "The baseline" and "The human-driver baseline")
BASELINE_DEFINITIONS = {
    "minimum-time": "the same day (trains, timetable, events, radio, seed) driven to the "
    "static limits less the scenario's margin, full traction and late braking, without "
    "advice, without target points and without re-timing",
    "human": "the same day driven as a careful heavy-haul driver without advice drives "
    "it (8 km/h under the limit, coasting before each braking point, cyclic braking on "
    "long descents), without target points and without re-timing",
}


def by_name(name: str) -> Kpi:
    """The table's entry ``name``; an unknown name is an error naming the known ones."""
    for kpi in KPIS:
        if kpi.name == name:
            return kpi
    raise KeyError(f"no KPI {name!r}; the KPIs: {', '.join(k.name for k in KPIS)}")


def safety_kpis() -> list[Kpi]:
    """The KPIs a correct run has at 0."""
    return [k for k in KPIS if k.safety]


def safety_phrase() -> str:
    """The safety KPIs' labels in one phrase, for a sentence saying none happened:
    ``TSR violations, target points passed, ... or TSR applied twice``."""
    labels = [k.label for k in safety_kpis()]
    return labels[0] if len(labels) == 1 else f"{', '.join(labels[:-1])} or {labels[-1]}"


def swept() -> list[str]:
    """Every dotted path into the KPI object a sweep gives the spread of, in table order."""
    return [path for kpi in KPIS for path in kpi.swept()]


# ------------------------------------------------------------------------ the KPI object


def kpi_object(
    result: LineResult, baseline: LineResult | None = None, human: LineResult | None = None
) -> dict[str, Any]:
    """The KPI object of ``railpilot line simulate --json``: the run, its trains, then
    every entry of :data:`KPIS`, and the baselines' figures of the KPIs set against them:
    the minimum-time ``baseline``'s as ``baseline`` (its headline ``baseline_energy_kwh``),
    the ``human`` one's headline as ``human_baseline_energy_kwh``, and each given one's in
    ``baselines``, by driver (cosim/driver.py ``BASELINES``)."""
    out: dict[str, Any] = {
        "scenario": result.scenario.name,
        "seed": result.seed,
        "driver": DRIVER_LABELS[result.driver],
        "train_model": result.scenario.train_model,
        "sim_s": result.sim_s,
        "trains": train_rows(result),
    }
    for kpi in KPIS:
        value = kpi.of_run(result)
        if value is not None or not kpi.optional:
            out[kpi.name] = value
    baselines: dict[str, dict[str, Any]] = {}
    # by the slot it is given in (a study may set any run against this one)
    for name, run in (("minimum-time", baseline), ("human", human)):
        if run is None:
            continue
        base = kpi_object(run)
        baselines[name] = {k.name: base[k.name] for k in KPIS if k.against_baseline}
        out[f"{HEADLINE_PREFIX[name]}_{HEADLINE}"] = base[HEADLINE]
    if baseline is not None:
        out["baseline"] = baselines["minimum-time"]
    if baselines:
        out["baselines"] = baselines
    return out


def dig(kpis: Mapping[str, Any], dotted: str) -> float | None:
    """The number at ``dotted`` (``"a.b"``) in a KPI object; None where there is none."""
    obj: Any = kpis
    for part in dotted.split("."):
        if not isinstance(obj, Mapping) or part not in obj:
            return None
        obj = obj[part]
    return obj if isinstance(obj, int | float) else None


def _shown(value: Any) -> str:
    """A figure in the text: ``-`` where a run has none (never "None")."""
    return "-" if value is None else str(value)


def text_lines(kpis: Mapping[str, Any]) -> list[str]:
    """The KPIs of one run as the command line prints them: one line each of those with a
    ``text``, then one for each of its figures marked ``text``; each baseline's beside it
    where the KPI object has it, and which way is better at the end."""
    baselines = kpis.get("baselines", {})
    lines = []
    for kpi in KPIS:
        text = kpi.text
        if text is None or kpi.name not in kpis:
            continue
        against = [(name, f[kpi.name]) for name, f in baselines.items() if kpi.name in f]
        line = f"  {kpi.label}: {text(kpis[kpi.name])}"
        beside = [f"{TEXT_LABELS[name]} {text(value)}" for name, value in against]
        lines.append(_with_better(line, beside, kpi.better))
        for figure in kpi.figures:
            if figure.text:
                path = kpi.path(figure)
                line = f"  {figure.title}: {_shown(dig(kpis, path))}"
                beside = [
                    f"{TEXT_LABELS[name]} {_shown(dig({kpi.name: value}, path))}"
                    for name, value in against
                ]
                lines.append(_with_better(line, beside, figure.better))
    return lines


def _with_better(line: str, beside: list[str], better: str | None) -> str:
    """A line of the text, the baselines' figures beside it, and which way is better."""
    if beside:
        line += f" ({'; '.join(beside)})"
    return f"{line} [{better_phrase(better)}]" if better is not None else line


# ------------------------------------------------------------------------------ a sweep


def spread(values: Sequence[float], seeds: Sequence[int]) -> dict[str, Any]:
    """How a sweep aggregates one swept figure: its smallest, quantiles
    (:data:`SWEEP_QUANTILES`), largest and mean, and which runs to look at again (the
    first seed giving each extreme). ``values[k]`` is the run of ``seeds[k]``."""
    found = list(zip(values, seeds, strict=True))
    ordered = sorted(values)
    quantiles = np.quantile(
        np.asarray(ordered, dtype=float), [q for _, q in SWEEP_QUANTILES], method=QUANTILE_METHOD
    )
    return {
        "min": ordered[0],
        **{
            name: round(float(value), SWEEP_DIGITS)
            for (name, _), value in zip(SWEEP_QUANTILES, quantiles, strict=True)
        },
        "max": ordered[-1],
        "mean": round(sum(ordered) / len(ordered), SWEEP_DIGITS),
        "min_seed": min(found)[1],
        "max_seed": max(found, key=lambda pair: (pair[0], -pair[1]))[1],
    }


def sweep_summary(seeds: Sequence[int], results: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The spread of every swept figure over the runs (``results[k]`` the KPI object of
    ``seeds[k]``), and for each KPI counted so, the runs where it was not 0."""
    out: dict[str, Any] = {"kpis": {}}
    for path in swept():
        found = [
            (v, s) for s, r in zip(seeds, results, strict=True) if (v := dig(r, path)) is not None
        ]
        if found:
            out["kpis"][path] = spread([v for v, _ in found], [s for _, s in found])
    for kpi in KPIS:
        if kpi.count_runs_not_zero:
            out[f"runs_with_{kpi.name}"] = sum(1 for r in results if r[kpi.name])
    return out


def progress_line(kpis: Mapping[str, Any]) -> str:
    """A finished run of a sweep in a few words: its safety KPIs counted over a sweep and
    its net energy."""
    counts = ", ".join(f"{kpis[k.name]} {k.label}" for k in KPIS if k.count_runs_not_zero)
    unit = by_name(HEADLINE).figures[0].unit
    return f"{counts}, {kpis[HEADLINE]} {unit}"
