"""Paper 002: precise stopping with combined-reaching-law QSMC, against PID.

* ``results``: the paper's scenario (constant -0.65 m/s^2 from 19.8 m/s, stop point
  301.6 m, brake lag ``tau`` and delay ``sigma``, a disturbance acceleration between
  100 m and 200 m), one run per controller, figures like the paper's 6-8;
* ``sigma_sweep``: table 3 -- for each sigma in {1.05, 1.15, 1.25, 1.35} s (tau fixed,
  both controllers designed for the nominal sigma = 1.2 s) a Monte Carlo of 1,000 runs
  with a random disturbance of -2.3 % to +2.3 % of the target acceleration;
* ``realistic``: the same stop with the effects of a real train switched on
  (railpilot.sim.realism; values in docs/paper-002-qsmc.md) and the plant varied, run
  through the same Monte Carlo for PID and QSMC: where controllers really differ.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from railpilot.brakes.lag_delay import pade_difference
from railpilot.brakes.lag_delay_brake import LagDelayBrake
from railpilot.reproduce.base import Reproduction, Table
from railpilot.reproduce.realism_study import (
    ladder_table,
    on_a_real_train,
    public_stats,
    run_both_references,
    run_ladder,
    shares_text,
    stats_table,
)
from railpilot.reproduce.tuning_search import pid_params
from railpilot.scenario.model import ATOModel, ControllerSpec, Scenario, SimSettings
from railpilot.scenario.montecarlo import Distribution, MonteCarloSpec
from railpilot.sim.batch import MonteCarloResult, run_montecarlo
from railpilot.sim.disturbance import Disturbance, Region
from railpilot.sim.reference import constant_deceleration
from railpilot.sim.run import simulate
from railpilot.vehicle.train import Train

CONTROLLERS = ("pid", "qsmc")
SIGMAS_S = (1.05, 1.15, 1.25, 1.35)
NOMINAL_SIGMA_S = 1.2
#: brake response time constant tau [s]: lost in the paper's extraction; see docs
TAU_S = 0.5
DECEL_MPS2 = 0.65
V0_MPS = 19.8
TOLERANCE_M = 0.30
RUNS = 1000
SEED = 2002
#: the PID's tuning for this plant: the winner of ``python -m railpilot.reproduce.tune_qsmc_stop``
#: (SIMC tau_c = 0.5 theta, position loop 0.5 / (theta + T + tau_c))
PID_TUNING = {"tau_c_factor": 0.5, "position_factor": 0.5}


def paper_scenario(sigma_s: float = NOMINAL_SIGMA_S) -> Scenario:
    """Paper 002's stop with the plant delay ``sigma_s``; the ATO designed for 1.2 s."""
    train = Train(
        mass_kg=300e3,
        rotating_mass_factor=0.0,
        davis_a0=0.0,
        davis_a1=0.0,
        davis_a2=0.0,
        max_service_decel_mps2=1.0,
    )
    scenario = Scenario(
        name="paper002-qsmc-stop",
        train=train,
        brake=LagDelayBrake(lag_s=TAU_S, delay_s=sigma_s, max_decel_mps2=1.0),
        reference=constant_deceleration(V0_MPS, DECEL_MPS2, 0.0, coast_s=3.0),
        # the paper's disturbance acceleration between 100 m and 200 m (value lost):
        # 0.05 m/s^2 pushing the train on, as a 5 per mille down-grade would
        disturbance=Disturbance(regions=(Region(100.0, 200.0, 0.05 * train.effective_mass_kg),)),
        ato=ATOModel(davis=(0.0, 0.0, 0.0), brake_delay_s=NOMINAL_SIGMA_S, brake_lag_s=TAU_S),
        controller=ControllerSpec("qsmc"),
        sim=SimSettings(dt_s=0.01, duration_s=40.0),
    )
    # the PID baseline is tuned for this plant (tune_qsmc_stop), not paper 000's
    pid = pid_params(scenario, **PID_TUNING)
    return replace(scenario, controller=ControllerSpec("qsmc", {"pid": pid}))


def random_disturbance(scenario: Scenario) -> Scenario:
    """Add the paper's random disturbance: -2.3 % to +2.3 % of the target acceleration."""
    return replace(
        scenario,
        disturbance=replace(scenario.disturbance, target_fraction=0.023, random_hold_s=1.0),
    )


def realistic_scenario() -> Scenario:
    """The paper's stop on a real train (values and sources in docs/paper-002-qsmc.md)."""
    real = on_a_real_train(random_disturbance(paper_scenario()), "paper002-realistic", notches=7)
    # both controllers are tuned for the slower ATO cycle (QSMC's rule does it itself)
    pid = pid_params(real, **PID_TUNING)
    return replace(real, controller=ControllerSpec("qsmc", {"pid": pid}))


