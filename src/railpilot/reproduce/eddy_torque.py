"""``railpilot reproduce eddy-torque``: paper 003's two constant-torque cases.

Both cases (3500 N m from 160 km/h, 4500 N m from 200 km/h; 100 s at 1e-4 s) with the
open loop and the three torque controllers. Metrics are computed on every step
(``record_every=1``); the figures use every 10th step except the first-second zoom.

The simulation is deterministic, so a ranking can differ by any amount and still look
"consistent". To tell a real difference from an accident of the chopper-ripple phase,
every closed-loop run is repeated with the initial speed shifted by
``SPREAD_OFFSETS_KMH`` (a few tenths of a km/h: the same experiment, a different ripple
phase); the spread (max - min) of each metric over those runs is the run-to-run noise
a ranking has to beat (``overshoot_spread_nm``, ``steady_variance_spread_nm2``).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from railpilot.eddy.scenario import CONTROLLERS, EddyScenario
from railpilot.eddy.simulate import EddyResult, warm_up
from railpilot.reproduce.base import Reproduction, Table

CASES: tuple[tuple[float, float], ...] = ((3500.0, 160.0), (4500.0, 200.0))
#: Initial-speed shifts [km/h] of the repeated runs that measure the run-to-run spread.
SPREAD_OFFSETS_KMH: tuple[float, ...] = (-0.2, -0.1, 0.1, 0.2)
CLOSED = ("pid", "fuzzy", "fuzzy_pi")
SPREAD_KEYS = (
    ("overshoot_nm", "overshoot_spread_nm"),
    ("steady_variance_nm2", "steady_variance_spread_nm2"),
)
METRIC_KEYS = (
    "rise_time_s",
    "settling_time_s",
    "peak_time_s",
    "overshoot_nm",
    "steady_mean_nm",
    "steady_max_nm",
    "steady_min_nm",
    "steady_variance_nm2",
    "hold_until_speed_kmh",
)


def run_case(
    demand_nm: float,
    speed_kmh: float,
    duration_s: float = 100.0,
    spread_offsets_kmh: tuple[float, ...] = (),
) -> tuple[dict[str, dict[str, Any]], dict[str, EddyResult], EddyScenario]:
    """Simulate one case with every controller; returns metrics, thinned results, scenario.

    With ``spread_offsets_kmh`` each closed-loop controller is also run from
    ``speed_kmh + offset`` and its row gets the spread (max - min over all its runs) of
    overshoot and steady variance (keys in ``SPREAD_KEYS``).
    """
    scenario = EddyScenario.from_mapping(
        {"torque_demand_nm": demand_nm, "initial_speed_kmh": speed_kmh, "duration_s": duration_s}
    )
    metrics: dict[str, dict[str, Any]] = {}
    results: dict[str, EddyResult] = {}
    for name in CONTROLLERS:
        result, m = scenario.run(name, record_every=1)
        row: dict[str, Any] = m.to_dict()
        row["wall_time_s"] = result.metadata["wall_time_s"]
        metrics[name] = row
        # figures need 1 ms resolution at most (the zoom on the first second included),
        # except the ripple close-up, which keeps every step of a 10 ms window
        thin = result.every(10)
        window = (result.time_s >= 10.0) & (result.time_s <= 10.01)
        thin.metadata["ripple"] = (result.time_s[window].copy(), result.torque_nm[window].copy())
        results[name] = thin
    if spread_offsets_kmh:
        for name in CLOSED:
            seen = {key: [_num(metrics[name][key])] for key, _ in SPREAD_KEYS}
            for offset in spread_offsets_kmh:
                shifted = EddyScenario.from_mapping(
                    {
                        "torque_demand_nm": demand_nm,
                        "initial_speed_kmh": speed_kmh + offset,
                        "duration_s": duration_s,
                    }
                )
                _, m = shifted.run(name, record_every=1)
                row = m.to_dict()
                for key, _ in SPREAD_KEYS:
                    seen[key].append(_num(row[key]))  # type: ignore[arg-type]
            for key, spread_key in SPREAD_KEYS:
                metrics[name][spread_key] = max(seen[key]) - min(seen[key])
    return metrics, results, scenario


def _num(value: float | None) -> float:
    """JSON ``None`` (an undefined metric) back to ``nan`` for comparisons and formatting."""
    return math.nan if value is None else float(value)


def rank_verdict(values: dict[str, float], spreads: dict[str, float]) -> str:
    """Compare closed-loop values (lower is better) with the paper's order.

    ``"paper"``: fuzzy_pi best and pid worst, each by a margin larger than the
    run-to-run spreads of the two controllers compared; ``"tie"``: the paper's order
    only by margins inside that spread (or equal values); ``"not paper"``: the order is
    reversed by a margin larger than the spread.
    """
    if not spreads:
        spreads = dict.fromkeys(values, 0.0)

    def beats(a: str, b: str) -> str:  # "yes": a < b beyond noise, "no": a > b beyond it
        gap = values[b] - values[a]
        noise = spreads[a] + spreads[b]
        if gap > noise:
            return "yes"
        if -gap > noise:
            return "no"
        return "tie"

    pairs = [beats("fuzzy_pi", "fuzzy"), beats("fuzzy_pi", "pid"), beats("fuzzy", "pid")]
    if all(p == "yes" for p in pairs):
        return "paper"
    if "no" in pairs:
        return "not paper"
    return "tie"


VERDICT_TEXT = {
    "paper": "the paper's order, every margin larger than the run-to-run spread",
    "tie": "NOT a meaningful ranking: some margins are inside the run-to-run spread",
    "not paper": "NOT the paper's order (beyond the run-to-run spread)",
}


def _rank_claims(case: dict[str, Any], label: str) -> list[str]:
    res = case["results"]
    out = []
    for key, spread_key, what in (
        ("overshoot_nm", "overshoot_spread_nm", "overshoot"),
        ("steady_variance_nm2", "steady_variance_spread_nm2", "steady variance"),
    ):
        values = {c: _num(res[c][key]) for c in CLOSED}
        spreads = {c: _num(res[c].get(spread_key)) for c in CLOSED if spread_key in res[c]}
        numbers = ", ".join(
            f"{c} {values[c]:.3f}" + (f" (spread {spreads[c]:.3f})" if c in spreads else "")
            for c in CLOSED
        )
        verdict = rank_verdict(values, spreads if len(spreads) == len(CLOSED) else {})
        out.append(f"{label}: {what} {numbers} -- {VERDICT_TEXT[verdict]}.")
    return out


def run(
    out_dir: Path,
    *,
    duration_s: float = 100.0,
    spread_offsets_kmh: tuple[float, ...] = SPREAD_OFFSETS_KMH,
) -> Reproduction:
    """Run both cases, write fig. 7/8-like PNGs into ``out_dir``, return the reproduction."""
    from railpilot.report.eddy_plots import (
        plot_settled_ripple,
        plot_torque_vs_speed,
        plot_torque_vs_time,
    )
    from railpilot.report.figure import save_figure

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    compile_s = warm_up()
    cases: list[dict[str, Any]] = []
    tables: list[Table] = []
    figures: list[Path] = []
    findings: list[str] = []
    t0 = time.perf_counter()
    for number, (demand, speed) in enumerate(CASES, start=1):
        metrics, results, scenario = run_case(demand, speed, duration_s, spread_offsets_kmh)
        label = f"case {number} ({demand:.0f} N m from {speed:.0f} km/h)"
        cases.append({"torque_demand_nm": demand, "initial_speed_kmh": speed, "results": metrics})
        rows = [
            [name]
            + [metrics[name][k] if metrics[name][k] is not None else "n/a" for k in METRIC_KEYS]
            for name in CONTROLLERS
        ]
        tables.append(
            Table(
                title=f"Paper 003 Table 4, {label}",
                columns=[
                    "controller",
                    "rise [s]",
                    "settling [s]",
                    "peak [s]",
                    "overshoot [N m]",
                    "mean [N m]",
                    "max [N m]",
                    "min [N m]",
                    "variance [(N m)^2]",
                    "hold until [km/h]",
                ],
                rows=rows,
                note=(
                    "Rise 10-90 %; settling into +-2 %; overshoot = largest torque of the run "
                    "minus the demand; steady statistics from 5 s until the speed falls to "
                    "30 km/h (or to 10 km/h above the current-limit speed if that is higher); "
                    "hold = end of the longest stretch within +-1 %."
                ),
            )
        )
        title = f"Case {number}: {demand:.0f} N m from {speed:.0f} km/h"
        for plot, kind in (
            (plot_torque_vs_speed, "torque_speed"),
            (plot_torque_vs_time, "torque_time"),
            (plot_settled_ripple, "ripple"),
        ):
            figures.append(
                save_figure(plot(results, demand, title), out_dir / f"eddy_case{number}_{kind}.png")
            )
        limit = scenario.holdable_down_to_kmh(scenario.build_table())
        findings.extend(_rank_claims(cases[-1], label))
        open_loop = metrics["open_loop"]
        holds = ", ".join(
            f"{c} {_num(metrics[c]['hold_until_speed_kmh']):.2f}"
            for c in ("pid", "fuzzy", "fuzzy_pi")
        )
        findings.append(
            f"{label}: closed loop holds the demand within 1 % down to {holds} km/h "
            f"(current limit makes it unreachable below {limit:.1f} km/h); the open loop "
            f"leaves the band at {_num(open_loop['hold_until_speed_kmh']):.1f} km/h and "
            f"its steady variance is {_num(open_loop['steady_variance_nm2']):.0f} (N m)^2."
        )
    fpi = cases[0]["results"]["fuzzy_pi"]
    findings.append(
        f"Case 1 fuzzy adaptive PI: overshoot {_num(fpi['overshoot_nm']):.2f} N m (target <= 4.6), "
        f"steady variance {_num(fpi['steady_variance_nm2']):.2f} (N m)^2 (target <= 5.6)."
    )
    lead_a = scenario.coil.reference_lead_a
    for number, case in enumerate(cases, start=1):
        res = case["results"]
        var = [_num(res[c]["steady_variance_nm2"]) for c in CLOSED]
        peak = [_num(res[c]["overshoot_nm"]) for c in CLOSED]
        peak_t = ", ".join(f"{c} {_num(res[c]['peak_time_s']):.1f} s" for c in CLOSED)
        pid_worst = all(
            _num(res["pid"][k]) == max(_num(res[c][k]) for c in CLOSED)
            for k in ("overshoot_nm", "steady_variance_nm2")
        )
        findings.append(
            f"Case {number}: the closed-loop steady variances lie within "
            f"{100.0 * (max(var) - min(var)) / min(var):.1f} % of each other and the "
            f"overshoots within {max(peak) - min(peak):.2f} N m; the largest torque comes at "
            f"{peak_t}: the chopper ripple of the settled loop, not a transient, wherever it "
            "is seconds after the rise. The +-0.1 A hysteresis band and the coil slopes set "
            f"that ripple for every controller; the +-{lead_a:g} A reference lead (the "
            "anti-windup) makes every fast controller's arrival voltage-limited and alike."
            + (
                " PID (paper gains) is worst because it follows the speed-driven torque drift "
                "with the lowest gain (its 0.1 s-mean torque wanders most)."
                if pid_worst
                else ""
            )
        )
    findings.append(
        "The paper's PID overshoot (111.7 N m, settling 3.2 s) is not reproduced: no reading "
        "of its gains with a drive-like anti-windup overshoots at all; only an integrator "
        "left to wind up during the voltage-limited rise shows that character, and its size "
        "then depends on the assumed sample period (docs/paper-003-eddy-brake.md)."
    )
    payload = {"scenario": "eddy-torque", "cases": cases}
    tables.append(
        Table(
            title="Run time",
            columns=["item", "seconds"],
            rows=[
                ["one-off compile/cache load", compile_s],
                ["all simulations", time.perf_counter() - t0],
            ],
        )
    )
    return Reproduction(
        scenario="eddy-torque",
        title=(
            "Paper 003: eddy-current brake torque control "
            "(open loop, PID, fuzzy, fuzzy adaptive PI)"
        ),
        payload=payload,
        tables=tables,
        figures=figures,
        findings=findings,
    )
