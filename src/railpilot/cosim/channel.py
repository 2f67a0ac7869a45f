"""The simulated radio channel between the trains and the ground (docs/cosim.md).

The co-simulation runs the same link endpoints as the live system. Only the transport is
different: instead of TCP, each train's frames cross a :class:`RadioChannel` in
simulated time. The channel models what the link must survive on a real line:

- **latency**: each packet arrives ``latency_min_s`` plus a log-normal excess with median
  ``latency_median_s - latency_min_s`` and shape ``latency_sigma`` later. Packets of one
  direction keep their order: the radio bearer delivers in order, as the live link's TCP
  does;
- **loss**: each packet is lost with probability ``loss`` (a packet is whatever one
  endpoint had to send at one instant: one or more whole frames);
- **dead zones**: stretches of line, by km post, without radio coverage. A train whose
  head is inside one can neither send nor receive;
- **outages**: windows of simulated time in which the whole line has no radio (a base
  station controller down).

The draws come from one :class:`random.Random` per train, seeded with ``(seed,
train_id)``. The same seed gives the same run, and adding a train does not change what
another train's channel draws.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from railpilot.errors import ConfigError, is_finite_number
from railpilot.schema.channel import ChannelFileTable
from railpilot.schema.config import given_values
from railpilot.schema.validate import check
from railpilot.units import km_post_to_m

T = TypeVar("T")

#: Why a packet did not arrive (the keys of :attr:`ChannelCounters.lost`).
LOSS_CAUSES = ("random", "dead_zone", "outage")


def _check_span(where: str, start: tuple[str, float], end: tuple[str, float], kind: str) -> None:
    """Both ends finite and >= 0, the end beyond the start; else a ConfigError naming the
    field (``where.name``)."""
    for name, value in (start, end):
        if not is_finite_number(value) or value < 0:
            raise ConfigError(f"{where}.{name}", value, f"{kind} >= 0")
    if end[1] <= start[1]:
        raise ConfigError(f"{where}.{end[0]}", end[1], f"{kind} beyond {start[0]} ({start[1]})")


@dataclass(frozen=True)
class DeadZone:
    """A stretch of line without radio coverage, between two km posts [km]."""

    start_km: float
    end_km: float

    def __post_init__(self) -> None:
        _check_span("dead_zone", ("start_km", self.start_km), ("end_km", self.end_km), "a km post")

    def holds(self, position_m: float) -> bool:
        """Whether km-post position ``position_m`` [m] is inside the zone (ends included)."""
        return km_post_to_m(self.start_km) <= position_m <= km_post_to_m(self.end_km)


@dataclass(frozen=True)
class Outage:
    """A window of simulated time with no radio anywhere on the line [s from the start]."""

    start_s: float
    end_s: float

    def __post_init__(self) -> None:
        _check_span("outage", ("start_s", self.start_s), ("end_s", self.end_s), "a time [s]")

    def holds(self, t_s: float) -> bool:
        return self.start_s <= t_s < self.end_s


@dataclass(frozen=True)
class ChannelModel:
    """What the radio does to packets (module docstring). Times in seconds."""

    latency_min_s: float = 0.05
    latency_median_s: float = 0.15
    latency_sigma: float = 0.5
    loss: float = 0.0
    dead_zones: tuple[DeadZone, ...] = ()
    outages: tuple[Outage, ...] = ()

    def __post_init__(self) -> None:
        checks: list[tuple[str, float, float, float, str]] = [
            ("latency_min_s", self.latency_min_s, 0.0, 10.0, "0..10 s"),
            ("latency_median_s", self.latency_median_s, 0.0, 10.0, "0..10 s"),
            ("latency_sigma", self.latency_sigma, 0.0, 3.0, "0..3"),
            ("loss", self.loss, 0.0, 0.99, "a probability 0..0.99"),
        ]
        for name, value, lo, hi, allowed in checks:
            if not is_finite_number(value) or not lo <= value <= hi:
                raise ConfigError(f"channel.{name}", value, allowed)
        if self.latency_median_s < self.latency_min_s:
            raise ConfigError(
                "channel.latency_median_s",
                self.latency_median_s,
                f">= latency_min_s ({self.latency_min_s})",
            )
        for name, items, kind in (
            ("dead_zones", self.dead_zones, DeadZone),
            ("outages", self.outages, Outage),
        ):
            for i, item in enumerate(items):
                if not isinstance(item, kind):
                    raise ConfigError(f"channel.{name}[{i}]", item, f"a {kind.__name__}")

    @classmethod
    def from_mapping(
        cls, table: Mapping[str, Any] | ChannelFileTable, where: str = "channel"
    ) -> ChannelModel:
        """A model from a scenario file's ``[channel]`` table (its format:
        railpilot.schema.channel; a table the line-run file's check has already read is
        taken as it is). The keys are the fields above, with ``dead_zones = [{start_km,
        end_km}, ...]`` and ``outages = [{start_s, end_s}, ...]``. An unknown key or a bad
        value is a :class:`ConfigError` naming it (``channel.dead_zones[2].end_km``)."""
        checked = check(ChannelFileTable, table, ConfigError, at=(where,))
        zones = tuple(
            _entry(DeadZone, (z.start_km, z.end_km), f"{where}.dead_zones[{i}]")
            for i, z in enumerate(checked.dead_zones)
        )
        outages = tuple(
            _entry(Outage, (o.start_s, o.end_s), f"{where}.outages[{i}]")
            for i, o in enumerate(checked.outages)
        )
        numbers = given_values(checked, *_NUMBERS)
        try:
            return cls(dead_zones=zones, outages=outages, **numbers)
        except ConfigError as error:  # the dataclass names its fields as "channel.<key>"
            name = error.field.rpartition(".")[2]
            raise ConfigError(f"{where}.{name}", error.value, error.allowed) from None

    def covered(self, position_m: float | None, t_s: float) -> str | None:
        """Why the radio is down for a train at ``position_m`` [m] at ``t_s`` [s], or None
        when it is up (an unknown position is taken to be covered)."""
        if any(o.holds(t_s) for o in self.outages):
            return "outage"
        if position_m is not None and any(z.holds(position_m) for z in self.dead_zones):
            return "dead_zone"
        return None


#: the channel's numbers a file may give (the rest of its keys are its lists)
_NUMBERS = ("latency_min_s", "latency_median_s", "latency_sigma", "loss")


def _entry(kind: Callable[[float, float], T], ends: tuple[float, float], place: str) -> T:
    """A dead zone or an outage from its two ends; its error names the entry's place in
    the file (``channel.dead_zones[2].end_km``), where the item names itself by its kind."""
    try:
        return kind(*ends)
    except ConfigError as error:
        key = error.field.rpartition(".")[2]
        raise ConfigError(f"{place}.{key}", error.value, error.allowed) from None


@dataclass
class ChannelCounters:
    """What one train's channel did, both directions together."""

    packets: int = 0
    delivered: int = 0
    lost: dict[str, int] = field(default_factory=lambda: dict.fromkeys(LOSS_CAUSES, 0))

    def as_dict(self) -> dict[str, Any]:
        return {"packets": self.packets, "delivered": self.delivered, "lost": dict(self.lost)}


