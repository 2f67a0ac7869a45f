"""The onboard re-plans while running: a TSR received
mid-route, a target point set by a stopped train ahead and cleared when it moves on; and
the origin-to-port run with the shipped timetable."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railpilot.cli import main
from railpilot.line import load_line
from railpilot.line.model import UP
from railpilot.onboard.drive import (
    TARGET_STOP_MARGIN_M,
    TargetRequest,
    TsrRequest,
    drive,
    heavy_haul_loaded,
)
from railpilot.units import kmh_to_mps

# whole drives between stations
pytestmark = pytest.mark.slow

LINE = load_line("heavy-haul")
#: a block signal of the up line between stations 5 (km 122.8) and 6 (km 155.8)
SIGNAL_M = next(
    s.position_m for s in LINE.signals if s.direction == UP and 140e3 < s.position_m < 142e3
)


def _target_run(set_s: float, clear_s: float):  # type: ignore[no-untyped-def]
    return drive(
        LINE,
        heavy_haul_loaded(),
        5,
        6,
        running_time_s=1940.0,
        targets=(TargetRequest(SIGNAL_M, set_s, clear_s),),
    )


def test_a_target_point_that_clears_while_braking_costs_under_one_per_cent() -> None:
    # set when the train is ~7 km before the signal, cleared 300 s later while it brakes
    outcome = _target_run(700.0, 1000.0)
    summary = outcome.summary()
    assert [r["reason"] for r in summary["replans"]] == [
        "target point set",
        "target point cleared",
    ]
    r = outcome.result
    # it did brake for the target: slower at the clearing than the first plan there
    t_clear = np.searchsorted(r["time_s"], 1000.0)
    planned_there = np.interp(r["position_m"][t_clear], outcome.plan.s_m, outcome.plan.speed_mps)
    assert r["speed_mps"][t_clear] < planned_there - kmh_to_mps(20.0)
    assert summary["target_points_passed"] == 0
    assert summary["max_overspeed_kmh"] == 0.0
    assert abs(summary["running_time_s"] - 1940.0) / 1940.0 < 0.01
    assert abs(summary["stop_error_m"]) <= 2.0


def test_a_train_held_at_a_target_stops_short_of_it_and_goes_on_when_it_clears() -> None:
    outcome = _target_run(700.0, 1200.0)
    r = outcome.result
    x = outcome.km_post(r["position_m"])
    held = (r["time_s"] >= 700.0) & (r["time_s"] < 1200.0)
    # at rest before the red signal by the safety distance, within the stop's tolerance
    # short of the target stop and never beyond it
    (stop,) = outcome.mrsp_timeline[1][1].targets
    at_rest = held & (r["speed_mps"] == 0.0)
    assert at_rest.any()
    assert np.all(x[held] <= stop.position_m + 1e-6)
    assert x[at_rest].max() >= stop.position_m - 2.0 * TARGET_STOP_MARGIN_M
    # and it reached the station afterwards
    summary = outcome.summary()
    assert abs(summary["stop_error_m"]) <= 2.0
    assert summary["target_points_passed"] == 0
    assert summary["max_overspeed_kmh"] == 0.0


def _tsr_run(set_s: float):  # type: ignore[no-untyped-def]
    tsr = TsrRequest(100_000.0, 102_000.0, kmh_to_mps(60.0), set_s=set_s)
    return drive(LINE, heavy_haul_loaded(), 4, 5, running_time_s=1880.0, tsrs=(tsr,))


def test_a_tsr_received_mid_run_is_checked_where_the_train_is() -> None:
    summary = _tsr_run(300.0).summary()
    (replan,) = summary["replans"]
    assert replan["reason"] == "TSR received"
    (check,) = summary["tsr_checks"]
    # checked at the train's position when it arrived, not at the departure
    assert check["checked_at_km"] == pytest.approx(replan["at_km"])
    assert 90.82 < check["checked_at_km"] < 99.0
    # the line falls there at least 4 per mille (the line data, not the check): the table
    # (docs/onboard.md) says regeneration alone does not bring 80 -> 60 km/h in 3 km on
    # 4 per mille down, so neither does it here from 70 km/h in about 6 km of 6 per mille
    falls = [
        g.permille
        for g in LINE.gradients
        if g.end_m > check["checked_at_km"] * 1e3 and g.start_m < 100e3
    ]
    assert max(falls) <= -4.0
    assert check["regen_sufficient"] is False
    assert check["air_brake_from_km"] < 100.0
    assert check["feasible"] is True
    # the whole train kept to the static limits and the TSR from when it was received
    assert summary["max_overspeed_kmh"] == 0.0
    # received a third of the way through: the rest of the supplement absorbs most of it
    assert abs(summary["running_time_s"] - 1880.0) / 1880.0 < 0.02


def test_a_tsr_received_too_late_is_reported_infeasible() -> None:
    # 170 m before the zone at 70 km/h: even full service cannot make it, the check says
    # so, and the overspeed through the zone's entry is reported, not hidden
    summary = _tsr_run(600.0).summary()
    (check,) = summary["tsr_checks"]
    assert check["distance_m"] < 500.0
    assert check["feasible"] is False
    assert summary["max_overspeed_kmh"] > 0.0


def test_origin_to_port_with_a_tsr_and_a_target_point(capsys) -> None:  # type: ignore[no-untyped-def]
    """The issue's must-show: every section within 1 % of the shipped timetable, no
    overspeed anywhere along the train, no target point passed, every stop within 2 m; with a TSR
    received mid-route and a target point from a stopped train ahead."""
    code = main(
        [
            "drive",
            "heavy-haul",
            "--from",
            "1",
            "--to",
            "20",
            "--timetable",
            "heavy-haul",
            "--tsr",
            "100.0:102.0:60@5000",
            "--target",
            f"{SIGNAL_M / 1000.0}@8633:8933",
            "--model",
            "point-mass",
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["sections"]) == 19
    assert out["max_section_conformity_pct"] < 1.0
    assert out["max_overspeed_kmh"] == 0.0
    assert out["target_points_passed"] == 0
    assert out["max_abs_stop_error_m"] <= 2.0
    reasons = {(r["section"], r["reason"]) for r in out["replans"]}
    assert ("3-4", "TSR received") in reasons
    assert ("5-6", "target point set") in reasons
    assert ("5-6", "target point cleared") in reasons


def test_the_preset_is_its_consist_hauled_by_the_example_drive_without_its_handover() -> None:
    from dataclasses import replace
    from pathlib import Path

    from railpilot.scenario.consist_file import consist_preset
    from railpilot.scenario.loader import load_scenario

    example = load_scenario(Path(__file__).parents[2] / "examples" / "heavy_haul_run.toml")
    preset = heavy_haul_loaded()
    assert preset.consist == consist_preset("heavy-haul-10kt")
    assert preset.train == preset.consist.point_mass_train()
    assert example.brake.handover_kmh == 50.0
    air = replace(example.brake.air, max_decel_mps2=preset.train.max_service_decel_mps2)
    assert preset.brake == replace(example.brake, handover_kmh=0.0, air=air)


def test_traction_against_the_air_brake_is_the_smaller_force_over_the_distance() -> None:
    # A loaded train from station 1 to 2: the kernel's running sum against the same
    # integral taken afterwards from its every step (forces held over a step, the
    # trapezoid of its speeds), and against the traction it is part of
    outcome = drive(LINE, heavy_haul_loaded(), 1, 2, running_time_s=1560.0)
    series, metrics = outcome.result.series, outcome.result.metrics
    v, dt = series["speed_mps"], np.diff(series["time_s"])
    traction = np.clip(-series["electric_n"], 0.0, None)
    both = np.minimum(traction, np.clip(series["air_n"], 0.0, None))
    distance = (v[:-1] + v[1:]) / 2 * dt
    against = metrics["energy_traction_against_air_j"]
    np.testing.assert_allclose(against, np.sum(both[:-1] * distance), rtol=1e-9)
    np.testing.assert_allclose(metrics["energy_traction_j"], np.sum(traction[:-1] * distance))
    assert 0.0 < against < metrics["energy_traction_j"]
    eff = heavy_haul_loaded().brake.locomotive.traction_efficiency
    np.testing.assert_allclose(
        metrics["energy_traction_against_air_kwh"], against / eff / 3.6e6, rtol=1e-12
    )


@pytest.mark.parametrize(("origin", "to"), [(5, 4), (4, 3), (3, 2)])
def test_the_empty_train_climbs_to_its_stop_on_time(origin: int, to: int) -> None:
    """The empty train's climbs into stations 4, 3 and 2 (up to 12 per mille against it).
    The stop law's held command, most of it done by the gradient and the resistance, used
    to coast the train to its stop at walking pace as they fell with speed: 10.8, 13.2 and
    10.9 % over the plan (docs/precise-stop.md, "Climbing to a stop"). The same 1 % and
    2 m as the loaded train's sections, and the planned time itself, not the timetable's."""
    from railpilot.onboard.drive import heavy_haul_empty

    outcome = drive(LINE, heavy_haul_empty(), origin, to)
    summary = outcome.summary()
    requested = summary["requested_running_time_s"]
    assert abs(summary["running_time_s"] - requested) / requested < 0.01
    assert abs(summary["stop_error_m"]) <= 2.0
    assert summary["max_overspeed_kmh"] == 0.0
    # it pulled on to the plan's braking: its speed 1 km before the stop is the plan's
    r = outcome.result
    stop_s = outcome.plan.s_m[-1]
    i = np.searchsorted(r["position_m"], stop_s - 1000.0)
    planned = np.interp(r["position_m"][i], outcome.plan.s_m, outcome.plan.speed_mps)
    assert r["speed_mps"][i] == pytest.approx(planned, abs=kmh_to_mps(2.0))


@pytest.mark.parametrize(("origin", "to"), [(20, 19), (4, 3)])
def test_the_empty_train_stops_at_the_point_as_regeneration_fades(origin: int, to: int) -> None:
    """The empty train brakes its stops with regeneration alone, the air brake off, until
    regeneration fades below 10 km/h; its air brake then takes a minute to build. The stop
    law's prediction, in steps of a sixteenth of that minute, saw the fade in four steps,
    handed over too late and the train stopped 0.26 m (level) and 0.32 m (a climb) beyond
    the point. Now within 5 cm (measured on these two: 31 and 22 mm short)."""
    from railpilot.onboard.drive import heavy_haul_empty

    summary = drive(LINE, heavy_haul_empty(), origin, to).summary()
    assert abs(summary["stop_error_m"]) < 0.05
    assert summary["max_overspeed_kmh"] == 0.0


def test_the_stop_law_brakes_for_a_limit_before_the_stop() -> None:
    """The empty train into station 1 with a TSR received on the way: its re-planned
    curve brakes from 75 to 40 km/h for the station's 45 km/h throat about 2 km before
    the stop, while the stop law has already latched. Its held command lands the train at
    the stop and knows nothing of the throat: 11.7 km/h over the limit at the head (0.9
    before the climb's mend). The stop law now brakes as tracking asks when the reference
    brakes for a lower limit and harder."""
    from railpilot.onboard.drive import heavy_haul_empty

    tsr = TsrRequest(14_000.0, 16_000.0, kmh_to_mps(45.0), 300.0)
    outcome = drive(LINE, heavy_haul_empty(), 2, 1, tsrs=(tsr,))
    summary = outcome.summary()
    assert [r["reason"] for r in summary["replans"]] == ["TSR received"]
    assert summary["max_overspeed_kmh"] == 0.0
    assert abs(summary["stop_error_m"]) <= 2.0
