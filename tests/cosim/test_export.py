"""A line run's tables (cosim/export.py) against the result they come from and its KPIs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from railpilot.cosim.export import (
    SECTION_COLUMNS,
    TRACE_COLUMNS,
    events_document,
    section_table,
    trace_table,
)
from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping

# a line day, exported
pytestmark = pytest.mark.slow

#: two trains, a TSR and a re-timing's cause (a train standing), within an hour and a half
SCENARIO = {
    "name": "export",
    "line": "heavy-haul",
    "seed": 3,
    "duration_h": 1.5,
    "services": [
        {
            "kind": "loaded",
            "from": 1,
            "to": 3,
            "first_departure_min": 1.0,
            "every_min": 15.0,
            "count": 2,
            "first_id": 101,
        }
    ],
    "events": [
        {
            "at_min": 10.0,
            "op": "tsr_set",
            "start_km": 30.0,
            "end_km": 32.0,
            "limit_kmh": 45,
            "valid_until_min": 80,
            "reason": "track work",
        },
        {"at_min": 30.0, "op": "train_failure", "train": 101, "stand_min": 10.0},
    ],
}


@pytest.fixture(scope="module")
def run():  # type: ignore[no-untyped-def]
    return run_line(line_scenario_from_mapping(SCENARIO))


def test_the_trace_is_the_trackside_samples_in_km_and_kmh(run) -> None:  # type: ignore[no-untyped-def]
    table = trace_table(run)
    assert tuple(table.columns) == TRACE_COLUMNS
    assert len(table) == sum(len(rows) for rows in run.trace.values())
    for train_id, rows in run.trace.items():
        mine = table[table["train"] == train_id]
        assert set(mine["number"]) == {run.drivers[train_id].service.number}
        assert_allclose(mine["t_s"], rows[:, 0])
        assert_allclose(mine["km"] * 1000.0, rows[:, 1])
        assert_allclose(mine["speed_kmh"] / 3.6, rows[:, 2])
    assert set(table["driver"]) == {"advised"}


def test_the_sections_are_those_the_kpis_are_computed_from(run) -> None:  # type: ignore[no-untyped-def]
    table = section_table(run)
    kpis = run.kpis()
    assert tuple(table.columns) == SECTION_COLUMNS
    assert len(table) == sum(t["sections_run"] for t in kpis["trains"].values())
    for train_id, row in kpis["trains"].items():
        mine = table[table["train"] == int(train_id)]
        finished = mine["conformity_pct"].dropna()
        assert_allclose(finished, row["conformity_pct"]["sections"], atol=5e-4)
        net = (mine["energy_traction_kwh"] - mine["energy_regenerated_kwh"]).sum()
        assert net == pytest.approx(row["energy_kwh"], abs=0.05)
        assert mine["energy_traction_against_air_kwh"].sum() == pytest.approx(
            row["energy_traction_against_air_kwh"], abs=0.05
        )
        # conformity as paper 001 defines it, from the row's own times
        for r in mine.itertuples():
            if math.isfinite(r.arrival_s):
                planned = r.planned_arrival_s - r.planned_departure_s
                actual = r.arrival_s - r.departure_s
                assert r.conformity_pct == pytest.approx((actual - planned) / planned * 100)


def test_the_events_are_on_the_runs_clock_and_are_json(run) -> None:  # type: ignore[no-untyped-def]
    document = events_document(run)
    text = json.dumps(document, default=str)  # what --out writes, NaN aside
    assert json.loads(text)["scenario"] == "export"
    kinds = [e["event"] for e in document["events"]]
    assert "tsr_set" in kinds and "train_failure" in kinds
    assert document["retiming"], "the standing train must make the ground re-time"
    times = [e["t_s"] for e in document["retiming"]]
    # within the run, not on the ground's clock (1.8e9 s on)
    assert all(0.0 <= t <= run.sim_s for t in times)
    logged = [e["t_s"] for e in run.kpis()["retiming"]["log"]]
    assert_allclose(logged, np.round(times[: len(logged)], 1), atol=0.051)
    # the log in the result keeps the ground's own times
    assert run.retiming[0]["t_s"] - run.scenario.epoch_s == pytest.approx(times[0])
    # the TSR's validity, as the ground answered it, on the run's clock too: from when it
    # was set (10 min) for the 80 minutes the scenario gives (operations count from now)
    (tsr_set,) = [e for e in document["events"] if e["event"] == "tsr_set"]
    assert tsr_set["t_s"] == pytest.approx(600.0)
    assert tsr_set["result"]["valid_from_s"] == pytest.approx(600.0)
    assert tsr_set["result"]["valid_until_s"] == pytest.approx(5400.0)
    assert tsr_set["tsr"]["from_s"] == tsr_set["result"]["valid_from_s"]
    (kept,) = [e for e in run.events if e["event"] == "tsr_set"]
    assert kept["result"]["valid_from_s"] == pytest.approx(run.scenario.epoch_s + 600.0)
