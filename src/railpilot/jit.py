"""Numba's ``njit`` for this package, with an on-disk cache that notices every edit a
compiled kernel depends on.

Numba keeps a kernel compiled with ``cache=True`` on disk and checks it against one
stamp: the source of the kernel's own file. A kernel also compiles in code and constants
from other files: the simulation core's loop inlines the resistance laws of
vehicle/profile.py and vehicle/resistance.py, looks the line up with interp.py's
``interp_at`` and freezes the constants of units.py and sim/layout.py into its machine
code. After an edit to one of those, Numba went on loading the old machine code, and the
run gave the old physics without a word.

Here every kernel of this package is stamped with the sources of its file and of every
module of the package that file imports, directly or through another (found by reading
the imports, not by running them). An edit to any of them compiles the kernel again on
its next call. It is conservative: an edit a kernel does not use can compile it again
too, once, a few seconds.

Kernel modules take ``njit`` from here (``from railpilot.jit import njit``), so the
stamp is in place before any of them is decorated. :func:`watch_package` puts any other
package under the same rule (the tests use it on a package of their own). Kernels
outside a watched package keep Numba's own stamp.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
from pathlib import Path
from typing import Any

from numba import njit
from numba.core import caching

__all__ = ["njit", "source_closure", "source_closure_digest", "watch_package"]

#: watched packages: their directory -> their import name
_WATCHED: dict[Path, str] = {}


def watch_package(name: str, directory: str | os.PathLike[str]) -> None:
    """Stamp the on-disk cache of every kernel defined in ``directory`` (the package
    ``name``) with the sources of its import closure within that package."""
    _WATCHED[Path(directory).resolve()] = name
    _install_locators()


def source_closure(path: str | os.PathLike[str]) -> list[Path]:
    """The files of ``path``'s watched package that importing ``path`` runs: the file
    itself and every module of the package it imports, directly or through another, with
    the ``__init__.py`` of each package on the way. Sorted. Empty for a file outside every
    watched package."""
    start = Path(path).resolve()
    package = _package_of(start)
    if package is None:
        return []
    root, name = package
    seen: set[Path] = set()
    todo = [start]
    while todo:
        file = todo.pop()
        if file in seen:
            continue
        seen.add(file)
        todo.extend(_scan(file, root, name)[1])
    return sorted(seen)


def source_closure_digest(path: str | os.PathLike[str]) -> str:
    """SHA-256 over the files of :func:`source_closure` (each one's path within its
    package and content): it changes when any of them does."""
    start = Path(path).resolve()
    package = _package_of(start)
    files = source_closure(start) if package else [start]
    root = package[0] if package else start.parent
    digest = hashlib.sha256()
    for file in files:
        content_digest, _ = _scan(file, root, package[1] if package else "")
        digest.update(file.relative_to(root).as_posix().encode() + b"\0" + content_digest)
    return digest.hexdigest()


def _package_of(file: Path) -> tuple[Path, str] | None:
    """(the directory, the import name) of the watched package ``file`` is in."""
    for root, name in _WATCHED.items():
        if file.is_relative_to(root):
            return root, name
    return None


def _scan(file: Path, root: Path, package: str) -> tuple[bytes, tuple[Path, ...]]:
    """``file``'s content's SHA-256, and the files of the package at ``root`` (import
    name ``package``) that its imports name, the ``__init__.py`` of their packages
    included."""
    try:
        stat = file.stat()
    except OSError:
        return b"", ()
    return _scan_cached(file, root, package, stat.st_mtime_ns, stat.st_size)


# An import statement at the start of a line: ``import a.b as c, d`` or ``from ..a import
# (b, c)``. Read with a pattern rather than parsed (60 modules parsed cost a quarter of a
# second at every start); a match in a string only makes the stamp wider, never narrower.
_IMPORT = re.compile(r"^[ \t]*import[ \t]+([\w. \t,]+)", re.MULTILINE)
_FROM_IMPORT = re.compile(
    r"^[ \t]*from[ \t]+(\.*)([\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[\w. \t,*]+)", re.MULTILINE
)
_AS = re.compile(r"[ \t]+as[ \t]+\w+")
_COMMENT = re.compile(r"#[^\n]*")


@functools.lru_cache(maxsize=4096)
def _scan_cached(
    file: Path, root: Path, package: str, mtime_ns: int, size: int
) -> tuple[bytes, tuple[Path, ...]]:
    # keyed by the file's time and size too, so that a file edited while the process runs
    # is read again (as Numba does for the kernel's own file)
    content = file.read_bytes()
    # the package ``file`` is in, within root: where its relative imports start, whether
    # ``file`` is a module or the package's __init__.py
    here = file.relative_to(root).parent.parts
    found: list[Path] = []
    for level, dotted in _imported_names(content.decode("utf-8", errors="replace")):
        if level:
            if level - 1 > len(here):
                continue  # beyond the package's top: Python refuses it
            parts = [*here[: len(here) - (level - 1)], *filter(None, dotted.split("."))]
        else:
            first, _, rest = dotted.partition(".")
            if first != package:
                continue
            parts = rest.split(".") if rest else []
        for depth in range(len(parts) + 1):
            found.extend(_module_file(root, tuple(parts[:depth])))
    return hashlib.sha256(content).digest(), tuple(dict.fromkeys(found))


def _imported_names(text: str) -> list[tuple[int, str]]:
    """The modules ``text`` imports, as (relative level, dotted name); the names a
    ``from`` import brings in are included, as any of them may be a module."""
    text = _COMMENT.sub("", text)  # a ")" in a comment would end a list early
    names: list[tuple[int, str]] = []
    for match in _IMPORT.finditer(text):
        names.extend((0, name) for name in _listed(match[1]))
    for match in _FROM_IMPORT.finditer(text):
        level, base = len(match[1]), match[2]
        names.append((level, base))
        names.extend(
            (level, f"{base}.{name}" if base else name) for name in _listed(match[3].strip("()"))
        )
    return names


def _listed(names: str) -> list[str]:
    """The dotted names of an import's list (``as`` dropped)."""
    stripped = (_AS.sub("", part).strip() for part in names.split(","))
    return [name for name in stripped if name]


