"""``railpilot drive LINE --train TRAIN --from A --to B``: one station pair under the
onboard driving system (docs/onboard.md, "railpilot drive")."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

from railpilot.commands._common import file_stem, log, out_dir_argument, print_json
from railpilot.errors import ConfigError, LineError, RunFailed
from railpilot.units import km_post_to_m, kmh_to_mps, m_to_km_post

if TYPE_CHECKING:
    from railpilot.line.model import RailLine
    from railpilot.onboard.drive import DriveOutcome


def register(subparsers: argparse._SubParsersAction) -> None:
    from railpilot.onboard.shipped_trains import SHIPPED_TRAINS

    p = subparsers.add_parser(
        "drive",
        help="plan and drive one station pair under the onboard system",
        description=__doc__,
    )
    p.add_argument("line", help="a shipped line ('heavy-haul', 'metro') or a line file")
    p.add_argument("--train", default="heavy-haul-loaded", choices=sorted(SHIPPED_TRAINS))
    p.add_argument("--from", dest="from_station", type=int, required=True, help="station id")
    p.add_argument("--to", dest="to_station", type=int, required=True, help="station id")
    times = p.add_mutually_exclusive_group()
    times.add_argument("--running-time", type=float, help="[s]; default: fastest + 10 %%")
    times.add_argument(
        "--timetable",
        help="a timetable file, or 'heavy-haul' (the shipped one): drive every section of "
        "it from --from to --to",
    )
    p.add_argument(
        "--tsr",
        action="append",
        default=[],
        metavar="START_KM:END_KM:KMH[@SET_S]",
        help="a temporary speed restriction, received SET_S s after the departure from "
        "--from (default 0: known at departure; repeatable)",
    )
    p.add_argument(
        "--target",
        action="append",
        default=[],
        metavar="KM[@SET_S[:CLEAR_S]]",
        help="a signal held at red (a target point), from SET_S until CLEAR_S s after the "
        "departure from --from (default: from the start, never cleared; repeatable)",
    )
    p.add_argument(
        "--margin",
        type=float,
        default=5.0,
        metavar="KMH",
        help="the plan keeps this far below the MRSP [km/h] (default 5)",
    )
    p.add_argument(
        "--model",
        choices=("consist", "point-mass"),
        default="consist",
        help="the train that follows the plan: every vehicle of its consist with couplers and "
        "the freight air brake along the train (default), or the point mass with the "
        "precise-stop controller (docs/consist-run.md)",
    )
    p.add_argument("--out", type=out_dir_argument, help="write the figures here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run)


def parse_tsr(text: str) -> tuple[float, float, float, float]:
    """``START_KM:END_KM:KMH[@SET_S]`` -> (start [m], end [m], limit [m/s], set [s])."""
    body, _, when = text.partition("@")
    allowed = "START_KM:END_KM:KMH[@SET_S], numbers, SET_S >= 0"
    try:
        start, end, kmh = (float(p) for p in body.split(":"))
        set_s = float(when) if when else 0.0
    except ValueError:
        raise ConfigError("--tsr", text, allowed) from None
    if not (start < end and 0 < kmh <= 200):
        raise ConfigError("--tsr", text, "START_KM < END_KM and a limit in (0, 200] km/h")
    if not (math.isfinite(set_s) and set_s >= 0):
        raise ConfigError("--tsr", text, allowed)
    return (
        float(km_post_to_m(start)),
        float(km_post_to_m(end)),
        float(kmh_to_mps(kmh)),
        set_s,
    )


def parse_target(text: str) -> tuple[float, float, float]:
    """``KM[@SET_S[:CLEAR_S]]`` -> (signal [m], set [s], clear [s]; inf: never)."""
    km, _, when = text.partition("@")
    set_text, _, clear_text = when.partition(":")
    allowed = "KM[@SET_S[:CLEAR_S]], numbers, 0 <= SET_S < CLEAR_S"
    try:
        signal = float(km)
        set_s = float(set_text) if set_text else 0.0
        clear_s = float(clear_text) if clear_text else math.inf
    except ValueError:
        raise ConfigError("--target", text, allowed) from None
    if not (math.isfinite(signal) and math.isfinite(set_s) and 0 <= set_s < clear_s):
        raise ConfigError("--target", text, allowed)
    return float(km_post_to_m(signal)), set_s, clear_s


def _check_on_line(
    line: RailLine, texts: list[str], spans_m: list[tuple[float, float]], option: str
) -> None:
    """Each of ``option``'s km-post spans [m] inside ``line`` (a TSR or a signal off the
    line would be planned for and never met; the ground refuses them as well)."""
    lo, hi = m_to_km_post(line.start_m), m_to_km_post(line.end_m)
    for text, (start_m, end_m) in zip(texts, spans_m, strict=True):
        if not line.start_m <= start_m <= end_m <= line.end_m:
            raise ConfigError(option, text, f"km posts on line {line.name}, {lo:g} to {hi:g}")


def run(args: argparse.Namespace) -> int:
    from railpilot.line import load_line
    from railpilot.onboard.drive import TargetRequest, TsrRequest, drive, train_preset

    # every input is checked before anything runs or is written
    tsrs = tuple(TsrRequest(*parse_tsr(t)) for t in args.tsr)
    if args.running_time is not None and not args.running_time > 0:
        raise ConfigError("--running-time", args.running_time, "a running time > 0 [s]")
    line = load_line(args.line)
    preset = train_preset(args.train)
    for name, station in (("--from", args.from_station), ("--to", args.to_station)):
        try:
            line.station(station)
        except LineError as exc:
            ids = ", ".join(str(s.id) for s in line.stations)
            raise ConfigError(name, station, f"a station id of {line.name}: {ids}") from exc
    targets = tuple(TargetRequest(*parse_target(t)) for t in args.target)
    _check_on_line(line, args.tsr, [(t.start_m, t.end_m) for t in tsrs], "--tsr")
    _check_on_line(line, args.target, [(t.signal_m, t.signal_m) for t in targets], "--target")
    if args.timetable is not None:
        from railpilot.cosim.scenario import check_timetable
        from railpilot.onboard.timetable import load_timetable

        timetable = load_timetable(args.timetable, line)
        driven = (args.from_station, args.to_station)
        try:
            check_timetable(timetable.sections, line, preset.name, args.margin, driven)
        except ConfigError as error:
            raise error.in_file(os.path.basename(args.timetable)) from None
        sections = timetable.between(*driven)
        return _run_timetable(args, line, preset, sections, tsrs, targets)
    outcome = drive(
        line,
        preset,
        args.from_station,
        args.to_station,
        running_time_s=args.running_time,
        tsrs=tsrs,
        targets=targets,
        margin_kmh=args.margin,
        model=args.model,
    )
    _check_arrived(outcome, line)
    summary = outcome.summary()
    if args.out is not None:
        summary["figures"] = _save_figures(args.out, line.name, outcome)
    if args.json:
        print_json(summary)
    else:
        log(
            f"{summary['running_time_s']:.0f} s "
            f"(planned {summary['planned_running_time_s']:.0f} s), "
            f"traction {summary['energy_traction_kwh']:.0f} kWh, regenerated "
            f"{summary['energy_regenerated_kwh']:.0f} kWh, stop error "
            f"{summary['stop_error_m']:.2f} m"
        )
        # the advice a driver follows, as the drive ahead on the model made it
        for instruction in summary["advice"]:
            log(f"  {instruction['time_s']:6.0f} s  {instruction['text']}")
    return 0


class DriveNotFinished(RunFailed):
    """The train did not come to its stop: the command says why and exits 1 (a run that
    cannot finish, errors.RunFailed)."""


def _check_arrived(outcome: DriveOutcome, line: RailLine) -> None:
    """A drive whose train did not come to its stop, or stopped farther from it than a
    train that has arrived (``ARRIVED_WITHIN_M``, the line runs' rule), says where and why
    and fails (no NaN printed; a timetable's drive stops at this section)."""
    import math

    from railpilot.onboard.drive import ARRIVED_WITHIN_M

    r = outcome.result
    if not math.isfinite(r.metrics["running_time_s"]):
        raise DriveNotFinished(
            f"the train did not stop at station {outcome.to_station} within the run's "
            f"{float(r['time_s'][-1]):.0f} s: its head is at km "
            f"{float(outcome.km_post(r['position_m'][-1:])[0]) / 1000.0:.3f}, "
            f"{float(r['speed_mps'][-1]) * 3.6:.1f} km/h"
        )
    error_m = float(r.metrics["stop_error_m"])
    if abs(error_m) <= ARRIVED_WITHIN_M:
        return
    stop_km = outcome.arrival_m / 1000.0
    grade = float(line.gradient_at(outcome.arrival_m, outcome.direction))
    slope = (
        "on the level"
        if grade == 0
        else f"on a {'descent' if grade < 0 else 'climb'} of {abs(grade):.1f} per mille"
    )
    raise DriveNotFinished(
        f"the train stopped {abs(error_m):,.1f} m {'past' if error_m > 0 else 'short of'} "
        f"station {outcome.to_station}'s stop point (km {stop_km:.3f}, {slope}): its "
        f"braking, planned for the line, did not bring it to the stop within "
        f"{ARRIVED_WITHIN_M:g} m"
    )


def _consist_totals(results: list[dict[str, object]]) -> dict[str, object]:
    """The consist metrics over a timetable's sections: the worst forces and recharge
    margin, the summed times and counts."""
    from railpilot.onboard.consist_drive import CONSIST_METRICS

    if not results or CONSIST_METRICS[0] not in results[0]:
        return {}
    worst = {"max_coupler_tension_kn": max, "max_coupler_compression_kn": max}
    out: dict[str, object] = {}
    for key in CONSIST_METRICS:
        values: list[float] = [
            float(r[key])  # type: ignore[arg-type]
            for r in results
            if r[key] is not None and r[key] == r[key]
        ]
        if key == "min_recharge_margin_s":
            out[key] = min(values) if values else None
        elif key == "coupler_force_limit_kn":
            out[key] = results[0][key]
        else:
            out[key] = worst.get(key, sum)(values)
    return out


def _save_figures(out: Path, line_name: str, outcome: DriveOutcome) -> list[str]:
    """The speed and energy figures of one station pair, named after the line and stations;
    on the consist model its brake cycles, forces and coupler forces as well
    (``<line>_<from>_<to>_cycles.png``)."""
    from railpilot.report.drive_plots import energy_figure, section_figure, speed_figure
    from railpilot.report.figure import save_figure

    stem = file_stem(line_name, str(outcome.from_station), str(outcome.to_station))
    out.mkdir(parents=True, exist_ok=True)
    figures = [
        str(save_figure(speed_figure(outcome), out / f"{stem}_speed.png")),
        str(save_figure(energy_figure(outcome), out / f"{stem}_energy.png")),
    ]
    if outcome.result.meta.get("model") == "consist":
        figures.append(str(save_figure(section_figure(outcome), out / f"{stem}_cycles.png")))
    return figures


def _run_timetable(args, line, preset, sections, tsrs, targets) -> int:  # type: ignore[no-untyped-def]
    """Every section of the timetable, one after the other, each from stop to stop."""
    from railpilot.onboard.drive import drive

    results = []
    clock_s = 0.0  # since the departure from --from (no dwell: the timetable has none)
    for section in sections:
        log(f"section {section.from_id} -> {section.to_id} ({section.running_time_s:.0f} s)")
        outcome = drive(
            line,
            preset,
            section.from_id,
            section.to_id,
            running_time_s=section.running_time_s,
            tsrs=tsrs,
            targets=targets,
            margin_kmh=args.margin,
            start_time_s=clock_s,
            model=args.model,
        )
        _check_arrived(outcome, line)
        clock_s += outcome.result.metrics["running_time_s"]
        summary = outcome.summary()
        summary["from"] = section.from_id
        summary["to"] = section.to_id
        summary["timetable_running_time_s"] = section.running_time_s
        summary["conformity_pct"] = (
            (summary["running_time_s"] - section.running_time_s) / section.running_time_s * 100.0
        )
        if args.out is not None:
            summary["figures"] = _save_figures(args.out, line.name, outcome)
        results.append(summary)
    actual = sum(r["running_time_s"] for r in results)
    planned = sum(r["timetable_running_time_s"] for r in results)
    total = {
        "sections": results,
        "running_time_s": actual,
        "timetable_running_time_s": planned,
        "conformity_pct": (actual - planned) / planned * 100.0,
        "max_section_conformity_pct": max(abs(r["conformity_pct"]) for r in results),
        "energy_traction_kwh": sum(r["energy_traction_kwh"] for r in results),
        "energy_regenerated_kwh": sum(r["energy_regenerated_kwh"] for r in results),
        "energy_traction_against_air_kwh": sum(
            r["energy_traction_against_air_kwh"] for r in results
        ),
        "max_overspeed_kmh": max(r["max_overspeed_kmh"] for r in results),
        "target_points_passed": sum(r["target_points_passed"] for r in results),
        "max_abs_stop_error_m": max(abs(r["stop_error_m"]) for r in results),
        "model": args.model,
        **_consist_totals(results),
        "tsr_checks": [c for r in results for c in r["tsr_checks"]],
        "replans": [
            dict(p, section=f"{r['from']}-{r['to']}") for r in results for p in r["replans"]
        ],
    }
    if args.json:
        print_json(total)
    else:
        log(
            f"{len(results)} sections: {actual:.0f} s against {planned:.0f} s "
            f"({total['conformity_pct']:+.2f} %), worst section "
            f"{total['max_section_conformity_pct']:.2f} %"
        )
    return 0
