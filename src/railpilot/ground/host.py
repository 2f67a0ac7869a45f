"""The ground's application rules, hosted once: :class:`GroundHost` (no I/O, time passed in).

Whatever carries the ground's frames (the live asyncio server, the co-simulation's radio),
the same rules decide what happens to them:

- **delivery or queueing**: a request for a train goes to its live, registered connection
  at once, else into the train's :class:`~railpilot.link.TrainRecord`, from which the link
  core sends it on the train's next registration; running times (not kept) only to a live
  registered train;
- **persistence before effect**: with a :class:`~railpilot.ground.journal.GroundJournal`,
  each request is committed before it changes or sends anything;
- **undo of a refused request**: a request the train's record refuses (a cancel of a
  session the train was never sent, a command number used twice) is reported for that
  train and leaves no record behind for a train the ground had never heard of; the other
  trains of the request still get it;
- **take-over on re-registration**: a train that registers on a new connection takes its
  deliveries over, and the old connection (a half-dead link the train has given up on) is
  closed;
- **connection sync**: which trains have an open connection, for the dispatch core;
- **command dispatch**: the dispatch core's commands carried out, and a dispatcher's
  operation decided, recorded in the store (or rolled back when the store refuses it).

A transport owns the connections and hands the host their events and the time; the host
tells the transport, through :class:`Transport`, to write out what an endpoint queued
(``flush``) or to close a connection. Each transport keeps its own clock, queue and
sockets; nothing here waits or reads a clock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Generic, Protocol, TypeVar

from railpilot.link import (
    Event,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    LinkError,
    RunningTimes,
    TrainDeregistered,
    TrainRecord,
    TrainRegistered,
)

from .dispatch import (
    CancelTsrOn,
    Command,
    DeliverTsr,
    GroundDispatch,
    KeptCommand,
    Outcome,
    SendRunningTimes,
    command_trains,
    kept_message,
)
from .journal import Apply, GroundJournal, Request, command_request
from .operations import Operation, OperationError
from .store import Snapshot, StoreError


def refuse_keyless(operation: object, keys: KeyStore, keys_from: str) -> None:
    """A named train without a key can never register (authentication on): a delivery
    would wait for it forever, so the whole request is refused (OperationError naming the
    trains; ``keys_from`` says where the keys come from)."""
    keyless = [t for t in getattr(operation, "trains", ()) if keys.active(t) is None]
    if keyless:
        raise OperationError(
            {
                "trains": f"{keyless!r} is not allowed: expected train ids that have a key "
                f"{keys_from}(authentication is on)"
            }
        )


class HostedConnection(Protocol):
    """What the host needs of a transport's connection."""

    @property
    def endpoint(self) -> GroundEndpoint: ...

    @property
    def open(self) -> bool: ...


C = TypeVar("C", bound=HostedConnection)

#: ``note(level, event, fields)``: where a transport logs the host's deliveries
Note = Callable[[int, str, dict[str, object]], None]
#: logging levels of the notes (the standard library's values)
INFO, WARNING = 20, 30


C_contra = TypeVar("C_contra", bound=HostedConnection, contravariant=True)


class Transport(Protocol[C_contra]):
    """What the host asks of the transport that carries its frames."""

    def flush(self, conn: C_contra, now_s: float) -> None:
        """Write out what ``conn``'s endpoint queued and hand its events to the host."""

    def close(self, conn: C_contra, reason: str) -> None:
        """Close ``conn`` (both ends, as the transport closes a connection)."""


