"""The ground endpoint (TCP server side): one per accepted connection.

Three state machines, each with ONE transition table in this file:

* :data:`TRANSITIONS` - the connection/registration state of the train on this
  connection;
* :data:`TSR_TRANSITIONS` - delivery of one TSR session (set, acknowledge, cancel);
* :data:`DELIVERY_TRANSITIONS` - delivery of one kept message (``Message.KIND``: a
  dispatch command, a target point ...), whatever its kind.

What must survive reconnects (pending deliveries, replay-protection timestamps, the last
running info) lives in a :class:`TrainRecord` per train, in a mapping the server owns and
passes to every endpoint. A TSR issued while the train is offline waits there.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, field
from enum import Enum

from .config import GroundConfig
from .endpoint import Endpoint, transition
from .errors import LocalProtocolError, StateError
from .events import (
    DeliveryAcknowledged,
    DispatchAcknowledged,
    Event,
    TargetPointAcknowledged,
    TrainDeregistered,
    TrainRegistered,
    TsrAcknowledged,
    TsrCancelAcknowledged,
    TsrRefusedByTrain,
)
from .frame import Frame
from .keys import KeyStore
from .messages import (
    ANSWERS,
    KEPT_KINDS,
    DeregisterRequest,
    DeregisterResponse,
    DispatchAck,
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
    TimeCheck,
    TimeOffsetReport,
    TsrCancel,
    TsrCancelAck,
    TsrSet,
    TsrSetAck,
    TsrSetResult,
    key_of,
)
from .safety import HeldValue, PeerHistory, PeriodicSupervisor, SecureChannel

# --- connection / registration ---------------------------------------------------------------


class GroundState(Enum):
    AWAITING_REGISTRATION = "awaiting registration"  # connected, train not (yet) managed
    REGISTERED = "registered"  # managed: running info accepted, deliveries sent
    DEREGISTERED = "deregistered"  # train said goodbye; may register again
    FAILED = "failed"  # a periodic message timed out; waiting for the adapter to close
    CLOSED = "closed"  # connection gone; the endpoint is finished


class GroundInput(Enum):
    LINK_FAILURE = "link failure"  # a periodic timeout (tick) or a rejection flood
    CONNECTION_LOST = "connection lost"  # adapter
    SEND = "send"  # application sends an unacknowledged message
    RECV_REGISTER_ACCEPTED = "register (accepted)"
    RECV_REGISTER_REFUSED = "register (refused)"
    RECV_DEREGISTER = "deregister"
    RECV_DATA = "data"  # running info, planned curve, offset report
    RECV_ACK = "acknowledgement"  # of a TSR set/cancel, target point or dispatch command
    RECV_HEARTBEAT = "heartbeat"


_G = GroundState
_GI = GroundInput
_LIVE = (_G.AWAITING_REGISTRATION, _G.REGISTERED, _G.DEREGISTERED)

#: The ground connection state machine: (state, input) -> next state.
TRANSITIONS: Mapping[tuple[GroundState, GroundInput], GroundState] = {
    (_G.AWAITING_REGISTRATION, _GI.RECV_REGISTER_ACCEPTED): _G.REGISTERED,
    (_G.AWAITING_REGISTRATION, _GI.RECV_REGISTER_REFUSED): _G.AWAITING_REGISTRATION,
    (_G.AWAITING_REGISTRATION, _GI.RECV_DEREGISTER): _G.DEREGISTERED,  # confirm anyway
    (_G.REGISTERED, _GI.RECV_REGISTER_ACCEPTED): _G.REGISTERED,  # our response was lost
    (_G.REGISTERED, _GI.RECV_DEREGISTER): _G.DEREGISTERED,
    (_G.REGISTERED, _GI.RECV_DATA): _G.REGISTERED,
    (_G.REGISTERED, _GI.RECV_ACK): _G.REGISTERED,
    (_G.REGISTERED, _GI.SEND): _G.REGISTERED,
    # an acknowledgement answers our own request: one that crossed the train's
    # DEREGISTER_REQUEST still closes the delivery (else it would show pending forever)
    (_G.DEREGISTERED, _GI.RECV_ACK): _G.DEREGISTERED,
    (_G.DEREGISTERED, _GI.RECV_DEREGISTER): _G.DEREGISTERED,  # our confirmation was lost
    (_G.DEREGISTERED, _GI.RECV_REGISTER_ACCEPTED): _G.REGISTERED,
    (_G.DEREGISTERED, _GI.RECV_REGISTER_REFUSED): _G.DEREGISTERED,
    **{(s, _GI.RECV_HEARTBEAT): s for s in _LIVE},
    **{(s, _GI.LINK_FAILURE): _G.FAILED for s in _LIVE},
    **{(s, _GI.CONNECTION_LOST): _G.CLOSED for s in (*_LIVE, _G.FAILED)},
}


# --- TSR delivery ----------------------------------------------------------------------------


class TsrState(Enum):
    PENDING_SET = "pending set"  # TsrSet resent every resend interval until acknowledged
    ACTIVE = "active"  # train confirmed it applied the TSR
    RECONFIRMING = "reconfirming"  # train re-registered: TsrSet resent until confirmed again
    PENDING_CANCEL = "pending cancel"  # TsrCancel resent until acknowledged
    CANCELLED = "cancelled"
    REFUSED = "refused"  # the train found it implausible or expired
    EXPIRED = "expired"  # validity ended on the ground clock; nothing more is sent


class TsrInput(Enum):
    ACK_APPLIED = "set ack (applied)"
    ACK_REFUSED = "set ack (refused)"
    CANCEL_REQUESTED = "cancel requested"  # application
    CANCEL_ACK = "cancel ack"
    REREGISTERED = "train registered again"
    VALIDITY_ENDED = "validity ended"


_T = TsrState
_TI = TsrInput
_TSR_FINAL = (_T.CANCELLED, _T.REFUSED, _T.EXPIRED)

#: TSR session delivery: (state, input) -> next state.
TSR_TRANSITIONS: Mapping[tuple[TsrState, TsrInput], TsrState] = {
    (_T.PENDING_SET, _TI.ACK_APPLIED): _T.ACTIVE,
    (_T.PENDING_SET, _TI.ACK_REFUSED): _T.REFUSED,
    (_T.PENDING_SET, _TI.CANCEL_REQUESTED): _T.PENDING_CANCEL,
    (_T.PENDING_SET, _TI.REREGISTERED): _T.PENDING_SET,
    (_T.PENDING_SET, _TI.VALIDITY_ENDED): _T.EXPIRED,
    (_T.ACTIVE, _TI.ACK_APPLIED): _T.ACTIVE,  # duplicate acknowledgement
    # A late answer to a resend that reached the train after the TSR expired there; the
    # train confirmed it earlier and would have re-registered had it lost it.
    (_T.ACTIVE, _TI.ACK_REFUSED): _T.ACTIVE,
    (_T.ACTIVE, _TI.CANCEL_REQUESTED): _T.PENDING_CANCEL,
    (_T.ACTIVE, _TI.REREGISTERED): _T.RECONFIRMING,  # the train may have restarted
    (_T.ACTIVE, _TI.VALIDITY_ENDED): _T.EXPIRED,
    (_T.RECONFIRMING, _TI.ACK_APPLIED): _T.ACTIVE,
    (_T.RECONFIRMING, _TI.ACK_REFUSED): _T.REFUSED,
    (_T.RECONFIRMING, _TI.CANCEL_REQUESTED): _T.PENDING_CANCEL,
    (_T.RECONFIRMING, _TI.REREGISTERED): _T.RECONFIRMING,
    (_T.RECONFIRMING, _TI.VALIDITY_ENDED): _T.EXPIRED,
    (_T.PENDING_CANCEL, _TI.CANCEL_ACK): _T.CANCELLED,
    (_T.PENDING_CANCEL, _TI.ACK_APPLIED): _T.PENDING_CANCEL,  # late set ack
    (_T.PENDING_CANCEL, _TI.ACK_REFUSED): _T.PENDING_CANCEL,
    (_T.PENDING_CANCEL, _TI.REREGISTERED): _T.PENDING_CANCEL,
    (_T.PENDING_CANCEL, _TI.VALIDITY_ENDED): _T.PENDING_CANCEL,  # a cancel is harmless
    # Late duplicates after the end are tolerated, nothing else is.
    **{(s, i): s for s in _TSR_FINAL for i in (_TI.ACK_APPLIED, _TI.ACK_REFUSED, _TI.CANCEL_ACK)},
    **{(s, _TI.REREGISTERED): s for s in _TSR_FINAL},
    **{(s, _TI.VALIDITY_ENDED): s for s in _TSR_FINAL},
}

_TSR_SENDS_SET = (_T.PENDING_SET, _T.RECONFIRMING)
#: states in which a TSR delivery is (re)sent: its TsrSet, or its TsrCancel
_TSR_SENDS = (*_TSR_SENDS_SET, _T.PENDING_CANCEL)


# --- delivery of a kept message (dispatch command, target point ...) ----------------------


class DeliveryState(Enum):
    PENDING = "pending"  # resent every resend interval until acknowledged
    ACKNOWLEDGED = "acknowledged"


class DeliveryInput(Enum):
    ACK = "ack"
    REREGISTERED = "train registered again"


#: Delivery of a kept message: (state, input) -> next state.
DELIVERY_TRANSITIONS: Mapping[tuple[DeliveryState, DeliveryInput], DeliveryState] = {
    (DeliveryState.PENDING, DeliveryInput.ACK): DeliveryState.ACKNOWLEDGED,
    (DeliveryState.PENDING, DeliveryInput.REREGISTERED): DeliveryState.PENDING,
    (DeliveryState.ACKNOWLEDGED, DeliveryInput.ACK): DeliveryState.ACKNOWLEDGED,
    (DeliveryState.ACKNOWLEDGED, DeliveryInput.REREGISTERED): DeliveryState.ACKNOWLEDGED,
}


@dataclass(slots=True)
class TsrDelivery:
    tsr: TsrSet
    state: TsrState = TsrState.PENDING_SET
    next_send_s: float = 0.0


@dataclass(slots=True)
class Delivery:
    """One kept message (``Message.KIND``) to one train and where its delivery stands."""

    message: Message
    state: DeliveryState = DeliveryState.PENDING
    next_send_s: float = 0.0


@dataclass(slots=True)
class TrainRecord:
    """Everything the ground keeps about one train across connections."""

    train_id: int
    #: The train's last registration stands: set by an accepted REGISTER_REQUEST, cleared
    #: only by a DEREGISTER_REQUEST on the connection that holds the registration.
    registered: bool = False
    #: ``GroundEndpoint.serial`` of the connection on which the registration was accepted
    #: (it stays after that connection closed: no other connection holds it then).
    registered_on: int | None = None
    registration: RegisterRequest | None = None
    history: PeerHistory = field(default_factory=PeerHistory)
    tsrs: dict[int, TsrDelivery] = field(default_factory=dict)
    #: kind (``Message.KIND``) -> key -> delivery: every kept message the train was sent,
    #: a book per kind of :data:`~railpilot.link.messages.KEPT_KINDS` (an empty one for a
    #: kind not given), in that order.
    books: dict[str, dict[int, Delivery]] = field(default_factory=dict)
    running_info: HeldValue = field(default_factory=HeldValue)
    #: Onboard clock minus ground clock from the last TIME_OFFSET_REPORT [s].
    time_offset_s: float | None = None
    #: The kept messages not yet acknowledged, by kind and key: the part of the books
    #: the resend scans look at. Why: the books keep every one ever sent (a train is sent
    #: dozens of target points a day), an acknowledged one never changes again, and the
    #: scans run on every frame. Kept by the methods below and by ``GroundEndpoint``;
    #: built from the books a record is made with. ``{"target_point": {id: delivery}, ...}``.
    unacknowledged: dict[str, dict[int, Delivery]] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        unknown = set(self.books) - set(KEPT_KINDS)
        if unknown:
            raise LocalProtocolError(
                f"books {sorted(unknown)} are not kept kinds: expected {', '.join(KEPT_KINDS)}"
            )
        self.books = {kind: self.books.get(kind, {}) for kind in KEPT_KINDS}
        self.unacknowledged = {
            kind: {i: d for i, d in book.items() if d.state is DeliveryState.PENDING}
            for kind, book in self.books.items()
        }

    @property
    def target_points(self) -> dict[int, Delivery]:
        return self.books["target_point"]

    @property
    def dispatch_commands(self) -> dict[int, Delivery]:
        return self.books["dispatch_command"]

    def delivery_books(self) -> tuple[tuple[str, dict[int, Delivery]], ...]:
        """``(kind, book)`` of every kept kind, in :data:`KEPT_KINDS` order."""
        return tuple(self.books.items())

    # The server may call these for a train that is offline; the next connection of the
    # train delivers them after registration.

    def add_tsr(self, tsr: TsrSet) -> None:
        """Queue a TSR (idempotent for the same TSR; a reused session number is an error)."""
        existing = self.tsrs.get(tsr.session)
        if existing is not None:
            if existing.tsr != tsr:
                raise LocalProtocolError(
                    f"TSR session {tsr.session} already used for a different restriction"
                )
            return
        self.tsrs[tsr.session] = TsrDelivery(tsr)

    def cancel_tsr(self, session: int) -> None:
        """Queue the cancellation of a TSR session."""
        delivery = self.tsrs.get(session)
        if delivery is None:
            raise LocalProtocolError(f"TSR session {session} was never set for this train")
        delivery.state = transition(
            TSR_TRANSITIONS, delivery.state, _TI.CANCEL_REQUESTED, remote=False
        )
        delivery.next_send_s = 0.0

    def add(self, message: Message) -> None:
        """Queue a kept message: one of ``REPLACES`` kind replaces the one under its key
        (a target point), of any other kind its key must not be used yet."""
        kind = message.KIND
        if kind not in self.books:
            raise LocalProtocolError(
                f"{type(message).__name__} is not kept: expected one of "
                f"{', '.join(cls.__name__ for cls in KEPT_KINDS.values())}"
            )
        ident = key_of(message)
        if not message.REPLACES and ident in self.books[kind]:
            raise LocalProtocolError(f"{kind.replace('_', ' ')} {ident} already queued")
        delivery = self.books[kind][ident] = Delivery(message)
        self.unacknowledged[kind][ident] = delivery

    def add_target_point(self, target: TargetPoint) -> None:
        """Queue a target point; a new one under the same id replaces the old."""
        self.add(target)

    def add_dispatch_command(self, command: DispatchCommand) -> None:
        """Queue a dispatch command (command numbers are used once)."""
        self.add(command)


_ENDPOINT_SERIALS = itertools.count(1)


class GroundEndpoint(Endpoint):
    """Protocol core of the ground front server for one connection (one train).

    Parameters
    ----------
    config
        Ground identity and timers.
    keys
        Per-train keys (required when ``config.require_auth``).
    records
        The server's ``train id -> TrainRecord`` mapping, shared by all connections so
        pending deliveries and replay protection survive reconnects. A private one is
        used when omitted.
    """

    def __init__(
        self,
        config: GroundConfig,
        keys: KeyStore | None = None,
        records: MutableMapping[int, TrainRecord] | None = None,
    ) -> None:
        timers = config.timers
        super().__init__(timers.cycle_s, config.max_frame_length, timers.max_consecutive_rejections)
        self.config = config
        #: Identifies this connection in ``TrainRecord.registered_on``.
        self.serial = next(_ENDPOINT_SERIALS)
        self.records: MutableMapping[int, TrainRecord] = records if records is not None else {}
        self.state = GroundState.AWAITING_REGISTRATION
        self.train_id: int | None = None
        self._channel = SecureChannel(
            local_id=config.ground_id,
            inbound=LinkDirection.UPLINK,
            keys=keys,
            require_auth=config.require_auth,
            max_round_trip_s=timers.max_round_trip_s,
            max_clock_skew_s=timers.max_clock_skew_s,
            history_for=self._history,
            counters=self.counters,
        )
        self._supervisors = {
            t: PeriodicSupervisor(t, timers.cycle_s, timers.timeout_cycles)
            for t in (MessageType.HEARTBEAT, MessageType.RUNNING_INFO)
        }
        self._next_time_check_s = 0.0

    def _history(self, train_id: int) -> PeerHistory:
        return self.record_for(train_id).history

    def record_for(self, train_id: int) -> TrainRecord:
        """The (shared) record of ``train_id``, created on first use."""
        record = self.records.get(train_id)
        if record is None:
            record = self.records[train_id] = TrainRecord(train_id)
            record.history.not_before_us = round(self.config.not_before_s * 1e6)
        return record

    @property
    def record(self) -> TrainRecord | None:
        """Record of the train on this connection (``None`` before it is known)."""
        return None if self.train_id is None else self.record_for(self.train_id)

    @property
    def holds_registration(self) -> bool:
        """This connection is the one on which the train's standing registration was made.

        Only that connection sends the train's deliveries, and only a DEREGISTER_REQUEST
        on it ends the registration (protocol.md 8.2).
        """
        record = self.record
        return (
            record is not None
            and record.registered
            and record.registered_on == self.serial
            and self.state is GroundState.REGISTERED
        )

    # --- lifecycle (adapter) --------------------------------------------------------------------

    def connection_made(self, now_s: float) -> None:
        """The server accepted a connection; call once."""
        if self._connected or self.state is not GroundState.AWAITING_REGISTRATION:
            raise LocalProtocolError("connection_made() called twice on one ground endpoint")
        self._start_connection(now_s)
        self._supervisors[MessageType.HEARTBEAT].start(now_s)

    def connection_lost(self, now_s: float) -> None:
        """The connection is gone; the endpoint is finished (make a new one next time)."""
        self.state = transition(TRANSITIONS, self.state, _GI.CONNECTION_LOST, remote=False)
        self._stop_connection()

    # --- application API ------------------------------------------------------------------------

    def send(self, message: Message, now_s: float) -> None:
        """Send an unacknowledged message now: StationStops, RunningTimes or TimeCheck."""
        if not isinstance(message, StationStops | RunningTimes | TimeCheck):
            raise LocalProtocolError(
                f"{type(message).__name__} is not sent with send(); use set_tsr(), "
                "cancel_tsr() or deliver()"
            )
        self.state = transition(TRANSITIONS, self.state, _GI.SEND, remote=False)
        self._queue(message, now_s)

    def set_tsr(self, tsr: TsrSet, now_s: float) -> None:
        """Deliver a TSR to this train; resent until acknowledged, also across reconnects."""
        self._require_record().add_tsr(tsr)
        self._pump(now_s)

    def cancel_tsr(self, session: int, now_s: float) -> None:
        """Cancel a TSR session; the cancel is resent until acknowledged."""
        self._require_record().cancel_tsr(session)
        self._pump(now_s)

    def deliver(self, message: Message, now_s: float) -> None:
        """Deliver a kept message (``Message.KIND``); resent until acknowledged, also
        across reconnects (:meth:`TrainRecord.add`)."""
        self._require_record().add(message)
        self._pump(now_s)

    def send_target_point(self, target: TargetPoint, now_s: float) -> None:
        """Deliver a target point (a new one under the same id replaces the old)."""
        self.deliver(target, now_s)

    def send_dispatch_command(self, command: DispatchCommand, now_s: float) -> None:
        """Deliver a dispatch command; resent until acknowledged."""
        self.deliver(command, now_s)

    def tsr_state(self, session: int) -> TsrState | None:
        record = self.record
        delivery = None if record is None else record.tsrs.get(session)
        return None if delivery is None else delivery.state

    def _require_record(self) -> TrainRecord:
        record = self.record
        if record is None:
            raise LocalProtocolError(
                "no train on this connection yet; use a record from `records` or wait for "
                "TrainRegistered"
            )
        return record

    # --- timers ---------------------------------------------------------------------------------

    def _link_usable(self) -> bool:
        return self.state in _LIVE

    def _tick(self, now_s: float) -> None:
        record = self.record
        if record is not None:
            for delivery in record.tsrs.values():
                if now_s >= delivery.tsr.valid_until_s:
                    delivery.state = transition(
                        TSR_TRANSITIONS, delivery.state, _TI.VALIDITY_ENDED, remote=False
                    )
        if self._connected and self.holds_registration:
            if now_s >= self._next_time_check_s:
                self._next_time_check_s = now_s + self.config.timers.time_check_interval_s
                self._queue(TimeCheck(now_s), now_s)
            self._pump(now_s)

    def _extra_deadline_s(self) -> float | None:
        record = self.record
        if not self._connected or not self.holds_registration or record is None:
            return None
        # asked after every step of every connection: one pass, no lists
        earliest = self._next_time_check_s
        for tsr in record.tsrs.values():
            if tsr.state in _TSR_SENDS and tsr.next_send_s < earliest:
                earliest = tsr.next_send_s
        for book in record.unacknowledged.values():
            for delivery in book.values():
                if delivery.state is DeliveryState.PENDING and delivery.next_send_s < earliest:
                    earliest = delivery.next_send_s
        return earliest

    def _pump(self, now_s: float) -> None:
        """Send every pending delivery that is due (only while the train is registered)."""
        record = self.record
        if not self._connected or not self.holds_registration or record is None:
            return
        resend = self.config.timers.resend_interval_s
        for delivery in record.tsrs.values():
            if now_s < delivery.next_send_s:
                continue
            message: Message
            if delivery.state in _TSR_SENDS_SET:
                message = delivery.tsr
            elif delivery.state is TsrState.PENDING_CANCEL:
                message = TsrCancel(delivery.tsr.session)
            else:
                continue
            if delivery.next_send_s:
                self.counters.resends += 1
            delivery.next_send_s = now_s + resend
            self._queue(message, now_s)
        for book in record.unacknowledged.values():
            for item in book.values():
                if item.state is DeliveryState.PENDING and now_s >= item.next_send_s:
                    if item.next_send_s:
                        self.counters.resends += 1
                    item.next_send_s = now_s + resend
                    self._queue(item.message, now_s)

    def _on_failure(self, now_s: float) -> None:
        self.state = transition(TRANSITIONS, self.state, _GI.LINK_FAILURE, remote=False)
        record = self.record
        if record is not None:
            record.running_info.valid = False

    # --- received messages -------------------------------------------------------------------

    def _on_message(self, frame: Frame, message: Message, now_s: float) -> None:
        if self.train_id is None:
            # The first authentic frame binds this connection to its train. Our HEARTBEAT
            # goes out at once: it is the fresh timestamp the train must echo before any
            # frame of it can change state (5.3), so a withheld frame never can.
            self.train_id = frame.source_id
            self._channel.peer_id = frame.source_id
            self._send_heartbeat(now_s)
        if isinstance(message, Heartbeat):
            self.state = transition(TRANSITIONS, self.state, _GI.RECV_HEARTBEAT, remote=True)
        elif isinstance(message, RegisterRequest):
            self._on_register(message, now_s)
        elif isinstance(message, DeregisterRequest):
            holder = self.holds_registration
            self.state = transition(TRANSITIONS, self.state, _GI.RECV_DEREGISTER, remote=True)
            record = self._require_record()
            self._supervisors[MessageType.RUNNING_INFO].stop()
            self._queue(DeregisterResponse(), now_s)
            # Only the connection that holds the registration can end it; on any other
            # connection the request ends only that connection's registration state.
            if holder:
                record.registered = False
                record.registered_on = None
                self._events.append(TrainDeregistered(record.train_id, message.reason))
        else:
            is_ack = type(message) in ANSWERS
            trigger = _GI.RECV_ACK if is_ack else _GI.RECV_DATA
            self.state = transition(TRANSITIONS, self.state, trigger, remote=True)
            self._on_data(frame, message, now_s)

    def _on_register(self, request: RegisterRequest, now_s: float) -> None:
        record = self._require_record()
        allowed = self.config.accepted_trains
        accepted = allowed is None or record.train_id in allowed
        trigger = _GI.RECV_REGISTER_ACCEPTED if accepted else _GI.RECV_REGISTER_REFUSED
        before = self.state
        self.state = transition(TRANSITIONS, self.state, trigger, remote=True)
        if not accepted:
            self._queue(RegisterResponse(RegisterResult.UNKNOWN_TRAIN), now_s)
            return
        self._queue(RegisterResponse(RegisterResult.ACCEPTED), now_s)
        if before is GroundState.REGISTERED:
            return  # a resent request: answer again, change nothing
        record.registered = True
        record.registered_on = self.serial
        record.registration = request
        self._events.append(TrainRegistered(record.train_id, request))
        # Re-deliver everything pending, and have active TSRs confirmed again: the train
        # may have restarted and lost them.
        for delivery in record.tsrs.values():
            delivery.state = transition(
                TSR_TRANSITIONS, delivery.state, _TI.REREGISTERED, remote=False
            )
            delivery.next_send_s = 0.0
        # (an acknowledged target point or dispatch command stays acknowledged)
        for book in record.unacknowledged.values():
            for item in book.values():
                item.state = transition(
                    DELIVERY_TRANSITIONS, item.state, DeliveryInput.REREGISTERED, remote=False
                )
                item.next_send_s = 0.0
        self._next_time_check_s = now_s
        self._tick(now_s)

    def _on_data(self, frame: Frame, message: Message, now_s: float) -> None:
        record = self._require_record()
        if isinstance(message, RunningInfo):
            record.running_info = HeldValue(message, now_s, True)
            self._deliver_data(frame, message)
        elif isinstance(message, TsrSetAck | TsrCancelAck):
            self._on_tsr_ack(record, message)
        elif type(message) in ANSWERS:
            self._on_delivery_ack(record, message)
        elif isinstance(message, TimeOffsetReport):
            record.time_offset_s = message.offset_s
            # onboard minus ground = how far the train's clock is ahead of ours
            self._channel.set_peer_clock_ahead(message.offset_us)
            self._deliver_data(frame, message)
        else:
            assert isinstance(message, PlannedCurve)
            self._deliver_data(frame, message)

    def _on_tsr_ack(self, record: TrainRecord, ack: TsrSetAck | TsrCancelAck) -> None:
        delivery = record.tsrs.get(ack.session)
        if delivery is None:
            raise StateError(f"acknowledgement for TSR session {ack.session} never sent")
        before = delivery.state
        if isinstance(ack, TsrCancelAck):
            trigger = _TI.CANCEL_ACK
        elif ack.result is TsrSetResult.APPLIED:
            trigger = _TI.ACK_APPLIED
        else:
            trigger = _TI.ACK_REFUSED
        delivery.state = transition(TSR_TRANSITIONS, delivery.state, trigger, remote=True)
        after = delivery.state
        if before is after:
            return
        if after is TsrState.ACTIVE and before is TsrState.PENDING_SET:
            self._events.append(TsrAcknowledged(record.train_id, ack.session))
        elif after is TsrState.REFUSED:
            assert isinstance(ack, TsrSetAck)
            self._events.append(TsrRefusedByTrain(record.train_id, ack.session, ack.result))
        elif after is TsrState.CANCELLED:
            assert isinstance(ack, TsrCancelAck)
            self._events.append(TsrCancelAcknowledged(record.train_id, ack.session, ack.result))

    def _on_delivery_ack(self, record: TrainRecord, ack: Message) -> None:
        kind, ident = ANSWERS[type(ack)].KIND, key_of(ack)
        item = record.books[kind].get(ident)
        if item is None:
            raise StateError(f"acknowledgement for {type(ack).__name__} {ident} never sent")
        before = item.state
        item.state = transition(DELIVERY_TRANSITIONS, item.state, DeliveryInput.ACK, remote=True)
        if before is item.state:
            return
        record.unacknowledged[kind].pop(ident, None)
        self._events.append(_acknowledged(record.train_id, kind, ack))


def _acknowledged(train_id: int, kind: str, ack: Message) -> Event:
    """The event of a kept message's first acknowledgement: the kind's own event where it
    has one, else a :class:`DeliveryAcknowledged`."""
    if isinstance(ack, DispatchAck):
        return DispatchAcknowledged(train_id, ack.command_number)
    if isinstance(ack, TargetPointAck):
        return TargetPointAcknowledged(train_id, ack.target_id, ack.result)
    # every acknowledgement carries the train's answer; the Message base declares no field
    return DeliveryAcknowledged(train_id, kind, key_of(ack), getattr(ack, "result"))  # noqa: B009
