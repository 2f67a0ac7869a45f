"""``railpilot montecarlo SCENARIO.toml``: a seeded Monte Carlo sweep of a scenario."""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from railpilot.commands._common import (
    controller_argument,
    file_stem,
    log,
    out_dir_argument,
    print_json,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "montecarlo",
        help="Monte Carlo sweep of a scenario file",
        description="Run N seeded runs of a scenario with the parameter distributions of its "
        "[montecarlo] table; print stop-error statistics and the worst run. Runs "
        "in parallel on the local cores, or on a Dask cluster with --scheduler.",
    )
    p.add_argument("scenario", type=Path, help="scenario TOML file with a [montecarlo] table")
    p.add_argument("--runs", type=int, help="number of runs (default: the file's)")
    p.add_argument("--seed", type=int, help="master seed (default: the file's)")
    p.add_argument(
        "--controller",
        action="append",
        type=controller_argument,
        metavar="NAME",
        help="controller to sweep (pid, smarc, qsmc, pstop, or module:Name for your own); "
        "repeat for several (default: the file's)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask distributed scheduler, e.g. tcp://127.0.0.1:8786",
    )
    p.add_argument("--out", type=out_dir_argument, help="folder for the stop-error histogram")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from railpilot.errors import ConfigError, ScenarioError
    from railpilot.scenario.loader import load_scenario_and_spec
    from railpilot.scenario.montecarlo import MonteCarloSpec
    from railpilot.sim.batch import check_spec, freeze_ato, run_montecarlo
    from railpilot.sim.run import resolve_controller

    scenario, spec = load_scenario_and_spec(args.scenario)
    spec = spec or MonteCarloSpec()
    for option, key, value in (("--runs", "runs", args.runs), ("--seed", "seed", args.seed)):
        if value is None:
            continue
        try:
            spec = replace(spec, **{key: value})
        except ConfigError as exc:  # the spec's own check, named as the option given
            raise ScenarioError(option, value, exc.allowed) from None
    controllers = args.controller or [scenario.controller.name]
    check_spec(scenario, spec)
    for name in controllers:
        # each controller is built before the first sweep runs: a bad name in second
        # place must not cost the first one's whole sweep
        resolve_controller(freeze_ato(scenario), name)
    results = {}
    summary = {}
    for name in controllers:
        started = time.perf_counter()
        result = run_montecarlo(
            scenario, name, spec, progress=not args.no_progress, scheduler=args.scheduler
        )
        stats = result.stats()
        stats["wall_s"] = time.perf_counter() - started
        results[name] = result
        summary[name] = stats
        log(f"{name}: {spec.runs} runs in {stats['wall_s']:.2f} s")
    files = []
    if args.out is not None:
        from railpilot.report.figure import save_figure
        from railpilot.report.montecarlo_plots import stop_error_histogram

        args.out.mkdir(parents=True, exist_ok=True)
        figure = stop_error_histogram(
            results, title=f"{scenario.name}: {spec.runs} runs, seed {spec.seed}"
        )
        path = args.out / f"{file_stem(scenario.name)}_stop_errors.png"
        files.append(str(save_figure(figure, path)))
    payload = {
        "scenario": scenario.name,
        "runs": spec.runs,
        "seed": spec.seed,
        "vary": [d.__dict__ for d in spec.vary],
        "results": summary,
        "files": files,
    }
    if args.json:
        print_json(payload)
        return 0
    for name, stats in summary.items():
        print(f"{scenario.name}  controller={name}  runs={stats['runs']}  seed={spec.seed}")
        for key, value in stats.items():
            if key != "worst_run_metrics":
                print(f"  {key:28s} {value}")
    for f in files:
        log(f"wrote {f}")
    return 0
