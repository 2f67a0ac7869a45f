"""A run advanced in pieces is the run advanced at once (sim/stepper.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from railpilot.errors import ConfigError
from railpilot.reproduce.precise_stop import heavy_haul_scenario
from railpilot.reproduce.qsmc_stop import realistic_scenario
from railpilot.scenario.model import ATOModel
from railpilot.sim import engine
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.run import simulate
from railpilot.sim.stepper import Stepper


@pytest.mark.parametrize(
    ("scenario", "controller"),
    [
        (realistic_scenario(), "qsmc"),
        (realistic_scenario(), "pid"),
        (heavy_haul_scenario(), "pstop"),
    ],
)
def test_pieces_equal_one_run(scenario, controller):
    # odd cut times (mid control period, mid record interval): the state carried between
    # calls is complete when every recorded channel and every metric is bit-identical
    whole = simulate(scenario, controller)
    stepper = Stepper(scenario, controller)
    for t in (0.0, 0.013, 3.3, 7.77, 20.05, 33.0):
        stepper.advance_to(t)
    stepper.run_to_end()
    pieces = stepper.result()
    assert pieces.metrics.keys() == whole.metrics.keys()
    for key, value in whole.metrics.items():
        assert_array_equal(pieces.metrics[key], value, err_msg=key)
    for name in ("time_s", "position_m", "speed_mps", "command_mps2", "air_n", "odometer_m"):
        assert_array_equal(pieces[name], whole[name], err_msg=name)


def test_pieces_after_the_first_call_the_compiled_loop_directly():
    # the first piece goes through Numba's dispatcher; later ones call the specialisation
    # it compiled (sim/stepper.py _compiled_entry): not the dispatcher again, which types
    # every argument on every call. Bit-identity of the pieces is test_pieces_equal_one_run
    stepper = Stepper(heavy_haul_scenario(), "pstop")
    stepper.advance_to(1.0)
    entry = stepper._compiled
    assert entry is not None and entry is not engine.run_kernel
    assert any(entry is o.entry_point for o in engine.run_kernel.overloads.values())
    stepper.advance_to(2.0)
    assert stepper.time_s == pytest.approx(2.0) and stepper._compiled is entry


def test_advance_is_idempotent_and_reports_the_train():
    stepper = Stepper(heavy_haul_scenario(), "pstop")
    stepper.advance_to(10.0)
    step, x = stepper.step, stepper.position_m
    stepper.advance_to(10.0)  # nothing left before 10 s
    stepper.advance_to(5.0)  # the past is not run again
    assert (stepper.step, stepper.position_m) == (step, x)
    assert stepper.time_s == pytest.approx(10.0)
    assert stepper.speed_mps > 0 and not stepper.finished


def test_replacing_the_reference_moves_the_stop():
    # a distance-based drive along a planned curve; halfway the curve is replaced by one
    # that stops 200 m earlier: the train stops there, and the metrics measure against it
    base = heavy_haul_scenario()
    s = np.linspace(0.0, 900.0, 91)
    v = np.sqrt(np.maximum(2 * 0.2 * (900.0 - s), 0.0))
    v = np.minimum(v, 16.0)
    first = PlannedProfile(s, v)
    scenario = replace(
        base,
        reference=first,
        ato=ATOModel(reference="distance", brake_delay_s=4.0, brake_lag_s=6.0),
        sim=replace(base.sim, duration_s=400.0),
    )
    stepper = Stepper(scenario, "pid")
    stepper.advance_to(5.0)
    x_now = stepper.position_m
    s2 = np.linspace(0.0, 700.0, 71)
    v2 = np.minimum(np.sqrt(np.maximum(2 * 0.2 * (700.0 - s2), 0.0)), 16.0)
    stepper.replace_reference(PlannedProfile(s2, v2))
    stepper.run_to_end()
    result = stepper.result()
    assert x_now < 700.0
    assert result.meta["stop_point_m"] == 700.0
    assert abs(result.metrics["stop_error_m"]) < 20.0
    assert result["position_m"][-1] < 800.0


def test_a_time_based_reference_cannot_be_replaced():
    stepper = Stepper(heavy_haul_scenario(), "pstop")
    with pytest.raises(ConfigError, match=r"ato\.reference"):
        stepper.replace_reference(PlannedProfile(np.array([0.0, 10.0]), np.array([1.0, 0.0])))