class GroundHost(Generic[C]):
    """The ground's application rules for one transport's connections (module docstring).

    ``config`` is the ground endpoints' configuration (its ``not_before_s`` is the replay
    floor of every record the host makes); ``journal`` the store's writer (None: in
    memory only); ``dispatch`` the dispatch core (None: a ground that only delivers what
    it is asked to); ``note``, where each delivery's outcome is logged (None: not logged).
    """

    def __init__(
        self,
        config: GroundConfig,
        transport: Transport[C],
        *,
        journal: GroundJournal | None = None,
        dispatch: GroundDispatch | None = None,
        note: Note | None = None,
    ) -> None:
        self.config = config
        self.transport = transport
        self.journal = journal
        self.dispatch = dispatch
        self.note = note
        #: train id -> its record, shared by every connection's endpoint
        self.records: dict[int, TrainRecord] = {}
        #: registered train id -> its current connection
        self.live: dict[int, C] = {}

    # ------------------------------------------------------------------ records

    def restore(self, snapshot: Snapshot, now_s: float) -> dict[str, int]:
        """Rebuild the train records from the store; returns what was taken back."""
        assert self.journal is not None
        self.records, summary = self.journal.restore(snapshot, self.config.not_before_s, now_s)
        return summary

    # ------------------------------------------------------------------ delivery

    def deliver(self, train_id: int, request: Request, apply: Apply, now_s: float) -> str:
        """Run ``apply(endpoint_or_record, now_s)`` on the train's live endpoint, else on its
        record; returns the outcome. Raises :class:`LinkError` (refused: no record is left
        for a train the ground had not heard of) or :class:`StoreError` (not committed:
        nothing changed, nothing sent)."""
        if self.journal is not None:
            self.journal.commit_request(self.records.get(train_id), train_id, request, apply, now_s)
        conn = self.live.get(train_id)
        if conn is not None and conn.open and conn.endpoint.train_id == train_id:
            apply(conn.endpoint, now_s)
            self.transport.flush(conn, now_s)
            outcome = "sending"
        else:
            record = self.records.get(train_id)
            created = record is None
            if record is None:
                record = self.records[train_id] = TrainRecord(train_id)
                record.history.not_before_us = round(self.config.not_before_s * 1e6)
            try:
                apply(record, now_s)
            except LinkError:
                if created:  # a refused request must not invent a train
                    del self.records[train_id]
                raise
            outcome = "queued until the train registers"
        if self.note is not None:
            self.note(INFO, request.action, {"train": train_id, "outcome": outcome})
        return outcome

    def deliver_each(
        self, train_ids: Iterable[int], request: Request, apply: Apply, now_s: float
    ) -> dict[int, str]:
        """:meth:`deliver` to every train; a refusal for one does not stop the others."""
        results: dict[int, str] = {}
        for train_id in train_ids:
            try:
                results[train_id] = self.deliver(train_id, request, apply, now_s)
            except (LinkError, StoreError) as exc:
                results[train_id] = f"error: {exc}"
                if self.note is not None:
                    self.note(
                        WARNING, f"{request.action}_refused", {"train": train_id, "error": exc}
                    )
        return results

    def send_running_times(
        self, train_ids: Iterable[int], times: RunningTimes, now_s: float
    ) -> dict[int, str]:
        """Running times now to each train registered on an open connection; they are not
        acknowledged and not kept (the dispatch core sends a train its last ones when it
        registers)."""
        results: dict[int, str] = {}
        for train_id in train_ids:
            conn = self.live.get(train_id)
            if conn is not None and conn.open and conn.endpoint.holds_registration:
                conn.endpoint.send(times, now_s)
                self.transport.flush(conn, now_s)
                results[train_id] = "sent"
            else:
                results[train_id] = "not sent: the train is not registered"
        return results

    def carry_out(self, commands: Iterable[Command], now_s: float) -> dict[int, str]:
        """Carry out the dispatch core's commands, in order; the outcome per train."""
        results: dict[int, str] = {}
        for command in commands:
            results |= self.carry_out_for(command, command_trains(command), now_s)
        return results

    def carry_out_for(
        self, command: Command, train_ids: Iterable[int], now_s: float
    ) -> dict[int, str]:
        """Carry out ``command`` for ``train_ids`` (a batch of its trains)."""
        if isinstance(command, SendRunningTimes):
            return self.send_running_times(train_ids, command.times, now_s)

        def apply(dest: GroundEndpoint | TrainRecord, at_s: float) -> None:
            apply_command(dest, command, at_s)

        return self.deliver_each(train_ids, command_request(command), apply, now_s)

    # ------------------------------------------------------------------ connections

    def on_event(self, conn: C, event: Event, now_s: float) -> list[Command]:
        """One event of ``conn``'s endpoint: take-over on registration, the live map on
        deregistration, then the dispatch core's commands (to :meth:`carry_out`)."""
        if isinstance(event, TrainRegistered):
            old = self.live.get(event.train_id)
            if old is not None and old is not conn:
                self.transport.close(old, "train registered on a new connection")
            self.live[event.train_id] = conn
        elif isinstance(event, TrainDeregistered) and self.live.get(event.train_id) is conn:
            del self.live[event.train_id]
        if self.dispatch is None:
            return []
        return self.dispatch.on_event(conn.endpoint.train_id, event, now_s)

    def closed(self, conn: C, train_id: int | None) -> None:
        """``conn`` (of ``train_id``, if known) is closed: it is no train's connection."""
        if train_id is not None and self.live.get(train_id) is conn:
            del self.live[train_id]

    def sync(self, open_train_ids: Iterable[int]) -> None:
        """What raises no event: which trains have an open connection now."""
        if self.dispatch is None:
            return
        open_now = set(open_train_ids)
        for train_id in self.dispatch.registry.train_ids():
            self.dispatch.connection(train_id, train_id in open_now)

    # ------------------------------------------------------------------ the dispatcher

    def operate(self, operation: Operation, actor: str, now_s: float) -> Outcome:
        """A dispatcher's operation: the core decides, what it changed on the line goes to
        the store, and the outcome's commands are the transport's to :meth:`carry_out`.
        Raises :class:`OperationError` (nothing done: a refusal of the store rolls the
        core back, since what is not stored is not in force either)."""
        assert self.dispatch is not None
        checkpoint = self.dispatch.checkpoint()
        outcome = self.dispatch.execute(operation, actor, now_s)
        if self.journal is not None:
            try:
                self.journal.record_operation(operation, outcome.result, actor, now_s)
            except StoreError as exc:
                self.dispatch.roll_back(checkpoint)
                raise OperationError({"form": f"the store refused it: {exc}"}) from None
        return outcome


def apply_command(dest: GroundEndpoint | TrainRecord, command: KeptCommand, now_s: float) -> None:
    """Carry out ``command`` on a train's live endpoint (sent now) or on its record (sent
    on its next registration)."""
    if isinstance(dest, GroundEndpoint):
        if isinstance(command, DeliverTsr):
            dest.set_tsr(command.tsr.message, now_s)
        elif isinstance(command, CancelTsrOn):
            dest.cancel_tsr(command.session, now_s)
        else:
            dest.deliver(kept_message(command), now_s)
    elif isinstance(command, DeliverTsr):
        dest.add_tsr(command.tsr.message)
    elif isinstance(command, CancelTsrOn):
        dest.cancel_tsr(command.session)
    else:
        dest.add(kept_message(command))


__all__ = ["GroundHost", "HostedConnection", "Transport", "apply_command"]
