"""The consist run (sim/consist_run.py): the driver, distributed power, the air brake along
the train and the dynamics together, checked against what each part's model says."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.errors import ConfigError
from railpilot.scenario.consist_file import consist_preset
from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
from railpilot.scenario.loader import read_toml
from railpilot.sim.consist_run import (
    ConsistDriver,
    ConsistRunSettings,
    ConsistScenario,
    DriverCommand,
    recharge_margins_s,
    run_consist,
)
from railpilot.vehicle.line import Line, Segment

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
LEVEL = Line(speed_limits=(Segment(0.0, 40_000.0, 80 / 3.6),))


def example(name: str) -> ConsistScenario:
    path = EXAMPLES / name
    return consist_scenario_from_mapping(read_toml(path), path.parent)


def braking(commands: tuple[DriverCommand, ...], **sim: object) -> ConsistScenario:
    """The 10,000 t train coasting at 50 km/h on the level, braked by ``commands`` (the
    run goes on at rest, to its duration)."""
    settings = ConsistRunSettings(
        **({"start_kmh": 50.0, "duration_s": 600.0, "record_every_s": 1.0} | sim)  # type: ignore[arg-type]
    )
    driver = ConsistDriver(
        commands=(DriverCommand(at_s=0.0, effort=0.0), *commands), end_at_rest=False
    )
    return ConsistScenario(
        "braking", consist_preset("heavy-haul-10kt"), LEVEL, driver, sim=settings
    )


@pytest.fixture(scope="module")
def ltd_example():
    return run_consist(example("heavy_haul_ltd.toml"))


def test_the_10kt_example_brakes_in_service_under_the_coupler_limit(ltd_example):
    m = ltd_example.metrics
    assert m["air_brake_applications"] >= 3
    assert m["air_brake_releases"] >= 2
    service_end = ltd_example.events["time_s"][ltd_example.events["kind"].index("emergency")]
    t = ltd_example.series["time_s"]
    forces = np.abs(ltd_example.fields["coupler_force_n"][t < service_end])
    assert forces.max() < 2_250e3
    assert m["coupler_force_limit_exceeded_s"] == 0.0
    # the run's largest forces are the recorded field's largest (recorded every 0.5 s)
    assert m["max_coupler_tension_kn"] >= ltd_example.fields["coupler_force_n"].max() / 1e3
    assert m["emergency_stopping_distance_m"] > 0.0


def test_a_second_application_before_recharge_brakes_weaker_by_the_mass_balance():
    """70 kPa, released after 100 s, 70 kPa again 120 s later (the train needs minutes to
    recharge): the second application's brake force, settled, is what the mass balance of
    each distributor's auxiliary reservoir gives (brakes/freight_air.py) and is weaker than
    the first by more than a tenth."""
    air = FreightAirBrake()
    commands = (
        DriverCommand(at_s=5.0, reduction_kpa=70.0),
        DriverCommand(at_s=105.0, reduction_kpa=0.0),
        DriverCommand(at_s=225.0, reduction_kpa=70.0),
    )
    run = run_consist(braking(commands, duration_s=400.0))
    consist = consist_preset("heavy-haul-10kt")
    t = run.series["time_s"]
    force = run.series["air_brake_n"]
    first = force[np.searchsorted(t, 100.0)]
    second = force[np.searchsorted(t, 320.0)]
    assert second < 0.9 * first
    # the mass balance: each cylinder holds what it still had when it applied again (the
    # release takes minutes to reach the rear) and the air its reservoir gave since (the
    # reservoir charged until the reduction reached it, then fell)
    later = (t >= 225.0) & (t <= 320.0)
    ar = run.fields["aux_reservoir_kpa"][later]
    applied_at = ar.argmax(axis=0)
    held = run.fields["brake_cylinder_kpa"][later][applied_at, np.arange(ar.shape[1])]
    bc = held + air.ar_to_bc_ratio * (ar.max(axis=0) - ar[-1])
    expected = float(np.sum(consist.service_brake_force_n() * bc) / air.full_service_bc_kpa())
    assert second == pytest.approx(expected, rel=0.02)
    # and the first the same way, from charged reservoirs: towards the 2.5 x reduction rule
    ar_first = run.fields["aux_reservoir_kpa"][np.searchsorted(t, 100.0)]
    bc_first = air.ar_to_bc_ratio * (consist.brake_pipe_kpa - ar_first)
    forces = consist.service_brake_force_n()
    assert first == pytest.approx(
        float(np.sum(forces * bc_first) / air.full_service_bc_kpa()), rel=0.02
    )
    rule = float(forces.sum()) * air.ar_to_bc_ratio * 70.0 / air.full_service_bc_kpa()
    assert 0.85 * rule < first <= rule
    margins = run.summary()["min_recharge_margin_s"]
    assert margins is not None and margins < 0.0


def test_the_20kt_train_brakes_with_lower_coupler_forces_with_distributed_power():
    scenario = example("heavy_haul_20kt_dp.toml")
    with_dp = run_consist(scenario)
    without = run_consist(replace(scenario, sim=replace(scenario.sim, distributed_power=False)))
    assert (
        with_dp.metrics["max_coupler_compression_kn"]
        < without.metrics["max_coupler_compression_kn"]
    )
    # and stops shorter: the mid-train valve applies the rear half sooner
    assert with_dp.metrics["final_position_m"] < without.metrics["final_position_m"]


def test_a_remote_unit_repeats_the_lead_s_reduction_after_the_radio_delay():
    """With distributed power the pipe at the mid-train locomotive starts to fall one radio
    delay after the lead's reduction (its own valve acts), not when the head's front
    arrives, which at the service front's speed takes longer."""
    consist = consist_preset("heavy-haul-20kt-dp")
    remote = int(consist.remote_indices()[0])
    settings = ConsistRunSettings(start_kmh=50.0, duration_s=40.0, record_every_s=0.05)
    driver = ConsistDriver(
        commands=(DriverCommand(at_s=0.0, effort=0.0), DriverCommand(at_s=5.0, reduction_kpa=70.0))
    )
    run = run_consist(ConsistScenario("dp", consist, LEVEL, driver, sim=settings))
    t = run.series["time_s"]
    falling = run.fields["brake_pipe_kpa"][:, remote] < consist.brake_pipe_kpa - 0.5
    start = float(t[np.argmax(falling)])
    front_s = FreightAirBrake().service_wave_mps
    head_front = 5.0 + (consist.front_m()[remote] + consist.lengths_m()[remote] / 2) / front_s
    assert 5.0 + consist.dp_radio_delay_s <= start < head_front
    assert start == pytest.approx(5.0 + consist.dp_radio_delay_s, abs=0.5)


def test_the_recharge_margin_is_the_time_between_less_the_time_needed():
    events = np.array([[10.0, 1.0, 0.0], [50.0, 2.0, 0.0], [200.0, 1.0, 0.0], [260.0, 2.0, 0.0]])
    assert recharge_margins_s(events, [100.0, 30.0]) == [200.0 - 50.0 - 100.0]


@pytest.mark.parametrize("reduction", [10.0, 49.0, 200.0])
def test_a_reduction_the_valve_cannot_make_is_refused_by_name(reduction):
    with pytest.raises(ConfigError, match=r"driver.commands\[1\].reduction_kpa"):
        braking((DriverCommand(at_s=5.0, reduction_kpa=reduction),))


def test_the_same_scenario_gives_the_same_numbers():
    scenario = braking((DriverCommand(at_s=5.0, reduction_kpa=70.0),), duration_s=120.0)
    a, b = run_consist(scenario), run_consist(scenario)
    assert a.metrics == b.metrics
    np.testing.assert_array_equal(a.fields["coupler_force_n"], b.fields["coupler_force_n"])
