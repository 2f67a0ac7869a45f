"""``railpilot simulate SCENARIO.toml``: run one scenario file."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from railpilot.commands._common import (
    controller_argument,
    file_stem,
    log,
    out_dir_argument,
    print_json,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "simulate",
        help="run one scenario file",
        description="Run a scenario TOML file and print its metrics; with --out, write the "
        "time series (CSV and Parquet) and figures, named SCENARIO_CONTROLLER.*.",
    )
    p.add_argument("scenario", type=Path, help="scenario TOML file")
    p.add_argument(
        "--controller",
        type=controller_argument,
        metavar="NAME",
        help="override the scenario's controller (pid, smarc, qsmc, pstop for braking scenarios; "
        "open_loop, pid, fuzzy, fuzzy_pi for eddy-brake ones; module:Name or "
        "path/to/file.py:Name for your own, docs/architecture.md)",
    )
    p.add_argument("--out", type=out_dir_argument, help="folder for time series and figures")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from railpilot.scenario.loader import read_toml, scenario_from_mapping

    data = read_toml(args.scenario)
    if data.get("kind") == "eddy-brake":
        return _run_eddy(args, data)
    if data.get("kind") == "train-dynamics":
        return _run_dynamics(args, data)
    scenario = scenario_from_mapping(data)  # validates everything before running
    from railpilot.sim.run import simulate

    result = simulate(scenario, args.controller)
    files: list[str] = []
    if args.out is not None:
        from railpilot.report import ep_plots
        from railpilot.report.figure import save_figure
        from railpilot.units import kmh_to_mps

        args.out.mkdir(parents=True, exist_ok=True)
        controller = result.meta["controller"]
        stem = file_stem(scenario.name, controller)
        files.append(str(result.to_csv(args.out / f"{stem}.csv")))
        files.append(str(result.to_parquet(args.out / f"{stem}.parquet")))
        co = kmh_to_mps(scenario.changeover_kmh)
        runs = {controller: result}
        for figure, kind in (
            (ep_plots.speed_distance(runs, co), "speed_distance"),
            (ep_plots.speed_error(runs, co), "speed_error"),
        ):
            files.append(str(save_figure(figure, args.out / f"{stem}_{kind}.png")))
    if args.json:
        print_json(
            {
                "scenario": scenario.name,
                "controller": result.meta["controller"],
                "metrics": result.summary(),
                "files": files,
            }
        )
    else:
        print(f"{scenario.name}  controller={result.meta['controller']}")
        for key, value in result.summary().items():
            print(f"  {key:32s} {value if value is None else f'{value:.4g}'}")
        for f in files:
            log(f"wrote {f}")
    return 0


def _run_eddy(args: argparse.Namespace, data: dict[str, Any]) -> int:
    """An ``eddy-brake`` scenario (paper 003): torque control of the eddy-current brake."""
    from railpilot.eddy.scenario import EddyScenario

    scenario = EddyScenario.from_mapping(data, base_dir=args.scenario.parent)
    # metrics from every step; the series kept every ``record_every``-th step
    result, metrics = scenario.run(args.controller)
    controller = args.controller or scenario.controller
    files: list[str] = []
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / f"{file_stem(scenario.name, controller)}.csv"
        result.to_pandas().to_csv(path)
        files.append(str(path))
    values = metrics.to_dict()
    if args.json:
        print_json(
            {"scenario": scenario.name, "controller": controller, "metrics": values, "files": files}
        )
    else:
        print(f"{scenario.name}  controller={controller}")
        for key, value in values.items():
            print(f"  {key:32s} {value}")
        for f in files:
            log(f"wrote {f}")
    return 0


def _run_dynamics(args: argparse.Namespace, data: dict[str, Any]) -> int:
    """A ``train-dynamics`` scenario: a consist driven along a line by a script (and, if
    the file asks, the same again without distributed power)."""
    from dataclasses import replace

    from railpilot.errors import ScenarioError
    from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
    from railpilot.sim.consist_run import run_consist

    if args.controller is not None:
        raise ScenarioError(
            "--controller",
            args.controller,
            "none: a train-dynamics scenario is driven by its script",
        )
    scenario = consist_scenario_from_mapping(data, base_dir=args.scenario.parent)
    runs = {"": run_consist(scenario)}
    if scenario.sim.compare_without_distributed_power:
        alone = replace(scenario, sim=replace(scenario.sim, distributed_power=False))
        runs = {"with_distributed_power": runs[""], "without_distributed_power": run_consist(alone)}
    files: list[str] = []
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        for label, result in runs.items():
            files += _write_dynamics(args.out, file_stem(scenario.name, label), result)
    if args.json:
        out: dict[str, Any] = {"scenario": scenario.name, "consist": scenario.consist.name}
        if "" in runs:
            out |= {"metrics": runs[""].summary(), "events": runs[""].events}
        else:
            out["runs"] = {
                label: {"metrics": r.summary(), "events": r.events} for label, r in runs.items()
            }
        print_json(out | {"files": files})
    else:
        print(f"{scenario.name}  consist={scenario.consist.name}")
        for label, result in runs.items():
            if label:
                print(f" {label.replace('_', ' ')}:")
            for key, value in result.summary().items():
                shown = value if not isinstance(value, float) else f"{value:.4g}"
                print(f"  {key:38s} {'n/a' if value is None else shown}")
        for f in files:
            log(f"wrote {f}")
    return 0


def _write_dynamics(out: Path, stem: str, result: Any) -> list[str]:
    """A consist run's files: its series (CSV), its fields along the train (NPZ) and its
    three figures."""
    import numpy as np

    from railpilot.report import consist_plots
    from railpilot.report.figure import save_figure

    series = out / f"{stem}.csv"
    np.savetxt(
        series,
        np.column_stack(list(result.series.values())),
        delimiter=",",
        header=",".join(result.series),
        comments="",
    )
    along = out / f"{stem}_fields.npz"
    np.savez_compressed(along, **result.fields, time_s=result.series["time_s"])
    files = [str(series), str(along)]
    for figure, kind in (
        (consist_plots.coupler_heat_map(result), "coupler_forces"),
        (consist_plots.brake_pipe_along_train(result), "brake_pipe"),
        (consist_plots.run_overview(result), "overview"),
    ):
        files.append(str(save_figure(figure, out / f"{stem}_{kind}.png")))
    return files
