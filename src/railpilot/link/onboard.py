"""The onboard endpoint (TCP client side): registration, periodic running info, TSRs.

All of the onboard's protocol state lives in ONE transition table, :data:`TRANSITIONS`;
an input that has no entry for the current state is a protocol error (a ``STATE``
rejection of the frame, or :class:`LocalProtocolError` for a local call).

Per-session TSR bookkeeping (applied once, acknowledged every time) is not a separate
state machine: it is a set membership (active / finished) explained in docs/protocol.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import Enum

from .config import OnboardConfig, reconnect_delay_s
from .endpoint import Endpoint, transition
from .errors import LinkConfigError, LocalProtocolError
from .events import (
    AppliedTsr,
    DeliveryReceived,
    Deregistered,
    DispatchCommandReceived,
    Registered,
    RegistrationRefused,
    TargetPointReceived,
    TimeChecked,
    TsrApplied,
    TsrCancelled,
    TsrExpired,
    TsrRefused,
)
from .frame import Frame
from .keys import KeyStore
from .messages import (
    MESSAGE_CLASSES,
    DeregisterReason,
    DeregisterRequest,
    DeregisterResponse,
    DispatchCommand,
    Heartbeat,
    LinkDirection,
    Message,
    MessageType,
    PlannedCurve,
    RegisterRequest,
    RegisterResponse,
    RegisterResult,
    RunningInfo,
    RunningTimes,
    StationStops,
    TargetPoint,
    TargetPointAck,
    TargetPointResult,
    TimeCheck,
    TimeOffsetReport,
    TravelDirection,
    TsrCancel,
    TsrCancelAck,
    TsrCancelResult,
    TsrSet,
    TsrSetAck,
    TsrSetResult,
    acknowledgement,
    key_of,
)
from .safety import PeerHistory, PeriodicSupervisor, SecureChannel


class OnboardState(Enum):
    DISCONNECTED = "disconnected"  # no connection; the adapter reconnects with backoff
    REGISTERING = "registering"  # connected, RegisterRequest sent, resent until answered
    REGISTERED = "registered"  # ground manages us; running info flows; TSRs accepted
    DEREGISTERING = "deregistering"  # DeregisterRequest sent, resent until confirmed
    DEREGISTERED = "deregistered"  # connected but not managed (shunting, leaving line)
    FAILED = "failed"  # a periodic message timed out; waiting for the adapter to close


class OnboardInput(Enum):
    CONNECTION_MADE = "connection made"  # adapter
    CONNECTION_LOST = "connection lost"  # adapter
    LINK_FAILURE = "link failure"  # ground heartbeat timed out, or a rejection flood
    REGISTER = "register"  # application: register again after deregistering
    DEREGISTER = "deregister"  # application: mode change, shutdown, leaving main line
    SEND = "send"  # application: send a data message (planned curve)
    RECV_REGISTER_ACCEPTED = "register accepted"  # RegisterResponse(ACCEPTED)
    RECV_REGISTER_REFUSED = "register refused"  # RegisterResponse(other)
    RECV_DEREGISTER_CONFIRMED = "deregister confirmed"  # DeregisterResponse
    RECV_DISPATCH = "dispatch data"  # time check, stops, times, target, TSR, command
    RECV_HEARTBEAT = "heartbeat"


_S = OnboardState
_I = OnboardInput
_CONNECTED = (_S.REGISTERING, _S.REGISTERED, _S.DEREGISTERING, _S.DEREGISTERED)

#: The onboard state machine: (state, input) -> next state. Nothing else changes state.
TRANSITIONS: Mapping[tuple[OnboardState, OnboardInput], OnboardState] = {
    (_S.DISCONNECTED, _I.CONNECTION_MADE): _S.REGISTERING,  # register after every connect
    (_S.REGISTERING, _I.RECV_REGISTER_ACCEPTED): _S.REGISTERED,
    (_S.REGISTERING, _I.RECV_REGISTER_REFUSED): _S.REGISTERING,  # retry after resend interval
    (_S.REGISTERING, _I.DEREGISTER): _S.DEREGISTERING,
    (_S.REGISTERED, _I.RECV_REGISTER_ACCEPTED): _S.REGISTERED,  # answer to a resent request
    (_S.REGISTERED, _I.DEREGISTER): _S.DEREGISTERING,
    (_S.REGISTERED, _I.SEND): _S.REGISTERED,
    (_S.REGISTERED, _I.RECV_DISPATCH): _S.REGISTERED,
    # While deregistering, restrictive data (TSR, target points) is still obeyed.
    (_S.DEREGISTERING, _I.RECV_DISPATCH): _S.DEREGISTERING,
    (_S.DEREGISTERING, _I.RECV_REGISTER_ACCEPTED): _S.DEREGISTERING,  # late answer
    (_S.DEREGISTERING, _I.RECV_DEREGISTER_CONFIRMED): _S.DEREGISTERED,
    (_S.DEREGISTERED, _I.RECV_DEREGISTER_CONFIRMED): _S.DEREGISTERED,  # resent confirmation
    (_S.DEREGISTERED, _I.REGISTER): _S.REGISTERING,
    **{(s, _I.RECV_HEARTBEAT): s for s in _CONNECTED},
    **{(s, _I.LINK_FAILURE): _S.FAILED for s in _CONNECTED},
    **{(s, _I.CONNECTION_LOST): _S.DISCONNECTED for s in (*_CONNECTED, _S.FAILED)},
}

#: What the ground sends besides the answers to our requests (and heartbeats).
_DOWNLINK_DATA = frozenset(
    cls.TYPE
    for cls in MESSAGE_CLASSES.values()
    if cls.DIRECTION is LinkDirection.DOWNLINK and cls not in (RegisterResponse, DeregisterResponse)
)


class OnboardEndpoint(Endpoint):
    """Protocol core of one train's onboard unit.

    ``keys`` must hold a key for ``config.train_id`` when ``config.require_auth``.
    The object lives as long as the onboard unit: it keeps TSRs, registration intent and
    replay-protection state across reconnects.
    """

    def __init__(self, config: OnboardConfig, keys: KeyStore | None = None) -> None:
        timers = config.timers
        super().__init__(timers.cycle_s, config.max_frame_length, timers.max_consecutive_rejections)
        if config.require_auth and (keys is None or keys.active(config.train_id) is None):
            raise LinkConfigError(
                "keys", keys, f"a KeyStore with a key for train {config.train_id} (auth required)"
            )
        self.config = config
        self.state = OnboardState.DISCONNECTED
        self._ground_history = PeerHistory()
        self._channel = SecureChannel(
            local_id=config.train_id,
            inbound=LinkDirection.DOWNLINK,
            keys=keys,
            require_auth=config.require_auth,
            max_round_trip_s=timers.max_round_trip_s,
            max_clock_skew_s=timers.max_clock_skew_s,
            history_for=self._history,
            peer_id=config.ground_id,
            key_train_id=config.train_id,
            counters=self.counters,
        )
        self._supervisors = {
            MessageType.HEARTBEAT: PeriodicSupervisor(
                MessageType.HEARTBEAT, timers.cycle_s, timers.timeout_cycles
            )
        }
        self._running_info: RunningInfo | None = None
        self._next_running_info_s = 0.0
        self._next_request_s = 0.0
        # REGISTER/DEREGISTER_REQUEST copies sent on this connection (0: not yet).
        self._requests_sent = 0
        self._deregister_reason: DeregisterReason | None = None
        self.reconnect_attempts = 0
        #: TSRs being enforced, by session number.
        self.active_tsrs: dict[int, AppliedTsr] = {}
        self._finished_tsrs: set[int] = set()  # cancelled or expired: never applied again
        #: Every target point received, by id; the newest id is the one in force.
        self.target_points: dict[int, TargetPoint] = {}
        #: kind -> keys of the kept messages received (``Message.KIND``), target points
        #: aside (``target_points``): each is reported once, acknowledged every time
        self._kept_seen: dict[str, set[int]] = {}
        self.time_offset_s: float | None = None

    def _history(self, peer_id: int) -> PeerHistory:
        return self._ground_history

    @property
    def target_point(self) -> TargetPoint | None:
        """The target point in force: the newest id supersedes every older one (a moved
        target or a clear comes under a fresh id; a resent older one arriving late is
        acknowledged but changes nothing). protocol.md 8.4."""
        return self.target_points[max(self.target_points)] if self.target_points else None

    # --- lifecycle (adapter) --------------------------------------------------------------------

    def connection_made(self, now_s: float) -> None:
        """A TCP connection to the ground is up: start registering.

        The first frame is a HEARTBEAT (echo 0, protocol.md 6.16); REGISTER_REQUEST follows
        as soon as a frame of the ground was accepted, so that it echoes a fresh ground
        timestamp (5.3).
        """
        self.state = transition(TRANSITIONS, self.state, _I.CONNECTION_MADE, remote=False)
        self._start_connection(now_s)
        self._supervisors[MessageType.HEARTBEAT].start(now_s)
        self._send_heartbeat(now_s)
        self._requests_sent = 0
        self._next_request_s = now_s

    def connection_lost(self, now_s: float) -> None:
        """The TCP connection is gone (closed by either side or after LinkFailed)."""
        self.state = transition(TRANSITIONS, self.state, _I.CONNECTION_LOST, remote=False)
        self._stop_connection()

    def reconnect_delay_s(self, random_fraction: float) -> float:
        """Delay before the next connection attempt; counts the attempt.

        ``random_fraction`` in [0, 1) comes from the adapter's seeded generator. The count
        resets when a registration succeeds.
        """
        delay = reconnect_delay_s(self.reconnect_attempts, self.config.timers, random_fraction)
        self.reconnect_attempts += 1
        return delay

    # --- application API ------------------------------------------------------------------------

    def update_running_info(self, info: RunningInfo) -> None:
        """Set the running info sent every cycle while registered (latest value wins)."""
        if not isinstance(info, RunningInfo):
            raise LocalProtocolError(f"expected RunningInfo, got {type(info).__name__}")
        self._running_info = info

    def send(self, message: Message, now_s: float) -> None:
        """Send a data message now (a :class:`PlannedCurve`); only while registered."""
        if not isinstance(message, PlannedCurve):
            raise LocalProtocolError(
                f"{type(message).__name__} is not sent by the application on the onboard"
            )
        self.state = transition(TRANSITIONS, self.state, _I.SEND, remote=False)
        self._queue(message, now_s)

    def deregister(self, reason: DeregisterReason, now_s: float) -> None:
        """Leave the ground's management (shunting mode, shutdown, leaving the main line).

        The DEREGISTER_REQUEST leaves now, or, on a connection where nothing of the ground
        has been accepted yet, as soon as something is (it must echo a ground timestamp).
        """
        self.state = transition(TRANSITIONS, self.state, _I.DEREGISTER, remote=False)
        self._deregister_reason = DeregisterReason(reason)
        self._requests_sent = 0
        self._send_request_now(now_s)

    def register(self, now_s: float) -> None:
        """Register again after a deregistration (the first one is automatic)."""
        self.state = transition(TRANSITIONS, self.state, _I.REGISTER, remote=False)
        self._requests_sent = 0
        self._send_request_now(now_s)

    # --- timers ---------------------------------------------------------------------------------

    def _link_usable(self) -> bool:
        return self.state in _CONNECTED

    def _ground_time_s(self, now_s: float) -> float:
        """The ground's clock as the onboard best knows it [s].

        TSR validity times are the ground's. The offset measured by the last time check
        (onboard minus ground, transmission delay included) is taken off, so a restriction
        is never lifted early by an onboard clock running ahead; the delay in the offset
        only errs on the safe side (lifted a little late). Before the first time check
        the onboard's own clock is used.
        """
        return now_s - (self.time_offset_s or 0.0)

    def _tick(self, now_s: float) -> None:
        ground_now = self._ground_time_s(now_s)
        for session, tsr in list(self.active_tsrs.items()):
            if ground_now >= tsr.valid_until_s:
                del self.active_tsrs[session]
                self._finished_tsrs.add(session)
                self._events.append(TsrExpired(session))
        if not self._connected:
            return
        timers = self.config.timers
        if self.state in (OnboardState.REGISTERING, OnboardState.DEREGISTERING):
            self._send_request_if_due(now_s)
        elif (
            self.state is OnboardState.REGISTERED
            and self._running_info is not None
            and now_s >= self._next_running_info_s
        ):
            self._next_running_info_s = now_s + timers.cycle_s
            if self._next_heartbeat_s != self._next_running_info_s:
                # A RUNNING_INFO travels with a HEARTBEAT. The first one after registering
                # restarts the heartbeat's cycle on its own (a heartbeat early is harmless;
                # the ground counts from the last one): from then on both fall due in the
                # same tick and leave in one write, one packet a cycle instead of two.
                self._send_heartbeat(now_s)
            self._queue(self._running_info, now_s)

    def _extra_deadline_s(self) -> float | None:
        offset = self.time_offset_s or 0.0  # valid_until is ground time: onboard = + offset
        times = [t.valid_until_s + offset for t in self.active_tsrs.values()]
        if (
            self.state in (OnboardState.REGISTERING, OnboardState.DEREGISTERING)
            and self._channel.heard_from_peer
        ):
            times.append(self._next_request_s)
        if self.state is OnboardState.REGISTERED and self._running_info is not None:
            times.append(self._next_running_info_s)
        return min(times) if times else None

    def _on_failure(self, now_s: float) -> None:
        self.state = transition(TRANSITIONS, self.state, _I.LINK_FAILURE, remote=False)

    def _send_request_now(self, now_s: float) -> None:
        self._next_request_s = now_s
        self._send_request_if_due(now_s)

    def _send_request_if_due(self, now_s: float) -> None:
        """Send (or resend) the REGISTER/DEREGISTER_REQUEST of the current state when due.

        Never before a frame of the ground was accepted on this connection: the request
        must echo a fresh ground timestamp, so that a withheld copy is refused later (5.3).
        """
        if not self._connected or not self._channel.heard_from_peer or now_s < self._next_request_s:
            return
        c = self.config
        request: RegisterRequest | DeregisterRequest
        if self.state is OnboardState.REGISTERING:
            request = RegisterRequest(c.train_number, c.loco_number, c.driver_id, c.train_length_m)
        elif self.state is OnboardState.DEREGISTERING:
            assert self._deregister_reason is not None
            request = DeregisterRequest(self._deregister_reason)
        else:
            return
        if self._requests_sent:
            self.counters.resends += 1
        self._requests_sent += 1
        self._queue(request, now_s)
        self._next_request_s = now_s + c.timers.resend_interval_s

    # --- received messages -------------------------------------------------------------------

    def _on_message(self, frame: Frame, message: Message, now_s: float) -> None:
        if isinstance(message, Heartbeat):
            self.state = transition(TRANSITIONS, self.state, _I.RECV_HEARTBEAT, remote=True)
            # the ground's first HEARTBEAT is what a pending request waits for
            self._send_request_if_due(now_s)
        elif isinstance(message, RegisterResponse):
            accepted = message.result is RegisterResult.ACCEPTED
            trigger = _I.RECV_REGISTER_ACCEPTED if accepted else _I.RECV_REGISTER_REFUSED
            before = self.state
            self.state = transition(TRANSITIONS, self.state, trigger, remote=True)
            if accepted and before is OnboardState.REGISTERING:
                self.reconnect_attempts = 0
                self._next_running_info_s = now_s
                self._events.append(Registered())
            elif not accepted:
                self._events.append(RegistrationRefused(message.result))
        elif isinstance(message, DeregisterResponse):
            before = self.state
            self.state = transition(
                TRANSITIONS, self.state, _I.RECV_DEREGISTER_CONFIRMED, remote=True
            )
            if before is OnboardState.DEREGISTERING:
                assert self._deregister_reason is not None
                self._events.append(Deregistered(self._deregister_reason))
        else:
            assert message.TYPE in _DOWNLINK_DATA
            self.state = transition(TRANSITIONS, self.state, _I.RECV_DISPATCH, remote=True)
            self._on_data(frame, message, now_s)

    def _on_data(self, frame: Frame, message: Message, now_s: float) -> None:
        if isinstance(message, TsrSet):
            self._on_tsr_set(message, now_s)
        elif isinstance(message, TsrCancel):
            self._on_tsr_cancel(message, now_s)
        elif isinstance(message, TargetPoint):
            ident = message.target_id
            if self.target_points.get(ident) != message:
                current = self.target_point
                in_force = current is None or ident >= current.target_id
                self.target_points[ident] = message
                if in_force:
                    self._events.append(TargetPointReceived(message))
                # else an older id arriving late (a resend overtaken by a newer one): kept
                # and acknowledged, and it changes nothing (protocol.md 8.4). Reported, it
                # would put back a target the ground has moved or cleared since
            self._queue(TargetPointAck(message.target_id, TargetPointResult.ACCEPTED), now_s)
        elif message.KIND:
            seen = self._kept_seen.setdefault(message.KIND, set())
            if key_of(message) not in seen:
                seen.add(key_of(message))
                self._events.append(
                    DispatchCommandReceived(message)
                    if isinstance(message, DispatchCommand)
                    else DeliveryReceived(message)
                )
            self._queue(acknowledgement(message), now_s)
        elif isinstance(message, TimeCheck):
            # whole us, so the offset sent is exactly onboard time - ground time (6.6)
            report = TimeOffsetReport.from_us(
                round(message.ground_time_s * 1e6), round(now_s * 1e6)
            )
            self.time_offset_s = report.offset_s
            self._channel.set_peer_clock_ahead(-report.offset_us)
            self._events.append(TimeChecked(message.ground_time_s, report.offset_s))
            self._queue(report, now_s)
        else:
            assert isinstance(message, StationStops | RunningTimes)
            self._deliver_data(frame, message)

    def _on_tsr_set(self, tsr: TsrSet, now_s: float) -> None:
        session = tsr.session
        applied = self.active_tsrs.get(session)
        if applied is not None:
            # A resend (our ack was lost): acknowledge again, do not apply twice. A
            # different restriction under the same session number is refused.
            same = (applied.start_m, applied.end_m, applied.limit_mps) == (
                tsr.start_m,
                tsr.end_m,
                tsr.limit_mps,
            ) and (applied.valid_from_s, applied.valid_until_s) == (
                tsr.valid_from_s,
                tsr.valid_until_s,
            )
            result = TsrSetResult.APPLIED if same else TsrSetResult.INVALID
        elif session in self._finished_tsrs:
            result = TsrSetResult.EXPIRED
        elif tsr.start_m == tsr.end_m or tsr.valid_until_s <= tsr.valid_from_s:
            result = TsrSetResult.INVALID
        elif tsr.valid_until_s <= self._ground_time_s(now_s):
            result = TsrSetResult.EXPIRED
        else:
            result = TsrSetResult.APPLIED
            applied = self._extend(tsr)
            self.active_tsrs[session] = applied
            self._events.append(TsrApplied(applied))
        if result is not TsrSetResult.APPLIED and applied is None:
            self._events.append(TsrRefused(session, result))
        self._queue(TsrSetAck(session, result), now_s)

    def _extend(self, tsr: TsrSet) -> AppliedTsr:
        """Extend the zone by one train length so the tail obeys the limit too (2.5)."""
        direction = self._running_info.direction if self._running_info else TravelDirection.UNKNOWN
        return AppliedTsr.of(tsr, self.config.train_length_m, direction)

    def _on_tsr_cancel(self, cancel: TsrCancel, now_s: float) -> None:
        session = cancel.session
        if self.active_tsrs.pop(session, None) is not None:
            self._finished_tsrs.add(session)
            self._events.append(TsrCancelled(session))
            result = TsrCancelResult.CANCELLED
        elif session in self._finished_tsrs:
            result = TsrCancelResult.CANCELLED  # resent cancel: our ack was lost
        else:
            # Cancel overtook (or replaced) a set we never got: remember it so a late set
            # of this session is never applied.
            self._finished_tsrs.add(session)
            result = TsrCancelResult.UNKNOWN_SESSION
        self._queue(TsrCancelAck(session, result), now_s)
