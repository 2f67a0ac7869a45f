"""``railpilot demo``: the main job -- reproduce every paper and write the report."""

from __future__ import annotations

import argparse

from railpilot.commands._common import log, out_dir_argument
from railpilot.reproduce import REPRODUCTIONS, load


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="reproduce every paper and write the HTML report",
        description="Run every reproduction, print its tables and write one HTML report.",
    )
    p.add_argument("--out", type=out_dir_argument, default="out", help="report folder [out]")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from railpilot.report.html import write_report

    sections = []
    for name in REPRODUCTIONS:
        log(f"reproducing {name} ...")
        reproduction = load(name).run(args.out)
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
