"""The heavy-haul train as a consist against published heavy-haul figures.

Runs the consist model (sim/consist_run.py) on the cases published figures exist for and
tabulates published against simulated (docs/consist-run.md explains each difference):

* ``service_10kt``: examples/heavy_haul_ltd.toml, the 10,000 t train's braking cycles on
  a 12 per mille descent (its in-train forces in service braking);
* ``emergency_10kt``: the 10,000 t train's emergency stop from 80 km/h on the level;
* ``service_20kt`` / ``emergency_20kt``: the 20,000 t combined train (head and mid-train
  HXD1) in a 100 kPa service application from 60 km/h and an emergency stop from 80 km/h,
  with distributed power and without (the mid-train brake valve cut out, the remote
  locomotive idle);
* ``radio_delay``: the 20,000 t emergency stop with the remote unit's radio delay at 0,
  1.5 (the consist's) and 3 s.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from railpilot.reproduce.base import Reproduction, Table, find_example
from railpilot.scenario.consist_file import consist_preset
from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
from railpilot.scenario.loader import read_toml
from railpilot.sim.consist_run import (
    ConsistDriver,
    ConsistResult,
    ConsistRunSettings,
    ConsistScenario,
    DriverCommand,
    run_consist,
)
from railpilot.vehicle.consist import Consist
from railpilot.vehicle.line import Line, Segment

#: level, straight, 80 km/h
LEVEL = Line(speed_limits=(Segment(0.0, 60_000.0, 80.0 / 3.6),))
#: the limit of coupler force in Chinese heavy-haul practice [kN] (Chang et al. 2023)
LIMIT_KN = 2_250.0


def braked(
    name: str, consist: Consist, start_kmh: float, command: DriverCommand, **sim: Any
) -> ConsistScenario:
    """``consist`` coasting at ``start_kmh`` on the level, ``command`` 5 s later."""
    settings = ConsistRunSettings(
        **({"start_kmh": start_kmh, "duration_s": 900.0, "record_every_s": 0.5} | sim)
    )
    driver = ConsistDriver(commands=(DriverCommand(at_s=0.0, effort=0.0), command))
    return ConsistScenario(name, consist, LEVEL, driver, sim=settings)


def _row(case: str, result: ConsistResult, length_m: float) -> list[Any]:
    m = result.metrics
    where_c = m["max_coupler_compression_from_head_m"]
    where_t = m["max_coupler_tension_from_head_m"]
    return [
        case,
        round(float(m["max_coupler_compression_kn"] or 0.0)),
        "-" if where_c is None else f"{where_c:.0f} m ({where_c / length_m:.2f} L)",
        round(float(m["max_coupler_tension_kn"] or 0.0)),
        "-" if where_t is None else f"{where_t:.0f} m ({where_t / length_m:.2f} L)",
        m["emergency_stopping_distance_m"]
        if m["emergency_stopping_distance_m"] is not None
        else m["final_position_m"],
    ]


def run(out_dir: Path) -> Reproduction:
    """Run the cases, write the coupler-force figures, return the tables."""
    from railpilot.report import consist_plots
    from railpilot.report.figure import save_figure

    out_dir.mkdir(parents=True, exist_ok=True)
    example = find_example("heavy_haul_ltd.toml")
    ten = consist_preset("heavy-haul-10kt")
    twenty = consist_preset("heavy-haul-20kt-dp")
    emergency = DriverCommand(at_s=5.0, emergency=True)
    service = DriverCommand(at_s=5.0, reduction_kpa=100.0)
    cases: dict[str, tuple[ConsistScenario, float]] = {
        "service_10kt": (
            consist_scenario_from_mapping(read_toml(example), example.parent),
            ten.length_m,
        ),
        "emergency_10kt": (braked("emergency-10kt", ten, 80.0, emergency), ten.length_m),
    }
    for label, command, kmh in (("service", service, 60.0), ("emergency", emergency, 80.0)):
        for dp in (True, False):
            name = f"{label}_20kt_{'dp' if dp else 'no_dp'}"
            scenario = braked(name.replace("_", "-"), twenty, kmh, command, distributed_power=dp)
            cases[name] = (scenario, twenty.length_m)
    for delay in (0.0, 3.0):
        delayed = replace(twenty, dp_radio_delay_s=delay)
        name = f"emergency_20kt_delay_{delay:g}s"
        cases[name] = (braked(name.replace("_", "-"), delayed, 80.0, emergency), twenty.length_m)
    results = {name: run_consist(scenario) for name, (scenario, _) in cases.items()}
    figures = [
        save_figure(consist_plots.coupler_heat_map(results[name]), out_dir / f"ltd_{name}.png")
        for name in ("service_10kt", "service_20kt_dp", "service_20kt_no_dp", "emergency_20kt_dp")
    ]
    figures.append(
        save_figure(
            consist_plots.brake_pipe_along_train(results["service_10kt"]),
            out_dir / "ltd_service_10kt_brake_pipe.png",
        )
    )
    rows = [_row(name, results[name], length) for name, (_, length) in cases.items()]
    table = Table(
        "In-train forces and stopping distances of the consist model",
        [
            "case",
            "max compression [kN]",
            "where (from the head)",
            "max tension [kN]",
            "where (from the head)",
            "stopping distance [m]",
        ],
        rows,
        note="service_10kt: the braking cycles of examples/heavy_haul_ltd.toml (its "
        "emergency at the end included, from the speed it had there); the rest from the "
        "level at 60 km/h (service, 100 kPa) or 80 km/h (emergency).",
    )
    cycles = results["service_10kt"].metrics
    ten_em = results["emergency_10kt"].metrics
    with_dp = results["service_20kt_dp"].metrics
    no_dp = results["service_20kt_no_dp"].metrics
    em_dp, em_no = results["emergency_20kt_dp"].metrics, results["emergency_20kt_no_dp"].metrics
    findings = [
        f"The 10,000 t train's service braking cycles stay under the {LIMIT_KN:,.0f} kN "
        f"limit: {cycles['max_coupler_compression_kn']:.0f} kN compression, "
        f"{cycles['max_coupler_tension_kn']:.0f} kN tension.",
        f"The 10,000 t train stops from 80 km/h in emergency in "
        f"{ten_em['emergency_stopping_distance_m']:.0f} m.",
        "Distributed power lowers the 20,000 t train's largest compression in a 100 kPa "
        f"service application from {no_dp['max_coupler_compression_kn']:.0f} kN to "
        f"{with_dp['max_coupler_compression_kn']:.0f} kN, and in emergency from "
        f"{em_no['max_coupler_compression_kn']:.0f} kN to "
        f"{em_dp['max_coupler_compression_kn']:.0f} kN.",
    ]
    payload = {name: {"metrics": r.metrics, "events": r.events} for name, r in results.items()}
    return Reproduction(
        "heavy-haul-ltd",
        "The heavy-haul consist: in-train forces and stopping distances",
        payload,
        [table],
        figures,
        findings,
    )
