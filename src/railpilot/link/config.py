"""Configuration of the link endpoints: timers and identities, validated on construction.

Defaults and allowed ranges are the ones docs/protocol.md states (section "Timers").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from .errors import LinkConfigError
from .framing import (
    ABSOLUTE_MAX_FRAME_LENGTH,
    DEFAULT_MAX_FRAME_LENGTH,
    MAC_LENGTH,
    MIN_FRAME_LENGTH,
)
from .messages import IDENT_LEN

MAX_DEVICE_ID = 0xFFFF_FFFF


def _check_number(name: str, value: Any, lo: float, hi: float) -> None:
    if (
        not isinstance(value, int | float)
        or isinstance(value, bool)
        or not math.isfinite(value)
        or not lo <= value <= hi
    ):
        raise LinkConfigError(name, value, f"a number in [{lo}, {hi}]")


def _check_int(name: str, value: Any, lo: int, hi: int) -> None:
    if type(value) is not int or not lo <= value <= hi:
        raise LinkConfigError(name, value, f"an integer in [{lo}, {hi}]")


@dataclass(frozen=True, slots=True)
class LinkTimers:
    """Timers shared by both ends (docs/protocol.md, "Timers")."""

    #: Period of heartbeats and running info; the unit of timeout counting [s].
    cycle_s: float = 1.0
    #: A periodic message times out when more than this many whole cycles pass without a
    #: valid new one (paper 001, section 1.2 (2)).
    timeout_cycles: int = 3
    #: Wait for an acknowledgement (or registration response) before sending again [s].
    resend_interval_s: float = 2.0
    #: Largest age of the echoed timestamp: bounds round trip + one peer cycle [s].
    max_round_trip_s: float = 3.0
    #: Ground sends a time check after registration and then this often [s].
    time_check_interval_s: float = 60.0
    #: First reconnect delay; doubles per failed attempt up to ``reconnect_max_s`` [s].
    reconnect_initial_s: float = 1.0
    reconnect_max_s: float = 30.0
    #: Fraction of the delay drawn at random (0 = none, 1 = anywhere in [0, delay]).
    reconnect_jitter: float = 0.5
    #: Before a time check has measured the clock offset on a connection, a frame may be
    #: timestamped at most this far ahead of the receiver's clock; later, at most
    #: ``max_round_trip_s`` ahead of the peer's clock as the offset predicts it [s]. A frame
    #: beyond is implausible and refused, so it can never advance the accepted timestamp.
    max_clock_skew_s: float = 10.0
    #: A connection on which this many frames in a row were rejected is not speaking the
    #: protocol: the endpoint reports a link failure and the adapter closes it.
    max_consecutive_rejections: int = 16

    def __post_init__(self) -> None:
        _check_number("timers.cycle_s", self.cycle_s, 0.05, 60.0)
        _check_int("timers.timeout_cycles", self.timeout_cycles, 1, 100)
        _check_number("timers.resend_interval_s", self.resend_interval_s, 0.1, 600.0)
        _check_number("timers.max_round_trip_s", self.max_round_trip_s, 0.01, 600.0)
        if self.max_round_trip_s <= self.cycle_s:
            # The echo can legitimately be one peer cycle old; a tighter bound would
            # reject good frames.
            raise LinkConfigError(
                "timers.max_round_trip_s", self.max_round_trip_s, f"> cycle_s ({self.cycle_s})"
            )
        _check_number("timers.time_check_interval_s", self.time_check_interval_s, 1.0, 86400.0)
        _check_number("timers.reconnect_initial_s", self.reconnect_initial_s, 0.01, 60.0)
        _check_number(
            "timers.reconnect_max_s", self.reconnect_max_s, self.reconnect_initial_s, 3600.0
        )
        _check_number("timers.reconnect_jitter", self.reconnect_jitter, 0.0, 1.0)
        _check_number("timers.max_clock_skew_s", self.max_clock_skew_s, 0.01, 86400.0)
        _check_int(
            "timers.max_consecutive_rejections", self.max_consecutive_rejections, 1, 1_000_000
        )


def reconnect_delay_s(attempt: int, timers: LinkTimers, random_fraction: float) -> float:
    """Delay before reconnect attempt ``attempt`` (0-based): exponential backoff + jitter.

    ``delay = min(max, initial * 2**attempt) * (1 - jitter * random_fraction)`` with
    ``random_fraction`` in [0, 1) drawn by the caller from a seeded generator (the core
    owns no randomness).
    """
    if not 0.0 <= random_fraction < 1.0:
        raise LinkConfigError("random_fraction", random_fraction, "a number in [0, 1)")
    base = min(timers.reconnect_max_s, timers.reconnect_initial_s * 2.0 ** min(attempt, 30))
    return base * (1.0 - timers.reconnect_jitter * random_fraction)


def _check_common(prefix: str, local_id: int, max_frame_length: int, timers: LinkTimers) -> None:
    _check_int(f"{prefix}_id", local_id, 1, MAX_DEVICE_ID)
    _check_int(
        "max_frame_length",
        max_frame_length,
        MIN_FRAME_LENGTH + MAC_LENGTH,
        ABSOLUTE_MAX_FRAME_LENGTH,
    )
    if not isinstance(timers, LinkTimers):
        raise LinkConfigError("timers", timers, "a LinkTimers")


@dataclass(frozen=True, slots=True)
class OnboardConfig:
    """Identity and settings of one onboard unit (TCP client)."""

    train_id: int
    ground_id: int
    train_number: str
    loco_number: str
    driver_id: int
    #: One train length; every TSR is extended by it (paper 001, section 2.5) [m].
    train_length_m: float
    #: Reject frames without a valid MAC (EN 50159 category 3 needs it).
    require_auth: bool = True
    timers: LinkTimers = field(default_factory=LinkTimers)
    max_frame_length: int = DEFAULT_MAX_FRAME_LENGTH

    def __post_init__(self) -> None:
        _check_common("train", self.train_id, self.max_frame_length, self.timers)
        _check_int("ground_id", self.ground_id, 1, MAX_DEVICE_ID)
        if self.ground_id == self.train_id:
            raise LinkConfigError("ground_id", self.ground_id, "an id different from train_id")
        for name in ("train_number", "loco_number"):
            value = getattr(self, name)
            if not isinstance(value, str) or not 1 <= len(value) <= IDENT_LEN:
                raise LinkConfigError(name, value, f"1..{IDENT_LEN} printable ASCII characters")
        _check_int("driver_id", self.driver_id, 0, MAX_DEVICE_ID)
        _check_number("train_length_m", self.train_length_m, 0.0, 10_000.0)


#: Default allowance [s] for trains' clocks lagging the ground's when a freshly started
#: ground refuses frames timestamped before its start (``GroundConfig.not_before_s``).
REPLAY_WINDOW_S = 10.0


@dataclass(frozen=True, slots=True)
class GroundConfig:
    """Identity and settings of the ground front server (one endpoint per connection)."""

    ground_id: int
    require_auth: bool = True
    #: Trains allowed to register; ``None`` = any train (with a key when auth is required).
    accepted_trains: frozenset[int] | None = None
    timers: LinkTimers = field(default_factory=LinkTimers)
    max_frame_length: int = DEFAULT_MAX_FRAME_LENGTH
    #: Epoch time [s] before which no frame can be genuine (the server's start less a
    #: clock allowance); a new train record refuses older frames as replays. 0 = none.
    not_before_s: float = 0.0

    def __post_init__(self) -> None:
        _check_common("ground", self.ground_id, self.max_frame_length, self.timers)
        if not (math.isfinite(self.not_before_s) and self.not_before_s >= 0):
            raise LinkConfigError("not_before_s", self.not_before_s, "epoch seconds >= 0")
        if self.accepted_trains is not None and not isinstance(self.accepted_trains, frozenset):
            raise LinkConfigError("accepted_trains", self.accepted_trains, "a frozenset or None")