@functools.lru_cache(maxsize=16384)
def _module_file(root: Path, parts: tuple[str, ...]) -> tuple[Path, ...]:
    """The file of the module ``parts`` (within the package at ``root``), if there is one.
    Kept for the process: a module file created while it runs is not looked for again."""
    directory = root.joinpath(*parts)
    candidates = [directory / "__init__.py", *([directory.with_suffix(".py")] if parts else [])]
    return tuple(candidate for candidate in candidates if candidate.is_file())[:1]


class _ClosureStamp:
    """A locator for the kernels of watched packages only, whose stamp is the sources of
    the kernel's import closure (the rest of the locator, where the cache lives, is
    Numba's)."""

    _py_file: str

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        if _package_of(Path(py_file).resolve()) is None:
            return None
        return super().from_function(py_func, py_file)  # type: ignore[misc]

    def get_source_stamp(self) -> str:
        return source_closure_digest(self._py_file)


def _numba_class(name: str) -> Any:
    # Numba 0.68 names them without the underscore that earlier releases gave them
    found = getattr(caching, name, None) or getattr(caching, f"_{name}", None)
    if found is None:
        raise ImportError(f"numba.core.caching has no {name}: railpilot.jit needs updating")
    return found


def _install_locators() -> None:
    impl = _numba_class("CacheImpl")
    if any(issubclass(cls, _ClosureStamp) for cls in impl._locator_classes):
        return
    # the same places as Numba's own (a user's NUMBA_CACHE_DIR first, then beside the
    # source, then the user's cache directory), tried before them
    ours = [
        type(f"ClosureStamped{base}", (_ClosureStamp, _numba_class(base)), {})
        for base in ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    ]
    impl._locator_classes = [*ours, *impl._locator_classes]


watch_package(__name__.rpartition(".")[0], Path(__file__).parent)
