"""The package has no import cycles: not between modules, not between sub-packages.

Read from the source (top-level ``import`` statements only: an import inside a function,
or under ``if TYPE_CHECKING``, runs later or never and cannot make a cycle at import
time). Issue 9 found two (scenario <-> sim, report <-> reproduce).
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "railpilot"


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up) + (f".{node.module}" if node.module else "")
                targets = [base] + [f"{base}.{a.name}" for a in node.names]
            else:
                continue
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


def test_no_module_imports_itself_through_others() -> None:
    assert _cycle(_graph()) is None


def test_no_subpackage_imports_itself_through_others() -> None:
    packages: dict[str, set[str]] = {}
    for module, targets in _graph().items():
        mine = _subpackage(module)
        packages.setdefault(mine, set()).update(
            _subpackage(t) for t in targets if _subpackage(t) != mine
        )
    assert _cycle(packages) is None


def test_the_simulator_does_not_import_the_scenario_package() -> None:
    graph = _graph()
    offenders = {
        (m, t)
        for m, targets in graph.items()
        if m.startswith("railpilot.sim")
        for t in targets
        if t.startswith("railpilot.scenario")
    }
    assert offenders == set()
