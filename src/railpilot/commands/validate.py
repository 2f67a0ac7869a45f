"""``railpilot validate FILE``: check a file a user writes, with the reader that runs it.

Each format (railpilot.schema.formats.FORMATS) is read by the function the commands that
use it call, so a file this command calls valid is one they accept, cross-checks
included (a line run's headways, stations and dead zones; a timetable's stations on its
line). Nothing is run or written. Without ``--as`` the format is guessed from the file's
top-level keys (:func:`guess_format`; the table is in docs/file-formats.md).

The readers are imported when called: the parser must not import the simulation core.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from railpilot.errors import MISSING, ConfigError

#: what the guess looks at, in its order (named in the error when it finds nothing)
GUESS_KEYS = (
    "kind",
    "services",
    "sections",
    "categories/end_km",
    "[[train]]",
    "vehicle_types/draft_gears",
    "a braking scenario's tables",
)

#: a braking scenario's top-level tables (railpilot.schema.scenario.ScenarioFileTable)
_SCENARIO_TABLES = frozenset(
    {"train", "brake", "reference", "disturbance", "ato", "controller", "sim", "realism"}
    | {"montecarlo"}
)

#: ``kind = ...`` -> the format; any other kind is read as ``railpilot simulate`` reads it,
#: as a braking scenario (whose reader then names the kinds it knows)
_KINDS = {"eddy-brake": "eddy-brake", "train-dynamics": "train-dynamics"}


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "validate",
        help="check a file railpilot reads, without running it",
        description=(
            "Read FILE with the reader railpilot runs it with and say whether it is valid "
            "(exit 0) or what is wrong with it (exit 2). Nothing is run or written. "
            "Without --as the format is guessed from the file's top-level keys "
            "(docs/file-formats.md)."
        ),
    )
    p.add_argument("file", type=Path, metavar="FILE", help="the file to check (TOML or JSON)")
    p.add_argument(
        "--as",
        dest="format",
        metavar="FORMAT",
        help="the file's format (railpilot schema --list); default: guessed",
    )
    p.add_argument(
        "--line",
        default="heavy-haul",
        metavar="LINE",
        help="a timetable's line, whose stations it must name: a shipped line or a line "
        "file (default: heavy-haul)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from railpilot.schema.formats import FORMATS

    path: Path = args.file
    name = args.format
    if name is None:
        name = _guessed(path)
    elif name not in FORMATS:
        raise ConfigError("--as", name, f"one of {', '.join(FORMATS)}")
    _READERS[name](path, args)
    print(f"{path}: a valid {described(FORMATS[name].title)} ({name})")
    return 0


def described(title: str) -> str:
    """A format's title as the ok line says it: up to its colon, without its article
    ("A line run: the line, ..." -> "line run")."""
    head = title.partition(":")[0]
    for article in ("A ", "An ", "The "):
        if head.startswith(article):
            return head[len(article) :]
    return head


def guess_format(data: Any) -> str | None:
    """The format a parsed file's top-level keys tell, or None. The first rule that fits:

    ``kind`` eddy-brake / train-dynamics -> that format, any other ``kind`` -> scenario;
    ``services`` -> line-run; ``sections`` -> timetable; ``categories`` or ``end_km`` ->
    line; ``[[train]]`` entries with ``id`` or ``keys`` -> keys, other ``[[train]]``
    entries -> consist; ``vehicle_types`` or ``draft_gears`` -> consist-library; a braking
    scenario's table (``[train]``, ``[brake]``, ``[reference]``, ``[sim]`` ...) -> scenario.

    Each key is one only its format has at the top; a scenario file without ``kind`` is a
    braking scenario, as ``railpilot simulate`` reads it.
    """
    if not isinstance(data, Mapping):
        return None
    if "kind" in data:
        kind = data["kind"]
        return _KINDS.get(kind, "scenario") if isinstance(kind, str) else "scenario"
    if "services" in data:
        return "line-run"
    if "sections" in data:
        return "timetable"
    if "categories" in data or "end_km" in data:
        return "line"
    train = data.get("train")
    if isinstance(train, list):
        entries = [e for e in train if isinstance(e, Mapping)]
        keyed = any("id" in e or "keys" in e for e in entries)
        return "keys" if keyed and not any("type" in e for e in entries) else "consist"
    if "vehicle_types" in data or "draft_gears" in data:
        return "consist-library"
    if _SCENARIO_TABLES & data.keys():
        return "scenario"
    return None


def _guessed(path: Path) -> str:
    from railpilot.schema.formats import FORMATS
    from railpilot.schema.reading import read_document

    # a file that is not TOML/JSON at all: the reader's own "expected valid TOML (...)"
    data = read_document(path, "FILE", "TOML or JSON file", ConfigError)
    name = guess_format(data)
    if name is not None:
        return name
    keys = ", ".join(map(str, data)) if isinstance(data, Mapping) else "none: it is no table"
    raise ConfigError(
        "--as",
        MISSING,
        f"one of {', '.join(FORMATS)}: the file's top-level keys ({keys or 'none'}) name "
        f"no format (looked for {', '.join(GUESS_KEYS)})",
    )


# --- the readers: each is the one the commands call -------------------------------------


def _scenario(path: Path, args: argparse.Namespace) -> None:
    # simulate's and montecarlo's reader ([montecarlo] is checked too)
    from railpilot.scenario.loader import read_toml, scenario_and_spec_from_mapping

    scenario_and_spec_from_mapping(read_toml(path))


def _kind_said(data: Any, kind: str) -> None:
    """``railpilot simulate`` routes a file by its ``kind``: one without it is read as a
    braking scenario, whatever else it holds."""
    from railpilot.errors import ScenarioError

    given = data.get("kind", MISSING) if isinstance(data, Mapping) else MISSING
    if given is MISSING:
        raise ScenarioError(
            "kind", MISSING, f"'{kind}' (without it, railpilot simulate reads a braking scenario)"
        )


def _eddy_brake(path: Path, args: argparse.Namespace) -> None:
    from railpilot.eddy.scenario import EddyScenario
    from railpilot.scenario.loader import read_toml

    data = read_toml(path)
    _kind_said(data, "eddy-brake")
    EddyScenario.from_mapping(data, base_dir=path.parent)  # as simulate does


def _train_dynamics(path: Path, args: argparse.Namespace) -> None:
    from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
    from railpilot.scenario.loader import read_toml

    data = read_toml(path)
    _kind_said(data, "train-dynamics")
    consist_scenario_from_mapping(data, base_dir=path.parent)  # as simulate does


def _consist(path: Path, args: argparse.Namespace) -> None:
    from railpilot.scenario.consist_file import load_consist

    load_consist(path)


def _consist_library(path: Path, args: argparse.Namespace) -> None:
    # the shipped library's reader, on this file
    from railpilot.scenario.consist_file import ConsistError, parse_library
    from railpilot.schema.reading import read_document

    def error(field: str, value: Any, allowed: str) -> ConfigError:
        return ConsistError(field, value, allowed, source=str(path))

    parse_library(read_document(path, "FILE", "consist library TOML file", error), str(path))


def _line_run(path: Path, args: argparse.Namespace) -> None:
    from railpilot.cosim.scenario import load_line_scenario

    load_line_scenario(path)  # with its cross-checks: headways, stations, dead zones


def _keys(path: Path, args: argparse.Namespace) -> None:
    from railpilot.link.keys import load_key_file

    load_key_file(path)  # refuses a file group or others may read, as the ground does


def _line(path: Path, args: argparse.Namespace) -> None:
    from railpilot.line.loader import read_line

    read_line(path)


def _timetable(path: Path, args: argparse.Namespace) -> None:
    from railpilot.line.loader import load_line
    from railpilot.onboard.timetable import load_timetable

    try:
        line = load_line(args.line)
    except ConfigError as exc:
        if exc.field != "LINE":  # a line file's own error names its entry
            raise
        raise ConfigError("--line", exc.value, exc.allowed) from None
    # a Path, not a str: a file named like a shipped timetable is still this file
    load_timetable(path, line)


#: format name -> its reader (raises the reader's ConfigError/RailpilotError)
_READERS: dict[str, Callable[[Path, argparse.Namespace], None]] = {
    "scenario": _scenario,
    "eddy-brake": _eddy_brake,
    "consist": _consist,
    "line-run": _line_run,
    "keys": _keys,
    "line": _line,
    "timetable": _timetable,
    "train-dynamics": _train_dynamics,
    "consist-library": _consist_library,
}
