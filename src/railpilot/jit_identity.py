"""Compiled steps that are the same function in every process, so that the compiled loop
specialised for them comes from Numba's on-disk cache.

The simulation core's loop (sim/engine.py ``run_kernel``) takes the controller's and the
brake's compiled steps as arguments and is specialised for each pair. Numba types such
an argument by the step's dispatcher object, and the cache index it writes names that
object by a random UUID, drawn afresh in every process: a new process never found its
entry and compiled the loop again (about 6 s a pair on a 2-core machine; each train of
a live line run is a process of its own). Giving every registered step a UUID drawn from
its name and its module's source makes the entry of one process the entry of the next.

An edited module gives its steps a new UUID, so the loop is compiled again for them (a
helper a step calls from *another* module is not covered: after editing one, delete the
cache, docs/architecture.md "Numba's on-disk cache").
"""

from __future__ import annotations

import hashlib
import sys
import uuid
from pathlib import Path
from typing import Any, TypeVar

D = TypeVar("D")

#: namespace of the UUIDs given here (any fixed UUID would do: uuid5 of the project's
#: name is the same in every process and every release)
NAMESPACE = uuid.uuid5(uuid.NAMESPACE_URL, "railpilot")


def same_in_every_process(dispatcher: D) -> D:
    """Give ``dispatcher`` (an ``@njit`` function of this package) a UUID that every
    process computes alike: from its module, its qualified name and its module's source.
    Returns it, so it can wrap a registry's entry. For functions defined at a module's
    top level: two closures made by one factory share a name and a source, so they would
    share an identity too."""
    d: Any = dispatcher
    func = d.py_func
    digest = hashlib.sha256(_source(func)).hexdigest()
    wanted = str(uuid.uuid5(NAMESPACE, f"{func.__module__}.{func.__qualname__}:{digest}"))
    # Numba draws its own UUID the first time the dispatcher is pickled, and keeps it
    given = d._MemoMixin__uuid
    if given is None:
        d._set_uuid(wanted)
    elif given != wanted:
        raise RuntimeError(f"{func.__qualname__} already has a UUID of its own ({given})")
    return dispatcher


def _source(func: Any) -> bytes:
    """The source of ``func``'s module, or (a module without a readable file) its own
    compiled code: what changes when the step does."""
    path = getattr(sys.modules.get(func.__module__), "__file__", None)
    if path:
        try:
            return Path(path).read_bytes()
        except OSError:
            pass
    return func.__code__.co_code + repr(func.__code__.co_consts).encode()
