"""What the onboard and ground endpoints share: bytes in, events out, time passed in.

An adapter drives an endpoint like this (no I/O and no clock inside)::

    conn.connection_made(now_s)
    loop:
        conn.receive_data(bytes_from_socket, now_s)   # on every read
        conn.tick(now_s)                              # on a timer, e.g. every 50-100 ms
        socket.write(conn.data_to_send())
        for event in conn.events(): app.handle(event)
        if any LinkFailed event: close the socket
    conn.connection_lost(now_s)

``now_s`` is the local clock in seconds since the Unix epoch (``time.time()`` in
production, a fake clock in tests); it must not go backwards by much, since frame
timestamps are derived from it.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Iterator, Mapping
from enum import Enum
from typing import TypeVar

from .errors import FrameError, LocalProtocolError, StateError
from .events import (
    REJECTION_BY_CHECK,
    Event,
    LinkFailed,
    MessageReceived,
    PeriodicTimedOut,
    SequenceGap,
)
from .frame import Frame
from .framing import FrameDecoder
from .messages import Heartbeat, Message, MessageType
from .safety import HeldValue, LinkCounters, PeriodicSupervisor, SecureChannel

S = TypeVar("S", bound=Enum)
T = TypeVar("T", bound=Enum)

_PEEK = struct.Struct(">BBHBHIIIQ")  # header up to the timestamp, for rejection events


def transition(table: Mapping[tuple[S, T], S], state: S, trigger: T, *, remote: bool) -> S:
    """Look ``(state, trigger)`` up in a transition table.

    A missing entry is a protocol error: :class:`StateError` (the frame is rejected) when
    the peer caused it, :class:`LocalProtocolError` when our application did.
    """
    new_state = table.get((state, trigger))
    if new_state is None:
        if remote:
            raise StateError(f"{trigger.name} not allowed in state {state.name}")
        raise LocalProtocolError(f"{trigger.name} not allowed in state {state.name}")
    return new_state


class Endpoint:
    """Shared machinery of :class:`OnboardEndpoint` and :class:`GroundEndpoint`."""

    _channel: SecureChannel

    def __init__(
        self, cycle_s: float, max_frame_length: int, max_consecutive_rejections: int
    ) -> None:
        self.counters = LinkCounters()
        # Frames rejected in a row on this connection; at the limit the peer is taken for
        # not speaking the protocol (random bytes, a flood) and the link fails.
        self._max_consecutive_rejections = max_consecutive_rejections
        self._consecutive_rejections = 0
        self._decoder = FrameDecoder(max_frame_length)
        self._events: deque[Event] = deque()
        self._outgoing: list[bytes] = []
        self._connected = False
        self._cycle_s = cycle_s
        self._next_heartbeat_s = 0.0
        # Newest periodic message per type within one receive cycle (paper 1.2 (1)).
        self._pool: dict[MessageType, tuple[int, Event]] = {}
        self._supervisors: dict[MessageType, PeriodicSupervisor] = {}

    # --- public API ---------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self._connected

    def receive_data(self, data: bytes, now_s: float) -> None:
        """Feed bytes read from the connection. Any split of the byte stream is fine.

        One call is one receive cycle: of several periodic messages of one type in it,
        only the newest is delivered.
        """
        if not self._connected:
            raise LocalProtocolError("receive_data() called while not connected")
        for item in self._decoder.feed(data):
            if isinstance(item, FrameError):
                self._reject(item, None, now_s)
            else:
                self._receive_frame(item, now_s)
        self.counters.bytes_discarded = self._decoder.bytes_discarded
        if self._pool:
            for _, event in self._pool.values():
                self._events.append(event)
            self._pool.clear()

    def next_event(self) -> Event | None:
        """The oldest pending event, or ``None``."""
        return self._events.popleft() if self._events else None

    def events(self) -> Iterator[Event]:
        """Drain the pending events, oldest first."""
        while self._events:
            yield self._events.popleft()

    def data_to_send(self) -> bytes:
        """Bytes to write to the connection now (empty when there are none)."""
        if not self._outgoing:
            return b""
        data = b"".join(self._outgoing)
        self._outgoing.clear()
        return data

    def tick(self, now_s: float) -> None:
        """Advance the timers: heartbeats, periodic sends, timeouts, resends, expiries."""
        if self._connected and self._link_usable():
            # The ground learns who its peer is from the first frame; until then it has
            # nobody to address a heartbeat to.
            if now_s >= self._next_heartbeat_s and self._channel.peer_id is not None:
                self._send_heartbeat(now_s)
            # Every message that has timed out by now is reported (its held value made
            # invalid), then the link fails once. The onboard sends its RUNNING_INFO with its
            # HEARTBEAT, so both time out at the same instant; stopping at the first would
            # leave the other's held value valid on a failed link.
            failed: PeriodicSupervisor | None = None
            for supervisor in self._supervisors.values():
                if supervisor.poll(now_s):
                    self.counters.timeouts += 1
                    self._events.append(
                        PeriodicTimedOut(supervisor.message_type, supervisor.missed_cycles(now_s))
                    )
                    if failed is None:
                        failed = supervisor
            if failed is not None:
                self._fail(f"{failed.message_type.name} timed out", now_s)
        self._tick(now_s)

    def next_deadline_s(self) -> float | None:
        """Latest time by which :meth:`tick` should be called next (``None``: no timer)."""
        if not self._connected:
            return self._extra_deadline_s()
        # no heartbeat is sent before the peer is known (tick() could not act on it)
        earliest = self._next_heartbeat_s if self._channel.peer_id is not None else None
        for supervisor in self._supervisors.values():
            if supervisor.active and not supervisor.timed_out:
                deadline = supervisor.deadline_s()
                if earliest is None or deadline < earliest:
                    earliest = deadline
        extra = self._extra_deadline_s()
        if extra is not None and (earliest is None or extra < earliest):
            earliest = extra
        return earliest

    def held_value(self, message_type: MessageType) -> HeldValue | None:
        """Last accepted value of a supervised periodic message, with its validity."""
        supervisor = self._supervisors.get(message_type)
        return None if supervisor is None else supervisor.held

    # --- for subclasses -----------------------------------------------------------------------

    def _link_usable(self) -> bool:
        raise NotImplementedError

    def _tick(self, now_s: float) -> None:
        raise NotImplementedError

    def _extra_deadline_s(self) -> float | None:
        return None

    def _on_message(self, frame: Frame, message: Message, now_s: float) -> None:
        raise NotImplementedError

    def _on_failure(self, now_s: float) -> None:
        raise NotImplementedError

    def _queue(self, message: Message, now_s: float) -> None:
        self._outgoing.append(self._channel.encode(message, now_s))

    def _send_heartbeat(self, now_s: float) -> None:
        self._next_heartbeat_s = now_s + self._cycle_s
        self._queue(Heartbeat(), now_s)

    def _start_connection(self, now_s: float) -> None:
        self._connected = True
        self._decoder.reset()
        self._outgoing.clear()
        self._pool.clear()
        self._channel.new_connection(now_s)
        self._consecutive_rejections = 0
        self._next_heartbeat_s = now_s

    def _stop_connection(self) -> None:
        self._connected = False
        self._decoder.reset()
        self._outgoing.clear()
        for supervisor in self._supervisors.values():
            supervisor.stop()

    def _fail(self, reason: str, now_s: float) -> None:
        self.counters.link_failures += 1
        self._on_failure(now_s)
        self._events.append(LinkFailed(reason))

    def _deliver_data(self, frame: Frame, message: Message) -> None:
        event = MessageReceived(message, frame.source_id, frame.timestamp_us)
        if message.PERIODIC:
            previous = self._pool.get(message.TYPE)
            if previous is not None:
                self.counters.superseded += 1
                if previous[0] > frame.timestamp_us:  # cannot happen after the checks
                    return
            self._pool[message.TYPE] = (frame.timestamp_us, event)
        else:
            self._events.append(event)

    # --- receive path ---------------------------------------------------------------------------

    def _receive_frame(self, raw: bytes, now_s: float) -> None:
        self.counters.frames_received += 1
        try:
            frame, message, lost = self._channel.receive(raw, now_s)
        except FrameError as exc:
            self._reject(exc, raw, now_s)
            return
        if lost:
            self.counters.sequence_gaps += 1
            self.counters.frames_lost += lost
            self._events.append(SequenceGap(frame.sequence - lost, frame.sequence, lost))
        try:
            self._on_message(frame, message, now_s)
        except StateError as exc:
            self._reject(exc, raw, now_s)
            return
        self.counters.frames_accepted += 1
        self._consecutive_rejections = 0
        # IntEnum keys hash like their int codes, so the raw code finds them.
        supervisor = self._supervisors.get(frame.message_type)  # type: ignore[call-overload]
        if supervisor is not None and not supervisor.timed_out:
            supervisor.accept(message, now_s)

    def _reject(self, exc: FrameError, raw: bytes | None, now_s: float) -> None:
        self.counters.rejected[exc.check] += 1
        mtype = src = seq = None
        if raw is not None and len(raw) >= _PEEK.size:
            _, _, _, mtype, _, src, _, seq, _ = _PEEK.unpack_from(raw)
        self._events.append(REJECTION_BY_CHECK[exc.check](exc.detail, mtype, src, seq))
        self._consecutive_rejections += 1
        if (
            self._consecutive_rejections == self._max_consecutive_rejections
            and self._connected
            and self._link_usable()
        ):
            # Every frame rejected, many times over: not a peer on a noisy link (which gets
            # most frames through) but something that does not speak the protocol.
            self._fail(
                f"{self._consecutive_rejections} frames in a row rejected: the peer is not "
                "speaking the protocol",
                now_s,
            )
