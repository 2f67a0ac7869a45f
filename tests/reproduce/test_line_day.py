"""The line-day section of the report (railpilot.reproduce.line_day) on the first
``UNTIL_S`` of the short day: the section's tables and findings say what the two runs'
KPIs say, and both figures are written. The whole day (about a minute) is `make demo`'s.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from railpilot.cosim.scenario import load_line_scenario
from railpilot.errors import ConfigError
from railpilot.reproduce import REPRODUCTIONS, base, line_day

# the short line day, run twice
pytestmark = pytest.mark.slow

#: long enough for the first loaded train to run a section (about 15 s for both runs)
UNTIL_S = 1800.0
#: the KPIs the findings call safe when all are 0 in both runs
SAFETY = ("tsr_violations", "target_points_passed", "tsr_applied_twice", "overspeeds")


@pytest.fixture(scope="module")
def section(tmp_path_factory):
    out = tmp_path_factory.mktemp("line_day")
    return line_day.run(out, until_s=UNTIL_S), out


def _rows(table):
    return {row[0]: row[1:] for row in table.rows}


def test_registered_before_the_dashboard():
    names = list(REPRODUCTIONS)
    assert names[-1] == "dashboard"
    assert names.index("line-day") < names.index("dashboard")


def test_both_runs_are_the_short_day(section):
    payload = section[0].payload
    assert payload["advised"]["driver"] == "advised"
    assert payload["baseline"]["driver"] == "baseline"
    assert payload["advised"]["trains"].keys() == payload["baseline"]["trains"].keys()
    # something happened: a train arrived, the link carried frames
    assert any(t["sections_run"] for t in payload["advised"]["trains"].values())
    assert payload["advised"]["link"]["channel"]["packets"] > 0


def test_the_kpi_table_is_the_kpis(section):
    payload = section[0].payload
    a, b = payload["advised"], payload["baseline"]
    rows = _rows(section[0].tables[0])
    for run, kpis in ((0, a), (1, b)):
        conformity = kpis["conformity_pct"]
        # no train at its destination yet in the first half hour: no end-to-end mean
        mean = conformity["mean_end_to_end"]
        assert rows["end-to-end conformity, mean [%]"][run] == ("-" if mean is None else mean)
        assert rows["|section conformity|, mean [%]"][run] == conformity["mean_abs_section"]
        assert rows["net energy [kWh]"][run] == round(kpis["energy_kwh"])
        traction = sum(t["energy_traction_kwh"] for t in kpis["trains"].values())
        assert rows["traction drawn [kWh]"][run] == round(traction)
        assert rows["red signal stops"][run] == kpis["red_signal_stops"]
        assert rows["TSR violations"][run] == kpis["tsr_violations"]
        assert rows["target points passed"][run] == kpis["target_points_passed"]
        assert rows["TSR applied twice"][run] == kpis["tsr_applied_twice"]
        assert rows["overspeeds above the static limits"][run] == kpis["overspeeds"]
        finished = sum(t["finished"] for t in kpis["trains"].values())
        assert rows["trains finished"][run] == finished
    assert rows["net energy [kWh]"][2] == round(a["energy_kwh"]) - round(b["energy_kwh"])


def test_the_train_table_is_each_trains_kpis(section):
    payload = section[0].payload
    table = section[0].tables[1]
    assert len(table.rows) == len(payload["advised"]["trains"])
    by_number = {row[0]: row for row in table.rows}
    for train_id, a in payload["advised"]["trains"].items():
        b = payload["baseline"]["trains"][train_id]
        row = by_number[a["number"]]
        assert row[1] == a["kind"]
        for cell, value in (
            (row[4], a["conformity_pct"]["end_to_end"]),
            (row[5], b["conformity_pct"]["end_to_end"]),
            (row[6], a["arrival_delay_s"]),
            (row[7], b["arrival_delay_s"]),
        ):
            if value is None:
                assert cell == "-"
            else:
                assert cell == pytest.approx(value, abs=0.5)
        assert row[8:] == [round(a["energy_kwh"]), round(b["energy_kwh"])]


def test_the_link_table_is_the_link_report(section):
    payload = section[0].payload
    rows = _rows(section[0].tables[-1])
    a, b = payload["advised"]["link"], payload["baseline"]["link"]
    for name, value in a["ground"].items():
        if name == "rejected":
            for check, n in value.items():
                assert rows[f"rejected: {check}"][0] == n
        else:
            label = name.replace("_", " ")
            assert rows[label][:4] == [
                value,
                a["onboard"][name],
                b["ground"][name],
                b["onboard"][name],
            ]
    assert rows["radio: packets"][0] == a["channel"]["packets"]
    assert rows["radio: delivered"][2] == b["channel"]["delivered"]
    assert rows["sessions: connects"][0] == a["connects"]
    assert rows["sessions: link failures"][2] == b["link_failures"]


def test_the_knock_on_table_is_the_day_without_the_failure(section):
    reproduction = section[0]
    knock = reproduction.payload["knock_on"]
    assert knock["own_train"] == 102 and knock["event"]["label"] == "train_failure"
    (table,) = [t for t in reproduction.tables if "failure cost each train" in t.title]
    assert [row[0] for row in table.rows] == [
        t["number"] + (" (failed)" if t["own"] else "") for t in knock["trains"].values()
    ]
    # cut at 30 min, before the failure at 45: the day without it is the same to the bit
    assert knock["event"]["at_s"] > UNTIL_S
    assert all(row[3] in (0.0, "-") and row[4] == 0 for row in table.rows)
    assert knock["knock_on_others_s"] == 0.0


def test_findings_are_computed_from_the_kpis(section):
    reproduction = section[0]
    a, b = reproduction.payload["advised"], reproduction.payload["baseline"]
    text = " ".join(reproduction.findings)
    assert f"{a['energy_kwh']:.0f} kWh advised, {b['energy_kwh']:.0f} kWh baseline" in text
    safe = all(k[key] == 0 for k in (a, b) for key in SAFETY)
    assert ("No TSR violation" in text) == safe
    # a violation in the baseline is said, not hidden
    worse = copy.deepcopy(b)
    worse["tsr_violations"] = 1
    said = " ".join(line_day.findings(a, worse))
    assert "No TSR violation" not in said and "tsr violations 0 advised / 1 baseline" in said


def test_both_figures_are_written(section):
    reproduction, out = section
    names = [p.name for p in reproduction.figures]
    assert names == [line_day.TIME_DISTANCE_PNG, line_day.ENERGY_PNG]
    for path in reproduction.figures:
        assert path.parent == out
        assert path.stat().st_size > 10_000


def test_a_stand_away_from_the_stops_is_found():
    scenario = load_line_scenario(line_day.scenario_path())
    service = scenario.services[0]
    line = scenario.line
    origin = line.station(service.stops[0].station).stop_m(service.direction)
    t = np.arange(0.0, 1000.0)
    # at the origin's stop 100 s, running, then at rest 10 min 5 km on
    head = np.where(t < 100, origin, np.where(t < 300, origin + 5000.0 * (t - 100) / 200, 0))
    head = np.where(t >= 300, origin + 5000.0, head)
    speed = np.where((t >= 100) & (t < 300), 25.0, 0.0)
    trace = {service.train_id: np.column_stack([t, head, speed])}
    [stand] = line_day.long_stands(scenario, trace)
    assert stand.number == service.number
    assert (stand.from_s, stand.until_s) == (300.0, 999.0)
    assert stand.km == pytest.approx((origin + 5000.0) / 1000.0)


def test_no_examples_folder_is_a_clear_error(monkeypatch, tmp_path):
    # the examples are looked for next to the package's source (reproduce/base.py)
    monkeypatch.setattr(base, "__file__", str(tmp_path / "a" / "b" / "c" / "base.py"))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match="examples are not installed"):
        line_day.scenario_path()
