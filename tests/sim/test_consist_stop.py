"""The consist driver's stop (sim/consist_run.py): its prediction of where an application
stops the train, checked against the closed form of the same deceleration law and against
the air brake's own settled force; the fill time it is made with; where a plan's last
braking begins."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from railpilot.scenario.consist_file import consist_preset
from railpilot.sim.consist_run import (
    DP_AIR_FILL_S,
    DP_DAVIS_A0,
    DP_DAVIS_A1,
    DP_DAVIS_A2,
    DP_EFFECTIVE_MASS_KG,
    DP_WEIGHT_SHARE,
    N_DRIVER,
    ConsistDriver,
    ConsistRunSettings,
    ConsistScenario,
    ConsistStepper,
    DriverCommand,
    _air_built_mps2,
    _stop_distance_m,
    final_braking_m,
)
from railpilot.vehicle.line import Line


def _driver_params(fill_s: float) -> np.ndarray:
    """Driver parameters with no running resistance: the line and the air alone."""
    drv = np.zeros(N_DRIVER)
    drv[DP_AIR_FILL_S] = fill_s
    drv[DP_WEIGHT_SHARE] = 1.0
    drv[[DP_DAVIS_A0, DP_DAVIS_A1, DP_DAVIS_A2]] = 0.0
    return drv


def _closed_form_stop_m(v0: float, line: float, air: float, tau: float) -> float:
    """The stop of ``dv/dt = -(line + air (1 - exp(-t / tau)))`` from ``v0``: the time it
    takes found by bisection on the closed-form speed, the distance by the closed-form
    integral."""

    def speed(t: float) -> float:
        return v0 - line * t - air * (t - tau * (1.0 - math.exp(-t / tau)))

    lo, hi = 0.0, 1.0
    while speed(hi) > 0.0:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if speed(mid) > 0.0 else (lo, mid)
    t = 0.5 * (lo + hi)
    return (
        v0 * t
        - line * t * t / 2.0
        - air * (t * t / 2.0 - tau * t + tau * tau * (1.0 - math.exp(-t / tau)))
    )


@settings(max_examples=60, deadline=None)
@given(
    v0=st.floats(2.0, 30.0),
    line=st.floats(-0.12, 0.12),
    air=st.floats(0.15, 0.5),
    tau=st.floats(5.0, 60.0),
)
def test_the_predicted_stop_is_the_closed_form_of_a_first_order_fill(
    v0: float, line: float, air: float, tau: float
) -> None:
    """From empty cylinders filling to ``air`` with time constant ``tau`` on a line giving
    ``line`` (negative: a descent), the prediction lands where the closed form does
    within 0.1 m and 0.1 % (its 0.25 s steps take the fill at their middle)."""
    if line + air <= 0.02:
        return  # a descent the application does not hold: it predicts no stop at all
    predicted = _stop_distance_m(_driver_params(tau), v0, line, 0.0, air)
    exact = _closed_form_stop_m(v0, line, air, tau)
    assert abs(predicted - exact) <= 0.1 + 1e-3 * exact


def test_an_application_that_cannot_hold_the_descent_predicts_no_stop() -> None:
    assert math.isinf(_stop_distance_m(_driver_params(30.0), 10.0, -0.12, 0.0, 0.1))


def _stepper(preset: str, reduction_kpa: float = 0.0) -> ConsistStepper:
    """``preset`` at a stand on the level, charged, applying ``reduction_kpa`` at once."""
    commands = (DriverCommand(at_s=0.0, effort=0.0, reduction_kpa=reduction_kpa),)
    driver = ConsistDriver(commands=commands, end_at_rest=False)
    sim = ConsistRunSettings(duration_s=400.0, start_kmh=0.0)
    return ConsistStepper(ConsistScenario("stop", consist_preset(preset), Line(), driver, sim=sim))


def _settled_mps2(stepper: ConsistStepper) -> float:
    """The air brake's deceleration once the cylinders have settled (the train at a
    stand: its force the cylinders' pressure alone)."""
    stepper.run_to_end()
    force = stepper.result().series["air_brake_n"][-1]
    return float(force) / stepper.inputs.driver[DP_EFFECTIVE_MASS_KG]


@pytest.mark.parametrize("reduction_kpa", [50.0, 70.0, 120.0])
def test_the_built_up_deceleration_is_the_air_brake_s_settled_one(reduction_kpa: float) -> None:
    """Before the application, the driver's mass balance gives what the cylinders settle
    at once the application has run on the air brake model; a second application before
    the reservoirs have recharged (50 kPa, released, then ``reduction_kpa`` 60 s later)
    gives less, and the prediction follows it there too."""
    fresh = _stepper("heavy-haul-10kt", reduction_kpa)
    mass = fresh.inputs.driver[DP_EFFECTIVE_MASS_KG]
    predicted = _air_built_mps2(fresh.inputs, fresh.air_p, fresh.air_s, mass, reduction_kpa)
    assert predicted == pytest.approx(_settled_mps2(fresh), rel=0.01)

    driver = ConsistDriver(
        commands=(
            DriverCommand(at_s=0.0, effort=0.0, reduction_kpa=50.0),
            DriverCommand(at_s=120.0, reduction_kpa=0.0),
        ),
        end_at_rest=False,
    )
    sim = ConsistRunSettings(duration_s=180.0)
    again = ConsistStepper(
        ConsistScenario("again", consist_preset("heavy-haul-10kt"), Line(), driver, sim=sim)
    )
    again.run_to_end()
    depleted = _air_built_mps2(again.inputs, again.air_p, again.air_s, mass, reduction_kpa)
    assert depleted < predicted


def test_the_fill_time_is_shorter_with_a_remote_valve_along_the_train() -> None:
    """The 20,000 t train's remote locomotive reduces the pipe from its middle too: its
    cylinders fill sooner than the 10,000 t train's, which has one valve at its head."""
    single = _stepper("heavy-haul-10kt").inputs.driver[DP_AIR_FILL_S]
    distributed = _stepper("heavy-haul-20kt-dp").inputs.driver[DP_AIR_FILL_S]
    assert 5.0 < distributed < single < 120.0


@given(st.lists(st.floats(0.0, 30.0), min_size=2, max_size=30))
def test_the_last_braking_begins_where_the_speed_last_stops_falling(speeds: list[float]) -> None:
    profile = np.asarray([*speeds, 0.0])
    x = np.arange(profile.size, dtype=float) * 10.0
    start = final_braking_m(x, profile)
    i = int(np.searchsorted(x, start))
    assert np.all(np.diff(profile[i:]) < 0.0)
    assert i == 0 or profile[i - 1] <= profile[i]
