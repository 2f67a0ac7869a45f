"""What the ground must not lose: TSRs, deliveries and their state, an audit log - the part
of the ground store every backend shares.

One store per ground server. :class:`~railpilot.ground.store.Store` is the embedded
default, SQLite (a file, or ``":memory:"`` for tests);
:class:`~railpilot.ground.store_postgres.PostgresStore` is the same store on a PostgreSQL
server, for a dispatch centre. :func:`~railpilot.ground.store.open_store` picks one from
``ground serve --db``. The server writes to it *before* a frame leaves (DESIGN habit
14, persistence before effect) and rebuilds its train records from
:meth:`GroundStore.load` when it starts, so after ``kill -9`` every pending delivery is
resent and every active TSR can still be cancelled. docs/ground-store.md has the schema,
the write points and how to inspect a database.

The interface is small and speaks the link's own types (:class:`~railpilot.link.TsrSet`,
:class:`~railpilot.link.TsrState` ...), never SQL:

* :meth:`GroundStore.record_tsr` - a line-level TSR as the dispatcher set it (once per
  session);
* :meth:`GroundStore.record_tsr_state` - one train's delivery state of a TSR session;
* :meth:`GroundStore.record_tsr_cancel` - the dispatcher asked to cancel a session;
* :meth:`GroundStore.record_delivery` / :meth:`GroundStore.record_delivery_state` - the
  kept messages (``Message.KIND``: target points, dispatch commands ...) per train, all
  kinds in one table;
* :meth:`GroundStore.record_registration` - a train's last registration (so ``all`` still
  names it after a restart);
* :meth:`GroundStore.audit` - an append-only log entry (time, actor, action, train, detail);
* :meth:`GroundStore.transaction` - several of the above atomically (each one alone is
  atomic);
* :meth:`GroundStore.load` - everything needed to rebuild the server's train records.

All of that - validation, SQL, transactions, the snapshot - lives once, in
:class:`GroundStore`. A backend only supplies what must differ: the connection, how a
statement is run (placeholders), column types in the schema, how to begin a transaction,
the names already in the database, and its durability settings. The shared SQL is
written so that it is safe with several processes on one database (PostgreSQL): every
check-then-write is one statement (``ON CONFLICT``, ``UPDATE ... WHERE``) that the
database evaluates against the latest committed row.

SQLite durability: WAL journal with ``synchronous=FULL``. In WAL mode ``NORMAL`` already
survives ``kill -9`` of the process (the WAL lives in the OS page cache), but after a
power loss it may roll back the last commits; the ground may by then have sent the frame
those commits announced, and a train enforcing a TSR the ground no longer knows cannot
be cancelled. ``FULL`` makes every commit durable before the call returns, at one fsync
per transaction. ``synchronous="NORMAL"`` is accepted for benchmarks and tests.

Every time is passed in (``at_s``, seconds since the epoch on the ground clock): the store
reads no clock.
"""

from __future__ import annotations

import json
import math
import re
from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, contextmanager, suppress
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from enum import Enum
from pathlib import Path
from typing import Any, ClassVar, Final, Protocol, Self, TypeVar, get_type_hints

from railpilot.errors import RailpilotError
from railpilot.link import (
    KEPT_KINDS,
    DeliveryState,
    DispatchCommand,
    Message,
    MessageFieldError,
    RegisterRequest,
    TargetPoint,
    TargetReason,
    TsrSet,
    TsrState,
)
from railpilot.units import mps_to_kmh

#: ``railpilot ground serve`` keeps its store here unless told otherwise (``--db``).
DEFAULT_PATH: Final = "ground.db"
MEMORY: Final = ":memory:"
#: ``--db`` values that name a PostgreSQL server (libpq's URL schemes); anything else is
#: a SQLite file.
POSTGRES_SCHEMES: Final = ("postgresql://", "postgres://")
#: The schema this code writes; a database with a newer one is refused, an older one
#: migrated (:meth:`GroundStore._migrate`).
SCHEMA_VERSION: Final = 2
SYNCHRONOUS: Final = ("FULL", "NORMAL")

