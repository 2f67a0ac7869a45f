"""The receive-side safety layer and the matching send side (paper 001, section 1.2).

:class:`SecureChannel` is one connection's view of one peer: it builds outgoing frames
(sequence number, strictly rising timestamp, echo, MAC, CRC, stuffing) and runs every
check on incoming ones in the order of docs/protocol.md section 5.4: framing, version,
length, CRC, flags, type, body length, direction, destination, source, MAC, body fields,
sequence (repeat / reorder), timestamp (newer than the last of that type, not before the
receiver started, not implausibly far ahead of the receiver's clock), delay (echo 0 only on a
HEARTBEAT at connection set-up; otherwise the echo is a timestamp the receiver sent on this
connection, at most ``max_round_trip_s`` old). The *state* check is the endpoint's.

A frame changes no state until it passed all of them. A sequence *gap* is not a rejection:
the frame is accepted and the gap counted (frames were deleted on the way).

:class:`PeriodicSupervisor` is the timeout counting of section 1.2 (2) with last-value hold.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from .codec import decode_body, encode_body
from .errors import (
    AuthenticationError,
    DelayError,
    DestinationIdError,
    LocalProtocolError,
    SequenceError,
    SourceIdError,
    TimestampError,
    TypeCheckError,
)
from .events import Check
from .frame import Frame, encode_frame, parse_frame, verify_mac
from .keys import KeyStore
from .messages import MESSAGE_CLASSES, LinkDirection, Message, MessageType

#: How many recent sequence numbers are remembered to tell a repeat from a late frame.
SEQUENCE_WINDOW = 64
_U32_MAX = 0xFFFF_FFFF


@dataclass(slots=True)
class LinkCounters:
    """What one endpoint saw; for logs, metrics and tests (never reset by the core)."""

    frames_sent: int = 0
    frames_received: int = 0
    frames_accepted: int = 0
    #: Rejected frames per failed check.
    rejected: Counter[Check] = field(default_factory=Counter)
    #: Accepted frames that arrived after a sequence gap, and the frames missing in gaps.
    sequence_gaps: int = 0
    frames_lost: int = 0
    #: Rejected sequence numbers: seen before (repetition) / lower but unseen (reordering).
    repeats: int = 0
    reorders: int = 0
    #: Periodic messages replaced by a newer one of the same type in the same cycle.
    superseded: int = 0
    timeouts: int = 0
    resends: int = 0
    link_failures: int = 0
    bytes_discarded: int = 0


@dataclass(slots=True)
class PeerHistory:
    """What survives reconnects about one peer: the newest accepted timestamps.

    Kept across connections so that frames replayed from an earlier connection fail the
    timestamp check even though sequence numbers restart.
    """

    last_timestamp_us: dict[int, int] = field(default_factory=dict)
    newest_timestamp_us: int = 0
    #: Frames timestamped at or before this are refused whatever their type: a ground that
    #: has just started has received nothing earlier, so such a frame is a replay of a
    #: recording made before the restart (0 = no floor).
    not_before_us: int = 0
    #: Newest timestamp we sent to this peer: our timestamps keep rising across
    #: connections (and across ground endpoints of one train), so the peer's per-type
    #: "newer than last" rule never drops a good frame after a quick reconnect.
    last_sent_timestamp_us: int = 0


class SecureChannel:
    """Send and receive side of one connection to one peer.

    Parameters
    ----------
    local_id
        Our device id; incoming frames must be addressed to it.
    inbound
        Direction of the frames we receive (``DOWNLINK`` on the onboard).
    keys
        Key store, or ``None`` for an unauthenticated link (then ``require_auth`` must be
        false).
    require_auth
        Reject frames without a valid MAC.
    history_for
        Peer id -> that peer's :class:`PeerHistory` (called only for authentic frames).
    peer_id
        The peer's device id, or ``None`` until it is known (ground before registration).
    key_train_id
        Train whose keys protect this link; ``None`` = the peer (the ground's view).
    """

    def __init__(
        self,
        *,
        local_id: int,
        inbound: LinkDirection,
        keys: KeyStore | None,
        require_auth: bool,
        max_round_trip_s: float,
        max_clock_skew_s: float,
        history_for: Callable[[int], PeerHistory],
        peer_id: int | None = None,
        key_train_id: int | None = None,
        counters: LinkCounters | None = None,
    ) -> None:
        self.local_id = local_id
        self.peer_id = peer_id
        self._inbound = inbound
        self._keys = keys
        self._require_auth = require_auth
        self._max_rtt_us = round(max_round_trip_s * 1e6)
        self._max_skew_us = round(max_clock_skew_s * 1e6)
        self._history_for = history_for
        self._key_train_id = key_train_id
        self.counters = counters if counters is not None else LinkCounters()
        self._allowed_types = frozenset(
            int(t)
            for t, cls in MESSAGE_CLASSES.items()
            if cls.DIRECTION in (inbound, LinkDirection.BOTH)
        )
        self.new_connection(0.0)

    # --- connection lifecycle -------------------------------------------------------------

    def new_connection(self, now_s: float) -> None:
        """Start a connection at ``now_s``: sequence numbers, echoes and offset start afresh."""
        self._tx_sequence = 0
        self._rx_next = 0
        self._rx_seen: set[int] = set()
        # The echo is per connection: a fresh peer endpoint has sent nothing we could echo.
        self._rx_newest_us = 0
        # Our first and newest timestamp on this connection: a valid echo lies between them,
        # so no frame made for another connection (or before it) passes the delay check.
        self._tx_first_us = 0
        self._tx_last_us = 0
        self._started_us = int(now_s * 1e6)
        # Set once the peer echoed one of our timestamps: from then on it has heard from us
        # and never sends echo 0 again on this connection.
        self._peer_echoed = False
        # The peer's clock minus ours as the last time check on this connection measured it
        # [us]; None until then (the looser ``max_clock_skew_s`` bound applies).
        self._peer_clock_ahead_us: int | None = None

    @property
    def heard_from_peer(self) -> bool:
        """True once a frame of the peer was accepted on this connection (we can echo it)."""
        return self._rx_newest_us != 0

    def set_peer_clock_ahead(self, ahead_us: int) -> None:
        """Record the peer's clock minus ours [us], as a time check measured it (8.5)."""
        self._peer_clock_ahead_us = int(ahead_us)

    def latest_plausible_timestamp_us(self, now_s: float) -> int:
        """The newest timestamp a genuine frame of the peer can carry at ``now_s`` (5.2)."""
        now_us = int(now_s * 1e6)
        if self._peer_clock_ahead_us is None:
            return now_us + self._max_skew_us
        # The measured offset holds one transmission delay (at most a round trip); allow it.
        return now_us + self._peer_clock_ahead_us + self._max_rtt_us

    # --- send -------------------------------------------------------------------------------

    def encode(self, message: Message, now_s: float) -> bytes:
        """Wire bytes of ``message`` as the next frame on this connection."""
        if self.peer_id is None:
            raise LocalProtocolError("the peer is not known yet, so nothing can be sent to it")
        if self._tx_sequence > _U32_MAX:
            raise LocalProtocolError(
                "sequence numbers exhausted on this connection; close it and reconnect"
            )
        # Strictly rising timestamps, even if the clock did not advance (or went back),
        # so the receiver's "newer than last" rule never drops a good frame.
        echo = self._rx_newest_us
        if echo == 0 and message.TYPE is not MessageType.HEARTBEAT:
            # Only a HEARTBEAT may carry echo 0 (5.3): anything else waits until the peer
            # has been heard on this connection, so that its echo proves it is fresh.
            raise LocalProtocolError(
                f"{message.TYPE.name} cannot be sent before a frame of the peer was accepted "
                "on this connection (only a HEARTBEAT may carry echo 0)"
            )
        history = self._history_for(self.peer_id)
        ts = max(int(now_s * 1e6), history.last_sent_timestamp_us + 1)
        history.last_sent_timestamp_us = ts
        if self._tx_first_us == 0:
            self._tx_first_us = ts
        self._tx_last_us = ts
        key_id, key = 0, None
        if self._keys is not None:
            active = self._keys.active(self._key_train())
            if active is not None:
                key_id, key = active
            elif self._require_auth:
                raise LocalProtocolError(f"no active key for train {self._key_train()}")
        wire = encode_frame(
            message.TYPE,
            self.local_id,
            self.peer_id,
            self._tx_sequence,
            ts,
            echo,
            encode_body(message),
            key_id,
            key,
        )
        self._tx_sequence += 1
        self.counters.frames_sent += 1
        return wire

    def _key_train(self) -> int:
        if self._key_train_id is not None:
            return self._key_train_id
        assert self.peer_id is not None
        return self.peer_id

    # --- receive ----------------------------------------------------------------------------

    def receive(self, raw: bytes, now_s: float) -> tuple[Frame, Message, int]:
        """Run every check on one unstuffed frame.

        Returns ``(frame, message, lost)`` where ``lost`` is the number of frames missing
        before this one (0 normally). Raises a :class:`FrameError` subclass otherwise;
        nothing is changed then.
        """
        frame = parse_frame(raw)  # length, crc, version/flags, type, body length
        mtype = frame.message_type
        if mtype not in self._allowed_types:
            raise TypeCheckError(f"{MessageType(mtype).name} may not be sent in this direction")
        if frame.destination_id != self.local_id:
            raise DestinationIdError(f"addressed to {frame.destination_id}, we are {self.local_id}")
        src = frame.source_id
        if self.peer_id is not None:
            if src != self.peer_id:
                raise SourceIdError(f"source {src}, expected {self.peer_id}")
        elif src == 0 or src == self.local_id:
            raise SourceIdError(f"source {src} cannot be a peer")
        self._authenticate(raw, frame)
        message = decode_body(mtype, frame.body)  # BODY check
        seq = frame.sequence
        lost = 0
        if seq < self._rx_next:
            if seq in self._rx_seen:
                self.counters.repeats += 1
                raise SequenceError(f"sequence {seq} repeated")
            self.counters.reorders += 1
            raise SequenceError(f"sequence {seq} arrived after {self._rx_next - 1} (reordered)")
        lost = seq - self._rx_next
        history = self._history_for(src)
        last = history.last_timestamp_us.get(mtype, 0)
        if frame.timestamp_us <= last:
            raise TimestampError(
                f"timestamp {frame.timestamp_us} us not newer than {last} us for "
                f"{MessageType(mtype).name}"
            )
        if frame.timestamp_us <= history.not_before_us:
            raise TimestampError(
                f"timestamp {frame.timestamp_us} us is before the receiver started "
                f"({history.not_before_us} us, less the replay window): a replayed frame"
            )
        now_us = int(now_s * 1e6)
        latest_us = self.latest_plausible_timestamp_us(now_s)
        if frame.timestamp_us > latest_us:
            # Accepting it would make every later genuine frame "not newer" (a lock-out).
            raise TimestampError(
                f"timestamp {frame.timestamp_us} us is implausible: "
                f"{(frame.timestamp_us - now_us) / 1e6:.3f} s ahead of the receiver's clock "
                f"(at most {(latest_us - now_us) / 1e6:.3f} s allowed)"
            )
        self._check_echo(mtype, frame.echo_timestamp_us, now_us)
        # All checks passed: commit.
        self._rx_next = seq + 1
        self._rx_seen.add(seq)
        if len(self._rx_seen) > 2 * SEQUENCE_WINDOW:  # prune rarely: amortised O(1)
            floor = self._rx_next - SEQUENCE_WINDOW
            self._rx_seen = {s for s in self._rx_seen if s >= floor}
        history.last_timestamp_us[mtype] = frame.timestamp_us
        if frame.timestamp_us > history.newest_timestamp_us:
            history.newest_timestamp_us = frame.timestamp_us
        if frame.timestamp_us > self._rx_newest_us:
            self._rx_newest_us = frame.timestamp_us
        if frame.echo_timestamp_us:
            self._peer_echoed = True
        return frame, message, lost

    def _check_echo(self, mtype: int, echo: int, now_us: int) -> None:
        """The delay check (5.3): every accepted frame is fresh, whatever its echo."""
        if echo == 0:
            # A frame with echo 0 proves nothing about its age, so it may only be the
            # content-free HEARTBEAT that opens a connection, and only at set-up.
            if mtype != MessageType.HEARTBEAT:
                raise DelayError(
                    f"echo 0 on a {MessageType(mtype).name}: only a HEARTBEAT may carry "
                    "echo 0, before its sender has heard from the receiver"
                )
            if self._peer_echoed:
                raise DelayError("echo 0 after the peer has echoed us on this connection")
            if now_us - self._started_us > self._max_rtt_us:
                raise DelayError(
                    f"echo 0 more than {self._max_rtt_us / 1e6:.3f} s after the connection "
                    "started (the set-up window)"
                )
            return
        if not self._tx_first_us <= echo <= self._tx_last_us or self._tx_first_us == 0:
            raise DelayError(f"echoed timestamp {echo} us was not sent on this connection")
        age_us = now_us - echo
        if age_us > self._max_rtt_us:
            raise DelayError(
                f"echoed timestamp is {age_us / 1e6:.3f} s old "
                f"(limit {self._max_rtt_us / 1e6:.3f} s)"
            )

    def _authenticate(self, raw: bytes, frame: Frame) -> None:
        if frame.mac is None:
            if self._require_auth:
                raise AuthenticationError("frame is not authenticated; authentication required")
            return
        train = self._key_train_id if self._key_train_id is not None else frame.source_id
        key = None if self._keys is None else self._keys.lookup(train, frame.key_id)
        if key is None:
            raise AuthenticationError(f"no key id {frame.key_id} for train {train}")
        verify_mac(key, raw, frame)


@dataclass(slots=True)
class HeldValue:
    """Last accepted value of a periodic message, held until it times out."""

    message: Message | None = None
    received_at_s: float = -math.inf
    valid: bool = False


class PeriodicSupervisor:
    """Timeout counting of one periodic message type (paper 001, section 1.2 (2)).

    ``missed_cycles`` is the number of whole cycles since the last valid new message (or
    since supervision started). More than ``timeout_cycles`` -> timed out: the held value
    becomes invalid and the caller reports a link failure. A valid new message clears it.
    """

    def __init__(self, message_type: MessageType, cycle_s: float, timeout_cycles: int) -> None:
        self.message_type = message_type
        self.cycle_s = cycle_s
        self.timeout_cycles = timeout_cycles
        self.held = HeldValue()
        self.active = False
        self.timed_out = False
        self._since_s = 0.0

    def start(self, now_s: float) -> None:
        self.active = True
        self.timed_out = False
        self._since_s = now_s

    def stop(self) -> None:
        self.active = False

    def accept(self, message: Message, now_s: float) -> None:
        self.held = HeldValue(message, now_s, True)
        self.active = True
        self.timed_out = False
        self._since_s = now_s

    def missed_cycles(self, now_s: float) -> int:
        return max(0, math.floor((now_s - self._since_s) / self.cycle_s))

    def deadline_s(self) -> float:
        """Time at which, without news, the message times out."""
        return self._since_s + (self.timeout_cycles + 1) * self.cycle_s

    def poll(self, now_s: float) -> bool:
        """True exactly once when the message times out at ``now_s``."""
        if not self.active or self.timed_out:
            return False
        if self.missed_cycles(now_s) > self.timeout_cycles:
            self.timed_out = True
            self.held.valid = False
            return True
        return False
