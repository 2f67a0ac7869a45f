"""Running scenarios (railpilot.sim.run) and the result object (railpilot.sim.result)."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from railpilot.control.pid import TrackingPID
from railpilot.control.smarc import P_ETA, SMARC
from railpilot.errors import ConfigError
from railpilot.scenario.model import ControllerSpec, Scenario, SimSettings
from railpilot.sim.disturbance import Disturbance, Region
from railpilot.sim.reference import constant_deceleration
from railpilot.sim.result import CHANNELS, METRICS
from railpilot.sim.run import make_controller, simulate

# paper 000 default scenario, 50 s is enough to stop (about 46 s)
BASE = Scenario(sim=SimSettings(duration_s=50.0))


def with_random(seed):
    return dataclasses.replace(BASE, disturbance=Disturbance(random_std_n=20e3, seed=seed))


@pytest.mark.parametrize("controller", ["pid", "smarc"])
def test_same_scenario_twice_gives_identical_metrics(controller):
    first = simulate(with_random(1), controller)
    second = simulate(with_random(1), controller)
    assert first.metrics == second.metrics  # bit for bit (nan would not compare equal)
    assert_array_equal(first["speed_mps"], second["speed_mps"])


def test_different_seeds_give_different_runs():
    a = simulate(with_random(1))
    b = simulate(with_random(2))
    assert a.metrics["stop_error_m"] != b.metrics["stop_error_m"]
    assert not np.array_equal(a["speed_mps"], b["speed_mps"])


def test_controller_object_is_reset_before_a_run():
    ctrl = make_controller(BASE, "smarc")
    first = simulate(BASE, ctrl)
    assert simulate(BASE, ctrl).metrics == first.metrics


def test_metrics_keys_are_the_documented_ones():
    result = simulate(BASE)
    assert set(METRICS) <= set(result.metrics)
    assert all(isinstance(v, float) for v in result.metrics.values())


def test_series_has_every_channel_with_equal_length():
    result = simulate(BASE)
    names = [name for name, _ in CHANNELS]
    assert list(result.series) == names
    assert {len(result[name]) for name in names} == {BASE.sim.n_steps}


def test_record_every_decimates_the_series():
    result = simulate(dataclasses.replace(BASE, sim=SimSettings(duration_s=50.0, record_every=10)))
    assert_allclose(np.diff(result["time_s"]), 0.1)
    assert len(result["time_s"]) == 500


def test_default_run_stops_near_the_stop_point():
    # paper 000 scenario without model error: |stop error| well under a metre
    result = simulate(BASE)
    assert result.meta["stopped"]
    assert abs(result.metrics["stop_error_m"]) < 0.5
    assert result.metrics["max_decel_mps2"] <= BASE.train.max_service_decel_mps2


def test_recorded_state_is_at_the_recorded_time():
    # constant-deceleration reference, train starts on it: x(0) = start, v(0) = v0
    scenario = dataclasses.replace(BASE, reference=constant_deceleration(19.8, 0.65, 1000.0))
    result = simulate(scenario)
    assert result["time_s"][0] == 0.0
    assert result["position_m"][0] == pytest.approx(1000.0, abs=1e-9)
    assert result["speed_mps"][0] == pytest.approx(19.8, abs=1e-9)


def test_positive_region_disturbance_makes_the_train_stop_later():
    # +60 kN pushing the train on over its last 150 m (a tail wind, an unmodelled down-grade)
    stop = BASE.reference.stop_m
    pushed = dataclasses.replace(
        BASE, disturbance=Disturbance(regions=(Region(stop - 150.0, stop + 10.0, 60e3),))
    )
    base, push = simulate(BASE).metrics, simulate(pushed).metrics
    assert push["stop_time_s"] > base["stop_time_s"]
    assert push["stop_error_m"] > base["stop_error_m"]


def test_negative_constant_disturbance_makes_an_open_loop_train_stop_shorter():
    # no feedback at all: a constant 30 kN holding back must shorten the stop
    open_loop = SMARC(c=0.0, ks=0.0, alpha=0.0, eta=0.0, gamma=(0.0, 0.0))
    held = dataclasses.replace(BASE, disturbance=Disturbance(constant_n=-30e3))
    assert (
        simulate(held, open_loop).metrics["stop_error_m"]
        < simulate(BASE, open_loop).metrics["stop_error_m"]
    )


def test_to_pandas_is_indexed_by_time():
    result = simulate(BASE)
    frame = result.to_pandas()
    assert frame.index.name == "time_s"
    assert_array_equal(frame["speed_mps"].to_numpy(), result["speed_mps"])


def test_csv_round_trip(tmp_path):
    result = simulate(BASE)
    path = result.to_csv(tmp_path / "run.csv")
    back = pd.read_csv(path, index_col="time_s")
    assert list(back.columns) == [name for name, _ in CHANNELS[1:]]
    assert_allclose(back["position_m"].to_numpy(), result["position_m"], rtol=1e-15)
    assert_allclose(back.index.to_numpy(), result["time_s"], rtol=1e-15)


def test_parquet_round_trip_keeps_series_and_metrics(tmp_path):
    result = simulate(with_random(3))
    path = result.to_parquet(tmp_path / "run.parquet")
    table = pq.read_table(path)
    for name, _ in CHANNELS:
        assert_array_equal(table.column(name).to_numpy(), result[name])
    info = json.loads(table.schema.metadata[b"railpilot"])
    assert info["metrics"]["stop_error_m"] == result.metrics["stop_error_m"]
    assert info["meta"]["controller"] == "smarc"


def test_summary_turns_nan_into_none():
    # too short to stop: stop error and stop time are undefined
    result = simulate(dataclasses.replace(BASE, sim=SimSettings(duration_s=5.0)))
    summary = result.summary()
    assert summary["stop_time_s"] is None
    assert summary["stop_error_m"] is None
    assert isinstance(summary["max_speed_error_mps"], float)


@pytest.mark.parametrize(("name", "cls"), [("pid", TrackingPID), ("smarc", SMARC)])
def test_make_controller_builds_the_named_controller(name, cls):
    assert isinstance(make_controller(BASE, name), cls)


def test_make_controller_applies_overrides():
    scenario = dataclasses.replace(
        BASE, controller=ControllerSpec("smarc", {"smarc": {"eta": 0.2}})
    )
    ctrl = make_controller(scenario)
    assert ctrl.params[P_ETA] == 0.2


def test_make_controller_rejects_unknown_parameter_naming_it():
    scenario = dataclasses.replace(BASE, controller=ControllerSpec("pid", {"pid": {"kq": 1.0}}))
    with pytest.raises(ConfigError) as info:
        make_controller(scenario)
    assert info.value.field == "controller.pid.kq"
