"""Lateness as a railway reports it (cosim/kpis.py ``lateness``, ``punctuality``): the
mean lateness counting an early arrival as 0, the early arrivals apart, the signed mean
beside them; every figure a report sets against a baseline says which way is better, the
text says it on every line and defines each baseline, and the report's section does too
(reproduce/line_day.py)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cosim.tiny_line_run import TINY
from railpilot.cosim import kpis as table
from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.reproduce import line_day


def test_an_early_arrival_is_not_late_and_is_counted_apart() -> None:
    # 168 s early, 30 s late, 90 s late: late on average by (0 + 30 + 90) / 3 = 40 s; the
    # signed mean, (-168 + 30 + 90) / 3 = -16 s, would make the three look early
    out = table.punctuality([-168.0, 30.0, 90.0])
    assert out["mean_lateness_s"] == 40.0
    assert out["mean_delay_s"] == -16.0
    assert out["early_arrivals"] == 1
    assert out["mean_earliness_s"] == 168.0
    assert out["within_1_min_pct"] == pytest.approx(200.0 / 3.0, abs=0.05)


def test_nothing_to_average_is_none_never_a_number() -> None:
    assert table.lateness([]) == {
        "mean_lateness_s": None,
        "early_arrivals": 0,
        "mean_earliness_s": None,
    }
    # on time to the second is not early
    assert table.lateness([0.0, 12.0]) == {
        "mean_lateness_s": 6.0,
        "early_arrivals": 0,
        "mean_earliness_s": None,
    }
    # an arrival not made is not averaged: the share on time counts it as late
    out = table.punctuality([None, -60.0])
    assert out["not_made"] == 1 and out["mean_lateness_s"] == 0.0
    assert out["within_1_min_pct"] == 50.0


delays = st.lists(st.floats(-3600.0, 3600.0, allow_nan=False), max_size=40)


@given(delays)
def test_the_lateness_is_the_signed_mean_with_early_as_zero(made: list[float]) -> None:
    out = table.lateness(made)
    if not made:
        return
    late = [max(d, 0.0) for d in made]
    assert out["mean_lateness_s"] == pytest.approx(sum(late) / len(late), abs=0.051)
    assert out["mean_lateness_s"] >= 0.0
    # never below the signed mean: counting the early ones as 0 only raises it
    assert out["mean_lateness_s"] + 0.051 >= sum(made) / len(made)
    early = [-d for d in made if d < 0.0]
    assert out["early_arrivals"] == len(early)
    if early:
        assert out["mean_earliness_s"] == pytest.approx(sum(early) / len(early), abs=0.051)


def test_every_figure_set_against_a_baseline_says_which_way_is_better() -> None:
    allowed = {table.LOWER, table.HIGHER, table.NEARER_ZERO}
    for kpi in table.KPIS:
        if kpi.against_baseline or kpi.safety:
            for figure in kpi.figures:
                assert figure.better in allowed, kpi.path(figure)
        if kpi.text is not None and kpi.against_baseline:
            assert kpi.better in allowed, kpi.name
    punctuality = table.by_name("punctuality")
    better = {f.path: f.better for f in punctuality.figures}
    assert better["within_3_min_pct"] == table.HIGHER
    assert better["mean_lateness_s"] == table.LOWER
    assert better["mean_delay_s"] == table.NEARER_ZERO  # early is no better than late
    assert table.by_name("conformity_pct").figures[0].better == table.NEARER_ZERO


@pytest.fixture(scope="module")
def runs():  # type: ignore[no-untyped-def]
    scenario = line_scenario_from_mapping(TINY)
    return run_line(scenario), run_line(scenario, driver="minimum-time")


@pytest.mark.slow
def test_the_text_gives_each_lateness_figure_beside_the_baselines(runs) -> None:  # type: ignore[no-untyped-def]
    advised, baseline = runs
    kpis = advised.kpis(baseline)
    lines = table.text_lines(kpis)
    punctuality = kpis["punctuality"]
    for path in ("mean_lateness_s", "early_arrivals", "mean_earliness_s", "mean_delay_s"):
        figure = next(f for f in table.by_name("punctuality").figures if f.path == path)
        line = next(x for x in lines if x.startswith(f"  {figure.title}: "))
        value = punctuality[path]
        shown = "-" if value is None else str(value)
        assert line.startswith(f"  {figure.title}: {shown} (baseline ")
        assert line.endswith(f"[{figure.better} is better]")
    on_time = next(x for x in lines if x.startswith("  punctuality: "))
    assert f"on time within {table.ON_TIME_TOLERANCE_MIN} min" in on_time
    assert on_time.endswith("[higher is better]")
    assert all("None" not in line for line in lines)


@pytest.mark.slow
def test_the_reports_table_says_which_way_each_row_is_better(runs) -> None:  # type: ignore[no-untyped-def]
    advised, baseline = runs
    a, b = advised.kpis(), baseline.kpis()
    kpi_table = line_day.kpi_table(a, b)
    assert kpi_table.columns[-1] == "better"
    rows = {row[0]: row for row in kpi_table.rows}
    for kpi in table.KPIS:
        if kpi.against_baseline or kpi.safety:
            for figure in kpi.figures:
                assert rows[figure.title][-1] == f"{figure.better} is better", figure.title
    assert rows["punctuality: lateness, mean (an early arrival as 0) [s]"][1:3] == [
        "-" if (v := k["punctuality"]["mean_lateness_s"]) is None else v for k in (a, b)
    ]
    # the table defines its baseline in one sentence
    assert kpi_table.note.startswith("The baseline is the same day")
    assert line_day.findings(a, b)[0] == line_day.baseline_sentence()


def test_the_reports_finding_gives_lateness_as_a_railway_does() -> None:
    pa = table.punctuality([-168.0, 30.0, 90.0])
    pb = table.punctuality([200.0, 30.0, None])
    said = line_day.punctuality_finding(pa, pb)
    assert "Mean lateness, an early arrival counted as 0: 40.0 s advised, 115.0 s baseline" in said
    assert "early arrivals: 1 (by 168.0 s on average) advised, none baseline" in said
    assert "signed mean delay, where early minutes offset late ones: -16.0 s advised" in said
    assert f"at most {table.ON_TIME_TOLERANCE_MIN} min late" in said
    assert "None" not in said
