"""``railpilot drive``'s overspeed and target-point figures (onboard/drive.py
``whole_train_limit_mps`` and ``DriveOutcome.summary``): the whole train against the static
limits and the TSRs as given, from when the onboard knew them, on the run's clock."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from railpilot.line import load_line
from railpilot.line.model import DOWN, UP
from railpilot.onboard.drive import (
    TargetRequest,
    TsrRequest,
    drive,
    heavy_haul_loaded,
    whole_train_limit_mps,
)
from railpilot.onboard.mrsp import SpeedProfile, travelled_m
from railpilot.units import kmh_to_mps, mps_to_kmh

#: 80 up to km 1, 60 on km 1-2, 80 to km 10 [m/s for short]
STATIC = SpeedProfile([0.0, 1000.0, 2000.0, 10_000.0], [80.0, 60.0, 80.0])
LENGTH_M = 500.0
#: 30 on km 5-5.1, known from 100 s
TSR = TsrRequest(5000.0, 5100.0, 30.0, set_s=100.0)


@pytest.mark.parametrize(
    ("t", "head", "limit"),
    [
        (0.0, 1200.0, 60.0),  # the head in the lower limit
        (0.0, 900.0, 80.0),  # the whole train before it
        (0.0, 2400.0, 60.0),  # the head out of it, the tail (km 1.9) still in it
        (0.0, 2600.0, 80.0),  # the tail out too
        (50.0, 5300.0, 80.0),  # over the TSR's zone before it was known
        (150.0, 5300.0, 30.0),  # and after
        (150.0, 5000.0, 30.0),  # the head on the zone's start
        (150.0, 5600.0, 30.0),  # the tail on the zone's end
        # the tail past the zone: free, where the MRSP's zone (extended by the train's
        # length) would hold the tail up to km 5.6, the head to km 6.1
        (150.0, 5650.0, 80.0),
    ],
)
def test_the_whole_train_up_by_hand(t: float, head: float, limit: float) -> None:
    assert whole_train_limit_mps(STATIC, (TSR,), t, head, UP, LENGTH_M) == limit


def test_going_down_the_tail_is_on_the_other_side() -> None:
    heads = np.array([500.0, 1600.0, 4500.0, 4600.0])
    # km 0.5-1.0 touches the 60's edge; km 1.6-2.1 in it; km 4.5-5.0 touches the TSR's
    # start; km 4.6-5.1 on it
    assert_array_equal(
        whole_train_limit_mps(STATIC, (TSR,), np.full(4, 200.0), heads, DOWN, LENGTH_M),
        [60.0, 60.0, 30.0, 30.0],
    )


# ---------------------------------------------------------------- on a real drive

LINE = load_line("heavy-haul")
#: a block signal of the up line between stations 5 (km 122.8) and 6 (km 155.8)
SIGNAL_M = next(
    s.position_m for s in LINE.signals if s.direction == UP and 140e3 < s.position_m < 142e3
)
#: the section's departure on the run's clock (as a later section of a timetable drive)
DEPART_S = 5000.0


@pytest.fixture(scope="module")
def later_section():  # type: ignore[no-untyped-def]
    """Section 5 -> 6 driven with nothing on the way, departing at ``DEPART_S``."""
    return drive(LINE, heavy_haul_loaded(), 5, 6, running_time_s=1940.0, start_time_s=DEPART_S)


def test_a_plain_section_is_not_over_anything(later_section) -> None:  # type: ignore[no-untyped-def]
    summary = later_section.summary()
    assert summary["max_overspeed_kmh"] == 0.0
    assert summary["target_points_passed"] == 0


def test_target_points_are_read_on_the_runs_clock(later_section) -> None:  # type: ignore[no-untyped-def]
    r = later_section.result
    x = later_section.km_post(r["position_m"])
    passed_at = r["time_s"][np.argmax(travelled_m(x, UP, SIGNAL_M) > 0.0)]
    assert 0.0 < passed_at < 1940.0  # the train ran past the signal (nobody held it)

    def passed(set_s: float, clear_s: float) -> int:
        held = (TargetRequest(SIGNAL_M, set_s, clear_s),)
        return int(replace(later_section, target_requests=held).summary()["target_points_passed"])

    # held on the run's clock while the train went by (section time + DEPART_S): passed
    assert passed(DEPART_S, DEPART_S + 3000.0) == 1
    # held only before the section began, as read on the run's clock: not passed (read on
    # the section's clock, this request would cover the whole passing)
    assert passed(0.0, DEPART_S) == 0
    # held from just after the head went by: not passed (it was past already)
    assert passed(DEPART_S + passed_at + 1.0, DEPART_S + 3000.0) == 0
    assert passed(DEPART_S + passed_at - 1.0, DEPART_S + 3000.0) == 1


def test_a_signal_behind_the_departure_is_not_passed(later_section) -> None:  # type: ignore[no-untyped-def]
    behind = max(
        s.position_m
        for s in LINE.signals
        if s.direction == UP and s.position_m < later_section.departure_m
    )
    held = (TargetRequest(behind, 0.0, DEPART_S + 3000.0),)
    summary = replace(later_section, target_requests=held).summary()
    assert summary["target_points_passed"] == 0


def test_a_tsr_the_train_ran_through_is_its_overspeed(later_section) -> None:  # type: ignore[no-untyped-def]
    r = later_section.result
    head = later_section.km_post(r["position_m"])
    tail = head - later_section.train_length_m  # going up
    start, end = 130_000.0, 130_200.0
    limit = kmh_to_mps(30.0)
    on = (np.maximum(head, tail) >= start) & (np.minimum(head, tail) <= end)
    assert on.any()
    expected = float(mps_to_kmh(np.max(r["speed_mps"][on]) - limit))
    assert expected > 20.0  # it ran through at its planned speed, not at 30

    def overspeed(set_s: float) -> float:
        tsr = (TsrRequest(start, end, limit, set_s),)
        return float(replace(later_section, tsr_requests=tsr).summary()["max_overspeed_kmh"])

    assert overspeed(0.0) == pytest.approx(expected, abs=1e-9)
    # known only after the train had left the zone (on the run's clock): nothing to obey
    left_s = DEPART_S + r["time_s"][np.flatnonzero(on)[-1]]
    assert overspeed(left_s + 1.0) == 0.0
