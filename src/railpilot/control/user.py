"""Your own controller in the simulator: what runs is what you passed.

Two ways in (docs/architecture.md, "Your own controller"):

* **A Python object** with ``reset()`` and ``update(reference, measurement, dt) ->
  command``: ``reference = (x_ref [m], v_ref [m/s], a_ref [m/s^2])``, ``measurement =
  (x [m], v [m/s])`` (measured, with the scenario's sensor effects), ``dt`` the control
  period [s]; ``command`` is the acceleration wanted [m/s^2] (negative brakes). The ATO
  adds its resistance model as a feed-forward and clamps the sum, as for every built-in
  controller. The simulator calls ``update`` from its compiled loop at every control
  update (Numba's object mode: the same plant code, about a microsecond more per call),
  so any Python runs; a Monte Carlo runs such a controller one run after another
  (``reset()`` before each), never in parallel.
* **A compiled step**: an object with a Numba ``@njit`` function ``step`` of the signature
  in control/base.py and float64 arrays ``params`` and ``state`` (subclass
  :class:`CompiledController`). It runs in the fast path and in parallel Monte Carlo.

A built-in controller's class runs its registered kernel; a subclass of it that overrides
``update`` runs its ``update`` (the Python path), one that brings a ``step`` runs that.
:func:`bind` decides, and never substitutes one law for another.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import itertools
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numba import cfunc, objmode, types
from numba.core.dispatcher import Dispatcher
from numba.core.errors import NumbaError

from railpilot.errors import ConfigError
from railpilot.jit import njit
from railpilot.jit_identity import same_in_every_process

from .base import Controller
from .registry import CONTROLLERS, builtin_entry_of, controller_entry


class Reference(NamedTuple):
    """What a Python controller is told to track at one control update."""

    x_m: float
    v_mps: float
    a_mps2: float


class Measurement(NamedTuple):
    """What a Python controller measures at one control update."""

    x_m: float
    v_mps: float


class CompiledController:
    """Base for a user's compiled controller: ``step`` (an ``@njit`` function with the
    signature of control/base.py), ``params`` and ``state`` (float64 arrays).

    ``reset()`` restores the state given at construction; the simulator copies
    ``params`` and ``state`` for every run, so one object serves a whole Monte Carlo.
    """

    name = "compiled"
    step: Any = None

    def __init__(self, params: Any, state: Any) -> None:
        self.params = np.asarray(params, dtype=float).copy()
        self.state = np.asarray(state, dtype=float).copy()
        self._state0 = self.state.copy()
        if not isinstance(type(self).step, Dispatcher):
            raise ConfigError(
                f"{type(self).__name__}.step",
                type(self).step,
                "a Numba @njit function (signature: control/base.py)",
            )

    def reset(self) -> None:
        self.state[:] = self._state0


# --- the Python path ----------------------------------------------------------------------

#: Python controllers taking part in a run now, by handle (the compiled loop passes the
#: handle in its params and finds the object here).
_LIVE: dict[int, Any] = {}
_HANDLES = itertools.count(1)


def _python_update(
    handle: int, rx: float, rv: float, ra: float, x: float, v: float, dt: float
) -> float:
    controller = _LIVE[handle]
    command = controller.update(Reference(rx, rv, ra), Measurement(x, v), dt)
    try:
        u = float(command)
    except (TypeError, ValueError):
        u = math.nan
    if math.isnan(u):
        # the user's code, not the simulation, went wrong: say so, naming the method
        raise ConfigError(
            f"{type(controller).__name__}.update()",
            command,
            "a number: the commanded acceleration [m/s^2]",
        )
    return u


@njit(cache=True)
def python_step(
    params: np.ndarray,
    state: np.ndarray,
    ref_x: float,
    ref_v: float,
    ref_a: float,
    x: float,
    v: float,
    resist_mps2: float,
    u_min: float,
    u_max: float,
    dt: float,
) -> float:
    """The step (control/base.py) that calls a Python controller's ``update``."""
    handle = int(params[0])
    with objmode(u="float64"):
        u = _python_update(handle, ref_x, ref_v, ref_a, x, v, dt)
    return u + resist_mps2


# the loop compiled for the Python path is found again in Numba's cache by the next
# process (railpilot/jit_identity.py)
same_in_every_process(python_step)


# --- a user's compiled step ------------------------------------------------------------

_ARRAY = types.float64[::1]
#: control/base.py's step as a Numba type: ``(params, state, 9 floats) -> u``
STEP_SIGNATURE = types.float64(_ARRAY, _ARRAY, *(types.float64,) * 9)


