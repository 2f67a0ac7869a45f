"""What the ground commits to its store before anything leaves, and what it takes back
after a restart (docs/ground-store.md): :class:`GroundJournal`.

Transport-free, time passed in, so the live server (net/server.py) and the co-simulation
(cosim/link_sim.py) keep their ground in the store the same way:

- a dispatcher's request for one train (:meth:`GroundJournal.commit_request`) is tried on a
  copy of the train's record first, so the link core refuses it (``LinkError``) exactly as
  it would for real and nothing is written then; what the copy holds is committed with
  the audit entry in one transaction, and only after that may the real record change and
  the frame leave;
- each step of a connection (:meth:`GroundJournal.commit_step`): the delivery states it
  changed and the events the audit log keeps (registrations, acknowledgements), in one
  transaction, before the step's frames leave;
- :meth:`GroundJournal.restore` rebuilds the train records from the store after a restart.

The journal remembers what it last committed per delivery, so a step writes only what
differs (running info, the bulk of the traffic, writes nothing).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from dataclasses import fields as dataclass_fields
from enum import Enum
from typing import Any

from railpilot.link import (
    DeliveryAcknowledged,
    DeliveryState,
    DispatchAcknowledged,
    DispatchCommand,
    Event,
    GroundEndpoint,
    Message,
    TargetPoint,
    TargetPointAcknowledged,
    TrainDeregistered,
    TrainRecord,
    TrainRegistered,
    TsrAcknowledged,
    TsrCancelAcknowledged,
    TsrRefusedByTrain,
    TsrSet,
    TsrState,
)
from railpilot.link.ground import Delivery, TsrDelivery

from .dispatch import (
    CancelTsrOn,
    DeliverMessage,
    DeliverTsr,
    KeptCommand,
    SendTargetPoint,
    restriction_from_view,
    restriction_view,
)
from .operations import CancelTsr, ClearRestriction, Operation, SetRestriction, SetTsr
from .store import AuditEntry, GroundStore, Snapshot
from .targets import DeclaredRestriction

#: ``apply(endpoint_or_record, now_s)``: a request carried out on a train's live endpoint
#: (sent now) or on its record (sent on its next registration).
Apply = Callable[[GroundEndpoint | TrainRecord, float], None]

#: The audit log's name of each event it keeps (TrainRegistered also updates ``trains``);
#: a DeliveryAcknowledged is named after its kind (:func:`audit_name`).
EVENT_NAMES: dict[type, str] = {
    TsrAcknowledged: "tsr_acknowledged",
    TsrCancelAcknowledged: "tsr_cancel_acknowledged",
    TsrRefusedByTrain: "tsr_refused_by_train",
    DispatchAcknowledged: "dispatch_acknowledged",
    TargetPointAcknowledged: "target_point_acknowledged",
    TrainRegistered: "registered",
    TrainDeregistered: "deregistered",
}
_AUDITED = (*EVENT_NAMES, DeliveryAcknowledged)


def audit_name(event: Event) -> str:
    """The audit log's (and the server log's) name of an event it keeps."""
    if isinstance(event, DeliveryAcknowledged):
        return f"{event.kind}_acknowledged"
    return EVENT_NAMES[type(event)]


#: ((kind, train id, id), (state, message) now, (state, message) committed or None)
_Change = tuple[tuple[str, int, int], tuple[Enum, Any], tuple[Enum, Any] | None]


@dataclass(frozen=True, slots=True)
class Request:
    """A dispatcher's request as the store keeps it."""

    action: str  # the audit log's (and the server log's) event name
    actor: str
    detail: dict[str, Any]
    reason: str = ""  # TSR reason (tsr_set)
    cancels: int | None = None  # TSR session (tsr_cancel)


def tsr_set_request(tsr: TsrSet, actor: str, reason: str = "") -> Request:
    detail = {
        "session": tsr.session,
        "start_m": tsr.start_m,
        "end_m": tsr.end_m,
        "limit_mps": tsr.limit_mps,
        "valid_from_s": tsr.valid_from_s,
        "valid_until_s": tsr.valid_until_s,
        "reason": reason,
    }
    return Request("tsr_set", actor, detail, reason)


