"""The operator's punctuality KPI of a line run (cosim/line_run.py ``TrainRun.
arrival_delays_s``, ``punctuality``): every arrival at a timetabled stop against the
timetable, by hand, and on a real short day against the trains' own sections."""

from __future__ import annotations

import math

import pytest

from railpilot.cosim import kpis as kpi_table
from railpilot.cosim.driver import SectionRun, Service, Stop
from railpilot.cosim.line_run import TrainRun, punctuality, run_line
from railpilot.cosim.scenario import load_line_scenario
from railpilot.reproduce.base import find_example

# a short line day
pytestmark = pytest.mark.slow

#: three stops: away at 0 s, at station 2 from 1,000 to 1,100 s, at station 3 at 2,000 s
SERVICE = Service(
    7,
    "K7",
    "loaded",
    (Stop(1, math.nan, 0.0), Stop(2, 1000.0, 1100.0), Stop(3, 2000.0, math.nan)),
)


def _run(*arrivals: float) -> TrainRun:
    """The service run with these arrivals (nan: the section begun and not finished)."""
    plan = [(1, 2, 0.0, 1000.0), (2, 3, 1100.0, 2000.0)]
    sections = [
        SectionRun(a, b, dep, arr, dep, arrival)
        for (a, b, dep, arr), arrival in zip(plan, arrivals, strict=False)
    ]
    return TrainRun(SERVICE, sections, len(arrivals) == 2, 0, 0)


@pytest.mark.parametrize(
    ("run", "end_s", "delays"),
    [
        (_run(1030.0, 2250.0), 3000.0, [30.0, 250.0]),
        (_run(980.0, 2000.0), 3000.0, [-20.0, 0.0]),  # early counts as early
        (_run(1030.0, math.nan), 2500.0, [30.0, None]),  # due, not made: late
        (_run(1030.0, math.nan), 1500.0, [30.0]),  # not due yet: not counted
        (_run(1030.0), 2500.0, [30.0, None]),  # the section not even begun
        (_run(), 500.0, []),
    ],
)
def test_each_arrival_against_the_timetable(run: TrainRun, end_s: float, delays: list) -> None:  # type: ignore[type-arg]
    assert run.arrival_delays_s(end_s) == delays


def test_the_shares_on_time_count_an_arrival_not_made_as_late() -> None:
    out = punctuality([30.0, 250.0, -20.0, None, 61.0])
    assert out == {
        "arrivals": 5,
        "not_made": 1,
        "within_1_min_pct": 40.0,  # 30, -20
        "within_3_min_pct": 60.0,  # and 61
        "within_5_min_pct": 80.0,  # and 250
        "mean_delay_s": 80.2,  # of the four made
        "max_delay_s": 250.0,
        "mean_lateness_s": 85.2,  # (30 + 250 + 0 + 61) / 4 = 85.25: the early one as 0
        "early_arrivals": 1,
        "mean_earliness_s": 20.0,
    }
    # a boundary is on time
    assert punctuality([60.0])["within_1_min_pct"] == 100.0
    assert punctuality([])["within_3_min_pct"] is None
    assert punctuality([None])["mean_delay_s"] is None


@pytest.fixture(scope="module")
def short_day():  # type: ignore[no-untyped-def]
    return run_line(load_line_scenario(find_example("line_short_day.toml")))


def test_a_short_day_reads_the_arrivals_the_trains_made(short_day) -> None:  # type: ignore[no-untyped-def]
    kpis = short_day.kpis()
    made = []
    for train_id, run in short_day.drivers.items():
        row = kpis["trains"][str(train_id)]
        expected = [round(s.arrival_s - s.planned_arrival_s, 1) for s in run.sections]
        assert row["arrival_delays_s"] == expected  # every train finished its day
        assert row["arrival_delays_s"][-1] == row["arrival_delay_s"]
        made += expected
    on_time = kpis["punctuality"]
    assert (
        on_time["arrivals"]
        == len(made)
        == sum(len(r.service.stops) - 1 for r in short_day.drivers.values())
    )
    assert on_time["max_delay_s"] == max(made)
    # the train that failed and stood 10 minutes (K102) is the latest, most of it still lost
    assert max(kpis["trains"]["102"]["arrival_delays_s"]) == max(made) > 480.0
    assert on_time["within_5_min_pct"] < 100.0


def test_the_safety_kpis_are_zero_on_the_shipped_short_day(short_day) -> None:  # type: ignore[no-untyped-def]
    kpis = short_day.kpis()
    for kpi in kpi_table.safety_kpis():
        assert kpis[kpi.name] == 0, kpi.name
