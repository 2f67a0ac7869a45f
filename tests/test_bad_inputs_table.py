"""docs/file-formats.md's "What is refused" tables against the code.

The script scripts/bad_inputs.py runs every case as a subprocess (some 60 of them, 80 to
110 s on two shared cores): too long for a test, so the full run is the script's
(``python scripts/bad_inputs.py --check docs/file-formats.md``). Here a fixed
subset, a few of each kind of input, runs in this process through ``railpilot.cli.main``,
each in a folder of its own as the script runs them, and its row must be the docs' row; and
every case of the script must have a row in the docs.
"""

from __future__ import annotations

import importlib.util
import socket
import sys
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest

from railpilot.cli import main

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "file-formats.md"


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bad_inputs", ROOT / "scripts" / "bad_inputs.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


bad_inputs = _script()
CASES = {case.name: case for case in bad_inputs.CASES}

#: a few cases of each kind of input: the checks across files (a timetable conflict, a dead
#: zone and a running time against the line), one rule of each file's own, and the live run's
#: ports and paths
SUBSET = (
    "trains-1-min-apart",
    "dead-zone-off-line",
    "station-not-on-line",
    "gradients-overlap",
    "station-beyond-end",
    "speed-limit-0",
    "line-run-names-broken-line",
    "running-time-60s",
    "unknown-station-later",
    "running-time-nan",
    "http-port-70000",
    "busy-link-port",
    "screenshot-missing-folder",
)


def _generated(doc: str) -> str:
    start, end = bad_inputs.between_markers(doc)
    return doc[start:end]


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A port another program listens on, as the script holds one."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        yield held.getsockname()[1]


@pytest.mark.slow
@pytest.mark.parametrize("name", SUBSET)
def test_a_case_gives_its_row_of_the_docs(
    name: str,
    tmp_path: Path,
    busy_port: int,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    case = CASES[name]
    folder = tmp_path / name
    inputs = bad_inputs.prepare(case, folder)
    monkeypatch.chdir(folder)
    argv = [a.replace(bad_inputs.BUSY_PORT, str(busy_port)) for a in case.argv]
    try:
        exit_code = main(argv)
    except SystemExit as exc:  # argparse's own refusals
        exit_code = exc.code
    out, err = capsys.readouterr()

    outcome = bad_inputs.outcome_of(case, folder, inputs, exit_code, out, err, 0.0, busy_port)

    assert outcome.faults == (), outcome.stderr_lines
    assert bad_inputs.row(case, outcome) in _generated(DOC.read_text()).splitlines()


def test_every_case_has_a_row_in_the_docs() -> None:
    rows = [
        line
        for line in _generated(DOC.read_text()).splitlines()
        if line.startswith("| ") and not line.startswith("| input |")
    ]
    for case in bad_inputs.CASES:
        assert sum(row.startswith(bad_inputs.row_start(case)) for row in rows) == 1, case.name
    assert len(rows) == len(bad_inputs.CASES)


def test_an_unclean_refusal_is_listed_with_every_fault(tmp_path: Path) -> None:
    case = CASES["speedup-0"]
    inputs = bad_inputs.prepare(case, tmp_path)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "kpis.json").write_text("{}")
    stderr = "Traceback (most recent call last):\nValueError: speedup is nan\n"

    outcome = bad_inputs.outcome_of(case, tmp_path, inputs, 1, "x = None\n", stderr, 0.0, 0)
    listed = bad_inputs.tables([case], [outcome]).split("Not yet refused cleanly")[1]

    for fault in (
        "exit 1",
        "2 lines on stderr",
        "output on stdout",
        "wrote out, out/kpis.json",
        "'Traceback' in the output",
        "'nan' in the output",
        "'None' in the output",
        "does not name '--speedup = 0'",
    ):
        assert fault in listed


def test_the_value_a_case_gives_may_be_named_back(tmp_path: Path) -> None:
    case = CASES["speedup-nan"]
    inputs = bad_inputs.prepare(case, tmp_path)
    message = "railpilot: error: --speedup = nan is not allowed: expected a time scale in [1, 200]"

    outcome = bad_inputs.outcome_of(case, tmp_path, inputs, 2, "", message, 0.0, 0)

    assert outcome.faults == ()
