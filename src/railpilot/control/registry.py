"""The one place that maps a controller's name to its implementation.

Everything that lists controllers (the command line's choices, scenario validation, the
simulator, the Monte Carlo, the tuning defaults) reads :data:`CONTROLLERS`; an unknown
name is an error naming the allowed ones, never a fall-through.

Adding a built-in controller (docs/architecture.md, "Adding a controller"): write one
module in control/ with its :class:`~railpilot.control.base.Controller` class, its
``*_ato_step`` kernel (the signature in control/base.py) and its tuning rule, then add one
``ControllerEntry`` line below.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from railpilot.errors import ConfigError
from railpilot.jit_identity import same_in_every_process

from .base import Controller
from .pid import TrackingPID, pid_ato_step
from .pstop import PredictiveStop, pstop_ato_step
from .qsmc import QSMC, qsmc_ato_step
from .smarc import SMARC, smarc_ato_step
from .tuning import (
    pid_tuning_default,
    pstop_tuning_default,
    qsmc_tuning_default,
    smarc_tuning_default,
)

#: ``tuning(theta_s, lag_s, control_period_s) -> constructor keywords``: the documented
#: rule for a plant ``exp(-theta s) / (s (lag s + 1))`` seen every control period.
Tuning = Callable[[float, float, float], dict[str, Any]]


@dataclass(frozen=True)
class ControllerEntry:
    """A built-in controller: its class (its constructor is its configuration), the
    compiled step the simulator calls, and its tuning default."""

    name: str
    cls: type[Controller]
    step: Any  # a Numba dispatcher with the signature of control/base.py
    tuning: Tuning

    def __post_init__(self) -> None:
        # the loop compiled for this step is found again in Numba's cache by the next
        # process (railpilot/jit_identity.py)
        same_in_every_process(self.step)


CONTROLLERS: dict[str, ControllerEntry] = {
    entry.name: entry
    for entry in (
        ControllerEntry("pid", TrackingPID, pid_ato_step, pid_tuning_default),
        ControllerEntry("smarc", SMARC, smarc_ato_step, smarc_tuning_default),
        ControllerEntry("qsmc", QSMC, qsmc_ato_step, qsmc_tuning_default),
        ControllerEntry("pstop", PredictiveStop, pstop_ato_step, pstop_tuning_default),
    )
}


def controller_entry(name: str, field: str = "controller.name") -> ControllerEntry:
    """The entry of ``name``; a ConfigError naming the allowed names otherwise."""
    entry = CONTROLLERS.get(name)
    if entry is None:
        raise ConfigError(
            field, name, f"one of {', '.join(CONTROLLERS)} or module:Name (your own controller)"
        )
    return entry


def builtin_entry_of(controller: Controller) -> ControllerEntry | None:
    """The entry whose law ``controller`` runs unchanged, or None.

    Only an instance of the registered class itself, or of a subclass that changes
    neither ``update`` nor brings its own ``step``: a subclass that overrides ``update``
    runs its own ``update`` (the Python-stepped path), never the built-in kernel.
    """
    for entry in CONTROLLERS.values():
        if isinstance(controller, entry.cls):
            cls = type(controller)
            if cls is entry.cls:
                return entry
            overrides_update = cls.update is not entry.cls.update  # type: ignore[attr-defined]
            if not overrides_update and getattr(controller, "step", None) is None:
                return entry
            return None
    return None
