"""Re-timing in the loop on a line (ground/online_retimer.py, cosim/driver.py).

Two loaded trains from Shenchi South (1) to station 4, fifteen minutes apart; the first
fails twelve minutes in and stands ten minutes. The same day is run with the ground
re-timing and with the fixed plan (``[retiming] enabled = false``), on a clean radio.
Checked: the ground re-timed the failed train and the one behind it, over the link; each
section a train departed after new times came was planned for the ground's time, never
slower than the timetable, and the failed train ran at least one of its later sections on
a shorter time; with the fixed plan nothing is sent and every section is
planned for the timetable's time; and the failed train, running its later sections
faster, reaches its destination less late than under the fixed plan.
"""

from __future__ import annotations

import pytest

from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping

# whole line days with a failed train, re-timed and not
pytestmark = pytest.mark.slow

DAY = {
    "name": "a failure and re-timing",
    "line": "heavy-haul",
    "seed": 3,
    "duration_h": 2.5,
    "services": [
        {
            "kind": "loaded",
            "from": 1,
            "to": 4,
            "first_departure_min": 3.0,
            "every_min": 15.0,
            "count": 2,
            "first_id": 101,
        },
    ],
    "events": [{"at_min": 12.0, "op": "train_failure", "train": 101, "stand_min": 10.0}],
}
FAILED = 101


@pytest.fixture(scope="module")
def retimed():
    return run_line(line_scenario_from_mapping(DAY))


@pytest.fixture(scope="module")
def fixed():
    return run_line(line_scenario_from_mapping(DAY | {"retiming": {"enabled": False}}))


def test_the_ground_retimes_the_failed_train_and_the_one_behind(retimed):
    log = retimed.retiming
    solved = [e for e in log if "lateness_s" in e]
    assert solved and all(e["status"] == "optimal" for e in solved)
    assert min(e["t_s"] for e in solved) - retimed.scenario.epoch_s >= 12 * 60.0
    sent = {i for e in solved for i in e["sent_to"]}
    assert sent == {101, 102}
    for train_id in (101, 102):
        assert retimed.drivers[train_id].running_times_received >= 1
    kpis = retimed.kpis()
    assert kpis["retiming"]["trains_sent_times"] == [101, 102]
    assert kpis["tsr_violations"] == 0 and kpis["target_points_passed"] == 0


def test_each_section_is_planned_for_the_grounds_time(retimed):
    log = [e for e in retimed.retiming if "times_s" in e]
    for train_id, driver in retimed.drivers.items():
        sent = [t for e in log for t in e["times_s"].get(train_id, {}).items()]
        for section in driver.sections:
            pair = (section.from_station, section.to_station)
            target = section.target_running_time_s
            assert target <= section.planned_running_time_s + 1e-6  # never slower
            if pair in driver.running_times:
                # planned for a time the ground sent for this pair (the link carries ms)
                key = f"{pair[0]}-{pair[1]}"
                assert any(k == key and abs(t - target) < 2e-3 for k, t in sent)
            else:
                assert target == section.planned_running_time_s
    # the failed train ran a section after the failure on a time faster than timetabled
    later = retimed.drivers[FAILED].sections[1:]
    assert any(s.target_running_time_s < s.planned_running_time_s - 1.0 for s in later)


def test_the_fixed_plan_sends_nothing_and_keeps_the_timetable(fixed):
    assert fixed.retiming == []
    assert fixed.kpis()["retiming"]["runs"] == 0
    for driver in fixed.drivers.values():
        assert driver.running_times_received == 0
        for section in driver.sections:
            assert section.target_running_time_s == section.planned_running_time_s


def test_the_failed_train_recovers_lateness_against_the_fixed_plan(retimed, fixed):
    late = retimed.kpis()["trains"][str(FAILED)]["arrival_delay_s"]
    late_fixed = fixed.kpis()["trains"][str(FAILED)]["arrival_delay_s"]
    assert late < late_fixed - 30.0
    assert fixed.kpis()["tsr_violations"] == 0 and fixed.kpis()["target_points_passed"] == 0
