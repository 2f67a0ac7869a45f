"""The core runs without the optional parts (railpilot/extras.py): with Starlette, uvicorn,
websockets, psycopg and Dask made unimportable in a fresh interpreter, ``import railpilot``,
``railpilot --help``, ``drive`` and ``simulate`` work, and a command that needs one of them
stops before it starts, naming the extra that installs it."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from railpilot import extras
from railpilot.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
BLOCKED = sorted(name for names in extras.EXTRAS.values() for name in names)

#: Run in a fresh interpreter: every module of an extra raises ModuleNotFoundError on import,
#: as when it is not installed; then the command line runs with the given arguments.
RUNNER = """
import importlib.abc, sys
BLOCKED = {blocked!r}
assert not BLOCKED & {{m.partition(".")[0] for m in sys.modules}}, "imported before the block"

class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, NotInstalled())
if sys.argv[1:2] == ["--python"]:
    exec(sys.argv[2])
    sys.exit(0)
from railpilot.cli import main
sys.exit(main(sys.argv[1:]))
"""


def run_without_extras(tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    runner = tmp_path / "without_extras.py"
    runner.write_text(RUNNER.format(blocked=set(BLOCKED)))
    return subprocess.run(
        [sys.executable, str(runner), *args],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
    )


def test_the_block_makes_each_extra_module_unimportable(tmp_path: Path) -> None:
    code = f"import importlib\nfor name in {BLOCKED!r}:\n" + (
        "    try:\n        importlib.import_module(name)\n"
        "    except ModuleNotFoundError:\n        continue\n"
        "    raise SystemExit(f'{name} imported')\n"
    )
    done = run_without_extras(tmp_path, "--python", code)
    assert done.returncode == 0, done.stderr


def test_railpilot_imports_and_shows_its_help_without_the_extras(tmp_path: Path) -> None:
    done = run_without_extras(tmp_path, "--help")
    assert done.returncode == 0, done.stderr
    assert "ground" in done.stdout and "simulate" in done.stdout


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv",
    [
        ["drive", "heavy-haul", "--from", "1", "--to", "2"],
        ["simulate", str(EXAMPLES / "eddy_case2.toml")],
    ],
    ids=["drive", "simulate"],
)
def test_core_commands_run_without_the_extras(tmp_path: Path, argv: list[str]) -> None:
    # simulate writes its files and figures too (the report's path); drive's figures of a
    # whole station pair would only add time
    out = ["--out", str(tmp_path / "out")] if argv[0] == "simulate" else []
    done = run_without_extras(tmp_path, *argv, "--json", *out)
    assert done.returncode == 0, done.stderr
    assert isinstance(json.loads(done.stdout), dict)


def test_ground_serve_without_the_dashboard_runs_without_the_extras(tmp_path: Path) -> None:
    argv = ["ground", "serve", "--no-auth", "--port", "0", "--admin-port", "-1"]
    done = run_without_extras(tmp_path, *argv, "--db", ":memory:", "--seconds", "0.2")
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize(
    ("extra", "argv"),
    [
        ("web", ["ground", "serve", "--no-auth", "--http-port", "0"]),
        ("web", ["link", "loadtest", "--trains", "1", "--seconds", "1", "--dashboard"]),
        ("postgres", ["ground", "serve", "--no-auth", "--db", "postgresql://u@127.0.0.1:1/d"]),
        (
            "cluster",
            [
                "montecarlo",
                str(EXAMPLES / "paper000_montecarlo.toml"),
                "--runs",
                "2",
                "--scheduler",
                "tcp://127.0.0.1:1",
            ],
        ),
    ],
    ids=["dashboard", "loadtest-dashboard", "postgres-store", "dask-sweep"],
)
def test_a_command_that_needs_an_extra_names_it_and_writes_nothing(
    tmp_path: Path, extra: str, argv: list[str]
) -> None:
    out = tmp_path / "out"
    extra_args = ["--out", str(out)] if argv[0] == "montecarlo" else []
    if argv[:2] == ["ground", "serve"] and "--db" not in argv:
        extra_args = ["--db", str(tmp_path / "ground.db")]
    done = run_without_extras(tmp_path, *argv, *extra_args)
    assert done.returncode == 2, done.stderr
    assert f"'{extra}' extra" in done.stderr
    assert extras.install_hint(extra) in done.stderr
    assert "Traceback" not in done.stderr
    assert done.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["without_extras.py"]


def test_every_extra_is_an_optional_dependency_group_and_none_is_a_core_one() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    optional = project["optional-dependencies"]
    assert set(extras.EXTRAS) <= set(optional)
    core = " ".join(project["dependencies"]).lower()
    for extra, names in extras.EXTRAS.items():
        listed = " ".join(optional[extra]).lower()
        for name in names:
            # dask[distributed] provides both dask and distributed
            assert name in listed, (extra, name)
            assert name not in core, (extra, name)


def test_require_names_the_option_the_missing_module_and_the_extra(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(extras.EXTRAS, "web", ("railpilot_no_such_module",))
    with pytest.raises(ConfigError) as error:
        extras.require("web", "--http-port", 8080)
    message = str(error.value)
    assert "--http-port" in message and "8080" in message
    assert "railpilot_no_such_module" in message and "pip install 'railpilot[web]'" in message
    monkeypatch.setitem(extras.EXTRAS, "web", ("json",))
    extras.require("web", "--http-port", 8080)  # installed: nothing to say
