"""The ``railpilot`` command line: parse, call the library, print.

Each command group lives in the module that owns it and exposes
``register(subparsers)``; this file only wires them together. Machine-readable
output (``--json``) is exactly one JSON object on stdout; logs and progress go to
stderr. Exit codes: 0 success, 2 bad input (nothing was run or written),
1 any other failure.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

from railpilot import __version__
from railpilot.errors import RailpilotError
from railpilot.extras import extra_of, install_hint

#: Modules that add subcommands; each has ``register(subparsers) -> None`` and sets
#: ``func`` on its parsers via ``set_defaults(func=...)``. ``func(args) -> int``.
COMMAND_MODULES: tuple[str, ...] = (
    "railpilot.commands.simulate",
    "railpilot.commands.reproduce",
    "railpilot.commands.montecarlo",
    "railpilot.commands.demo",
    "railpilot.commands.link",
    "railpilot.commands.drive",
    "railpilot.commands.line",
    "railpilot.commands.schema",
    "railpilot.commands.validate",
)


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in one line, as every other error of the command line
    (``--help`` still prints the usage)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"railpilot: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="railpilot",
        description="Train braking control and train-ground dispatch communication.",
    )
    parser.add_argument("--version", action="version", version=f"railpilot {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    subparsers.required = True
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except RailpilotError as exc:
        print(f"railpilot: error: {exc}", file=sys.stderr)
        # bad input is 2; a run that could not finish says so with its own code
        return int(getattr(exc, "exit_code", 2))
    except ModuleNotFoundError as exc:
        # An optional part a command reached without checking for it first: say which
        # extra installs it rather than show a traceback.
        extra = extra_of(exc)
        if extra is None:
            raise
        print(
            f"railpilot: error: this needs railpilot's '{extra}' extra ({exc}): "
            f"{install_hint(extra)}",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print("railpilot: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
