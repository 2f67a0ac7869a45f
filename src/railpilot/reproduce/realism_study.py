"""Which real-train effect costs stopping accuracy: switch them on one at a time.

Starting from the plant variation alone (the paper's ATO cycle, an ideal measurement),
the effects of railpilot.sim.realism are added cumulatively in the order a train meets
them: the slower ATO cycle, brake notches (if the scenario has any), speed noise and
quantisation, odometry (wheel error, slip, balise resets), the falling approach, and
low adhesion. Each step is a Monte Carlo of the same runs, so the differences between
rows are the effect of what was added.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from railpilot.reproduce.base import Table
from railpilot.scenario.model import Scenario
from railpilot.scenario.montecarlo import MonteCarloSpec
from railpilot.sim.batch import MonteCarloResult, run_montecarlo
from railpilot.sim.realism import Realism
from railpilot.vehicle.line import Line, Segment

#: The ATO cycle of both papers' realistic variants [s]
ATO_CYCLE_S = 0.2


def on_a_real_train(scenario: Scenario, name: str, notches: int = 0) -> Scenario:
    """``scenario`` with the real-train effects switched on.

    Speed noise 0.03 m/s and 0.01 m/s resolution; odometry from the wheels (a sliding
    wheel reads 10 % slow) reset by balises 150 m, 30 m and 5 m before the stop point;
    slides held at 90 % of the adhesion (wheel-slide protection); ``notches`` brake
    notches (0 = stepless); a 0.2 s ATO cycle; a -3 per mille approach over the last
    200 m. What varies per run (adhesion, wheel error, the plant) is the spec's business.
    Values and sources: docs/paper-002-qsmc.md, "Realistic variant".
    """
    stop = scenario.reference.stop_m
    return replace(
        scenario,
        name=name,
        line=Line(gradients=(Segment(stop - 200.0, stop + 50.0, -3.0),)),
        realism=Realism(
            speed_noise_std_mps=0.03,
            speed_resolution_mps=0.01,
            slide_slip=0.1,
            balises_m=(stop - 150.0, stop - 30.0, stop - 5.0),
            slide_ratio=0.9,
            notches=notches,
        ),
        sim=replace(scenario.sim, control_period_s=ATO_CYCLE_S),
    )


def ladder(
    full: Scenario, spec: MonteCarloSpec, paper_cycle_s: float
) -> list[tuple[str, Scenario, MonteCarloSpec]]:
    """The cumulative steps from the plant variation alone to ``full``."""
    real = full.realism
    plant = replace(spec, vary=tuple(d for d in spec.vary if not d.key.startswith("realism.")))
    no_adhesion = replace(spec, vary=tuple(d for d in spec.vary if d.key != "realism.adhesion"))
    flat = replace(full, line=Line())
    steps: list[tuple[str, Scenario, MonteCarloSpec]] = [
        (
            "plant varied only",
            replace(flat, realism=Realism(), sim=replace(full.sim, control_period_s=paper_cycle_s)),
            plant,
        ),
        (f"+ {full.sim.control_period_s:g} s ATO cycle", replace(flat, realism=Realism()), plant),
    ]
    notches = Realism(notches=real.notches)
    if real.notches:
        steps.append((f"+ {real.notches} brake notches", replace(flat, realism=notches), plant))
    noisy = replace(
        notches,
        speed_noise_std_mps=real.speed_noise_std_mps,
        speed_resolution_mps=real.speed_resolution_mps,
        seed=real.seed,
    )
    steps.append(("+ speed noise and quantisation", replace(flat, realism=noisy), plant))
    odometry = replace(real, adhesion=0.0)
    steps.append(
        ("+ odometry (wheel error, slip, balises)", replace(flat, realism=odometry), no_adhesion)
    )
    steps.append(("+ falling approach", replace(full, realism=odometry), no_adhesion))
    steps.append(("+ low adhesion (everything)", full, spec))
    return steps


def run_ladder(
    full: Scenario, spec: MonteCarloSpec, paper_cycle_s: float, controllers: tuple[str, ...]
) -> list[dict[str, Any]]:
    """One row per step and controller: share within ±0.30 m, p99, mean, max jerk."""
    rows = []
    for label, scenario, step_spec in ladder(full, spec, paper_cycle_s):
        for name in controllers:
            stats = run_montecarlo(scenario, name, step_spec, progress=False).stats()
            rows.append(
                {
                    "step": label,
                    "controller": name,
                    "runs": stats["runs"],
                    "share_within_0_30_m": stats["share_within_0_30_m"],
                    "p99_abs_stop_error_m": stats["p99_abs_stop_error_m"],
                    "mean_stop_error_m": stats["mean_stop_error_m"],
                    "max_jerk_mps3": stats["max_jerk_mps3"],
                }
            )
    return rows


def ladder_table(rows: list[dict[str, Any]], controllers: tuple[str, ...]) -> Table:
    """The ladder as a table: one row per step, columns per controller."""
    steps = list(dict.fromkeys(r["step"] for r in rows))
    by = {(r["step"], r["controller"]): r for r in rows}
    columns = ["effects (cumulative)"]
    for name in controllers:
        columns += [f"{name.upper()} within ±0.30 m", f"{name.upper()} p99 [m]"]
    body = []
    for step in steps:
        line: list[Any] = [step]
        for name in controllers:
            r = by[(step, name)]
            line += [f"{r['share_within_0_30_m']:.1%}", r["p99_abs_stop_error_m"]]
        body.append(line)
    runs = rows[0]["runs"] if rows else 0
    return Table(
        "Real-train effects one at a time (cumulative)",
        columns,
        body,
        note=f"{runs} runs per cell, the same plant samples and seeds in every row.",
    )


def by_distance(scenario: Scenario) -> Scenario:
    """``scenario`` with the ATO re-planning on distance to go (``ato.reference``)."""
    return replace(scenario, ato=replace(scenario.ato, reference="distance"))


def stats_table(title: str, stats: dict[str, dict[str, Any]]) -> Table:
    """Stop-error statistics of a Monte Carlo per controller, one row each."""
    return Table(
        title,
        [
            "controller",
            "runs",
            "mean [m]",
            "std [m]",
            "p95 |err| [m]",
            "p99 [m]",
            "max [m]",
            "within ±0.30 m",
            "not stopped",
            "max jerk [m/s³]",
            "worst run seed",
        ],
        [
            [
                name.upper(),
                st["runs"],
                st["mean_stop_error_m"],
                st["std_stop_error_m"],
                st["p95_abs_stop_error_m"],
                st["p99_abs_stop_error_m"],
                st["max_abs_stop_error_m"],
                f"{st['share_within_0_30_m']:.1%}",
                st["not_stopped"],
                st["max_jerk_mps3"],
                st["worst_run_seed"],
            ]
            for name, st in stats.items()
        ],
        note="max is empty when a run did not stop within the simulated time (a braking-only "
        "ATO cannot pull a train that stopped short of the point).",
    )


def public_stats(result: MonteCarloResult) -> dict[str, Any]:
    """A sweep's statistics for a payload (the worst run's full metrics left out)."""
    stats = result.stats()
    stats.pop("worst_run_metrics")
    return stats


def run_both_references(
    scenario: Scenario, spec: MonteCarloSpec, controllers: tuple[str, ...]
) -> tuple[dict[str, MonteCarloResult], dict[str, MonteCarloResult]]:
    """The same sweep with the time-based and with the distance-to-go reference."""

    def sweep(s: Scenario) -> dict[str, MonteCarloResult]:
        return {name: run_montecarlo(s, name, spec, progress=False) for name in controllers}

    return sweep(scenario), sweep(by_distance(scenario))


def shares_text(stats: dict[str, dict[str, Any]]) -> str:
    """``"PID 94.9%, QSMC 60.7%"``: the share of stops within ±0.30 m per controller."""
    return ", ".join(f"{n.upper()} {st['share_within_0_30_m']:.1%}" for n, st in stats.items())
