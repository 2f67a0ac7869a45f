"""Benchmark: the 10,000 t train on the consist model, origin to port on the heavy-haul line.

``railpilot drive heavy-haul --from 1 --to 20`` on the consist model (one mass per
vehicle: one HXD1 and 105 loaded C80, the freight air brake along the train), and in the
same run the same drive on the point-mass model. Both are run once first on the first
section, so that neither time includes compiling. Prints one JSON object: ``wall_s`` (the
consist drive), ``masses``, ``mass_steps_per_s`` (masses times the dynamics' substeps, per
second of wall clock), ``point_mass_wall_s``; the goal (``wall_s`` under 30 s on a 2-core
machine) is reported, never asserted.
Usage: python benchmarks/ltd_speed.py [--from 1] [--to 20]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time

from railpilot.line import load_line
from railpilot.onboard.drive import CONSIST_MAX_DT_S, drive, heavy_haul_loaded
from railpilot.sim.consist_run import dynamics_inputs
from railpilot.vehicle.line import Line
from railpilot.vehicle.profile import elevation_table

GOAL_S = 30.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--from", dest="origin", type=int, default=1)
    parser.add_argument("--to", dest="port", type=int, default=20)
    args = parser.parse_args()
    line = load_line("heavy-haul")
    preset = heavy_haul_loaded()
    assert preset.consist is not None
    # compile both models (or load them from Numba's cache) on a short section
    drive(line, preset, args.origin, args.origin + 1, model="consist")
    drive(line, preset, args.origin, args.origin + 1, model="point-mass")
    started = time.perf_counter()
    consist = drive(line, preset, args.origin, args.port, model="consist")
    wall_s = time.perf_counter() - started
    started = time.perf_counter()
    point = drive(line, preset, args.origin, args.port, model="point-mass")
    point_wall_s = time.perf_counter() - started
    dyn, _ = dynamics_inputs(preset.consist, elevation_table(Line()))
    masses = int(dyn.mass_kg.shape[0])
    substeps = math.ceil(CONSIST_MAX_DT_S / float(dyn.max_substep_s[0]) - 1e-9)
    sim_s = float(consist.result["time_s"][-1])
    steps = sim_s / CONSIST_MAX_DT_S * substeps
    summary = consist.summary()
    print(
        json.dumps(
            {
                "wall_s": round(wall_s, 2),
                "masses": masses,
                "mass_steps_per_s": round(masses * steps / wall_s),
                "point_mass_wall_s": round(point_wall_s, 2),
                "ratio_to_point_mass": round(wall_s / point_wall_s, 2),
                "goal_s": GOAL_S,
                "goal_met": wall_s < GOAL_S,
                "sim_s": round(sim_s, 1),
                "dynamics_substep_s": float(dyn.max_substep_s[0]),
                "running_time_s": summary["running_time_s"],
                "point_mass_running_time_s": point.summary()["running_time_s"],
                "stop_error_m": summary["stop_error_m"],
                "max_coupler_tension_kn": summary["max_coupler_tension_kn"],
                "max_coupler_compression_kn": summary["max_coupler_compression_kn"],
                "air_brake_applications": summary["air_brake_applications"],
                "cpu": platform.processor() or platform.machine(),
                "cores": os.cpu_count(),
            }
        )
    )


if __name__ == "__main__":
    main()
