"""Before a TSR is sent: which trains it would catch above its limit (ground/tsr_warning.py)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from railpilot.errors import ConfigError
from railpilot.ground.operations import CancelTsr, OperationError, SetTsr
from railpilot.ground.tsr_warning import (
    AHEAD,
    INSIDE,
    UNKNOWN,
    LastReport,
    TsrWarning,
    confirm_flag,
    refuse_unconfirmed,
    trains_over_limit,
)
from railpilot.link.messages import RunningInfo, TravelDirection

UP, DOWN = TravelDirection.UP, TravelDirection.DOWN
START, END = 50_000.0, 52_000.0  # the TSR's km posts [m]
LIMIT = 12.5  # its limit [m/s] (45 km/h)
VALIDITY = 4.0  # how long a report stays valid [s]
NOW = 1000.0
BRAKE = 0.1  # the service braking rate the module documents [m/s^2]


def report(
    head: float,
    speed: float,
    *,
    direction: TravelDirection = UP,
    length: float = 1_600.0,
    age: float = 0.0,
    train: int = 7,
) -> LastReport:
    return LastReport(train, head, speed, length, direction, NOW - age)


def caught(*trains: LastReport) -> tuple:
    return trains_over_limit(START, END, LIMIT, trains, NOW, validity_s=VALIDITY)


def braking_m(speed: float) -> float:
    """The braking distance from ``speed`` down to the limit at the service rate, by hand."""
    return (speed**2 - LIMIT**2) / (2 * BRAKE)


speeds_over = st.floats(LIMIT + 0.01, 40.0)
speeds_under = st.floats(0.0, LIMIT)
lengths = st.floats(1.0, 3_000.0)
ages = st.floats(0.0, VALIDITY)
directions = st.sampled_from([UP, DOWN])


@given(share=st.floats(0.0, 1.0), speed=speeds_over, length=lengths, age=ages, way=directions)
def test_a_train_inside_the_stretch_faster_than_the_limit_is_always_listed(
    share: float, speed: float, length: float, age: float, way: TravelDirection
) -> None:
    head = START + share * (END - START)  # the head anywhere in the stretch
    (hit,) = caught(report(head, speed, direction=way, length=length, age=age))
    assert hit.where == INSIDE and hit.train_id == 7
    assert hit.excess_mps == pytest.approx(speed - LIMIT)


@given(behind=st.floats(0.0, 3_000.0), speed=speeds_over, length=st.floats(3_001.0, 10_000.0))
def test_a_train_whose_tail_is_still_in_the_stretch_is_inside(
    behind: float, speed: float, length: float
) -> None:
    # going UP, its head up to 3 km past the end: a longer train still has its tail inside
    (hit,) = caught(report(END + behind, speed, length=length))
    assert hit.where == INSIDE


@given(
    head=st.floats(0.0, 200_000.0),
    speed=speeds_under,
    length=lengths,
    age=ages,
    way=directions,
)
def test_a_train_at_or_below_the_limit_is_never_listed(
    head: float, speed: float, length: float, age: float, way: TravelDirection
) -> None:
    assert caught(report(head, speed, direction=way, length=length, age=age)) == ()


@given(margin=st.floats(1.0, 40_000.0), speed=speeds_over, age=ages, way=directions)
def test_a_train_far_ahead_of_the_stretch_is_never_listed(
    margin: float, speed: float, age: float, way: TravelDirection
) -> None:
    # farther from the near end than it runs since its report plus its braking distance
    gap = speed * age + braking_m(speed) + margin
    head = START - gap if way is UP else END + gap
    assert caught(report(head, speed, direction=way, age=age)) == ()


@given(beyond=st.floats(0.01, 40_000.0), speed=speeds_over, length=lengths, way=directions)
def test_a_train_past_the_stretch_is_never_listed(
    beyond: float, speed: float, length: float, way: TravelDirection
) -> None:
    # its tail beyond the far end: it runs away from the TSR
    head = END + length + beyond if way is UP else START - length - beyond
    assert caught(report(head, speed, direction=way, length=length)) == ()


def test_a_train_within_its_braking_distance_of_the_stretch_is_listed_as_ahead() -> None:
    # 20 m/s down to 12.5 m/s at 0.1 m/s^2: (400 - 156.25) / 0.2 = 1218.75 m
    assert braking_m(20.0) == pytest.approx(1218.75)
    (up,) = caught(report(START - 1218.0, 20.0))
    assert up.where == AHEAD and up.distance_m == pytest.approx(1218.0)
    (down,) = caught(report(END + 1218.0, 20.0, direction=DOWN))
    assert down.where == AHEAD
    assert caught(report(START - 1219.5, 20.0)) == ()
    # what it ran since its report counts too: 2 s at 20 m/s is 40 m more
    (late,) = caught(report(START - 1250.0, 20.0, age=2.0))
    assert late.where == AHEAD


def test_a_stale_report_is_listed_as_position_unknown_unless_past_the_stretch() -> None:
    stale = VALIDITY + 1.0
    (hit,) = caught(report(10_000.0, 5.0, age=stale))  # far, slow, but who knows now
    assert hit.where == UNKNOWN and hit.age_s == pytest.approx(stale)
    assert "position unknown" in hit.text()
    assert caught(report(END + 5_000.0, 30.0, age=stale)) == ()  # it had passed it


def test_a_train_of_unknown_direction_is_taken_as_running_either_way() -> None:
    ahead_up = report(START - 500.0, 20.0, direction=TravelDirection.UNKNOWN)
    ahead_down = report(END + 500.0, 20.0, direction=TravelDirection.UNKNOWN, train=8)
    assert [h.train_id for h in caught(ahead_up, ahead_down)] == [7, 8]


def test_inside_comes_first_then_ahead_then_unknown_each_by_train_id() -> None:
    trains = (
        report(10_000.0, 5.0, age=10.0, train=1),
        report(START - 100.0, 20.0, train=2),
        report(51_000.0, 20.0, train=4),
        report(51_000.0, 20.0, train=3),
    )
    assert [(h.where, h.train_id) for h in caught(*trains)] == [
        (INSIDE, 3),
        (INSIDE, 4),
        (AHEAD, 2),
        (UNKNOWN, 1),
    ]


@pytest.mark.parametrize(
    ("args", "field"),
    [
        ((START, START, LIMIT), "tsr.end_m"),
        ((START, END, 0.0), "tsr.limit_mps"),
        ((START, END, float("nan")), "tsr.limit_mps"),
    ],
)
def test_a_bad_tsr_is_an_error_naming_the_field(args: tuple, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        trains_over_limit(*args, (), NOW, validity_s=VALIDITY)


def test_the_view_is_in_the_dispatchers_units() -> None:
    (hit,) = caught(report(51_000.0, 20.0))  # 72 km/h inside a 45 km/h TSR
    view = hit.view()
    assert view["km"] == 51.0 and view["speed_kmh"] == 72.0
    assert view["over_limit_kmh"] == 27.0 and view["where"] == INSIDE
    assert view["text"] == "train 7: inside at km 51.000, 72 km/h, 27 km/h over the limit"


# ---------------------------------------------------------------------------- the gate


def registry_report(head: float, speed: float) -> tuple[int, RunningInfo, float, float]:
    info = RunningInfo(1, "K7", "L1", UP, speed, head)
    return 7, info, 1_600.0, NOW


SET = SetTsr(START, END, LIMIT, NOW, NOW + 600.0, "works")


def test_an_unconfirmed_tsr_over_a_faster_train_is_refused_naming_confirm() -> None:
    with pytest.raises(TsrWarning) as refused:
        refuse_unconfirmed(
            SET, [registry_report(51_000.0, 20.0)], NOW, validity_s=VALIDITY, confirm=False
        )
    assert isinstance(refused.value, OperationError)
    assert set(refused.value.errors) == {"confirm"}
    assert "train 7: inside" in refused.value.errors["confirm"]
    assert refused.value.view()["limit_kmh"] == 45.0
    assert [t["train"] for t in refused.value.view()["trains"]] == [7]


def test_a_confirmed_tsr_or_another_operation_passes() -> None:
    reports = [registry_report(51_000.0, 20.0)]
    refuse_unconfirmed(SET, reports, NOW, validity_s=VALIDITY, confirm=True)
    refuse_unconfirmed(CancelTsr(3), reports, NOW, validity_s=VALIDITY, confirm=False)
    slow = [registry_report(51_000.0, 10.0)]
    refuse_unconfirmed(SET, slow, NOW, validity_s=VALIDITY, confirm=False)


@pytest.mark.parametrize(
    ("request_", "op", "needle"),
    [
        ({"confirm": "yes"}, "tsr_set", "'yes' is not allowed: expected true or false"),
        ({"confirm": 1}, "tsr_set", "1 is not allowed: expected true or false"),
        ({"confirm": True}, "status", "expected confirm only with tsr_set"),
    ],
)
def test_a_bad_confirm_is_an_error_naming_it(request_: dict, op: str, needle: str) -> None:
    with pytest.raises(OperationError) as refused:
        confirm_flag(request_, op)
    assert needle in refused.value.errors["confirm"]


def test_confirm_is_false_when_left_out() -> None:
    assert confirm_flag({}, "tsr_set") is False
    assert confirm_flag({"confirm": True}, "tsr_set") is True
