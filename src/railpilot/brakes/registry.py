"""The one place that maps a brake model's name to its implementation.

The scenario loader's ``[brake] model = ...`` choices, the simulator and the Monte Carlo
read :data:`BRAKES`; an unknown name is an error naming the allowed ones.

Adding a brake model (docs/architecture.md, "Adding a brake"): write one module in
brakes/ with its configuration dataclass (the interface of brakes/base.py) and its
``*_ato_step`` kernel, then add one ``BrakeEntry`` line below.
"""

from __future__ import annotations

from dataclasses import dataclass

from railpilot.errors import ConfigError
from railpilot.jit_identity import same_in_every_process

from .base import BrakeModel, BrakeStep
from .brake_pipe import BrakePipeBrake, brake_pipe_ato_step
from .ep_blend import EPBrake, ep_ato_step
from .lag_delay_brake import LagDelayBrake, lag_delay_ato_step
from .locomotive_drive import LocomotiveDrive, locomotive_drive_ato_step


@dataclass(frozen=True)
class BrakeEntry:
    """A brake model: its configuration class and the compiled step the simulator calls."""

    name: str
    cls: type
    step: BrakeStep

    def __post_init__(self) -> None:
        # the loop compiled for this step is found again in Numba's cache by the next
        # process (railpilot/jit_identity.py)
        same_in_every_process(self.step)


BRAKES: dict[str, BrakeEntry] = {
    entry.name: entry
    for entry in (
        BrakeEntry("ep-blended", EPBrake, ep_ato_step),
        BrakeEntry("lag-delay", LagDelayBrake, lag_delay_ato_step),
        BrakeEntry("brake-pipe", BrakePipeBrake, brake_pipe_ato_step),
        BrakeEntry("locomotive-drive", LocomotiveDrive, locomotive_drive_ato_step),
    )
}


def brake_entry(name: str, field: str = "brake.model") -> BrakeEntry:
    """The entry of ``name``; a ConfigError naming the allowed names otherwise."""
    entry = BRAKES.get(name)
    if entry is None:
        raise ConfigError(field, name, f"one of {', '.join(BRAKES)}")
    return entry


def brake_entry_of(brake: BrakeModel) -> BrakeEntry:
    """The entry of a brake model's configuration object (by its class)."""
    for entry in BRAKES.values():
        if type(brake) is entry.cls:
            return entry
    raise ConfigError("brake", type(brake).__name__, f"a brake model of {', '.join(BRAKES)}")