def realistic_spec(runs: int = RUNS) -> MonteCarloSpec:
    """Plant variation of the realistic study."""
    return MonteCarloSpec(
        runs=runs,
        seed=SEED + 1,
        vary=(
            Distribution("brake.delay_s", "uniform", 1.05, 1.35),
            Distribution("brake.lag_s", "uniform", 0.4, 0.6),
            Distribution("train.mass_t", "uniform", 270.0, 330.0),
            Distribution("realism.wheel_scale_error", "uniform", -0.01, 0.01),
            Distribution("realism.adhesion", "uniform", 0.10, 0.18),
            Distribution("brake.gain", "uniform", 0.95, 1.05),
        ),
    )


def _sweep_row(sigma: float, name: str, result: MonteCarloResult) -> dict[str, Any]:
    stats = result.stats(TOLERANCE_M)
    return {
        "sigma_s": sigma,
        "controller": name,
        "runs": stats["runs"],
        "max_abs_stop_error_m": stats["max_abs_stop_error_m"],
        "p99_abs_stop_error_m": stats["p99_abs_stop_error_m"],
        "share_within_0_30_m": stats["share_within_0_30_m"],
        "mean_stop_error_m": stats["mean_stop_error_m"],
        "worst_run_seed": stats["worst_run_seed"],
    }


