"""Benchmark: a whole line (cosim/line_run.py) on the 590 km heavy-haul line.

``--trains`` trains (default 60) over ``--hours`` (default 9): half loaded from Shenchi
South (1) to Huanghua Port (20), half empty the other way, departing in turn every
``9 h / (trains / 2)`` in each direction (at most every 15 min); every train driven by the
onboard driving system and the simulation core, the ground's dispatch core and the full
protocol (HMAC-SHA256 on every frame) over the simulated radio, the trackside watching
every second. Seeded: the same run every time.

Prints one JSON object: ``sim_s`` (simulated), ``wall_s``, ``realtime_factor``
(sim_s / wall_s), ``train_hours`` (hours of trains on the line), ``wall_ms_per_train_hour``,
and the run's safety KPIs. The goal: a realtime factor of at least 500 for 60
trains over 9 h on a 2-core machine. It is reported, never asserted.

The baseline, measured in the same run (before and after the day, so the machine's drift
shows): what the protocol alone allows. ``protocol_frames_per_s`` is the best of several
repetitions of the cheapest frame there is, a HEARTBEAT (empty body), sent by one end and
received, checked and accepted by the other (benchmarks/link_speed.py's path, HMAC-SHA256),
in either direction. ``protocol_ceiling_rf`` is ``sim_s`` over the time the day's
``frames_received`` would take at that rate: the realtime factor if the trains, the ground,
the channel and the event loop cost nothing and every frame were a heartbeat, an upper
bound of what this protocol code allows on this machine. ``protocol_share_of_wall`` is
that time over ``wall_s``.

The simulation core is compiled for each kind of train (Numba, about 10 s) by the first
run after a change to it, and loaded from Numba's cache (well under a second) after that;
either way it is done before the clock starts (a short warm-up run with a train of each
kind on the line).

Usage: python benchmarks/line_speed.py [--trains 60] [--hours 9] [--loss 0.0]
"""

from __future__ import annotations

import argparse
import json
import statistics

from link_speed import frames_per_s  # benchmarks/ is the script's directory

from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.link import Heartbeat

#: Repetitions of the protocol's baseline, before the day and again after it.
PROTOCOL_REPETITIONS = 5


def scenario(trains: int, hours: float, loss: float, seed: int) -> dict:
    per_direction = max(trains // 2, 1)
    every = max(15.0, hours * 60.0 / per_direction)
    service = {"first_departure_min": 5.0, "every_min": every, "count": per_direction}
    services = [
        service | {"kind": "loaded", "from": 1, "to": 20, "first_id": 101},
        service | {"kind": "empty", "from": 20, "to": 1, "first_id": 2001},
    ]
    if trains == 1:
        services = services[:1]
    return {
        "name": f"line speed, {trains} trains, {hours:g} h",
        "line": "heavy-haul",
        "seed": seed,
        "duration_h": hours,
        "channel": {"loss": loss},
        "services": services,
    }


def protocol_frames_per_s() -> list[float]:
    """Heartbeats a second through the full protocol, each direction, PROTOCOL_REPETITIONS
    times."""
    return [
        frames_per_s(True, Heartbeat(), downlink=downlink)
        for _ in range(PROTOCOL_REPETITIONS)
        for downlink in (False, True)
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trains", type=int, default=60)
    parser.add_argument("--hours", type=float, default=9.0)
    parser.add_argument("--loss", type=float, default=0.0, help="frame loss (0..0.99)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    # compile the core for both kinds of train (a loaded and an empty one on the line)
    run_line(line_scenario_from_mapping(scenario(2, 0.25, 0.0, args.seed)))
    protocol = protocol_frames_per_s()
    result = run_line(
        line_scenario_from_mapping(scenario(args.trains, args.hours, args.loss, args.seed))
    )
    protocol += protocol_frames_per_s()
    kpis = result.kpis()
    frames = sum(kpis["link"][end].get("frames_received", 0) for end in ("ground", "onboard"))
    protocol_wall_s = frames / max(protocol)
    train_hours = sum(
        (rows[-1, 0] - rows[0, 0]) / 3600.0 for rows in result.trace.values() if len(rows)
    )
    print(
        json.dumps(
            {
                "trains": args.trains,
                "hours": args.hours,
                "loss": args.loss,
                "sim_s": result.sim_s,
                "wall_s": round(result.wall_s, 2),
                "realtime_factor": round(result.sim_s / result.wall_s, 1),
                "train_hours": round(train_hours, 1),
                "wall_ms_per_train_hour": round(1e3 * result.wall_s / max(train_hours, 1e-9), 1),
                "tsr_violations": kpis["tsr_violations"],
                "target_points_passed": kpis["target_points_passed"],
                "frames_received": frames,
                "protocol_frames_per_s": round(max(protocol)),
                "protocol_frames_per_s_median": round(statistics.median(protocol)),
                "protocol_ceiling_rf": round(result.sim_s / protocol_wall_s, 1),
                "protocol_share_of_wall": round(protocol_wall_s / result.wall_s, 3),
            }
        )
    )


if __name__ == "__main__":
    main()
