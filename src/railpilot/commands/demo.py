"""``railpilot demo``: the main job -- reproduce every paper and write the report."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

from railpilot.commands._common import log, out_dir_argument
from railpilot.reproduce import REPRODUCTIONS, load

if TYPE_CHECKING:
    from railpilot.report.drive_section import DrivenSection
    from railpilot.report.section import Reproduction


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="reproduce every paper and write the HTML report",
        description="Run every reproduction, print its tables and write one HTML report.",
    )
    p.add_argument("--out", type=out_dir_argument, default="out", help="report folder [out]")
    p.set_defaults(func=run)


@dataclass(frozen=True)
class DemoDrive:
    """A section the report's drive figures show: a train from one station to the next,
    in the shipped timetable's running time (``timetabled``) or else in the fastest run's
    plus 10 %."""

    train: str
    from_station: int
    to_station: int
    timetabled: bool


#: the loaded train's descents from the origin on the shipped timetable, and the empty
#: train's last section home (about 3 s of driving each)
DEMO_DRIVES = (
    DemoDrive("heavy-haul-loaded", 1, 2, timetabled=True),
    DemoDrive("heavy-haul-loaded", 2, 3, timetabled=True),
    DemoDrive("heavy-haul-loaded", 3, 4, timetabled=True),
    DemoDrive("heavy-haul-empty", 2, 1, timetabled=False),
)


def drive_cycles(out_dir: Path, drives: tuple[DemoDrive, ...] | None = None) -> Reproduction:
    """Drive ``drives`` (None: :data:`DEMO_DRIVES`) on the consist model and return the
    report's section of them."""
    from railpilot.line import load_line
    from railpilot.onboard.drive import drive, train_preset
    from railpilot.onboard.timetable import load_timetable
    from railpilot.report.drive_section import DrivenSection, drive_cycles_section

    line = load_line("heavy-haul")
    timetable = load_timetable("heavy-haul")
    driven: list[DrivenSection] = []
    for d in DEMO_DRIVES if drives is None else drives:
        command = (
            f"railpilot drive heavy-haul --train {d.train} --from {d.from_station} "
            f"--to {d.to_station}" + (" --timetable heavy-haul" if d.timetabled else "")
        )
        running_time_s = None
        if d.timetabled:
            (section,) = timetable.between(d.from_station, d.to_station)
            running_time_s = section.running_time_s
        outcome = drive(
            line,
            train_preset(d.train),
            d.from_station,
            d.to_station,
            running_time_s=running_time_s,
            model="consist",
        )
        given_s = outcome.plan.requested_time_s if running_time_s is None else running_time_s
        given_s = math.nan if given_s is None else given_s
        driven.append(DrivenSection(d.train, outcome, given_s, f"{command} --out DIR"))
    return drive_cycles_section(driven, out_dir)


def _reproduce(name: str, out_dir: Path) -> Reproduction:
    """``railpilot reproduce NAME``'s section, its figures written to ``out_dir``."""
    reproduction: Reproduction = load(name).run(out_dir)
    return reproduction


def _sections() -> list[tuple[str, Callable[[Path], Reproduction]]]:
    """Every section of the report in its order: the reproductions, with the drive
    figures after the heavy-haul train's published figures."""
    out: list[tuple[str, Callable[[Path], Reproduction]]] = []
    for name in REPRODUCTIONS:
        out.append((name, partial(_reproduce, name)))
        if name == "heavy-haul-ltd":
            out.append(("drive-cycles", drive_cycles))
    if not any(name == "drive-cycles" for name, _ in out):
        out.append(("drive-cycles", drive_cycles))
    return out


def run(args: argparse.Namespace) -> int:
    from railpilot.report.html import write_report

    sections = []
    for name, make in _sections():
        log(f"reproducing {name} ...")
        reproduction = make(args.out)
        sections.append(reproduction)
        print(f"\n== {reproduction.title}")
        for table in reproduction.tables:
            print()
            print(table.to_text())
        for finding in reproduction.findings:
            print(f"- {finding}")
    index = write_report(sections, args.out)
    print(f"\nReport: {index.resolve()}  (open it in a browser)")
    return 0
