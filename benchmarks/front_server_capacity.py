"""How many trains one ground front-server process holds with running-info p99 < 50 ms.

Runs ``railpilot link loadtest`` (railpilot.rigs.loadtest) at increasing train counts
(:data:`COUNTS`, up to the load test's ``MAX_TRAINS``), a short run each, and stops a
ladder at the first count whose p99 is 50 ms or more (or that loses a frame). Two ladders:

- ``link``: the front server's link layer alone (frames, checks, HMAC, the trains' records);
- ``dispatch``: with the ground's dispatch core as ``railpilot ground serve`` runs it
  (registry, TSR manager, block occupancy and target points every second);

and with ``--dashboard`` a third, with the dispatcher dashboard open in headless chromium.

Every run is on this machine: the onboard clients run in child processes on the same cores
as the server (and chromium, with ``--dashboard``), so they compete with it; each run
reports the server's CPU share and the clients' CPU seconds, and the load average before
it (another job on the machine shows there). docs/scaling.md has the numbers.

Prints one JSON object on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from typing import Any

from railpilot.rigs.loadtest import MAX_TRAINS, LoadtestOptions, run_loadtest

COUNTS = (250, 500, 750, 1000, 1500, 2000, 2500, 3000, 4000, 5000)
GOAL_P99_MS = 50.0
SECONDS = 15.0


def _run(trains: int, seconds: float, *, dispatch: bool, dashboard: bool) -> dict[str, Any]:
    load = os.getloadavg()[0]
    report = run_loadtest(
        LoadtestOptions(trains=trains, seconds=seconds, dispatch=dispatch, dashboard=dashboard)
    )
    run = {
        "trains": trains,
        "p50_ms": report["p50_latency_ms"],
        "p99_ms": report["p99_latency_ms"],
        "max_ms": report["max_latency_ms"],
        "lost": report["lost"],
        "server_cpu_pct": report["server_cpu_pct"],
        "clients_cpu_s": report["clients_cpu_s"],
        "load_avg_before": round(load, 2),
    }
    if dashboard:
        page = report["dashboard"]
        run |= {
            "updates_per_s": page.get("updates_per_s"),
            "max_gap_s": page.get("max_gap_s"),
            "snapshot_ms_p50": page.get("snapshot_ms_p50"),
        }
    print(f"{'+'.join(_name(dispatch, dashboard))}: {run}", file=sys.stderr, flush=True)
    return run


def _name(dispatch: bool, dashboard: bool) -> list[str]:
    return (
        ["link"]
        + (["dispatch"] if dispatch or dashboard else [])
        + (["dashboard"] if dashboard else [])
    )


def _ladder(seconds: float, top: int, *, dispatch: bool, dashboard: bool) -> dict[str, Any]:
    runs = []
    held = 0
    for trains in (n for n in COUNTS if n <= top):
        run = _run(trains, seconds, dispatch=dispatch, dashboard=dashboard)
        runs.append(run)
        if run["p99_ms"] is None or run["p99_ms"] >= GOAL_P99_MS or run["lost"]:
            break
        held = trains
    return {"trains_at_p99_under_50ms": held, "runs": runs}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=SECONDS, help=f"per run [{SECONDS}]")
    parser.add_argument("--max-trains", type=int, default=MAX_TRAINS, help="largest count")
    parser.add_argument("--dashboard", action="store_true", help="a third ladder, page open")
    args = parser.parse_args()
    link = _ladder(args.seconds, args.max_trains, dispatch=False, dashboard=False)
    dispatch = _ladder(args.seconds, args.max_trains, dispatch=True, dashboard=False)
    result: dict[str, Any] = {
        "trains_at_p99_under_50ms": link["trains_at_p99_under_50ms"],
        "runs": link["runs"],
        "with_dispatch": dispatch,
        "seconds_per_run": args.seconds,
        "goal_p99_ms": GOAL_P99_MS,
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    if args.dashboard:
        result["with_dashboard"] = _ladder(
            args.seconds, args.max_trains, dispatch=True, dashboard=True
        )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
