"""``railpilot line simulate SCENARIO``: a whole line, trains, ground and radio together,
in simulated time, with paper 001's KPIs; ``railpilot line knock-on SCENARIO EVENT``: what
one event cost each train; ``railpilot line run SCENARIO --speedup 60``: the same live, the
ground a server and each train a process over TCP (docs/line-run.md)."""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO, cast

from railpilot.commands._common import json_text, log, out_dir_argument, print_json
from railpilot.errors import ConfigError
from railpilot.units import hms

if TYPE_CHECKING:
    from railpilot.cosim.driver import DriverKind
    from railpilot.cosim.line_run import LineResult
    from railpilot.cosim.link_sim import LinkSim

#: ``line run``'s ports: option -> what listens there (each field of cosim/live.py's
#: LiveOptions is the option's name without its dashes, "_" for "-")
LIVE_PORT_HELP = {
    "--http-port": "the dashboard's port",
    "--link-port": "the ground's link port, where the trains connect",
    "--admin-port": "the ground's admin port, where the run's dispatcher speaks",
    "--control-port": "the run's control port, where its ground and trains report",
}

#: the baselines ``line simulate`` can run (cosim/driver.py ``BASELINES``; not imported
#: from there: the command line loads the simulation only when it runs one)
BASELINE_NAMES = ("minimum-time", "human")
#: the progress line on a terminal is rewritten at most this often [s of wall clock]
PROGRESS_EVERY_S = 1.0
#: how the progress line names each run of ``line simulate``, by driver
RUN_LABELS = {
    "advised": "advised",
    "minimum-time": "minimum-time baseline",
    "human": "human baseline",
}