def tsr_cancel_request(session: int, actor: str) -> Request:
    return Request("tsr_cancel", actor, {"session": session}, cancels=session)


def kept_request(message: Message, actor: str) -> Request:
    """The request to deliver a kept message (``Message.KIND``): named after its kind, its
    fields as the detail (enums by name)."""
    detail = {f.name: getattr(message, f.name) for f in dataclass_fields(message)}
    return Request(message.KIND, actor, {k: getattr(v, "name", v) for k, v in detail.items()})


def target_point_request(target: TargetPoint, actor: str) -> Request:
    return kept_request(target, actor)


def dispatch_request(command: DispatchCommand, actor: str) -> Request:
    return Request("dispatch", actor, {"command": command.command_number, "text": command.text})


def command_request(command: KeptCommand) -> Request:
    """The request the store keeps for one of the dispatch core's commands."""
    if isinstance(command, DeliverTsr):
        tsr = command.tsr
        return tsr_set_request(tsr.message, tsr.set_by or "ground", tsr.reason)
    if isinstance(command, CancelTsrOn):
        return tsr_cancel_request(command.session, command.actor)
    if isinstance(command, SendTargetPoint):
        return target_point_request(command.target, command.actor)
    if isinstance(command, DeliverMessage):
        return kept_request(command.message, command.actor)
    return dispatch_request(command.command, command.actor)


def declared_restrictions(audit_log: Iterable[AuditEntry]) -> dict[int, DeclaredRestriction]:
    """The dispatcher's declared restrictions still in force, replayed from the audit log
    (:meth:`GroundJournal.record_operation` wrote them before their target points left)."""
    restrictions: dict[int, DeclaredRestriction] = {}
    for entry in audit_log:
        if entry.action == "restriction_set":
            restrictions[int(entry.detail["id"])] = restriction_from_view(entry.detail)
        elif entry.action == "restriction_clear":
            restrictions.pop(int(entry.detail["id"]), None)
    return restrictions


