"""The core runs without the optional parts (railpilot/extras.py): with Starlette, uvicorn,
websockets, psycopg and Dask made unimportable in a fresh interpreter, ``import railpilot``,
``railpilot --help``, ``drive`` and ``simulate`` work, and a command that needs one of them
stops before it starts, naming the extra that installs it."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from railpilot import extras
from railpilot.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
BLOCKED = sorted(name for names in extras.EXTRAS.values() for name in names)

#: Run in a fresh interpreter: every module of an extra raises ModuleNotFoundError on import,
#: as when it is not installed; then each job of the list in argv[1] (JSON) runs in that
#: interpreter, one after the other, in its own working folder: a command line (``argv``)
#: or Python code (``python``). What each writes to the file descriptors 1 and 2 is caught
#: in the files ``out`` and ``err``, and its exit code printed, one JSON list, at the end.
#: One interpreter for all: each start imports the package again (about a second).
RUNNER = """
import importlib.abc, json, os, sys, traceback
BLOCKED = {blocked!r}
assert not BLOCKED & {{m.partition(".")[0] for m in sys.modules}}, "imported before the block"

class NotInstalled(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, NotInstalled())

def run(job):
    if "python" in job:
        exec(job["python"], {{}})
        return 0
    from railpilot.cli import main
    return main(job["argv"])

codes = []
for job in json.loads(sys.argv[1]):
    os.chdir(job["cwd"])
    with open(job["out"], "w") as out, open(job["err"], "w") as err:
        sys.stdout.flush(); sys.stderr.flush()
        saved = os.dup(1), os.dup(2)
        os.dup2(out.fileno(), 1); os.dup2(err.fileno(), 2)
        try:
            code = run(job)
        except SystemExit as stop:
            code = stop.code if isinstance(stop.code, int) else 1
        except BaseException:
            traceback.print_exc()
            code = 99
        finally:
            sys.stdout.flush(); sys.stderr.flush()
            os.dup2(saved[0], 1); os.dup2(saved[1], 2)
    codes.append(code)
print(json.dumps(codes))
"""


@dataclass(frozen=True)
class Done:
    """One job's exit code, what it wrote, and its working folder."""

    returncode: int
    stdout: str
    stderr: str
    cwd: Path


def run_without_extras(base: Path, jobs: dict[str, dict[str, Any]]) -> dict[str, Done]:
    """Run ``jobs`` (by name: ``argv`` or ``python``) in one interpreter without the
    extras, each in its own empty folder under ``base``."""
    runner = base / "without_extras.py"
    runner.write_text(RUNNER.format(blocked=set(BLOCKED)))
    listed = []
    for name, job in jobs.items():
        (base / name).mkdir()
        caught = base / f"{name}.caught"
        caught.mkdir()
        listed.append(
            job | {"cwd": str(base / name), "out": str(caught / "out"), "err": str(caught / "err")}
        )
    done = subprocess.run(
        [sys.executable, str(runner), json.dumps(listed)],
        capture_output=True,
        text=True,
        cwd=base,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    codes = json.loads(done.stdout.splitlines()[-1])
    return {
        name: Done(
            code,
            Path(job["out"]).read_text(),
            Path(job["err"]).read_text(),
            Path(job["cwd"]),
        )
        for (name, _), job, code in zip(jobs.items(), listed, codes, strict=True)
    }


BLOCK_CHECK = f"import importlib\nfor name in {BLOCKED!r}:\n" + (
    "    try:\n        importlib.import_module(name)\n"
    "    except ModuleNotFoundError:\n        continue\n"
    "    raise SystemExit(f'{name} imported')\n"
)

#: what needs an extra: the extra's name and a command line that reaches it
NEEDS_AN_EXTRA = {
    "dashboard": ("web", ["ground", "serve", "--no-auth", "--http-port", "0"]),
    "loadtest-dashboard": (
        "web",
        ["link", "loadtest", "--trains", "1", "--seconds", "1", "--dashboard"],
    ),
    "postgres-store": (
        "postgres",
        ["ground", "serve", "--no-auth", "--db", "postgresql://u@127.0.0.1:1/d"],
    ),
    "dask-sweep": (
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
}


def _with_outputs(name: str, argv: list[str]) -> list[str]:
    """``argv`` with the files it would write pointed into its own (empty) folder."""
    if argv[0] == "montecarlo":
        return [*argv, "--out", "out"]
    if argv[:2] == ["ground", "serve"] and "--db" not in argv:
        return [*argv, "--db", "ground.db"]
    return argv


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Done]:
    """The quick jobs, in one interpreter without the extras."""
    jobs: dict[str, dict[str, Any]] = {
        "block": {"python": BLOCK_CHECK},
        "help": {"argv": ["--help"]},
        "ground-serve": {
            "argv": [
                *("ground", "serve", "--no-auth", "--port", "0", "--admin-port", "-1"),
                *("--db", ":memory:", "--seconds", "0.2"),
            ]
        },
    }
    for name, (_, argv) in NEEDS_AN_EXTRA.items():
        jobs[name] = {"argv": _with_outputs(name, argv)}
    return run_without_extras(tmp_path_factory.mktemp("extras"), jobs)


def test_the_block_makes_each_extra_module_unimportable(quick: dict[str, Done]) -> None:
    assert quick["block"].returncode == 0, quick["block"].stderr


def test_railpilot_imports_and_shows_its_help_without_the_extras(quick: dict[str, Done]) -> None:
    done = quick["help"]
    assert done.returncode == 0, done.stderr
    assert "ground" in done.stdout and "simulate" in done.stdout


@pytest.mark.slow
def test_core_commands_run_without_the_extras(tmp_path: Path) -> None:
    # simulate writes its files and figures too (the report's path); drive's figures of a
    # whole station pair would only add time
    jobs = {
        "drive": {"argv": ["drive", "heavy-haul", "--from", "1", "--to", "2", "--json"]},
        "simulate": {
            "argv": ["simulate", str(EXAMPLES / "eddy_case2.toml"), "--json", "--out", "out"]
        },
    }
    for name, done in run_without_extras(tmp_path, jobs).items():
        assert done.returncode == 0, (name, done.stderr)
        assert isinstance(json.loads(done.stdout), dict), name


def test_ground_serve_without_the_dashboard_runs_without_the_extras(
    quick: dict[str, Done],
) -> None:
    done = quick["ground-serve"]
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("name", NEEDS_AN_EXTRA)
def test_a_command_that_needs_an_extra_names_it_and_writes_nothing(
    quick: dict[str, Done], name: str
) -> None:
    extra, _ = NEEDS_AN_EXTRA[name]
    done = quick[name]
    assert done.returncode == 2, done.stderr
    assert f"'{extra}' extra" in done.stderr
    assert extras.install_hint(extra) in done.stderr
    assert "Traceback" not in done.stderr
    assert done.stdout == ""
    assert list(done.cwd.iterdir()) == []


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
