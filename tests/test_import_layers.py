"""The package has no import cycles: not between modules, not between sub-packages.

Read from the source. Two graphs: the imports that run when a module is imported (the
module's top level), and every import, those inside functions included (they run later,
but a module that imports its importer at call time still belongs on the same layer, and
the dependency is as real). Imports under ``if TYPE_CHECKING:`` never run and are not
counted.
"""

from __future__ import annotations

import ast
import functools
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "railpilot"


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(tree: ast.Module, *, in_functions: bool) -> Iterator[ast.Import | ast.ImportFrom]:
    """The import statements of a module: its top level only, or every one (inside
    functions, classes, try blocks ...) but those under ``if TYPE_CHECKING:``."""
    if not in_functions:
        yield from (n for n in tree.body if isinstance(n, ast.Import | ast.ImportFrom))
        return
    todo: list[ast.AST] = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If) and _is_type_checking(node.test):
            todo.extend(node.orelse)  # the else branch does run
        else:
            todo.extend(ast.iter_child_nodes(node))


@functools.cache
def _modules() -> dict[str, tuple[Path, ast.Module]]:
    """Every module of the package by name: its file and its syntax tree (parsed once;
    the four graph tests read the same source)."""
    return {_module_name(p): (p, ast.parse(p.read_text())) for p in PACKAGE.rglob("*.py")}


def _graph(*, in_functions: bool = False) -> dict[str, set[str]]:
    modules = _modules()
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, (path, tree) in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in _imports(tree, in_functions=in_functions):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up) + (f".{node.module}" if node.module else "")
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            graph[name] |= {t for t in targets if t in modules and t != name}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` (as a path), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def _subpackage(module: str) -> str:
    return ".".join(module.split(".")[:2])


def _subpackages(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    packages: dict[str, set[str]] = {}
    for module, targets in graph.items():
        mine = _subpackage(module)
        packages.setdefault(mine, set()).update(
            _subpackage(t) for t in targets if _subpackage(t) != mine
        )
    return packages


def test_no_module_imports_itself_through_others() -> None:
    assert _cycle(_graph()) is None


def test_no_subpackage_imports_itself_through_others() -> None:
    assert _cycle(_subpackages(_graph())) is None


def test_no_module_cycle_counting_imports_inside_functions() -> None:
    assert _cycle(_graph(in_functions=True)) is None


def test_no_subpackage_cycle_counting_imports_inside_functions() -> None:
    assert _cycle(_subpackages(_graph(in_functions=True))) is None


def test_the_graph_sees_imports_inside_functions_but_not_type_checking_ones() -> None:
    """The reader itself: a call-time import counts, a TYPE_CHECKING one does not."""
    tree = ast.parse(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    import typing_only\nelse:\n    import at_run_time\n"
        "def f():\n    import in_function\n"
        "class C:\n    def g(self):\n        from pkg import in_method\n"
    )
    top = {a.name for n in _imports(tree, in_functions=False) for a in n.names}
    every = {a.name for n in _imports(tree, in_functions=True) for a in n.names}
    assert top == {"TYPE_CHECKING"}
    assert every == {"TYPE_CHECKING", "at_run_time", "in_function", "in_method"}


def test_the_simulator_does_not_import_the_scenario_package() -> None:
    graph = _graph(in_functions=True)
    offenders = {
        (m, t)
        for m, targets in graph.items()
        if m.startswith("railpilot.sim")
        for t in targets
        if t.startswith("railpilot.scenario")
    }
    assert offenders == set()


def test_only_the_command_line_runs_the_rigs() -> None:
    """Test and benchmark rigs (railpilot.rigs) stay out of the library's import graph:
    the command that runs them imports them, nothing else in the package does."""
    graph = _graph(in_functions=True)
    offenders = {
        (m, t)
        for m, targets in graph.items()
        if not m.startswith("railpilot.rigs") and m != "railpilot.commands.link"
        for t in targets
        if t.startswith("railpilot.rigs")
    }
    assert offenders == set()


def test_the_command_line_starts_without_the_simulation_core() -> None:
    """Every ``railpilot`` command builds the whole parser first: building it must not
    import the simulation core (numba's compiler, scipy), which would cost each command
    (a ground server, a decode of one frame, ``--help``) most of a second before it starts."""
    probe = (
        "import sys; from railpilot.cli import build_parser; build_parser(); "
        "print(' '.join(sorted({'numba', 'scipy'} & {m.partition('.')[0] for m in sys.modules})))"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, check=True, timeout=60
    )
    assert done.stdout.split() == []