_U32_MAX = 0xFFFF_FFFF
_MAX_ACTOR = 64
_MAX_REASON = 200
_MAX_ACTION = 64

E = TypeVar("E", bound=Enum)

# Every kept message (Message.KIND: target points, dispatch commands ...) sent to a train,
# by kind and key; ``message`` holds its fields as a JSON object (enums by name).
_DELIVERIES = """
CREATE TABLE deliveries (
    train_id     {int} NOT NULL,
    kind         TEXT NOT NULL,
    ident        {int} NOT NULL,
    message      TEXT NOT NULL,
    state        TEXT NOT NULL,
    updated_at_s {real} NOT NULL,
    PRIMARY KEY (train_id, kind, ident)
)"""

# One schema for every backend; {int}, {real} and {seq_key} are the column types that must
# differ (ids up to 2^32-1 need PostgreSQL's BIGINT, its REAL is a float4, and the audit
# sequence is AUTOINCREMENT in SQLite, an identity column in PostgreSQL).
_SCHEMA = """
CREATE TABLE schema_version (
    version {int} NOT NULL
);
-- A TSR as the dispatcher set it: one row per session number, line-wide.
CREATE TABLE tsrs (
    session        {int} PRIMARY KEY,
    start_m        {real} NOT NULL,
    end_m          {real} NOT NULL,
    limit_mps      {real} NOT NULL,
    valid_from_s   {real} NOT NULL,
    valid_until_s  {real} NOT NULL,
    reason         TEXT NOT NULL,
    actor          TEXT NOT NULL,
    set_at_s       {real} NOT NULL,
    cancelled_at_s {real},
    cancelled_by   TEXT
);
-- Its delivery to one train (docs/protocol.md 8.3: TsrState names).
CREATE TABLE tsr_deliveries (
    train_id     {int} NOT NULL,
    session      {int} NOT NULL REFERENCES tsrs (session),
    state        TEXT NOT NULL,
    updated_at_s {real} NOT NULL,
    PRIMARY KEY (train_id, session)
);
{deliveries};
-- The last accepted registration of each train.
CREATE TABLE trains (
    train_id        {int} PRIMARY KEY,
    train_number    TEXT NOT NULL,
    loco_number     TEXT NOT NULL,
    driver_id       {int} NOT NULL,
    train_length_m  {real} NOT NULL,
    registered_at_s {real} NOT NULL
);
-- Append-only: nothing ever updates or deletes a row.
CREATE TABLE audit (
    seq      {seq_key},
    at_s     {real} NOT NULL,
    actor    TEXT NOT NULL,
    action   TEXT NOT NULL,
    train_id {int},
    detail   TEXT NOT NULL
);
CREATE INDEX audit_by_train ON audit (train_id, seq);
"""


class StoreError(RailpilotError):
    """The store refused a value or could not use its database; nothing was written.

    A refused value is named as ``field = value is not allowed: expected ...``.
    """

    what_next: Final = "nothing was written"

    def __init__(
        self, message: str, field: str | None = None, value: Any = None, allowed: str = ""
    ) -> None:
        #: For a refused value: which, what it was, what is allowed (else None, None, "").
        self.field, self.value, self.allowed = field, value, allowed
        super().__init__(f"{message}; {self.what_next}")


def _refuse(field: str, value: Any, allowed: str) -> StoreError:
    return StoreError(
        f"{field} = {value!r} is not allowed: expected {allowed}", field, value, allowed
    )


# --- what load() returns ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class StoredTsr:
    """A line-level TSR as the dispatcher set it."""

    tsr: TsrSet
    actor: str
    reason: str
    set_at_s: float
    cancelled_at_s: float | None = None
    cancelled_by: str | None = None


