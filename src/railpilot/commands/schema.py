"""``railpilot schema``: the JSON Schema of each file format a user writes."""

from __future__ import annotations

import argparse
import sys

from railpilot.errors import ConfigError


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "schema",
        help="print the JSON Schema of a file format",
        description=(
            "Print the JSON Schema of a file format (an editor validates files with it; "
            "docs/file-formats.md), list the formats, or write every schema into a folder."
        ),
    )
    p.add_argument("format", nargs="?", metavar="FORMAT", help="a format (see --list)")
    p.add_argument("--list", action="store_true", help="list the formats")
    p.add_argument("--write", metavar="DIR", help="write every format's schema into DIR")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from railpilot.schema.formats import FORMATS, schema_text, write_schemas

    if args.list:
        for name, fmt in FORMATS.items():
            print(f"{name:<18} {fmt.title}")
        return 0
    if args.write:
        for path in write_schemas(args.write):
            print(path, file=sys.stderr)
        return 0
    if args.format not in FORMATS:
        raise ConfigError("FORMAT", args.format, f"one of {', '.join(FORMATS)} (or --list)")
    sys.stdout.write(schema_text(args.format))
    return 0