def run(out_dir: Path, runs: int = RUNS) -> Reproduction:
    """Run the reproduction, write figures into ``out_dir``, return tables and payload."""
    from railpilot.report import montecarlo_plots, stopping_plots
    from railpilot.report.figure import save_figure

    out_dir.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    nominal = paper_scenario()
    single = {name: simulate(nominal, name) for name in CONTROLLERS}
    noisy = random_disturbance(nominal)
    sweep: list[dict[str, Any]] = []
    sweep_results: dict[tuple[float, str], MonteCarloResult] = {}
    spec = MonteCarloSpec(runs=runs, seed=SEED)
    for sigma in SIGMAS_S:
        scenario = random_disturbance(paper_scenario(sigma))
        for name in CONTROLLERS:
            result = run_montecarlo(scenario, name, spec, progress=False)
            sweep_results[(sigma, name)] = result
            sweep.append(_sweep_row(sigma, name, result))
    realistic = realistic_scenario()
    real_spec = realistic_spec(runs)
    real_results, real_distance = run_both_references(realistic, real_spec, CONTROLLERS)
    ladder = run_ladder(realistic, realistic_spec(max(runs // 2, 1)), 0.01, CONTROLLERS)
    wall_s = time.perf_counter() - started

    disturbance = f"±{noisy.disturbance.target_fraction * 100:g} % random disturbance"
    seeded_runs = {
        name: [
            simulate(replace(noisy, disturbance=replace(noisy.disturbance, seed=seed)), name)
            for seed in range(20)
        ]
        for name in CONTROLLERS
    }
    realistic_title = f"Paper 002 on a real train, time-based reference: {runs} runs per controller"
    figures = [
        save_figure(stopping_plots.tracking(single), out_dir / "qsmc_stop_tracking.png"),
        save_figure(
            stopping_plots.position_error_runs(seeded_runs, TOLERANCE_M, disturbance),
            out_dir / "qsmc_stop_random_disturbance.png",
        ),
        save_figure(
            montecarlo_plots.stop_error_histogram(
                {n: sweep_results[(SIGMAS_S[-1], n)] for n in CONTROLLERS},
                TOLERANCE_M,
                title=f"sigma = {SIGMAS_S[-1]} s, {disturbance}, {runs} runs",
            ),
            out_dir / "qsmc_stop_sigma_1_35_histogram.png",
        ),
        save_figure(
            montecarlo_plots.stop_error_histogram(real_results, TOLERANCE_M, title=realistic_title),
            out_dir / "qsmc_stop_realistic_histogram.png",
        ),
    ]
    results = {
        name: {
            k: r.summary()[k]
            for k in (
                "stop_error_m",
                "max_speed_error_mps",
                "rms_speed_error_mps",
                "max_position_error_m",
                "max_decel_mps2",
                "max_jerk_mps3",
                "stop_time_s",
            )
        }
        for name, r in single.items()
    }
    realistic_stats = {name: public_stats(r) for name, r in real_results.items()}
    distance_stats = {name: public_stats(r) for name, r in real_distance.items()}
    pade = [
        {
            "sigma_s": s,
            "pade_order": order,
            "max_step_response_difference": pade_difference(TAU_S, s, 0.01, order),
        }
        for s in SIGMAS_S
        for order in (1, 3)
    ]
    tables = _tables(results, sweep, realistic_stats, pade)
    tables.insert(3, ladder_table(ladder, CONTROLLERS))
    tables.insert(
        3,
        stats_table(
            "Realistic variant, distance-to-go reference (the ATO re-plans on position)",
            distance_stats,
        ),
    )
    findings = _findings(results, sweep, realistic_stats)
    findings.append(
        "Realistic variant with the ATO re-planning on distance to go: within ±0.30 m "
        + shares_text(distance_stats)
        + "."
    )
    payload = {
        "scenario": "qsmc-stop",
        "results": results,
        "sigma_sweep": sweep,
        "realistic": realistic_stats,
        "realistic_distance_reference": distance_stats,
        "realism_ladder": ladder,
        "pade_vs_exact": pade,
        "tau_s": TAU_S,
        "nominal_sigma_s": NOMINAL_SIGMA_S,
        "wall_time_s": wall_s,
    }
    return Reproduction(
        "qsmc-stop", "Paper 002 — QSMC vs PID, precise stopping", payload, tables, figures, findings
    )


def _tables(
    results: dict[str, dict[str, Any]],
    sweep: list[dict[str, Any]],
    realistic: dict[str, dict[str, Any]],
    pade: list[dict[str, Any]],
) -> list[Table]:
    single = Table(
        f"Paper's scenario, one run (sigma {NOMINAL_SIGMA_S} s, tau {TAU_S} s, "
        "disturbance 100-200 m)",
        [
            "controller",
            "stop error [m]",
            "max |position error| [m]",
            "max speed error [m/s]",
            "max decel [m/s²]",
            "max jerk [m/s³]",
        ],
        [
            [
                n.upper(),
                r["stop_error_m"],
                r["max_position_error_m"],
                r["max_speed_error_mps"],
                r["max_decel_mps2"],
                r["max_jerk_mps3"],
            ]
            for n, r in results.items()
        ],
    )
    table3 = Table(
        "Table 3 reproduced: stop error per sigma (tau fixed, ±2.3 % random disturbance; "
        f"controllers designed for sigma = {NOMINAL_SIGMA_S} s)",
        [
            "sigma [s]",
            "controller",
            "runs",
            "max |stop error| [m]",
            "p99 [m]",
            "within ±0.30 m",
            "mean [m]",
        ],
        [
            [
                r["sigma_s"],
                r["controller"].upper(),
                r["runs"],
                r["max_abs_stop_error_m"],
                r["p99_abs_stop_error_m"],
                f"{r['share_within_0_30_m']:.1%}",
                r["mean_stop_error_m"],
            ]
            for r in sweep
        ],
    )
    real = Table(
        "Realistic variant (noise, odometry + balises, 7 notches, 0.2 s ATO cycle, "
        "adhesion 0.10-0.18, -3 ‰ approach, plant varied)",
        [
            "controller",
            "runs",
            "mean [m]",
            "std [m]",
            "p50 |err| [m]",
            "p95 [m]",
            "p99 [m]",
            "max [m]",
            "within ±0.30 m",
            "max jerk [m/s³]",
            "worst run seed",
        ],
        [
            [
                n.upper(),
                s["runs"],
                s["mean_stop_error_m"],
                s["std_stop_error_m"],
                s["p50_abs_stop_error_m"],
                s["p95_abs_stop_error_m"],
                s["p99_abs_stop_error_m"],
                s["max_abs_stop_error_m"],
                f"{s['share_within_0_30_m']:.1%}",
                s["max_jerk_mps3"],
                s["worst_run_seed"],
            ]
            for n, s in realistic.items()
        ],
    )
    pade_table = Table(
        "Brake model: exact delay vs its Pade approximant (largest step-response difference)",
        ["sigma [s]", "Pade order", "max difference [fraction of the step]"],
        [[p["sigma_s"], p["pade_order"], p["max_step_response_difference"]] for p in pade],
    )
    return [single, table3, real, pade_table]


def _findings(
    results: dict[str, dict[str, Any]],
    sweep: list[dict[str, Any]],
    realistic: dict[str, dict[str, Any]],
) -> list[str]:
    out = []
    for name in CONTROLLERS:
        rows = [r for r in sweep if r["controller"] == name]
        worst = max(r["max_abs_stop_error_m"] or float("inf") for r in rows)
        every = all(r["share_within_0_30_m"] == 1.0 for r in rows)
        out.append(
            f"{name.upper()}: worst |stop error| over the sigma sweep "
            f"{worst:.3f} m; "
            + ("every run within ±0.30 m" if every else "NOT every run within ±0.30 m")
            + (
                (" (the paper's claim holds)." if every else " (the paper's claim fails).")
                if name == "qsmc"
                else "."
            )
        )
    q, p = results["qsmc"], results["pid"]
    out.append(
        f"Paper's scenario: QSMC stops {q['stop_error_m']:+.3f} m, PID "
        f"{p['stop_error_m']:+.3f} m; max position error QSMC "
        f"{q['max_position_error_m']:.3f} m, PID {p['max_position_error_m']:.3f} m."
    )
    best = max(realistic, key=lambda n: realistic[n]["share_within_0_30_m"])
    out.append(
        "Realistic variant: share of stops within ±0.30 m "
        + shares_text(realistic)
        + f"; best {best.upper()}."
    )
    return out
