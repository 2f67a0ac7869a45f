"""The driving advice of a whole section (onboard/advice_list.py): what the drive on the
consist did, as instructions at km posts a driver can follow."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from railpilot.line import load_line
from railpilot.onboard.advice_list import FORCE_STEP_N, SHORTEST_STRETCH_M, advice_along
from railpilot.onboard.drive import drive, heavy_haul_loaded
from railpilot.sim.result import SimResult


@pytest.fixture(scope="module")
def loaded_1_2():  # type: ignore[no-untyped-def]
    return drive(load_line("heavy-haul"), heavy_haul_loaded(), 1, 2, model="consist")


def test_the_advice_is_the_drive_s_actions_in_the_order_the_train_meets_them(loaded_1_2) -> None:  # type: ignore[no-untyped-def]
    """Every application and release the consist's driver made is an instruction at its
    km post, with its depth and the speed of the release; the efforts alternate; the list
    ends with the stop at the arrival's km post and time."""
    advice = advice_along(loaded_1_2.result, loaded_1_2.km_post)
    metrics = loaded_1_2.result.metrics
    times = [i.time_s for i in advice]
    assert times == sorted(times)
    actions = [i.action for i in advice]
    assert actions.count("reduce") == metrics["air_brake_applications"] > 0
    assert actions.count("release") == metrics["air_brake_releases"]
    events = loaded_1_2.result.meta["brake_events"]
    depths = [e["reduction_kpa"] for e in events if e["kind"] == "application"]
    assert [i.value for i in advice if i.action == "reduce"] == depths
    efforts = [i for i in advice if i.action in ("power", "regenerate", "coast")]
    assert all((a.action, a.value) != (b.action, b.value) for a, b in itertools.pairwise(efforts))
    for i in efforts:
        if i.value is not None:
            assert i.value > 0 and (i.value * 1e3) % FORCE_STEP_N == pytest.approx(0.0, abs=1e-6)
    stop = advice[-1]
    assert stop.action == "stop"
    assert stop.km == pytest.approx(loaded_1_2.arrival_m / 1000.0, abs=0.002)
    assert stop.time_s == pytest.approx(metrics["running_time_s"])
    assert "stop at km" in stop.text and "reduce 50 kPa at km" in " ".join(i.text for i in advice)


def test_a_wobble_shorter_than_a_stretch_is_not_an_instruction() -> None:
    """A speed law's short burst of traction inside a regenerating stretch (shorter than
    SHORTEST_STRETCH_M) is merged into it; a long one is its own instruction."""
    x = np.arange(0.0, 3000.0, 10.0)
    electric = np.full(x.size, 300e3)  # regenerating 300 kN
    burst = (x >= 1000.0) & (x < 1000.0 + SHORTEST_STRETCH_M / 2)
    long = (x >= 2000.0) & (x < 2000.0 + 2 * SHORTEST_STRETCH_M)
    electric[burst] = -200e3
    electric[long] = -200e3
    series = {
        "time_s": x / 10.0,
        "position_m": x,
        "speed_mps": np.full(x.size, 10.0),
        "electric_n": electric,
    }
    advice = advice_along(SimResult(series, {"running_time_s": 300.0}, {}), lambda s: s)
    assert [(i.action, i.km) for i in advice] == [
        ("regenerate", 0.0),
        ("power", 2.0),
        ("regenerate", pytest.approx(2.0 + 2 * SHORTEST_STRETCH_M / 1000.0)),
        ("stop", pytest.approx(2.99)),
    ]