@dataclass(frozen=True, slots=True)
class StoredTrain:
    """What the store holds about one train: enough to rebuild its ``TrainRecord``."""

    train_id: int
    registration: RegisterRequest | None
    registered_at_s: float | None
    #: session -> delivery state (the restriction itself is ``Snapshot.tsrs[session]``)
    tsrs: Mapping[int, TsrState]
    #: kind (``Message.KIND``) -> key -> (message, delivery state), for every kept kind
    deliveries: Mapping[str, Mapping[int, tuple[Message, DeliveryState]]]

    @property
    def target_points(self) -> Mapping[int, tuple[TargetPoint, DeliveryState]]:
        return self.deliveries["target_point"]  # type: ignore[return-value]

    @property
    def dispatch_commands(self) -> Mapping[int, tuple[DispatchCommand, DeliveryState]]:
        return self.deliveries["dispatch_command"]  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """Everything :meth:`GroundStore.load` found, final states included.

    Final states (a TSR cancelled, refused or expired; a delivery acknowledged) are kept:
    the core never resends them, and with them a restarted ground answers a repeated
    request exactly as the one that stopped would have (a session number stays used).
    """

    tsrs: Mapping[int, StoredTsr]
    trains: Mapping[int, StoredTrain]


@dataclass(frozen=True, slots=True)
class AuditEntry:
    seq: int
    at_s: float
    actor: str
    action: str
    train_id: int | None
    detail: Mapping[str, Any]


# --- the store: everything both backends share -------------------------------------------


class Cursor(Protocol):
    """What the shared code needs of a backend's cursor (sqlite3's and psycopg's have it)."""

    @property
    def rowcount(self) -> int: ...

    def fetchall(self) -> Sequence[Any]: ...


