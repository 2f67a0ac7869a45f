"""The garbage collector on a live ground server (docs/scaling.md, "Garbage collection").

The ground server runs every train's frames on one event loop, so a pause of the cyclic
garbage collector is a pause for every train. A full collection walks every container
object the process holds. Measured at 1,000 trains on the development VM
(``railpilot link loadtest --trains 1000 --dashboard``): about 160,000 objects, 60–160 ms
per full collection, and a full collection every 3–4 s, each finding no garbage at all.
Two things cause that, and this module answers each:

- **The objects of start-up** (the modules of the server and the web stack, the line, the
  keys: about 100,000) are alive for the process's life, yet each full collection walks
  them again. :func:`freeze_startup` moves them out of the collector's reach
  (:func:`gc.freeze`) once the server has started.
- **The dashboard's snapshot** is tens of thousands of short-lived containers built and
  encoded in slices, with the loop running the trains' frames between the slices. Young
  collections in between find them alive and promote them to the oldest generation, where
  they die by reference counting; the promotions make CPython start full collections.
  :func:`collection_paused` holds automatic collection while a snapshot is built and
  encoded: its objects then die young, before any collector has seen them.

Neither changes what is freed: reference counting frees everything that is not in a
cycle, as always, and the collector runs again as soon as the pause ends.
"""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator

_pauses = 0  # nested or interleaved (one per coroutine in its window) pauses in force
_was_enabled = True


def freeze_startup() -> int:
    """Collect once, then freeze every object alive now (:func:`gc.freeze`): later
    collections skip them. Call it once, when the server has started and before trains
    connect. Returns how many objects were frozen."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()


@contextlib.contextmanager
def collection_paused() -> Iterator[None]:
    """Hold automatic garbage collection for the ``with`` block, which may span awaits.
    Pauses nest and interleave: collection resumes when the last one ends, and only if it
    was enabled before the first began."""
    global _pauses, _was_enabled
    if _pauses == 0:
        _was_enabled = gc.isenabled()
        gc.disable()
    _pauses += 1
    try:
        yield
    finally:
        _pauses -= 1
        if _pauses == 0 and _was_enabled:
            gc.enable()
