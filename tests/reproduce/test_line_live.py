"""The line-live section of the report (railpilot.reproduce.line_live): its tables show the
two runs' KPIs, and its findings say whether the live run kept the tolerance, from the
numbers. The runs themselves are tests/cosim/test_live.py's (the whole section, a live
hour at 60x, is `make demo`'s); here the section is fed the co-simulation's KPIs of the
live file's first 20 minutes as both runs, then one with a train moved off.
"""

from __future__ import annotations

import copy

import pytest

from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import load_line_scenario
from railpilot.reproduce import REPRODUCTIONS, line_live
from railpilot.reproduce.base import find_example

# a line run for its report
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def kpis() -> dict:  # type: ignore[type-arg]
    scenario = load_line_scenario(find_example(line_live.SCENARIO_FILE))
    return run_line(scenario, until_s=1200.0).kpis()


def test_registered_after_the_line_day_and_before_the_dashboard() -> None:
    names = list(REPRODUCTIONS)
    assert names.index("line-day") < names.index("line-live") < names.index("dashboard")


def test_the_train_table_is_the_kpis(kpis) -> None:  # type: ignore[no-untyped-def]
    table = line_live.train_table(kpis, kpis, "note")
    rows = {row[0]: row[1:] for row in table.rows}
    for row in kpis["trains"].values():
        got = rows[row["number"]]
        assert got[0] == got[1] == row["conformity_pct"]["end_to_end"]
        assert got[2] == got[3] == row["energy_kwh"]
        assert got[4] == got[5] == row["red_signal_stops"]
    assert rows["tsr violations"][-3:-1] == [kpis["tsr_violations"]] * 2


def test_findings_name_a_train_outside_the_tolerance(kpis) -> None:  # type: ignore[no-untyped-def]
    seen = {"screenshot": None, "skipped": "no browser here"}
    same = line_live.findings(kpis, kpis, seen)
    finished = [r for r in kpis["trains"].values() if r["conformity_pct"]["end_to_end"]]
    if finished:
        assert same[0].startswith("Every train's")
    moved = copy.deepcopy(kpis)
    row = next(iter(moved["trains"].values()))
    row["energy_kwh"] = row["energy_kwh"] * (1 + 2 * line_live.ENERGY_REL) + 1.0
    apart = line_live.findings(moved, kpis, seen)
    assert apart[0].startswith("Outside the tolerance") and row["number"] in apart[0]
    assert "no browser here" in apart[-1]


def test_the_link_table_has_both_sides_and_the_radio_of_both_runs(kpis) -> None:  # type: ignore[no-untyped-def]
    kpis = copy.deepcopy(kpis)
    other = copy.deepcopy(kpis)
    other["link"]["channel"]["lost_dead_zone"] = 12345
    table = line_live.link_table(kpis, other)
    sides = {row[0]: row[1:] for row in table.rows}
    assert sides["onboard"][0] == kpis["link"]["onboard"]["frames_sent"]
    assert sides["ground"][4] == kpis["link"]["ground"]["link_failures"]
    live, cosim = table.note.split("co-simulated:")
    assert f"{kpis['link']['channel']['packets']} packets" in live
    assert "dead zone 12345" in cosim and "dead zone 12345" not in live