class GroundStore(ABC):
    """The ground store: the interface the server uses, and all the logic behind it.

    A backend (:class:`Store` for SQLite, ``PostgresStore``) opens the connection, sets
    the class attributes below, implements the abstract methods, and calls
    :meth:`_migrate` once connected. Single-threaded, like the server's event loop that
    owns it. Each ``record_*`` / :meth:`audit` call is one transaction unless made inside
    :meth:`transaction`.
    """

    #: The constructor argument a refusal names ("path" for SQLite, "db" for PostgreSQL).
    _FIELD: ClassVar[str]
    #: The statement that starts a writing transaction, and a reading one (load()).
    _BEGIN_WRITE: ClassVar[str]
    _BEGIN_READ: ClassVar[str]
    #: The column types the schema template leaves open: int, real, seq_key.
    _COLUMN_TYPES: ClassVar[Mapping[str, str]]
    #: The backend's errors: each becomes a StoreError naming the database.
    _DB_ERRORS: ClassVar[tuple[type[Exception], ...]]

    def __init__(self, path: str) -> None:
        #: Where the store is, as status and logs show it (never a password).
        self.path = path
        self._depth = 0

    # --- what a backend supplies ---------------------------------------------------------

    @abstractmethod
    def _execute(self, sql: str, params: Sequence[Any] = ()) -> Cursor:
        """Run one statement written with ``?`` placeholders; raises the backend's errors."""

    @abstractmethod
    def _object_names(self) -> set[str]:
        """Names of the tables (and other objects) already in the store's database."""

    @abstractmethod
    def close(self) -> None: ...

    def _begin(self, sql: str) -> None:
        """Start an outermost transaction (PostgreSQL reconnects here if it must)."""
        self._execute(sql)

    def _lock_schema(self) -> None:  # noqa: B027 - a hook; doing nothing is the default
        """Keep other processes from creating the schema at the same time (inside
        :meth:`_migrate`'s transaction); SQLite's ``BEGIN IMMEDIATE`` already does."""

    # --- schema ----------------------------------------------------------------------------

    def _migrate(self) -> None:
        with self.transaction():
            self._lock_schema()
            names = self._object_names()
            if "schema_version" not in names:
                if names:
                    raise _refuse(
                        self._FIELD,
                        self.path,
                        "a railpilot ground store (this database has other tables)",
                    )
                # one statement at a time: sqlite3's executescript() would COMMIT our BEGIN
                deliveries = _DELIVERIES.format(**self._COLUMN_TYPES)
                for statement in _SCHEMA.format(**self._COLUMN_TYPES, deliveries=deliveries).split(
                    ";"
                ):
                    if statement.strip():
                        self._write(statement)
                self._write("INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,))
                return
            ((version,),) = self._read("SELECT max(version) FROM schema_version")
            if version is None or version > SCHEMA_VERSION:
                raise _refuse(
                    "schema_version",
                    version,
                    f"at most {SCHEMA_VERSION} (the database was written by a newer railpilot)",
                )
            # version < SCHEMA_VERSION: one step per version
            if version < 2:
                self._migrate_to_deliveries()

    def _migrate_to_deliveries(self) -> None:
        """Schema 1 -> 2: the target points and dispatch commands move from a table each
        into ``deliveries``, each row as the message it holds."""
        self._write(_DELIVERIES.format(**self._COLUMN_TYPES))
        rows: list[tuple[int, Message, str, float]] = [
            (train, TargetPoint(ident, position_m, _enum(TargetReason, reason, "reason")), st, at)
            for train, ident, position_m, reason, st, at in self._read(
                "SELECT train_id, target_id, position_m, reason, state, updated_at_s "
                "FROM target_points"
            )
        ]
        rows += [
            (train, DispatchCommand(ident, text), st, at)
            for train, ident, text, st, at in self._read(
                "SELECT train_id, command_number, text, state, updated_at_s FROM dispatch_commands"
            )
        ]
        for train_id, message, state, at_s in rows:
            self._write(
                "INSERT INTO deliveries (train_id, kind, ident, message, state, updated_at_s) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (train_id, message.KIND, _key(message), _message_json(message), state, at_s),
            )
        self._write("DROP TABLE target_points")
        self._write("DROP TABLE dispatch_commands")
        self._write("INSERT INTO schema_version (version) VALUES (?)", (2,))

    # --- lifecycle ---------------------------------------------------------------------------

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        return int(self._read("SELECT max(version) FROM schema_version")[0][0])

    def transaction(self) -> AbstractContextManager[None]:
        """Everything inside commits together or not at all.

        Nested use is a savepoint: an exception leaving the inner block undoes only the
        inner block's writes (the outer block decides about the rest).
        """
        return self._transaction(self._BEGIN_WRITE)

    @contextmanager
    def _transaction(self, begin: str) -> Iterator[None]:
        depth = self._depth
        try:
            if depth == 0:
                self._begin(begin)
            else:
                self._execute(f"SAVEPOINT s{depth}")
        except self._DB_ERRORS as exc:
            raise StoreError(f"cannot start a transaction on {self.path} ({exc})") from None
        self._depth = depth + 1
        try:
            yield
        except BaseException:
            self._depth = depth
            # A lost connection cannot roll back either; the exception that got us here
            # is the one to report (the database discards the open transaction itself).
            with suppress(*self._DB_ERRORS):
                if depth == 0:
                    self._execute("ROLLBACK")
                else:
                    self._execute(f"ROLLBACK TO s{depth}")
                    self._execute(f"RELEASE s{depth}")
            raise
        self._depth = depth
        try:
            self._execute("COMMIT" if depth == 0 else f"RELEASE s{depth}")
        except self._DB_ERRORS as exc:
            if depth == 0:  # SQLite keeps a transaction whose COMMIT failed open
                with suppress(*self._DB_ERRORS):
                    self._execute("ROLLBACK")
            raise StoreError(f"cannot commit to {self.path} ({exc})") from None

    def _write(self, sql: str, params: Sequence[Any] = ()) -> Cursor:
        try:
            return self._execute(sql, params)
        except self._DB_ERRORS as exc:
            raise StoreError(f"cannot write to {self.path} ({exc})") from None

    def _read(self, sql: str, params: Sequence[Any] = ()) -> Sequence[Any]:
        try:
            return self._execute(sql, params).fetchall()
        except self._DB_ERRORS as exc:
            raise StoreError(f"cannot read {self.path} ({exc})") from None

    # --- writes ------------------------------------------------------------------------------

    def record_tsr(self, tsr: TsrSet, *, actor: str, reason: str = "", at_s: float) -> None:
        """Keep a line-level TSR as the dispatcher set it.

        Idempotent for the same restriction (the first actor, reason and time stay); a
        session number already used for a different restriction is refused: the trains
        tell TSRs apart by session alone.
        """
        _check_type("tsr", tsr, TsrSet, "a TsrSet")
        _check_text("actor", actor, _MAX_ACTOR, empty=False)
        _check_text("reason", reason, _MAX_REASON, empty=True)
        _check_time("at_s", at_s)
        with self.transaction():
            # Insert first, compare after: an INSERT of a session another process is
            # inserting waits for it, and the SELECT after it sees the row that won.
            inserted = self._write(
                "INSERT INTO tsrs (session, start_m, end_m, limit_mps, valid_from_s, "
                "valid_until_s, reason, actor, set_at_s) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?) "
                "ON CONFLICT (session) DO NOTHING",
                (
                    tsr.session,
                    tsr.start_m,
                    tsr.end_m,
                    tsr.limit_mps,
                    tsr.valid_from_s,
                    tsr.valid_until_s,
                    reason,
                    actor,
                    at_s,
                ),
            ).rowcount
            if inserted:
                return
            existing = self._tsr(tsr.session)
            if existing is None:  # only a hand-edited database gets here
                raise StoreError(f"cannot write to {self.path} (session {tsr.session} vanished)")
            held, by = existing
            if held != tsr:
                raise _refuse(
                    "tsr.session",
                    tsr.session,
                    f"a session not used yet (it holds {_describe(held)}, set by {by})",
                )

    def record_tsr_cancel(self, session: int, *, actor: str, at_s: float) -> None:
        """Mark a line-level TSR cancelled by ``actor`` (the first cancel's time stays)."""
        _check_id("session", session)
        _check_text("actor", actor, _MAX_ACTOR, empty=False)
        _check_time("at_s", at_s)
        with self.transaction():
            self._require_tsr(session)
            self._write(
                "UPDATE tsrs SET cancelled_at_s = ?, cancelled_by = ? "
                "WHERE session = ? AND cancelled_at_s IS NULL",
                (at_s, actor, session),
            )

    def record_tsr_state(
        self, train_id: int, session: int, state: TsrState, *, at_s: float
    ) -> None:
        """Set (or create) one train's delivery state of a recorded TSR session."""
        _check_id("train_id", train_id)
        _check_id("session", session)
        _check_type("state", state, TsrState, f"a TsrState ({_names(TsrState)})")
        _check_time("at_s", at_s)
        with self.transaction():
            self._require_tsr(session)
            self._write(
                "INSERT INTO tsr_deliveries (train_id, session, state, updated_at_s) "
                "VALUES (?, ?, ?, ?) ON CONFLICT (train_id, session) DO UPDATE SET "
                "state = excluded.state, updated_at_s = excluded.updated_at_s",
                (train_id, session, state.name, at_s),
            )

    def record_delivery(
        self, train_id: int, message: Message, state: DeliveryState, *, at_s: float
    ) -> None:
        """Keep a kept message (``Message.KIND``: a target point, a dispatch command ...)
        for a train, with its delivery state.

        One of a ``REPLACES`` kind replaces the one under its key (a target point, as the
        core does); of any other kind a key names one message for good (a dispatch
        command number: a different text is refused).
        """
        _check_id("train_id", train_id)
        _check_type("state", state, DeliveryState, f"a DeliveryState ({_names(DeliveryState)})")
        _check_time("at_s", at_s)
        if not isinstance(message, Message) or message.KIND not in KEPT_KINDS:
            raise _refuse("message", message, " or ".join(f"a {c}" for c in _kept_names()))
        ident = _key(message)
        params = (train_id, message.KIND, ident, _message_json(message), state.name, at_s)
        upsert = (
            "INSERT INTO deliveries (train_id, kind, ident, message, state, updated_at_s) "
            "VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (train_id, kind, ident) DO UPDATE SET "
        )
        with self.transaction():
            if message.REPLACES:
                self._write(
                    upsert + "message = excluded.message, state = excluded.state, "
                    "updated_at_s = excluded.updated_at_s",
                    params,
                )
                return
            # The message check is the upsert's own WHERE: no row written means the key
            # holds another message (also when another process just wrote it).
            written = self._write(
                upsert + "state = excluded.state, updated_at_s = excluded.updated_at_s "
                "WHERE deliveries.message = excluded.message",
                params,
            ).rowcount
            if not written:
                raise _refuse(
                    f"message.{message.KEY}",
                    ident,
                    f"a {message.KEY.replace('_', ' ')} not used yet for train {train_id}",
                )

    def record_delivery_state(
        self,
        train_id: int,
        kind: type[Message],
        ident: int,
        state: DeliveryState,
        *,
        at_s: float,
    ) -> None:
        """Update the state of a recorded kept message (``kind``: its class)."""
        _check_id("train_id", train_id)
        _check_type("state", state, DeliveryState, f"a DeliveryState ({_names(DeliveryState)})")
        _check_time("at_s", at_s)
        if kind not in KEPT_KINDS.values():
            raise _refuse("kind", kind, " or ".join(_kept_names()))
        if type(ident) is not int or not 0 <= ident <= _U32_MAX:
            raise _refuse("ident", ident, f"an integer in [0, {_U32_MAX}]")
        with self.transaction():
            cursor = self._write(
                "UPDATE deliveries SET state = ?, updated_at_s = ? "
                "WHERE train_id = ? AND kind = ? AND ident = ?",
                (state.name, at_s, train_id, kind.KIND, ident),
            )
            if cursor.rowcount == 0:
                raise _refuse(
                    "ident", ident, f"a {kind.__name__} recorded for train {train_id} first"
                )

    def record_registration(self, train_id: int, request: RegisterRequest, *, at_s: float) -> None:
        """Keep a train's last accepted registration."""
        _check_id("train_id", train_id)
        _check_type("request", request, RegisterRequest, "a RegisterRequest")
        _check_time("at_s", at_s)
        with self.transaction():
            self._write(
                "INSERT INTO trains (train_id, train_number, loco_number, driver_id, "
                "train_length_m, registered_at_s) VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT "
                "(train_id) DO UPDATE SET train_number = excluded.train_number, loco_number "
                "= excluded.loco_number, driver_id = excluded.driver_id, train_length_m = "
                "excluded.train_length_m, registered_at_s = excluded.registered_at_s",
                (
                    train_id,
                    request.train_number,
                    request.loco_number,
                    request.driver_id,
                    request.train_length_m,
                    at_s,
                ),
            )

    def audit(
        self,
        action: str,
        *,
        actor: str,
        at_s: float,
        train_id: int | None = None,
        detail: Mapping[str, Any] | None = None,
    ) -> int:
        """Append one entry to the audit log; returns its sequence number."""
        _check_text("action", action, _MAX_ACTION, empty=False)
        _check_text("actor", actor, _MAX_ACTOR, empty=False)
        _check_time("at_s", at_s)
        if train_id is not None:
            _check_id("train_id", train_id)
        try:
            text = json.dumps(dict(detail or {}), sort_keys=True, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise _refuse("detail", detail, f"a JSON object of finite values ({exc})") from None
        with self.transaction():
            # fetchall(): sqlite3 finishes (resets) the statement only once it is read out
            ((seq,),) = self._write(
                "INSERT INTO audit (at_s, actor, action, train_id, detail) "
                "VALUES (?, ?, ?, ?, ?) RETURNING seq",
                (at_s, actor, action, train_id, text),
            ).fetchall()
        return int(seq)

    # --- reads -------------------------------------------------------------------------------

    def load(self) -> Snapshot:
        """Everything needed to rebuild the server's train records (final states included).

        Read in one transaction: one consistent state of every table, even while another
        process writes (PostgreSQL) or the ``sqlite3`` shell does.
        """
        with self._transaction(self._BEGIN_READ):
            return self._load()

    def _load(self) -> Snapshot:
        tsrs = {
            row[0]: StoredTsr(
                TsrSet(row[0], row[1], row[2], row[3], row[4], row[5]),
                actor=row[7],
                reason=row[6],
                set_at_s=row[8],
                cancelled_at_s=row[9],
                cancelled_by=row[10],
            )
            for row in self._read(
                "SELECT session, start_m, end_m, limit_mps, valid_from_s, valid_until_s, "
                "reason, actor, set_at_s, cancelled_at_s, cancelled_by FROM tsrs ORDER BY session"
            )
        }
        registrations: dict[int, tuple[RegisterRequest, float]] = {
            row[0]: (RegisterRequest(row[1], row[2], row[3], row[4]), row[5])
            for row in self._read(
                "SELECT train_id, train_number, loco_number, driver_id, train_length_m, "
                "registered_at_s FROM trains"
            )
        }
        states: dict[int, dict[int, TsrState]] = {}
        for train_id, session, state in self._read(
            "SELECT train_id, session, state FROM tsr_deliveries ORDER BY train_id, session"
        ):
            states.setdefault(train_id, {})[session] = _enum(
                TsrState, state, "tsr_deliveries.state"
            )
        deliveries: dict[int, dict[str, dict[int, tuple[Message, DeliveryState]]]] = {}
        for train_id, kind, ident, text, state in self._read(
            "SELECT train_id, kind, ident, message, state FROM deliveries "
            "ORDER BY train_id, kind, ident"
        ):
            books = deliveries.setdefault(train_id, {kind: {} for kind in KEPT_KINDS})
            cls = KEPT_KINDS.get(kind)
            if cls is None:
                raise _refuse("deliveries.kind", kind, " or ".join(KEPT_KINDS))
            books[kind][ident] = (
                _message_from_json(cls, text),
                _enum(DeliveryState, state, "deliveries.state"),
            )
        trains = {}
        for train_id in sorted({*registrations, *states, *deliveries}):
            registration = registrations.get(train_id)
            trains[train_id] = StoredTrain(
                train_id,
                registration=None if registration is None else registration[0],
                registered_at_s=None if registration is None else registration[1],
                tsrs=states.get(train_id, {}),
                deliveries=deliveries.get(train_id, {kind: {} for kind in KEPT_KINDS}),
            )
        return Snapshot(tsrs, trains)

    def audit_log(self, *, train_id: int | None = None, after_seq: int = 0) -> list[AuditEntry]:
        """Audit entries in the order they were written (optionally of one train)."""
        sql = "SELECT seq, at_s, actor, action, train_id, detail FROM audit WHERE seq > ?"
        params: tuple[Any, ...] = (after_seq,)
        if train_id is not None:
            sql += " AND train_id = ?"
            params += (train_id,)
        return [
            AuditEntry(seq, at_s, actor, action, train, json.loads(detail))
            for seq, at_s, actor, action, train, detail in self._read(sql + " ORDER BY seq", params)
        ]

    def _tsr(self, session: int) -> tuple[TsrSet, str] | None:
        """The restriction recorded under ``session`` and who set it."""
        rows = self._read(
            "SELECT session, start_m, end_m, limit_mps, valid_from_s, valid_until_s, actor "
            "FROM tsrs WHERE session = ?",
            (session,),
        )
        if not rows:
            return None
        row = rows[0]
        return TsrSet(row[0], row[1], row[2], row[3], row[4], row[5]), row[6]

    def _require_tsr(self, session: int) -> None:
        if not self._read("SELECT 1 FROM tsrs WHERE session = ?", (session,)):
            raise _refuse("session", session, "a session recorded with record_tsr() first")


# --- PostgreSQL URLs ---------------------------------------------------------------------------


def is_postgres_url(target: str | Path) -> bool:
    """Whether ``--db`` names a PostgreSQL server (``postgresql://...``) rather than a file."""
    return str(target).lower().startswith(POSTGRES_SCHEMES)


_URL_PASSWORD_PARAM = re.compile(r"([?&])password=[^&]*&?", re.IGNORECASE)
_KEYWORD_PASSWORD = re.compile(r"\bpassword\s*=\s*(?:'(?:[^'\\]|\\.)*'?|\S*)\s*", re.IGNORECASE)


def redact_dsn(dsn: str) -> str:
    """A PostgreSQL connection string without its password, for status, logs and errors.

    ``postgresql://ground:secret@db.example/railpilot`` -> ``postgresql://ground@db.example/
    railpilot``; a ``password=`` URL parameter or ``key=value`` entry is dropped. Works on
    strings libpq would refuse too (their error messages may quote the password).
    """
    if not is_postgres_url(dsn):
        return _KEYWORD_PASSWORD.sub("", dsn).strip()
    scheme, _, rest = dsn.partition("://")
    # user info ends at the last '@' before the query: a password may hold '/' or '@'
    head = rest.split("?", 1)[0]
    at = head.rfind("@")
    if at >= 0:
        user = head[:at].split(":", 1)[0]
        rest = f"{user}@{rest[at + 1 :]}"
    path, question, query = rest.partition("?")
    if question:
        query = _URL_PASSWORD_PARAM.sub(r"\1", "?" + query).rstrip("?&")
    return f"{scheme}://{path}{query}"


# --- validation --------------------------------------------------------------------------------


def _check_id(field: str, value: Any) -> None:
    if type(value) is not int or not 1 <= value <= _U32_MAX:
        raise _refuse(field, value, f"an integer in [1, {_U32_MAX}]")


def _check_time(field: str, value: Any) -> None:
    if (
        not isinstance(value, int | float)
        or isinstance(value, bool)
        or not math.isfinite(value)
        or value < 0
    ):
        raise _refuse(field, value, "epoch seconds (a finite number >= 0)")


def _check_text(field: str, value: Any, max_len: int, *, empty: bool) -> None:
    if (
        not isinstance(value, str)
        or len(value) > max_len
        or (not empty and not value.strip())
        or not value.isprintable()
    ):
        size = f"0..{max_len}" if empty else f"1..{max_len}"
        raise _refuse(field, value, f"{size} printable characters")


def _check_type(field: str, value: Any, kind: type, allowed: str) -> None:
    if not isinstance(value, kind):
        raise _refuse(field, value, allowed)


def _names(enum: type[Enum]) -> str:
    return ", ".join(enum.__members__)


def _enum(enum: type[E], name: str, field: str) -> E:
    """A stored enum name back to its member (a hand-edited database may hold anything)."""
    try:
        return enum[name]
    except KeyError:
        raise _refuse(field, name, f"one of {_names(enum)}") from None


def _kept_names() -> list[str]:
    return [cls.__name__ for cls in KEPT_KINDS.values()]


def _key(message: Message) -> int:
    return int(getattr(message, message.KEY))


def _message_json(message: Message) -> str:
    """A kept message's fields as the store keeps them: a JSON object, enums by name
    (floats as Python writes them, so they read back to the same bits)."""
    values = {f.name: getattr(message, f.name) for f in dataclass_fields(message)}
    return json.dumps({k: getattr(v, "name", v) for k, v in values.items()}, sort_keys=True)


_ENUM_FIELDS: dict[type[Message], dict[str, type[Enum]]] = {}


def _enum_fields(cls: type[Message]) -> dict[str, type[Enum]]:
    """The fields of ``cls`` that hold an enum, with its type (worked out once)."""
    found = _ENUM_FIELDS.get(cls)
    if found is None:
        found = _ENUM_FIELDS[cls] = {
            name: hint
            for name, hint in get_type_hints(cls).items()
            if isinstance(hint, type) and issubclass(hint, Enum)
        }
    return found


def _message_from_json(cls: type[Message], text: str) -> Message:
    """The inverse of :func:`_message_json` (a hand-edited database may hold anything)."""
    try:
        values = json.loads(text)
        for name, enum in _enum_fields(cls).items():
            values[name] = _enum(enum, values[name], f"deliveries.message.{name}")
        return cls(**values)
    except (ValueError, TypeError, KeyError, MessageFieldError):
        raise _refuse("deliveries.message", text, f"a {cls.__name__} as a JSON object") from None


def _describe(tsr: TsrSet) -> str:
    return (
        f"km {tsr.start_m / 1000:.3f}-{tsr.end_m / 1000:.3f} at {mps_to_kmh(tsr.limit_mps):.1f} "
        "km/h, "
        f"valid {tsr.valid_from_s:.0f}-{tsr.valid_until_s:.0f}"
    )