def channel_totals(counters: Iterable[ChannelCounters]) -> dict[str, int]:
    """The channels' counts summed, as a run's link statistics give them: ``packets``,
    ``delivered`` and ``lost_<cause>`` for each cause that lost one."""
    totals: dict[str, int] = {}
    for c in counters:
        totals["packets"] = totals.get("packets", 0) + c.packets
        totals["delivered"] = totals.get("delivered", 0) + c.delivered
        for cause, n in c.lost.items():
            totals[f"lost_{cause}"] = totals.get(f"lost_{cause}", 0) + n
    return totals


class RadioChannel:
    """One train's radio link to the ground (module docstring): decides, per packet,
    whether and when it arrives."""

    def __init__(
        self, model: ChannelModel, seed: int, train_id: int, origin_s: float = 0.0
    ) -> None:
        self.model = model
        #: the start of the run on the clock the times are given on [s]: outages are
        #: windows from the start of the run, the link's clock counts from the epoch
        self.origin_s = origin_s
        # A string seed is hashed the same way on every platform and Python version.
        self._rng = random.Random(f"railpilot-channel:{seed}:{train_id}")
        self._mu = (
            math.log(model.latency_median_s - model.latency_min_s)
            if model.latency_median_s > model.latency_min_s
            else None
        )
        #: the last arrival time per direction [s]: packets keep their order
        self._last_arrival = {"up": -math.inf, "down": -math.inf}
        self.counters = ChannelCounters()

    def up(self, now_s: float, position_m: float | None) -> bool:
        """Whether the radio is up for the train at ``position_m`` at ``now_s`` [s, the
        clock ``origin_s`` is on]."""
        return self.model.covered(position_m, now_s - self.origin_s) is None

    def transmit(self, direction: str, now_s: float, position_m: float | None) -> float | None:
        """A packet sent ``direction`` ("up": train to ground, "down": ground to train) at
        ``now_s`` [s, the clock ``origin_s`` is on] by or to a train whose head is at
        ``position_m`` [m]: its arrival time [s, the same clock], or None if it is lost."""
        self.counters.packets += 1
        # Draw both numbers for every packet, so one cause of loss does not shift the
        # draws of the packets after it.
        lost_draw = self._rng.random()
        excess = (
            0.0
            if self._mu is None
            else self._rng.lognormvariate(self._mu, self.model.latency_sigma)
        )
        cause = self.model.covered(position_m, now_s - self.origin_s)
        if cause is None and lost_draw < self.model.loss:
            cause = "random"
        if cause is not None:
            self.counters.lost[cause] += 1
            return None
        arrival = max(now_s + self.model.latency_min_s + excess, self._last_arrival[direction])
        self._last_arrival[direction] = arrival
        self.counters.delivered += 1
        return arrival