def register(subparsers: argparse._SubParsersAction) -> None:
    line = subparsers.add_parser(
        "line",
        help="a whole line: trains, ground and radio together",
        description="Run a line scenario (docs/line-run.md).",
    )
    sub = line.add_subparsers(dest="line_command", metavar="ACTION")
    sub.required = True
    p = sub.add_parser(
        "simulate",
        help="co-simulate a line scenario in simulated time and print its KPIs",
        description="Co-simulate SCENARIO: every train's onboard driving system and "
        "simulation core, the ground's dispatch core, and the safety link between them over "
        "a simulated radio, in simulated time. Prints paper 001's KPIs, against the baselines "
        "(the same day driven without advice: the minimum-time driver and the human driver). "
        "With --runs N, sweeps N seeds (locally on all cores, or on a Dask cluster with "
        "--scheduler) and prints each KPI's spread (of the advised runs).",
    )
    p.add_argument("scenario", type=Path, help="line-run TOML file (examples/heavy_haul_day.toml)")
    p.add_argument("--seed", type=int, help="seed (default: the file's)")
    p.add_argument("--runs", type=int, default=1, help="seeds to sweep (default 1)")
    p.add_argument("--no-baseline", action="store_true", help="skip the baseline runs")
    p.add_argument(
        "--baselines",
        default=",".join(BASELINE_NAMES),
        metavar="NAMES",
        help="the baselines to run beside a single run, comma-separated (default "
        f"{','.join(BASELINE_NAMES)}; the files of --out hold the minimum-time one)",
    )
    p.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler for --runs")
    p.add_argument(
        "--out",
        type=out_dir_argument,
        help="folder for one run's files (time_distance.png, trace.csv, sections.csv, "
        "events.json, kpis.json), or for a sweep's (--runs N): runs.csv (each seed's KPIs) "
        "and sweep.json (what is printed)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress on stderr: neither the simulated clock that a terminal shows while "
        "the day runs nor the timing lines (errors still)",
    )
    p.set_defaults(func=run)
    p = sub.add_parser(
        "knock-on",
        help="what one event of a scenario cost each train: the day with it and without it",
        description="Co-simulate SCENARIO twice with the same seed, as written and without its "
        "event EVENT (1-based, in the file's order), and print each train's arrival delay "
        "and net energy in both, and their difference: the event's own train's primary "
        "delay and the knock-on (secondary) delay of the trains it held up "
        "(docs/line-run.md, Knock-on delay).",
    )
    p.add_argument("scenario", type=Path, help="line-run TOML file (examples/line_short_day.toml)")
    p.add_argument("event", type=int, help="the event's number, 1 for the file's first")
    p.add_argument("--seed", type=int, help="seed (default: the file's)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run_knock_on)
    p = sub.add_parser(
        "run",
        help="run a line scenario live: the ground a server, each train a process over TCP",
        description="Run SCENARIO live: the ground (link server, store, dispatch, admin port "
        "and dashboard) in one process and every train (onboard driving system, simulation "
        "core, onboard unit) in its own, over TCP on loopback, on a clock --speedup times "
        "the wall's. Prints the dashboard's address when the ground is up, and the KPIs of "
        "`line simulate` at the end. The radio is loopback TCP: the file's [channel] is not "
        "applied (docs/line-run.md, Live).",
    )
    p.add_argument("scenario", type=Path, help="line-run TOML file (examples/line_live_short.toml)")
    p.add_argument(
        "--speedup",
        type=float,
        default=60.0,
        help="simulated seconds per wall-clock second (default 60: an hour in a minute)",
    )
    p.add_argument("--seed", type=int, help="seed (default: the file's)")
    p.add_argument("--until-min", type=float, help="stop after this many simulated minutes")
    for option, what in LIVE_PORT_HELP.items():
        p.add_argument(option, type=int, default=0, help=f"{what} (default: a free one)")
    p.add_argument("--screenshot", type=Path, help="PNG of the dashboard taken during the run")
    p.add_argument(
        "--screenshot-at-min", type=float, help="when to take it [simulated min] (default: mid-run)"
    )
    p.add_argument(
        "--out",
        type=out_dir_argument,
        help="folder for the run's files, as `line simulate --out` writes them "
        "(time_distance.png, trace.csv, sections.csv, events.json, kpis.json)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument(
        "--log-level",
        default="warning",
        choices=["debug", "info", "warning", "error"],
        help="the ground's, the trains' and the run's log on stderr (debug: a process's "
        "error with its traceback) [warning]",
    )
    p.set_defaults(func=run_live_command)


def run_knock_on(args: argparse.Namespace) -> int:
    """``railpilot line knock-on``: one event's cost to each train (cosim/knock_on.py)."""
    from railpilot.cosim.knock_on import knock_on
    from railpilot.cosim.scenario import load_line_scenario

    scenario = load_line_scenario(args.scenario)
    if args.seed is not None:
        _check_seed(args.seed)
    result = knock_on(scenario, args.event, seed=args.seed)
    out = result.summary()
    if args.json:
        print_json(out)
        return 0
    event = out["event"]
    print(
        f"{out['scenario']} (seed {out['seed']}): event {event['index']}, {event['label']} "
        f"at {event['at_s'] / 60.0:g} min; with it and without it"
    )
    header = ("delay with [s]", "without", "knock-on", "energy [kWh]")
    print(f"  {'train':8s} {header[0]:>15s} {header[1]:>9s} {header[2]:>9s} {header[3]:>13s}")
    for row in out["trains"].values():
        delay, energy = row["arrival_delay_s"], row["energy_kwh"]
        name = row["number"] + (" *" if row["own"] else "")
        print(
            f"  {name:8s} {_shown(delay['with']):>15s} {_shown(delay['without']):>9s}"
            f" {_shown(delay['knock_on']):>9s} {energy['knock_on']:>+13.1f}"
        )
    print(
        f"  knock-on of the other trains: {out['knock_on_others_s']} s in all, "
        f"{out['knock_on_others_late_s']} s of it later"
        + ("; * the event's own train" if out["own_train"] is not None else "")
    )
    return 0


def _shown(value: float | None) -> str:
    return "-" if value is None else f"{value:+.1f}"


def run_live_command(args: argparse.Namespace) -> int:
    """``railpilot line run``: the scenario live (cosim/live.py)."""
    from railpilot.cosim.live import MAX_SPEEDUP, LiveOptions, run_live
    from railpilot.cosim.scenario import load_line_scenario

    scenario = load_line_scenario(args.scenario)
    if args.seed is not None:
        _check_seed(args.seed)
    if not (math.isfinite(args.speedup) and 1.0 <= args.speedup <= MAX_SPEEDUP):
        raise ConfigError("--speedup", args.speedup, f"a time scale in [1, {MAX_SPEEDUP:g}]")
    if args.until_min is not None and not (math.isfinite(args.until_min) and args.until_min > 0):
        raise ConfigError("--until-min", args.until_min, "a number of minutes > 0")
    ports = _live_ports(args)
    minutes = scenario.duration_s / 60.0
    if args.screenshot_at_min is not None and not (
        math.isfinite(args.screenshot_at_min) and 0.0 < args.screenshot_at_min < minutes
    ):
        raise ConfigError(
            "--screenshot-at-min", args.screenshot_at_min, f"minutes in (0, {minutes:g})"
        )
    until_s = None if args.until_min is None else args.until_min * 60.0
    at_s = None
    if args.screenshot is not None:
        if not args.screenshot.parent.is_dir():  # found out before the run, not at its end
            folder = f"there is no folder {args.screenshot.parent}"
            allowed = f"a PNG file in a folder that exists ({folder})"
            raise ConfigError("--screenshot", str(args.screenshot), allowed)
        end = scenario.duration_s if until_s is None else min(until_s, scenario.duration_s)
        at_s = end / 2.0 if args.screenshot_at_min is None else args.screenshot_at_min * 60.0
    elif args.screenshot_at_min is not None:
        raise ConfigError("--screenshot-at-min", args.screenshot_at_min, "with --screenshot PATH")

    def announce(url: str, token: str) -> None:
        log(f"dashboard: {url}  token: {token}")

    level = getattr(logging, args.log_level.upper())
    options = LiveOptions(
        speedup=args.speedup,
        seed=args.seed,
        until_s=until_s,
        http_port=ports["http_port"],
        link_port=ports["link_port"],
        admin_port=ports["admin_port"],
        control_port=ports["control_port"],
        screenshot=args.screenshot,
        screenshot_at_s=at_s,
        on_dashboard=announce,
        log_level=level,
    )
    try:
        with _logging_to_stderr(level):
            result = run_live(args.scenario, options)
    except ConfigError as exc:
        option = _port_option(exc.field)
        if option is None:
            raise
        # a port the run could not listen on: named as the user gave it
        raise ConfigError(option, exc.value, exc.allowed) from None
    out = result.kpis()
    if args.out is not None:
        out["files"] = _write_run(args.out, out, result, None)
    if args.json:
        print_json(out)
    else:
        _print_text(out)
    return 0


def _live_ports(args: argparse.Namespace) -> dict[str, int]:
    """``line run``'s ports as LiveOptions' fields, each in range and none given twice."""
    ports: dict[str, int] = {}
    given: dict[int, str] = {}
    for option in LIVE_PORT_HELP:
        field = option.removeprefix("--").replace("-", "_")
        port = getattr(args, field)
        if not 0 <= port <= 65535:
            raise ConfigError(option, port, "0..65535 (0: a free one)")
        if port in given:  # the second would find the first holding it
            raise ConfigError(option, port, f"a port other than {given[port]}'s")
        if port != 0:
            given[port] = option
        ports[field] = port
    return ports


@contextlib.contextmanager
def _logging_to_stderr(level: int) -> Iterator[None]:
    """The run's own log lines as its processes' (``ts=... level=... event=...``,
    net/logfmt.py) for the command's length; the logging set up before is put back (the
    command may run inside a program that has its own)."""
    from railpilot.net.logfmt import setup_logging

    logger = logging.getLogger("railpilot")
    saved = (logger.handlers[:], logger.level, logger.propagate)
    setup_logging(level)
    try:
        yield
    finally:
        logger.handlers[:], logger.level, logger.propagate = saved


def _port_option(field: str) -> str | None:
    """The ``line run`` option of a LiveOptions port field, None for any other field."""
    option = "--" + field.replace("_", "-")
    return option if option in LIVE_PORT_HELP else None


class RunProgress:
    """Where a run is, on one line of a terminal rewritten in place (carriage return): the
    simulated clock, the trains running and arrived. The co-simulation calls it once a
    simulated second (``run_line``'s ``on_watch``); it writes at most once every
    ``every_s`` of ``clock`` (the wall clock): the clock is read here, never in the
    simulation, whose runs stay the same to the bit with it or without it."""

    def __init__(
        self,
        stream: TextIO,
        clock: Callable[[], float] = time.monotonic,
        every_s: float = PROGRESS_EVERY_S,
    ) -> None:
        self.stream = stream
        self.clock = clock
        self.every_s = every_s
        self._width = 0  # of the line on the terminal now (0: none)

    def planning(self, trains: int) -> None:
        """Say that the file's trains are being planned (loading a file plans every
        section of every train, which takes a while for many)."""
        self._show(f"planning {trains} train{'' if trains == 1 else 's'}...")

    def watch(self, label: str, duration_s: float) -> Callable[[LinkSim, float], None]:
        """The ``on_watch`` of one run, named ``label``, ``duration_s`` long [s]: its first
        call writes at once, the next ones every ``every_s`` at most."""
        last = -math.inf

        def on_watch(sim: LinkSim, t: float) -> None:
            nonlocal last
            now = self.clock()
            if now - last < self.every_s:
                return
            last = now
            self._show(progress_text(label, t, duration_s, sim.trains, sim.retiring))

        return on_watch

    def clear(self) -> None:
        """Take the line off the terminal (before anything else is written there)."""
        if self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
            self._width = 0

    def _show(self, text: str) -> None:
        # spaces over what is left of a longer line before it
        self.stream.write("\r" + text.ljust(self._width))
        self.stream.flush()
        self._width = len(text)


def progress_text(
    label: str, t: float, duration_s: float, trains: Mapping[int, Any], arrived: set[int]
) -> str:
    """The progress line at ``t`` [s since the run's start]: ``trains`` by id (each with
    the ``start_s`` its onboard comes up at, link_sim.py ``SimTrain``), ``arrived`` the ids
    of those at their destination; running: up and not arrived."""
    running = sum(1 for i, train in trains.items() if train.start_s <= t and i not in arrived)
    return (
        f"{label}: {hms(t)} of {hms(duration_s)} simulated, {running} running, "
        f"{len(arrived)} arrived of {len(trains)}"
    )


def _progress(args: argparse.Namespace) -> RunProgress | None:
    """The progress line of ``line simulate``, on a terminal and without --quiet only."""
    if args.quiet or not sys.stderr.isatty():
        return None
    return RunProgress(sys.stderr)


def _trains_asked(path: Path) -> int | None:
    """How many trains the line-run file at ``path`` asks for (its services' counts
    summed), read before the file is loaded and planned; None where it cannot tell (the
    loader then says what is wrong)."""
    from railpilot.errors import ScenarioError
    from railpilot.schema.reading import read_document

    data = read_document(path, "SCENARIO", "line-run file", ScenarioError)
    services = data.get("services") if isinstance(data, dict) else None
    if not isinstance(services, list):
        return None
    counts = [s.get("count", 1) if isinstance(s, dict) else None for s in services]
    if not all(isinstance(c, int) and not isinstance(c, bool) for c in counts):
        return None
    return sum(cast("list[int]", counts))


def run(args: argparse.Namespace) -> int:
    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_line_scenario

    progress = _progress(args)
    if progress is not None:
        trains = _trains_asked(args.scenario)
        if trains is not None:
            progress.planning(trains)
    try:
        scenario = load_line_scenario(args.scenario)
    finally:
        if progress is not None:
            progress.clear()
    say = (lambda _: None) if args.quiet else log
    if scenario.shifted_s:
        moved = ", ".join(f"{i} by {s / 60.0:.1f} min" for i, s in scenario.shifted_s.items())
        say(f"timetable conflicts cleared (conflicts = 'shift'): trains moved later: {moved}")
    seed = scenario.seed if args.seed is None else args.seed
    baselines = () if args.no_baseline else _baselines(args.baselines)
    if isinstance(args.runs, bool) or not 1 <= args.runs <= 100_000:
        raise ConfigError("--runs", args.runs, "a number of runs in [1, 100000]")
    _check_seed(seed, args.runs)
    if args.scheduler is not None and args.runs == 1:
        # one run goes in this process: a cluster named for it would silently be idle
        raise ConfigError("--scheduler", args.scheduler, "a cluster only for --runs N > 1")
    if args.runs > 1:
        out, results = sweep(args.scenario, seed, args.runs, args.scheduler, say)
        if args.out is not None:  # only now: a sweep that failed has written nothing
            out["files"] = _write_sweep(args.out, out, results)
    else:

        def one_run(driver: str) -> LineResult:
            watch = None if progress is None else progress.watch(RUN_LABELS[driver], end)
            try:
                return run_line(
                    scenario, seed=seed, driver=cast("DriverKind", driver), on_watch=watch
                )
            finally:
                if progress is not None:
                    progress.clear()

        end = scenario.duration_s
        result = one_run("advised")
        say(f"{scenario.name}: {result.sim_s:.0f} s simulated in {result.wall_s:.1f} s")
        runs: dict[str, LineResult] = {}
        for name in baselines:
            runs[name] = one_run(name)
            say(f"{name} baseline: {runs[name].wall_s:.1f} s")
        baseline = runs.get("minimum-time")
        out = result.kpis(baseline, runs.get("human"))
        if args.out is not None:
            out["files"] = _write_run(args.out, out, result, baseline)
    if args.json:
        print_json(out)
    else:
        _print_text(out)
    return 0


def _baselines(text: str) -> tuple[str, ...]:
    """``--baselines``: the names, each known and once, in the order given."""
    names = tuple(name.strip() for name in text.split(","))
    if not names or any(n not in BASELINE_NAMES for n in names) or len(set(names)) < len(names):
        allowed = f"a comma-separated list of {', '.join(BASELINE_NAMES)}, each once"
        raise ConfigError("--baselines", text, allowed)
    return names


def _check_seed(seed: int, runs: int = 1) -> None:
    """Refuse a ``--seed`` whose ``runs`` seeds (``seed`` on) are not all seeds a scenario
    file may give, [0, ``MAX_SEED``] (cosim/scenario.py)."""
    from railpilot.cosim.scenario import MAX_SEED

    last = MAX_SEED - (runs - 1)
    if not 0 <= seed <= last:
        allowed = f"a seed in [0, {last}]"
        if runs > 1:
            allowed += f" (--runs {runs} runs the seeds from it on, each at most {MAX_SEED})"
        raise ConfigError("--seed", seed, allowed)


def _sweep_run(path: str, seed: int) -> dict[str, Any]:
    """One seed of a sweep (in a worker: it reads the file itself)."""
    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.scenario import load_line_scenario

    return run_line(load_line_scenario(path), seed=seed).kpis()


def sweep(
    path: Path,
    seed: int,
    runs: int,
    scheduler: str | None,
    say: Callable[[str], None] = log,
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """``runs`` seeds from ``seed`` on, fanned out on this machine's cores or the Dask
    cluster at ``scheduler`` (cluster.py): the spread of each swept KPI (cosim/kpis.py
    ``sweep_summary``), and each run's KPIs in the order of its seed; ``say`` tells how
    far it is."""
    from railpilot.cluster import fan_out
    from railpilot.cosim.kpis import sweep_summary

    seeds = list(range(seed, seed + runs))
    started = time.perf_counter()
    calls = [(str(path), s) for s in seeds]
    finished = ((seeds[k], kpis) for k, kpis in fan_out(_sweep_run, calls, scheduler))
    by_seed = _collect(finished, runs, started, say)
    results = [by_seed[s] for s in seeds]
    out: dict[str, Any] = {
        "scenario": results[0]["scenario"],
        "runs": runs,
        "seeds": [seeds[0], seeds[-1]],
        "wall_s": round(time.perf_counter() - started, 2),
        **sweep_summary(seeds, results),
    }
    return out, results


def _write_sweep(folder: Path, out: dict[str, Any], results: list[dict[str, Any]]) -> list[str]:
    """``runs.csv`` (a row per seed: the seed and each swept KPI, cosim/kpis.py ``swept``,
    empty where the run has none) and ``sweep.json`` (``out`` as printed, these two files
    listed) in ``folder``; returns their paths."""
    import csv

    from railpilot.cosim.kpis import dig, swept

    folder.mkdir(parents=True, exist_ok=True)
    table = folder / "runs.csv"
    summary = folder / "sweep.json"
    files = [str(table), str(summary)]
    with table.open("w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        paths = swept()
        writer.writerow(["seed", *paths])
        for run in results:
            values = (dig(run, key) for key in paths)
            writer.writerow([run["seed"], *("" if v is None else v for v in values)])
    summary.write_text(json_text({**out, "files": files}), encoding="utf-8")
    return files


def _write_run(
    folder: Path, out: dict[str, Any], result: LineResult, baseline: LineResult | None
) -> list[str]:
    """One run's files in ``folder`` (cosim/export.py): ``time_distance.png``,
    ``trace.csv`` and ``sections.csv`` (the baseline's rows after the run's, told apart by
    ``driver``), ``events.json`` (the run's, and the baseline's beside it) and
    ``kpis.json`` (``out`` as printed, these files listed); returns their paths."""
    import pandas as pd

    from railpilot.cosim.export import events_document, section_table, trace_table
    from railpilot.report.figure import save_figure
    from railpilot.report.line_plots import time_distance

    runs = [result] if baseline is None else [result, baseline]
    folder.mkdir(parents=True, exist_ok=True)
    paths = [
        folder / name
        for name in ("time_distance.png", "trace.csv", "sections.csv", "events.json", "kpis.json")
    ]
    figure, trace, sections, events, kpis = paths
    files = [str(p) for p in paths]
    save_figure(time_distance(result, baseline), figure)
    pd.concat([trace_table(r) for r in runs], ignore_index=True).to_csv(trace, index=False)
    pd.concat([section_table(r) for r in runs], ignore_index=True).to_csv(sections, index=False)
    documents = [events_document(r) for r in runs]
    both = documents[0] if baseline is None else {"run": documents[0], "baseline": documents[1]}
    events.write_text(json_text(both), encoding="utf-8")
    kpis.write_text(json_text({**out, "files": files}), encoding="utf-8")
    return files


def _collect(
    finished: Iterator[tuple[int, dict[str, Any]]],
    runs: int,
    started: float,
    say: Callable[[str], None] = log,
) -> dict[int, dict[str, Any]]:
    """Each run's KPIs by seed, saying (``say``) how far a long sweep is as each one ends."""
    from railpilot.cosim.kpis import progress_line

    by_seed: dict[int, dict[str, Any]] = {}
    for seed, kpis in finished:
        by_seed[seed] = kpis
        say(
            f"seed {seed}: {progress_line(kpis)} ({len(by_seed)}/{runs},"
            f" {time.perf_counter() - started:.0f} s)"
        )
    return by_seed


def _print_text(out: dict[str, Any]) -> None:
    from railpilot.cosim.kpis import BASELINE_DEFINITIONS, KPIS, TEXT_LABELS, text_lines

    for path in out.get("files", []):
        log(f"wrote {path}")
    if "kpis" in out:
        print(f"{out['scenario']}: {out['runs']} runs, seeds {out['seeds'][0]}-{out['seeds'][1]}")
        for key, stats in out["kpis"].items():
            print(
                f"  {key:34s} min {stats['min']:>10} median {stats['median']:>10}"
                f" max {stats['max']:>10}"
            )
        for kpi in KPIS:
            if kpi.count_runs_not_zero:
                print(f"  runs with {kpi.label}: {out[f'runs_with_{kpi.name}']}")
        return
    print(
        f"{out['scenario']} (seed {out['seed']}): {len(out['trains'])} trains, {out['sim_s']:.0f} s"
    )
    for name in out.get("baselines", {}):
        print(f"  the {TEXT_LABELS[name]}: {BASELINE_DEFINITIONS[name]}.")
    for line in text_lines(out):
        print(line)
