"""A compiled kernel's on-disk cache notices edits to the modules it imports
(railpilot/jit.py).

Numba stamps a cached kernel with its own file only: after an edit to a helper another
file held (a resistance law the loop inlines, a constant it freezes), the old machine
code was loaded again. The test package below has that shape; each run is a fresh
process, as a user's next command is.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from child_process import ROOT, run_python_json
from railpilot.jit import source_closure, source_closure_digest, watch_package

PACKAGE = ROOT / "src" / "railpilot"

CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
if sys.argv[2] == "watched":
    from railpilot.jit import watch_package
    watch_package("kernels_pkg", sys.argv[1] + "/kernels_pkg")
from kernels_pkg.kernel import run
value = run(1.0)
stats = run.stats
print(json.dumps({"value": value, "hits": stats.cache_hits.total(),
                  "misses": stats.cache_misses.total()}))
"""


def _package(tmp_path: Path, law: str) -> None:
    """A package whose cached kernel inlines a law from another module, and reads a
    constant from a third."""
    pkg = tmp_path / "kernels_pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "constants.py").write_text("GAIN = 2.0\n")
    (pkg / "law.py").write_text(f"def law(x):\n    return {law}\n")
    (pkg / "kernel.py").write_text(
        textwrap.dedent(
            """
            from numba import njit

            from kernels_pkg import law
            from kernels_pkg.constants import GAIN

            _law = njit(inline="always")(law.law)


            @njit(cache=True)
            def run(x):
                return GAIN * _law(x)
            """
        )
    )


def _run(tmp_path: Path, mode: str) -> dict[str, float]:
    # no .pyc: an edited law of the same size within the same second could load stale
    return run_python_json(CHILD, str(tmp_path), mode, env={"PYTHONDONTWRITEBYTECODE": "1"})


@pytest.mark.slow
def test_numba_alone_loads_the_old_code_after_an_edit_to_an_inlined_module(
    tmp_path: Path,
) -> None:
    # the defect railpilot/jit.py mends, kept as a test: if Numba comes to notice it
    # itself, this fails and the mend can go
    _package(tmp_path, "x + 1.0")
    assert _run(tmp_path, "plain")["value"] == 4.0
    _package(tmp_path, "x + 10.0")
    assert _run(tmp_path, "plain")["value"] == 4.0  # stale: GAIN * (1 + 1)


@pytest.mark.slow
def test_a_watched_kernel_compiles_again_after_an_edit_to_an_inlined_module(
    tmp_path: Path,
) -> None:
    _package(tmp_path, "x + 1.0")
    assert _run(tmp_path, "watched")["value"] == 4.0
    assert _run(tmp_path, "watched") == {"value": 4.0, "hits": 1, "misses": 0}  # cached
    _package(tmp_path, "x + 10.0")
    assert _run(tmp_path, "watched") == {"value": 22.0, "hits": 0, "misses": 1}
    assert _run(tmp_path, "watched") == {"value": 22.0, "hits": 1, "misses": 0}


@pytest.mark.slow
def test_a_watched_kernel_compiles_again_after_an_edit_to_a_constant_it_reads(
    tmp_path: Path,
) -> None:
    _package(tmp_path, "x + 1.0")
    assert _run(tmp_path, "watched")["value"] == 4.0
    (tmp_path / "kernels_pkg" / "constants.py").write_text("GAIN = 30.0\n")
    assert _run(tmp_path, "watched") == {"value": 60.0, "hits": 0, "misses": 1}


def test_the_loops_closure_holds_what_it_inlines_and_not_the_whole_package() -> None:
    closure = {p.relative_to(PACKAGE).as_posix() for p in source_closure(PACKAGE / "sim/engine.py")}
    # the resistance laws it inlines, the interpolation it calls, the constants it freezes
    assert {
        "sim/engine.py",
        "vehicle/profile.py",
        "vehicle/resistance.py",
        "interp.py",
        "units.py",
        "sim/layout.py",
    } <= closure
    assert "cosim/line_run.py" not in closure
    assert "link/frame.py" not in closure


def test_a_file_outside_every_watched_package_has_no_closure(tmp_path: Path) -> None:
    outside = tmp_path / "mine.py"
    outside.write_text("import railpilot.units\n")
    assert source_closure(outside) == []
    before = source_closure_digest(outside)
    outside.write_text("import railpilot.units  # edited\n")
    assert source_closure_digest(outside) != before  # its own source still stamps it


def test_relative_parenthesised_and_aliased_imports_are_followed(tmp_path: Path) -> None:
    pkg = tmp_path / "closure_pkg"
    (pkg / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "",
        "sub/__init__.py": "",
        "sub/deep.py": "X = 1\n",
        "sub/other.py": "from .. import top  # the package's own module, two levels up\n",
        "top.py": "",
        "aliased.py": "",
        "unused.py": "",
        "kernel.py": textwrap.dedent(
            """
            import closure_pkg.aliased as a, numpy as np
            from .sub import (
                deep,  # a submodule named in a from-import (a module, too)
                other,
            )
            """
        ),
    }
    for name, text in files.items():
        (pkg / name).write_text(text)
    watch_package("closure_pkg", pkg)
    closure = {p.relative_to(pkg).as_posix() for p in source_closure(pkg / "kernel.py")}
    assert closure == {
        "__init__.py",
        "aliased.py",
        "kernel.py",
        "sub/__init__.py",
        "sub/deep.py",
        "sub/other.py",
        "top.py",
    }
    before = source_closure_digest(pkg / "kernel.py")
    (pkg / "unused.py").write_text("Y = 2\n")
    assert source_closure_digest(pkg / "kernel.py") == before  # not in the closure
    (pkg / "top.py").write_text("Z = 3\n")  # two imports away
    assert source_closure_digest(pkg / "kernel.py") != before


@pytest.mark.parametrize("kernel", ["sim/engine.py", "control/pid.py", "brakes/ep_blend.py"])
def test_the_packages_kernels_are_stamped_with_their_closure(kernel: str) -> None:
    import importlib

    module = importlib.import_module("railpilot." + kernel.removesuffix(".py").replace("/", "."))
    dispatchers = [
        value
        for value in vars(module).values()
        if hasattr(getattr(value, "_cache", None), "_impl")  # cache=True (not a NullCache)
    ]
    stamped = [
        d for d in dispatchers if Path(d.py_func.__code__.co_filename).resolve() == PACKAGE / kernel
    ]
    assert stamped, f"no cached kernel defined in {kernel}"
    for dispatcher in stamped:
        locator = dispatcher._cache._impl.locator
        assert locator.get_source_stamp() == source_closure_digest(PACKAGE / kernel)
