"""Compiled steps that are the same function in every process, so that the compiled loop
specialised for them comes from Numba's on-disk cache.

The simulation core's loop (sim/engine.py ``run_kernel``) takes the controller's and the
brake's compiled steps as arguments and is specialised for each pair. Numba types such
an argument by the step's dispatcher object, and the cache index it writes names that
object by a random UUID, drawn afresh in every process: a new process never found its
entry and compiled the loop again (about 6 s a pair on a 2-core machine; each train of
a live line run is a process of its own). Giving every registered step a UUID drawn from
its name and its module's source makes the entry of one process the entry of the next.

An edit to a step's module, or to any module of the package it imports (a helper it
calls, a constant it reads: railpilot/jit.py ``source_closure``), gives its steps a new
UUID, so the loop is compiled again for them.
"""

from __future__ import annotations

import hashlib
import sys
import uuid
from pathlib import Path
from typing import Any, TypeVar

from railpilot.jit import source_closure_digest

D = TypeVar("D")

#: namespace of the UUIDs given here (any fixed UUID would do: uuid5 of the project's
#: name is the same in every process and every release)
NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "railpilot")


def same_in_every_process(dispatcher: D) -> D:
    """Give ``dispatcher`` (an ``@njit`` function of this package) a UUID that every
    process computes alike: from its module, its qualified name and the sources its module
    imports from the package (railpilot/jit.py).
    Returns it, so it can wrap a registry's entry. For functions defined at a module's
    top level: two closures made by one factory share a name and a source, so they would
    share an identity too."""
    d: Any = dispatcher
    func = d.py_func
    digest = _source_digest(func)
    wanted = str(uuid.uuid5(NAMESPACE, f"{func.__module__}.{func.__qualname__}:{digest}"))
    # Numba draws its own UUID the first time the dispatcher is pickled, and keeps it
    given = d._MemoMixin__uuid
    if given is None:
        d._set_uuid(wanted)
    elif given != wanted:
        raise RuntimeError(f"{func.__qualname__} already has a UUID of its own ({given})")
    return dispatcher


def _source_digest(func: Any) -> str:
    """A digest of what ``func``'s compiled code is made from: the sources of its module's
    import closure within this package (railpilot/jit.py), or, for a module without a
    readable file, its own compiled code."""
    path = getattr(sys.modules.get(func.__module__), "__file__", None)
    if path and Path(path).is_file():
        return source_closure_digest(path)  # outside the package: the module's own source
    code = func.__code__.co_code + repr(func.__code__.co_consts).encode()
    return hashlib.sha256(code).hexdigest()
