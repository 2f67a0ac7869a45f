"""A coupling between two vehicles: the couplers' free slack and two friction draft gears.

One :class:`DraftGear` describes the whole connection between two neighbouring vehicles:
the free slack of the two coupler knuckles and the two draft gears in series (their
travels add, their forces are the same). The force law and its compiled twin are in
railpilot.sim.ltd; this module holds the parameters and their checks.
"""

from __future__ import annotations

from dataclasses import dataclass

from railpilot.checks import check_number
from railpilot.errors import ConfigError


@dataclass(frozen=True)
class DraftGear:
    """The connection between two vehicles (couplers and both draft gears), in series.

    Attributes
    ----------
    name
        Type name, e.g. ``"MT-2"``.
    slack_m
        Total free slack of the connection [m]: the relative travel, from bunched to
        stretched, over which the coupling carries no force.
    travel_m
        Travel of the two gears in series from free to solid [m], on each side
        (draft and buff), beyond the slack.
    preload_n
        Force [N] at which the gears start to move (friction-gear preload).
    force_at_travel_n
        Force [N] on the loading curve when the gears close (solid).
    unloading_ratio
        Unloading force over loading force at the same travel [-], in (0, 1]: the
        friction gear's hysteresis (the area between the curves is the energy it absorbs).
    stop_stiffness_n_per_m
        Stiffness [N/m] beyond solid: the coupler body and the wagon's underframe.
    damping_n_s_per_m
        Viscous damping [N s/m] across the connection, in the gear's travel and beyond.
    switching_speed_mps
        Relative speed [m/s] over which the gear passes from its unloading to its loading
        curve (a smooth switch instead of a jump at zero relative speed).
    """

    name: str
    slack_m: float
    travel_m: float
    preload_n: float
    force_at_travel_n: float
    unloading_ratio: float
    stop_stiffness_n_per_m: float
    damping_n_s_per_m: float
    switching_speed_mps: float = 0.01

    def __post_init__(self) -> None:
        where = f"draft_gear[{self.name!r}]" if isinstance(self.name, str) else "draft_gear"
        if not isinstance(self.name, str) or not self.name:
            raise ConfigError(f"{where}.name", self.name, "a non-empty string")
        check_number(f"{where}.slack_m", self.slack_m, minimum=0.0, maximum=1.0, error=ConfigError)
        check_number(
            f"{where}.travel_m", self.travel_m, positive=True, maximum=1.0, error=ConfigError
        )
        check_number(f"{where}.preload_n", self.preload_n, minimum=0.0, error=ConfigError)
        check_number(
            f"{where}.force_at_travel_n",
            self.force_at_travel_n,
            positive=True,
            error=ConfigError,
        )
        if self.force_at_travel_n < self.preload_n:
            raise ConfigError(
                f"{where}.force_at_travel_n",
                self.force_at_travel_n,
                f"a force >= preload_n ({self.preload_n:g} N)",
            )
        check_number(
            f"{where}.unloading_ratio",
            self.unloading_ratio,
            positive=True,
            maximum=1.0,
            error=ConfigError,
        )
        check_number(
            f"{where}.stop_stiffness_n_per_m",
            self.stop_stiffness_n_per_m,
            positive=True,
            error=ConfigError,
        )
        check_number(
            f"{where}.damping_n_s_per_m", self.damping_n_s_per_m, minimum=0.0, error=ConfigError
        )
        check_number(
            f"{where}.switching_speed_mps",
            self.switching_speed_mps,
            positive=True,
            error=ConfigError,
        )

    @property
    def gear_stiffness_n_per_m(self) -> float:
        """Mean slope of the loading curve within the travel [N/m]."""
        return (self.force_at_travel_n - self.preload_n) / self.travel_m