class GroundJournal:
    """The ground's writes to ``store`` and its restore from it (module docstring). The
    caller opens and closes the store; a :class:`~railpilot.ground.store.StoreError`
    from a commit means nothing of it was written."""

    def __init__(self, store: GroundStore) -> None:
        self.store = store
        #: (kind, train id, id) -> (state, message) as last committed: what a step
        #: changed is what differs from it.
        self._stored: dict[tuple[str, int, int], tuple[Enum, Any]] = {}
        #: (kind, train id) -> how many target points (dispatch commands) of the train
        #: are committed, and the ids of those committed in a state that may still change
        #: (not acknowledged). Why: a train's books keep every one it was ever sent, and
        #: a step is committed for every frame; an acknowledged one never changes again,
        #: so a step looks only at these, at the record's unacknowledged ones and, if
        #: the book holds more than was committed, at the whole book.
        self._committed: Counter[tuple[str, int]] = Counter()
        self._unsettled: dict[tuple[str, int], set[int]] = {}

    def record_operation(
        self, operation: Operation, result: Mapping[str, Any], actor: str, now_s: float
    ) -> None:
        """What a dispatcher's operation changed on the line, before any of its deliveries
        leave: a TSR set or cancelled (also one that concerns no train yet: without this,
        a restart would forget it before any train got it), a declared restriction set or
        cleared (in the audit log; :func:`declared_restrictions` replays them)."""
        store = self.store
        if isinstance(operation, SetTsr):
            tsr = operation.line_tsr(int(result["session"]), actor)
            store.record_tsr(tsr.message, actor=actor, reason=tsr.reason, at_s=now_s)
        elif isinstance(operation, CancelTsr):
            store.record_tsr_cancel(operation.session, actor=actor, at_s=now_s)
        elif isinstance(operation, SetRestriction | ClearRestriction):
            detail: dict[str, Any] = {"id": result["id"]}
            if isinstance(operation, SetRestriction):
                action = "restriction_set"
                detail |= restriction_view(operation.restriction)
            else:
                action = "restriction_clear"
            store.audit(action, actor=actor, at_s=now_s, detail=detail)

    def restore(
        self, snapshot: Snapshot, not_before_s: float, now_s: float
    ) -> tuple[dict[int, TrainRecord], dict[str, int]]:
        """The train records rebuilt from ``snapshot`` (final states included, never
        resent), and a summary (trains, TSRs, deliveries by state) also written to the
        audit log as ``restored``: where a restart shows in it.

        Every delivery gets ``next_send_s = 0``: the core sends what is pending as soon as
        the train registers, and (seeing a registration) turns each ACTIVE TSR into
        RECONFIRMING, so the train confirms it still enforces it - the train may have lost
        it while the ground was down. A TSR the train still holds is acknowledged again,
        never applied twice (the onboard applies a session once).
        """
        self._stored.clear()
        self._committed.clear()
        self._unsettled.clear()
        not_before_us = round(not_before_s * 1e6)
        counts: Counter[str] = Counter()
        records: dict[int, TrainRecord] = {}
        for stored in snapshot.trains.values():
            train_id = stored.train_id
            tsrs = {s: TsrDelivery(snapshot.tsrs[s].tsr, st) for s, st in stored.tsrs.items()}
            counts.update(st.name for st in stored.tsrs.values())
            self._remember((("tsr", train_id, s), (d.state, d.tsr), None) for s, d in tsrs.items())
            books: dict[str, dict[int, Delivery]] = {}
            for kind, items in stored.deliveries.items():
                books[kind] = {i: Delivery(message, st) for i, (message, st) in items.items()}
                counts.update(st.name for _, st in items.values())
                self._remember(
                    ((kind, train_id, i), (st, message), None) for i, (message, st) in items.items()
                )
            # made from its books, the record indexes their unacknowledged deliveries
            record = TrainRecord(train_id, registration=stored.registration, tsrs=tsrs, books=books)
            record.history.not_before_us = not_before_us
            records[train_id] = record
        summary = {
            "trains": len(snapshot.trains),
            "tsrs": len(snapshot.tsrs),
            **{state.lower(): n for state, n in sorted(counts.items())},
        }
        self.store.audit("restored", actor="ground", at_s=now_s, detail=summary)
        return records, summary

    def commit_request(
        self,
        existing: TrainRecord | None,
        train_id: int,
        request: Request,
        apply: Apply,
        now_s: float,
    ) -> None:
        """Commit a dispatcher's request for one train before anything else happens
        (module docstring); ``existing`` is the train's record, if it has one."""
        scratch = _scratch(existing if existing is not None else TrainRecord(train_id))
        apply(scratch, now_s)
        changes = self._changes(scratch)
        store = self.store
        with store.transaction():
            self._write_changes(train_id, changes, now_s, request.actor, request.reason)
            if request.cancels is not None:
                store.record_tsr_cancel(request.cancels, actor=request.actor, at_s=now_s)
            store.audit(
                request.action,
                actor=request.actor,
                at_s=now_s,
                train_id=train_id,
                detail=request.detail,
            )
        self._remember(changes)

    def commit_step(self, record: TrainRecord | None, events: list[Event], now_s: float) -> None:
        """Commit what one step of a connection changed: ``record``'s delivery states
        and the audited ``events`` (the cause, an acknowledgement, before its effect)."""
        changes = self._changes(record) if record is not None else []
        noted = [e for e in events if isinstance(e, _AUDITED)]
        if not changes and not noted:
            return
        store = self.store
        with store.transaction():
            for event in noted:
                self._audit_event(event, now_s)
            if record is not None:
                self._write_changes(record.train_id, changes, now_s, "ground", "")
            for key, (state, _), before in changes:
                if before is not None and before[0] is not state:
                    store.audit(
                        "delivery_state",
                        actor="ground",
                        at_s=now_s,
                        train_id=key[1],
                        detail={
                            "kind": key[0],
                            "id": key[2],
                            "from": before[0].name,
                            "to": state.name,
                        },
                    )
        self._remember(changes)

    def _audit_event(self, event: Event, now_s: float) -> None:
        values = {f.name: getattr(event, f.name) for f in dataclass_fields(event)}
        train_id = values.pop("train_id")
        if isinstance(event, TrainRegistered):
            self.store.record_registration(train_id, event.request, at_s=now_s)
            request = event.request
            values = {f.name: getattr(request, f.name) for f in dataclass_fields(request)}
        detail = {k: getattr(v, "name", v) for k, v in values.items()}  # enums by name
        self.store.audit(
            audit_name(event),
            actor=f"train {train_id}",
            at_s=now_s,
            train_id=train_id,
            detail=detail,
        )

    def _changes(self, record: TrainRecord) -> list[_Change]:
        """Deliveries of ``record`` whose state or message differ from what was committed."""
        train_id = record.train_id
        out: list[_Change] = []
        stored = self._stored
        for ident, tsr in record.tsrs.items():  # a handful a day: all of them
            key = ("tsr", train_id, ident)
            value: tuple[Enum, Any] = (tsr.state, tsr.tsr)
            before = stored.get(key)
            if before != value:
                out.append((key, value, before))
        for kind, book in record.delivery_books():
            if len(book) == self._committed[kind, train_id]:
                # nothing new: only what may still change (see __init__)
                unsettled = self._unsettled.get((kind, train_id))
                pending = record.unacknowledged[kind]
                if not unsettled and not pending:
                    continue  # the common case: every delivery settled
                idents: Iterable[int] = sorted((unsettled or set()).union(pending))
            else:
                idents = book
            for ident in idents:
                item = book.get(ident)
                if item is None:
                    continue
                key = (kind, train_id, ident)
                value = (item.state, item.message)
                before = stored.get(key)
                if before != value:
                    out.append((key, value, before))
        return out

    def _remember(self, changes: Iterable[_Change]) -> None:
        """``changes`` are committed: what a later step compares with."""
        for key, value, _ in changes:
            kind, train_id, ident = key
            if kind != "tsr":
                if key not in self._stored:
                    self._committed[kind, train_id] += 1
                unsettled = self._unsettled.setdefault((kind, train_id), set())
                if value[0] is DeliveryState.ACKNOWLEDGED:
                    unsettled.discard(ident)
                else:
                    unsettled.add(ident)
            self._stored[key] = value

    def _write_changes(
        self, train_id: int, changes: list[_Change], now_s: float, actor: str, reason: str
    ) -> None:
        store = self.store
        for (kind, _, ident), (state, message), before in changes:
            if isinstance(state, TsrState):
                if before is None or before[1] != message:
                    # idempotent: a TSR already recorded keeps its first actor and reason
                    store.record_tsr(message, actor=actor, reason=reason, at_s=now_s)
                store.record_tsr_state(train_id, ident, state, at_s=now_s)
            elif not isinstance(state, DeliveryState):
                raise TypeError(f"{kind} {ident}: {state!r} is not a delivery state")
            elif before is not None and before[1] == message:
                store.record_delivery_state(train_id, type(message), ident, state, at_s=now_s)
            else:
                store.record_delivery(train_id, message, state, at_s=now_s)


def _scratch(record: TrainRecord) -> TrainRecord:
    """A copy of the delivery books of ``record`` to try a request on (the record methods
    touch nothing else). The TSRs are copied one by one (a cancellation changes one);
    the kept messages' books share their deliveries, because a request only adds to
    those books (and they hold every one the train was ever sent)."""
    return TrainRecord(
        record.train_id,
        tsrs={s: replace(d) for s, d in record.tsrs.items()},
        books={kind: dict(book) for kind, book in record.books.items()},
    )
