"""The line live against its co-simulation (docs/line-run.md "Live").

``examples/line_live_short.toml`` (two loaded trains eight minutes apart and an empty one
the other way, a TSR, a failure, a radio dead zone; an hour) is run twice: co-simulated
(:func:`railpilot.cosim.line_run.run_line`), then live (:func:`railpilot.cosim.live.run_live`:
the ground a server process with its store, admin port and dashboard, each train its own
process over TCP on loopback) on a clock :data:`SPEEDUP` times the wall's. Halfway through
the live run, Debian's chromium photographs the dashboard.

The section's tables put each train's KPIs of the two runs side by side and the live
link's statistics; its findings say whether the live run stayed within the tolerance
tests/cosim/test_live.py asserts, from the numbers.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from railpilot.cosim.kpis import safety_kpis, safety_phrase
from railpilot.reproduce.base import Reproduction, Table, find_example

SCENARIO_FILE = "line_live_short.toml"
SCREENSHOT_PNG = "line_live_dashboard.png"
SPEEDUP = 60.0
#: when the dashboard is photographed [s of the run]: every train is on the line
SCREENSHOT_AT_S = 25 * 60.0
#: the tolerance of tests/cosim/test_live.py (per train)
CONFORMITY_PP = 1.0
ENERGY_REL = 0.03


def run(out_dir: Path) -> Reproduction:
    """Co-simulate, then run live with a screenshot into ``out_dir``; build the section."""
    from railpilot.cosim.line_run import run_line
    from railpilot.cosim.live import LiveOptions, run_live
    from railpilot.cosim.scenario import load_line_scenario

    out_dir.mkdir(parents=True, exist_ok=True)
    path = find_example(SCENARIO_FILE)
    started = time.perf_counter()
    cosim = run_line(load_line_scenario(path)).kpis()
    shot = out_dir / SCREENSHOT_PNG
    live_started = time.perf_counter()
    live = run_live(
        path, LiveOptions(speedup=SPEEDUP, screenshot=shot, screenshot_at_s=SCREENSHOT_AT_S)
    ).kpis()
    live_wall = time.perf_counter() - live_started
    seen = live["live"]["screenshot"] or {}
    figures = [shot] if seen.get("screenshot") else []
    payload = {
        "scenario": "line-live",
        "file": str(path),
        "speedup": SPEEDUP,
        "live": live,
        "cosim": cosim,
        "live_wall_s": round(live_wall, 2),
        "wall_s": round(time.perf_counter() - started, 2),
        "screenshot": seen,
    }
    note = (
        f"{live['sim_s'] / 3600:.2f} h at {SPEEDUP:g}x: the live run took {live_wall:.0f} s of "
        "wall clock with its processes' start; the co-simulation "
        f"{cosim['wall_s']:.1f} s."
    )
    return Reproduction(
        "line-live",
        f"The line live: ground server and train processes over TCP at {SPEEDUP:g}x, "
        "against the co-simulation",
        payload,
        [train_table(live, cosim, note), link_table(live, cosim)],
        figures,
        findings(live, cosim, seen),
    )


def _e2e(row: dict[str, Any]) -> float | None:
    value = row["conformity_pct"]["end_to_end"]
    return None if value is None else float(value)


def train_table(live: dict[str, Any], cosim: dict[str, Any], note: str) -> Table:
    rows = []
    for train, ours in live["trains"].items():
        theirs = cosim["trains"][train]
        rows.append(
            [
                ours["number"],
                _e2e(ours),
                _e2e(theirs),
                ours["energy_kwh"],
                theirs["energy_kwh"],
                ours["red_signal_stops"],
                theirs["red_signal_stops"],
                "yes" if ours["finished"] else "no",
            ]
        )
    for kpi in safety_kpis():
        key = kpi.name
        rows.append([key.replace("_", " "), "", "", "", "", live[key], cosim[key], ""])
    return Table(
        "Live against co-simulated, per train",
        [
            "train",
            "conformity live [%]",
            "co-sim [%]",
            "energy live [kWh]",
            "co-sim [kWh]",
            "red stops live",
            "co-sim",
            "finished live",
        ],
        rows,
        note,
    )


def _radio(link: dict[str, Any]) -> str:
    channel = link["channel"]
    lost = ", ".join(
        f"{k.removeprefix('lost_').replace('_', ' ')} {v}"
        for k, v in channel.items()
        if k.startswith("lost_")
    )
    return f"{channel['packets']} packets, {channel['delivered']} delivered, lost: {lost}"


def link_table(live: dict[str, Any], cosim: dict[str, Any]) -> Table:
    link = live["link"]
    rows = []
    for side in ("onboard", "ground"):
        counts = link[side]
        rejected = counts.get("rejected", {})
        rows.append(
            [
                side,
                counts["frames_sent"],
                counts["frames_received"],
                counts["timeouts"],
                counts["resends"],
                counts["link_failures"],
                ", ".join(f"{k} {v}" for k, v in sorted(rejected.items())) or "none",
            ]
        )
    return Table(
        "The live link (loopback TCP through the scenario's radio)",
        ["side", "frames sent", "received", "timeouts", "resends", "link failures", "rejected"],
        rows,
        f"{link['connects']} connections for {len(live['trains'])} trains; the ground's "
        "counts are its last process's (a restart starts them again). The radio, live: "
        f"{_radio(link)}; co-simulated: {_radio(cosim['link'])}.",
    )


def findings(live: dict[str, Any], cosim: dict[str, Any], seen: dict[str, Any]) -> list[str]:
    out = []
    apart = []
    for train, ours in live["trains"].items():
        theirs = cosim["trains"][train]
        a, b = _e2e(ours), _e2e(theirs)
        gap = None if a is None or b is None else abs(a - b)
        energy = abs(ours["energy_kwh"] - theirs["energy_kwh"]) / max(
            abs(theirs["energy_kwh"]), 1e-9
        )
        if gap is None or gap > CONFORMITY_PP or energy > ENERGY_REL:
            apart.append(ours["number"])
    if apart:
        out.append(
            f"Outside the tolerance (conformity {CONFORMITY_PP:g} pp, energy "
            f"{ENERGY_REL:.0%}): {', '.join(apart)}."
        )
    else:
        out.append(
            f"Every train's end-to-end conformity within {CONFORMITY_PP:g} percentage point and "
            f"energy within {ENERGY_REL:.0%} of the co-simulation's."
        )
    safety = [k.name for k in safety_kpis() if live[k.name] or cosim[k.name]]
    out.append(
        f"No {safety_phrase()}, live or co-simulated."
        if not safety
        else f"Safety KPIs not 0: {', '.join(safety)} (see the table)."
    )
    failures = live["link"]["link_failures"]
    delay = live["link"]["onboard"].get("rejected", {}).get("delay", 0)
    delay += live["link"]["ground"].get("rejected", {}).get("delay", 0)
    out.append(
        f"The live link failed {failures} time(s) and rejected {delay} frame(s) as late: at "
        f"{SPEEDUP:g}x a millisecond of the host's scheduling is {SPEEDUP:g} ms of the run's, "
        "and the delay check allows 3 s round trips (docs/line-run.md, Live). The trains "
        "reconnected; the cab signal kept them safe meanwhile."
        if failures or delay
        else "The live link neither failed nor rejected a frame as late."
    )
    if seen.get("screenshot"):
        out.append(
            f"The dashboard at {seen['t_s'] / 60:.0f} min showed {seen['trains_shown']} trains."
        )
    else:
        out.append(f"No screenshot: {seen.get('skipped', 'not taken')}.")
    return out
