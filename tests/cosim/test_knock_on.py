"""What one event cost each train (cosim/knock_on.py): the day with it and without it.

Three loaded trains 9 minutes apart on one track, an empty one the other way. The leader
fails and stands 6 minutes: it is later by that and by its stop and start, the train behind
it is held up (knock-on), and the train on the other track is not touched (its difference
would be the radio's draws only, and there are none here: no frame loss)."""

from __future__ import annotations

import pytest

from railpilot.cosim.knock_on import knock_on
from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.errors import ConfigError

# line days with and without a failed train
pytestmark = pytest.mark.slow

STAND_S = 360.0
DAY = {
    "name": "knock-on day",
    "line": "heavy-haul",
    "seed": 5,
    "duration_h": 1.6,
    "channel": {"loss": 0.0},
    "services": [
        {
            "kind": "loaded",
            "from": 1,
            "to": 2,
            "first_departure_min": 2.0,
            "every_min": 9.0,
            "count": 3,
            "first_id": 101,
        },
        {"kind": "empty", "from": 2, "to": 1, "first_departure_min": 2.0, "first_id": 201},
    ],
    "events": [
        {
            "at_min": 4.0,
            "op": "tsr_set",
            "start_km": 20.0,
            "end_km": 21.0,
            "limit_kmh": 60,
            "valid_until_min": 80,
            "reason": "track work",
        },
        {"at_min": 16.0, "op": "train_failure", "train": 101, "stand_min": STAND_S / 60.0},
    ],
}


@pytest.fixture(scope="module")
def failure() -> dict:
    return knock_on(line_scenario_from_mapping(DAY), 2).summary()


def test_the_failed_train_is_later_by_about_its_stand(failure: dict) -> None:
    assert failure["own_train"] == 101
    own = failure["trains"]["101"]
    assert own["own"] and own["number"] == "K101"
    # the stand, plus stopping and regaining line speed, v/2a each way for a loaded train:
    # at 60 km/h about 55 s braking at 0.15 m/s^2 and 85 s pulling away at 0.1 m/s^2
    assert 0.9 * STAND_S <= own["arrival_delay_s"]["knock_on"] <= STAND_S + 180.0


def test_the_train_behind_is_held_up_and_the_other_track_is_not(failure: dict) -> None:
    behind = failure["trains"]["102"]["arrival_delay_s"]["knock_on"]
    other = failure["trains"]["201"]["arrival_delay_s"]["knock_on"]
    assert behind > 60.0  # held at red behind the failed train for over a minute
    assert abs(other) < 5.0
    others = [t["arrival_delay_s"]["knock_on"] for k, t in failure["trains"].items() if k != "101"]
    assert failure["knock_on_others_s"] == pytest.approx(sum(others), abs=0.15)
    assert failure["knock_on_others_late_s"] == pytest.approx(
        sum(max(k, 0.0) for k in others), abs=0.15
    )


def test_the_day_without_the_event_has_no_failure(failure: dict) -> None:
    own = failure["trains"]["101"]["arrival_delay_s"]
    assert own["without"] < own["with"]
    assert failure["event"] == {"index": 2, "at_s": 960.0, "label": failure["event"]["label"]}


@pytest.mark.parametrize("index", [0, 3, -1, True, 1.5])
def test_an_event_number_outside_the_file_is_refused_naming_it(index: object) -> None:
    with pytest.raises(ConfigError) as err:
        knock_on(line_scenario_from_mapping(DAY), index)  # type: ignore[arg-type]
    assert err.value.field == "event" and "1..2" in str(err.value)


def test_a_day_cut_short_is_compared_at_the_last_stop_both_days_reached() -> None:
    from railpilot.cosim.knock_on import summary

    def day(delays: list[float | None], energy_kwh: float) -> dict:
        row = {"number": "K101", "arrival_delays_s": delays, "energy_kwh": energy_kwh}
        return {"seed": 5, "trains": {"101": row}}

    with_event = day([10.0, 50.0, None], 120.0)  # the failure: the last stop not reached
    without = day([10.0, 20.0, 30.0], 100.0)
    out = summary(line_scenario_from_mapping(DAY), 1, with_event, without)
    row = out["trains"]["101"]
    assert row["arrival_delay_s"] == {"with": 50.0, "without": 20.0, "knock_on": 30.0}
    assert row["knock_on_by_station_s"] == [0.0, 30.0, None]
    assert row["energy_kwh"]["knock_on"] == 20.0
    assert out["own_train"] is None  # event 1 is the TSR: no train of its own
    assert out["knock_on_others_s"] == 30.0
