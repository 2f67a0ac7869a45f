"""Benchmark: the link co-simulation (cosim/link_sim.py) on the heavy-haul line.

``--trains`` trains (default 60), half up and half down, spread along the 590 km line at
18 m/s, each coming up 5 s after the one before. HMAC-SHA256 on every frame, the dispatch
core ticking every second, a TSR set after 10 minutes. The trains move at constant speed:
this measures the link and the ground in the loop, not yet the trains' simulation core
(docs/cosim.md). Seeded: the same run every time.

Prints one JSON object: ``sim_s`` (simulated), ``wall_s``, ``realtime_factor``
(sim_s / wall_s), ``frames`` (ground and onboard, received), and the channel's counts.
The goal for the whole system, 60 trains over a 9-hour day, is a realtime factor
of at least 500. It is reported, never asserted.

Usage: python benchmarks/link_cosim_speed.py [--trains 60] [--hours 1] [--loss 0.3]
"""

from __future__ import annotations

import argparse
import json
import time

from railpilot.cosim.channel import ChannelModel, DeadZone
from railpilot.cosim.link_sim import LinkSim, SimTrain
from railpilot.ground.operations import parse_operation
from railpilot.line.loader import load_line
from railpilot.link import OnboardConfig, TravelDirection
from railpilot.link.keys import seeded_test_keys as loadtest_keys
from railpilot.net.client import Trajectory


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trains", type=int, default=60)
    parser.add_argument("--hours", type=float, default=1.0)
    parser.add_argument("--loss", type=float, default=0.0, help="packet loss (0..0.99)")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    line = load_line("heavy-haul")
    ids = range(20001, 20001 + args.trains)
    spacing_m = (line.end_m - line.start_m - 10_000.0) / max(1, args.trains // 2)
    trains = []
    for k, train_id in enumerate(ids):
        up = k % 2 == 0
        offset = 5_000.0 + (k // 2) * spacing_m
        start = line.start_m + offset if up else line.end_m - offset
        config = OnboardConfig(
            train_id=train_id,
            ground_id=1,
            train_number=f"K{train_id}",
            loco_number="HXD1",
            driver_id=train_id,
            train_length_m=2600.0,
        )
        direction = TravelDirection.UP if up else TravelDirection.DOWN
        mover = Trajectory(start_m=start, speed_mps=18.0, direction=direction)
        trains.append(SimTrain(config, mover, start_s=5.0 * k))
    dead_zones = (DeadZone(120.0, 125.0),) if args.loss else ()
    channel = ChannelModel(loss=args.loss, dead_zones=dead_zones)
    sim = LinkSim(line, trains, channel, loadtest_keys(args.seed, ids), seed=args.seed)
    sim_s = args.hours * 3600.0
    t0 = time.perf_counter()
    sim.run_until(min(600.0, sim_s))
    fields = {"start_km": 200, "end_km": 202, "limit_kmh": 40, "valid_until_min": 120}
    op = parse_operation("tsr_set", {**fields, "reason": "works"}, line=line, now_s=sim.now_s)
    sim.execute(sim.dispatch.execute(op, "benchmark", sim.now_s).commands)
    sim.run_until(sim_s)
    wall = time.perf_counter() - t0
    report = sim.link_report()
    frames = report["ground"]["frames_received"] + report["onboard"]["frames_received"]
    print(
        json.dumps(
            {
                "trains": args.trains,
                "sim_s": sim_s,
                "wall_s": round(wall, 2),
                "realtime_factor": round(sim_s / wall, 1),
                "frames": frames,
                "us_per_frame": round(wall / max(1, frames) * 1e6, 1),
                "loss": args.loss,
                "channel": report["channel"],
                "link_failures": report["link_failures"],
                "goal_realtime_factor": 500,
            }
        )
    )


if __name__ == "__main__":
    main()
