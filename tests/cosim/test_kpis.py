"""The line run's KPI table (cosim/kpis.py): every KPI of a run's object comes from the
table, in its order; the counts of what the trackside saw are the sightings the events
document lists; the safety KPIs are 0 on the shipped short day; and a sweep aggregates
each swept figure as NumPy does.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cosim.tiny_line_run import TINY
from railpilot.cosim import kpis as table
from railpilot.cosim.export import events_document
from railpilot.cosim.line_run import Overspeed, SignalPassedAtRed, TsrViolation, run_line
from railpilot.cosim.scenario import line_scenario_from_mapping

#: what the KPI object gives before the table's entries
HEADER = ["scenario", "seed", "driver", "train_model", "sim_s", "trains"]


@pytest.fixture(scope="module")
def runs():
    scenario = line_scenario_from_mapping(TINY)
    return run_line(scenario), run_line(scenario, advised=False)


def test_the_names_are_unique_and_found_by_name():
    names = [k.name for k in table.KPIS]
    assert len(set(names)) == len(names)
    for name in names:
        assert table.by_name(name).name == name
    with pytest.raises(KeyError, match="energy_kwh"):  # the known ones are named
        table.by_name("coupler_force")


def test_every_entry_after_the_trains_is_the_tables_in_its_order(runs):
    advised, baseline = runs
    kpis = advised.kpis(baseline)
    entries = [k.name for k in table.KPIS if not (k.optional and k.of_run(advised) is None)]
    assert list(kpis) == [
        *HEADER,
        *entries,
        f"baseline_{table.HEADLINE}",
        "baseline",
        "baselines",
    ]
    # left out of a co-simulated run's object without conflicts: the live run's figure,
    # and the shifts of a file that asked for conflicts to be shifted
    assert [k.name for k in table.KPIS if k.name not in kpis] == ["timetable_shifts_s", "live"]


def test_each_value_is_its_entrys_computed_from_the_run(runs):
    advised, _ = runs
    kpis = advised.kpis()
    for kpi in table.KPIS:
        if kpi.name in kpis:
            assert kpis[kpi.name] == kpi.of_run(advised), kpi.name


def test_the_baseline_holds_the_kpis_set_against_it(runs):
    advised, baseline = runs
    kpis, base = advised.kpis(baseline), baseline.kpis()
    against = [k.name for k in table.KPIS if k.against_baseline]
    assert list(kpis["baseline"]) == against
    assert kpis["baseline"] == {name: base[name] for name in against}
    assert kpis[f"baseline_{table.HEADLINE}"] == base[table.HEADLINE]


def test_every_figure_is_a_number_of_a_runs_object_or_missing(runs):
    advised, _ = runs
    kpis = advised.kpis()
    for kpi in table.KPIS:
        for figure in kpi.figures:
            path = kpi.path(figure)
            *inside, last = path.split(".")
            holder = kpis
            for part in inside:
                holder = holder[part]
            assert last in holder, path  # a figure the object has, if only as None
            value = holder[last]
            assert value is None or table.dig(kpis, path) == value, path


def test_the_safety_kpis_are_counts_of_the_trackside_or_the_ground():
    safety = {k.name for k in table.safety_kpis()}
    assert {"tsr_violations", "target_points_passed", "overspeeds"} <= safety
    assert all(table.by_name(name).figures[0].unit == "" for name in safety)
    # a sweep counts the runs of each trackside sighting
    counted = {k.name for k in table.KPIS if k.count_runs_not_zero}
    assert counted == {k.name for k in table.KPIS if k.records is not None}


def test_the_counts_are_the_sightings_the_events_document_lists(runs):
    advised, _ = runs
    seen = dataclasses.replace(
        advised,
        tsr_violations=[TsrViolation(101, 1, 60.0, ["head"], 52.5, 40.0)] * 2,
        signals_passed_at_red=[SignalPassedAtRed(101, 70.0, 12.3, "U3", [102])],
        overspeeds=[Overspeed(101, 10.0, 12.0, 11.0, 5.5, 83.0, 80.0, 3.0)] * 3,
    )
    kpis, document = seen.kpis(), events_document(seen)
    for kpi in table.KPIS:
        if kpi.records is None:
            continue
        key, of_run = kpi.records
        assert kpis[kpi.name] == len(of_run(seen)) == len(document[key]) > 0, kpi.name
        assert document[key] == [dataclasses.asdict(r) for r in of_run(seen)]
    assert kpis["max_overspeed_kmh"] == 3.0 == kpis["trains"]["101"]["max_overspeed_kmh"]


def test_the_text_prints_each_kpi_with_a_text_and_the_baseline_beside_it(runs):
    advised, baseline = runs
    kpis = advised.kpis(baseline)
    lines = table.text_lines(kpis)
    # each KPI's line, then a line for each of its figures printed on their own
    printed = [
        (f"  {title}: ", kpi)
        for kpi in table.KPIS
        if kpi.text is not None
        for title in (kpi.label, *(f.title for f in kpi.figures if f.text))
    ]
    assert len(lines) == len(printed)
    for line, (start, kpi) in zip(lines, printed, strict=True):
        assert line.startswith(start)
        assert ("(baseline " in line) == kpi.against_baseline
    assert all("(baseline" not in line for line in table.text_lines(advised.kpis()))


# --- a sweep ---------------------------------------------------------------------------

numbers = st.one_of(
    st.integers(-1000, 1000),
    st.floats(-1e6, 1e6, allow_nan=False).map(lambda x: round(x, 3)),
)


@given(st.lists(numbers, min_size=1, max_size=60), st.integers(0, 1000))
def test_a_figures_spread_is_numpys(values, first_seed):
    seeds = list(range(first_seed, first_seed + len(values)))
    spread = table.spread(values, seeds)
    assert list(spread) == [
        "min",
        *(name for name, _ in table.SWEEP_QUANTILES),
        "max",
        "mean",
        "min_seed",
        "max_seed",
    ]
    assert spread["min"] == min(values) and spread["max"] == max(values)
    for name, q in table.SWEEP_QUANTILES:
        # numpy's default percentile, on the values as the runs gave them (unsorted)
        expected = np.percentile(np.asarray(values, dtype=float), 100.0 * q)
        assert spread[name] == pytest.approx(expected, abs=1.5 * 10.0**-table.SWEEP_DIGITS)
        assert spread["min"] <= spread[name] <= spread["max"]
    assert spread["mean"] == pytest.approx(np.mean(values), abs=1e-4, rel=1e-12)
    # the first seed giving each extreme
    assert spread["min_seed"] == seeds[values.index(min(values))]
    assert spread["max_seed"] == seeds[values.index(max(values))]


# each example draws a whole KPI object per run: 40 cover every swept figure many times
@settings(max_examples=40)
@given(st.data(), st.integers(1, 8))
def test_a_sweep_summarises_every_swept_figure_and_counts_the_safety_runs(data, runs):
    seeds = list(range(runs))
    results = []
    for _ in seeds:
        kpis: dict = {}
        for path in table.swept():
            *inside, last = path.split(".")
            holder = kpis
            for part in inside:
                holder = holder.setdefault(part, {})
            holder[last] = data.draw(st.one_of(st.none(), st.integers(0, 3)))
        results.append(kpis)
    summary = table.sweep_summary(seeds, results)
    for path in table.swept():
        given_values = [r for r in (table.dig(k, path) for k in results) if r is not None]
        if given_values:
            assert summary["kpis"][path]["min"] == min(given_values)
            assert summary["kpis"][path]["max"] == max(given_values)
        else:  # no run has it: nothing to summarise
            assert path not in summary["kpis"]
    assert list(summary["kpis"]) == [p for p in table.swept() if p in summary["kpis"]]
    for kpi in table.KPIS:
        if kpi.count_runs_not_zero:
            counted = summary[f"runs_with_{kpi.name}"]
            assert counted == sum(1 for r in results if r[kpi.name])


def test_dig_finds_numbers_only():
    kpis = {"a": {"b": 2.5, "c": "x", "d": None}, "e": 3}
    assert table.dig(kpis, "a.b") == 2.5
    assert table.dig(kpis, "e") == 3
    for missing in ("a.c", "a.d", "a.z", "e.f", "a"):
        assert table.dig(kpis, missing) is None, missing