def step_pointer(owner: str, step: Dispatcher) -> Any:
    """A user's ``step`` behind a C function pointer of :data:`STEP_SIGNATURE`.

    The compiled loop takes it as a first-class function, typed by its signature and not
    by the function itself, so the loop compiled for it is the same for every user's
    step and comes from Numba's on-disk cache. A loop specialised on the user's function
    could not be cached (the cache cannot find the user's module again in another
    process): it was compiled in every process, about a minute on a 2-core machine. The
    call through the pointer costs nanoseconds a control update.

    An exception cannot leave a C callback, so one raised by the step becomes NaN, which
    the loop stops the run at and the simulator reports, naming ``owner`` and what the
    step raises when it calls it again from Python (sim/run.py ``check_commands``).
    """

    def call(  # type: ignore[no-untyped-def]
        params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, u_min, u_max, dt
    ):
        try:
            return step(params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, u_min, u_max, dt)
        except Exception:  # no exception crosses a C callback: NaN says it
            return np.nan

    try:
        return cfunc(STEP_SIGNATURE)(call)
    except NumbaError as exc:  # a step Numba cannot compile for control/base.py's signature
        said = str(exc).strip()
        first = said.splitlines()[0] if said else type(exc).__name__
        raise ConfigError(
            owner,
            getattr(step, "__name__", step),
            "a Numba function step(params, state, ref_x, ref_v, ref_a, x, v, resist_mps2, "
            f"u_min, u_max, dt) -> float (control/base.py); Numba says: {first}",
        ) from None


# --- binding ---------------------------------------------------------------------------


@dataclass
class Binding:
    """What the simulator runs for one controller object."""

    name: str
    step: Any
    params: np.ndarray
    state: np.ndarray
    #: the Python object the step calls (the Python path), None for compiled steps
    python: Any = None
    #: a user's compiled step, as errors name it (``"CompiledTracker.step"``); None for
    #: a built-in (named by ``name``) and the Python path (which checks every answer of
    #: ``update`` itself). The simulator stops a run whose step gave no number and
    #: names it (sim/run.py ``check_commands``).
    user_step: str | None = None
    #: that step itself (a Numba dispatcher, callable from Python), so the simulator can
    #: call it again with the failing update's inputs and show what it raised
    user_dispatcher: Any = None

    @property
    def parallel_safe(self) -> bool:
        """False for the Python path: one object, so runs go one after another."""
        return self.python is None

    def __enter__(self) -> Binding:
        if self.python is not None:
            self.python.reset()
            _LIVE[int(self.params[0])] = self.python
        return self

    def __exit__(self, *exc: object) -> None:
        if self.python is not None:
            _LIVE.pop(int(self.params[0]), None)


def bind(controller: Any) -> Binding:
    """How ``controller`` runs in the simulator; a ConfigError if it cannot.

    A built-in (an instance of a registered class, or a subclass changing neither
    ``update`` nor ``step``) runs its registered kernel; an object with a compiled
    ``step`` runs that; anything else with ``reset()`` and ``update()`` runs its
    ``update`` on the Python path.
    """
    name = str(getattr(controller, "name", type(controller).__name__))
    entry = builtin_entry_of(controller) if isinstance(controller, Controller) else None
    if entry is not None:
        controller.reset()
        return Binding(entry.name, entry.step, controller.params.copy(), controller.state.copy())
    step = getattr(type(controller), "step", None)
    if isinstance(step, Dispatcher):
        owner = f"{type(controller).__name__}.step"
        controller.reset()
        params = np.asarray(controller.params, dtype=float)
        state = np.asarray(controller.state, dtype=float)
        pointer = step_pointer(owner, step)
        return Binding(
            name, pointer, params.copy(), state.copy(), user_step=owner, user_dispatcher=step
        )
    if callable(getattr(controller, "update", None)) and callable(
        getattr(controller, "reset", None)
    ):
        handle = next(_HANDLES)
        return Binding(name, python_step, np.array([float(handle)]), np.zeros(0), controller)
    raise ConfigError(
        "controller",
        type(controller).__name__,
        "a built-in controller, an object with reset() and update(reference, measurement, "
        "dt), or one with a compiled step (control/user.py)",
    )


def is_user_spec(name: str) -> bool:
    """``module:Name`` or ``path/to/file.py:Name`` (not a registered name)."""
    return ":" in name and name not in CONTROLLERS


def load_controller(spec: str, field: str = "controller") -> Any:
    """Build the controller named by ``module:Name`` or ``path/file.py:Name``.

    ``Name`` is a class or a function; it is called without arguments.
    """
    module_name, _, attr = spec.rpartition(":")
    if not module_name or not attr:
        controller_entry(spec, field)  # raises, naming the built-in choices
    try:
        if module_name.endswith(".py") or "/" in module_name:
            path = Path(module_name)
            if not path.is_file():
                raise ConfigError(field, spec, f"module:Name with an existing file ({path})")
            # a name that is the same in every process, so Numba's cache of the user's
            # kernels finds their module again
            digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:12]
            mod_id = f"railpilot_user_{path.stem}_{digest}"
            module_spec = importlib.util.spec_from_file_location(mod_id, path)
            assert module_spec is not None and module_spec.loader is not None
            module = importlib.util.module_from_spec(module_spec)
            sys.modules[mod_id] = module
            module_spec.loader.exec_module(module)
        else:
            module = importlib.import_module(module_name)
    except ConfigError:
        raise
    except Exception as exc:  # the user's module: whatever it raises, say where
        raise ConfigError(
            field, spec, f"an importable module:Name ({type(exc).__name__}: {exc})"
        ) from exc
    factory = getattr(module, attr, None)
    if factory is None or not callable(factory):
        raise ConfigError(field, spec, f"a class or function named {attr!r} in {module_name}")
    try:
        controller = factory()
    except Exception as exc:
        raise ConfigError(
            field, spec, f"{attr}() to build a controller ({type(exc).__name__}: {exc})"
        ) from exc
    bind(controller)  # refuse now what the simulator could not run
    return controller
