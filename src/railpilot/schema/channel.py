"""A line run's ``[channel]`` table: what the simulated radio does to packets
(railpilot.cosim.channel, docs/cosim.md).

These models check each key alone; that a span ends beyond its start and that the median
latency is at least the least one are the channel model's own rules (its dataclasses).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated

from pydantic import Field

from railpilot.schema.fields import FileTable, Says, Unit, Words

#: the most a packet's latency may be [s], and the latency spread's largest shape
MAX_LATENCY_S = 10.0
MAX_LATENCY_SIGMA = 3.0
#: the largest chance that a packet is lost
MAX_LOSS = 0.99


class ChannelWords(Words):
    """The channel table's way: an unknown key is told the table's keys, sorted; a key a
    dead zone or an outage leaves out is named as that entry (``a table with end_km``)."""

    unknown_key = "one of {keys}"
    sorted_keys = True
    missing_as_table = True

    @staticmethod
    def table(keys: Sequence[str]) -> str:
        return "a table"


class ChannelTable(FileTable):
    WORDS = ChannelWords


class DeadZoneTable(ChannelTable):
    """A stretch of line without radio coverage: a train whose head is inside can neither
    send nor receive."""

    start_km: Annotated[float, Field(ge=0.0), Unit("km"), Says("a km post >= 0")]
    #: beyond start_km (the channel model's rule)
    end_km: Annotated[float, Field(ge=0.0), Unit("km"), Says("a km post >= 0")]


class OutageTable(ChannelTable):
    """A window of time from the start of the run with no radio anywhere on the line."""

    start_s: Annotated[float, Field(ge=0.0), Unit("s"), Says("a time [s] >= 0")]
    #: beyond start_s (the channel model's rule)
    end_s: Annotated[float, Field(ge=0.0), Unit("s"), Says("a time [s] >= 0")]


Latency = Annotated[
    float, Field(ge=0.0, le=MAX_LATENCY_S), Unit("s"), Says(f"0..{MAX_LATENCY_S:g} s")
]


class ChannelFileTable(ChannelTable):
    """``[channel]``: the radio between the trains and the ground: latency, loss, dead zones
    and outages (every key may be left out)."""

    # the lists come first: the channel model is given its entries before its numbers
    dead_zones: list[DeadZoneTable] = Field(default_factory=list)
    outages: list[OutageTable] = Field(default_factory=list)
    #: the least latency a packet has
    latency_min_s: Latency = 0.05
    #: the median latency; at least latency_min_s (the channel model's rule)
    latency_median_s: Latency = 0.15
    #: the log-normal shape of the latency above latency_min_s
    latency_sigma: Annotated[
        float, Field(ge=0.0, le=MAX_LATENCY_SIGMA), Says(f"0..{MAX_LATENCY_SIGMA:g}")
    ] = 0.5
    #: the chance that a packet is lost, each packet drawn alone
    loss: Annotated[float, Field(ge=0.0, le=MAX_LOSS), Says(f"a probability 0..{MAX_LOSS:g}")] = 0.0
