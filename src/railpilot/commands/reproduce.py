"""``railpilot reproduce NAME``: rebuild a paper's published result."""

from __future__ import annotations

import argparse

from railpilot.commands._common import log, out_dir_argument, print_json
from railpilot.reproduce import REPRODUCTIONS, load


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "reproduce",
        help="reproduce a paper's results",
        description="Re-run a paper's scenario with every controller it compares, write its "
        "figures and print its tables.",
    )
    p.add_argument("name", choices=sorted(REPRODUCTIONS), help="which result")
    p.add_argument("--out", type=out_dir_argument, default="out", help="folder for figures [out]")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    reproduction = load(args.name).run(args.out)
    if args.json:
        print_json(reproduction.payload)
        for fig in reproduction.figures:
            log(f"wrote {fig}")
        return 0
    print(reproduction.title)
    for table in reproduction.tables:
        print()
        print(table.to_text())
    print()
    for finding in reproduction.findings:
        print(f"- {finding}")
    for fig in reproduction.figures:
        log(f"wrote {fig}")
    return 0
