"""What the ground must not lose: TSRs, deliveries and their state, an audit log (issue 11).

One :class:`Store` per ground server, backed by SQLite (the embedded default: a file, or
``":memory:"`` for tests). The server writes to it *before* a frame leaves (DESIGN habit
14, persistence before effect) and rebuilds its train records from :meth:`Store.load` when
it starts, so after ``kill -9`` every pending delivery is resent and every active TSR can
still be cancelled. docs/ground-store.md has the schema, the write points and how to
inspect a database with the ``sqlite3`` shell.

The interface is small and speaks the link's own types (:class:`~railpilot.link.TsrSet`,
:class:`~railpilot.link.TsrState` ...), never SQL, so a PostgreSQL backend can sit behind
the same methods:

* :meth:`Store.record_tsr` - a line-level TSR as the dispatcher set it (once per session);
* :meth:`Store.record_tsr_state` - one train's delivery state of a TSR session;
* :meth:`Store.record_tsr_cancel` - the dispatcher asked to cancel a session;
* :meth:`Store.record_delivery` / :meth:`Store.record_delivery_state` - target points and
  dispatch commands per train;
* :meth:`Store.record_registration` - a train's last registration (so ``all`` still names
  it after a restart);
* :meth:`Store.audit` - an append-only log entry (time, actor, action, train, detail);
* :meth:`Store.transaction` - several of the above atomically (each one alone is atomic);
* :meth:`Store.load` - everything needed to rebuild the server's train records.

Durability: WAL journal with ``synchronous=FULL``. In WAL mode ``NORMAL`` already survives
``kill -9`` of the process (the WAL lives in the OS page cache), but after a power loss
it may roll back the last commits; the ground may by then have sent the frame those
commits announced, and a train enforcing a TSR the ground no longer knows cannot be
cancelled. ``FULL`` makes every commit durable before the call returns, at one fsync per
transaction. ``synchronous="NORMAL"`` is accepted for benchmarks and tests.

Every time is passed in (``at_s``, seconds since the epoch on the ground clock): the store
reads no clock.
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any, Final, TypeVar

from railpilot.errors import RailpilotError
from railpilot.link import (
    DeliveryState,
    DispatchCommand,
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
#: The schema this code writes; a database with a newer one is refused, an older one
#: migrated (there is none older yet).
SCHEMA_VERSION: Final = 1
SYNCHRONOUS: Final = ("FULL", "NORMAL")

_U32_MAX = 0xFFFF_FFFF
_MAX_ACTOR = 64
_MAX_REASON = 200
_MAX_ACTION = 64

E = TypeVar("E", bound=Enum)

_SCHEMA = """
CREATE TABLE schema_version (
    version INTEGER NOT NULL
);
-- A TSR as the dispatcher set it: one row per session number, line-wide.
CREATE TABLE tsrs (
    session        INTEGER PRIMARY KEY,
    start_m        REAL NOT NULL,
    end_m          REAL NOT NULL,
    limit_mps      REAL NOT NULL,
    valid_from_s   REAL NOT NULL,
    valid_until_s  REAL NOT NULL,
    reason         TEXT NOT NULL,
    actor          TEXT NOT NULL,
    set_at_s       REAL NOT NULL,
    cancelled_at_s REAL,
    cancelled_by   TEXT
);
-- Its delivery to one train (docs/protocol.md 8.3: TsrState names).
CREATE TABLE tsr_deliveries (
    train_id     INTEGER NOT NULL,
    session      INTEGER NOT NULL REFERENCES tsrs (session),
    state        TEXT NOT NULL,
    updated_at_s REAL NOT NULL,
    PRIMARY KEY (train_id, session)
);
CREATE TABLE target_points (
    train_id     INTEGER NOT NULL,
    target_id    INTEGER NOT NULL,
    position_m   REAL NOT NULL,
    reason       TEXT NOT NULL,
    state        TEXT NOT NULL,
    updated_at_s REAL NOT NULL,
    PRIMARY KEY (train_id, target_id)
);
CREATE TABLE dispatch_commands (
    train_id       INTEGER NOT NULL,
    command_number INTEGER NOT NULL,
    text           TEXT NOT NULL,
    state          TEXT NOT NULL,
    updated_at_s   REAL NOT NULL,
    PRIMARY KEY (train_id, command_number)
);
-- The last accepted registration of each train.
CREATE TABLE trains (
    train_id        INTEGER PRIMARY KEY,
    train_number    TEXT NOT NULL,
    loco_number     TEXT NOT NULL,
    driver_id       INTEGER NOT NULL,
    train_length_m  REAL NOT NULL,
    registered_at_s REAL NOT NULL
);
-- Append-only: nothing ever updates or deletes a row.
CREATE TABLE audit (
    seq      INTEGER PRIMARY KEY AUTOINCREMENT,
    at_s     REAL NOT NULL,
    actor    TEXT NOT NULL,
    action   TEXT NOT NULL,
    train_id INTEGER,
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
    target_points: Mapping[int, tuple[TargetPoint, DeliveryState]]
    dispatch_commands: Mapping[int, tuple[DispatchCommand, DeliveryState]]


@dataclass(frozen=True, slots=True)
class Snapshot:
    """Everything :meth:`Store.load` found, final states included.

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


# --- the store -------------------------------------------------------------------------------


class Store:
    """SQLite store of the ground (WAL, ``synchronous=FULL`` by default).

    Parameters
    ----------
    path
        Database file (created with its schema if missing), or ``":memory:"``.
    synchronous
        ``"FULL"`` (default: every commit survives a power loss) or ``"NORMAL"`` (survives
        a crash of the process only); see the module docstring.

    Single-threaded, like the server's event loop that owns it. Each ``record_*`` /
    :meth:`audit` call is one transaction unless made inside :meth:`transaction`.
    """

    def __init__(self, path: str | Path = DEFAULT_PATH, *, synchronous: str = "FULL") -> None:
        if synchronous not in SYNCHRONOUS:
            raise _refuse("synchronous", synchronous, f"one of {', '.join(SYNCHRONOUS)}")
        text = str(path)
        if text != MEMORY:
            file = Path(text)
            if file.is_dir():
                raise _refuse("path", text, "a database file, not a directory")
            if not file.parent.is_dir():
                raise _refuse("path", text, "a file in an existing directory")
        self.path = text
        self._depth = 0
        try:
            # isolation_level=None: no implicit transactions; ours are explicit (BEGIN).
            self._db = sqlite3.connect(text, isolation_level=None)
        except sqlite3.Error as exc:
            raise _refuse("path", text, f"a SQLite database that can be opened ({exc})") from None
        try:
            self._configure(synchronous)
            self._migrate()
        except BaseException:
            self._db.close()
            raise

    def _configure(self, synchronous: str) -> None:
        try:
            mode = self._db.execute("PRAGMA journal_mode=WAL").fetchone()[0]
            self._db.execute(f"PRAGMA synchronous={synchronous}")
            self._db.execute("PRAGMA foreign_keys=ON")
            # a reader (the sqlite3 shell) may hold a lock for a moment
            self._db.execute("PRAGMA busy_timeout=5000")
        except sqlite3.Error as exc:
            raise _refuse("path", self.path, f"a SQLite database ({exc})") from None
        if self.path != MEMORY and str(mode).lower() != "wal":
            raise _refuse("path", self.path, f"a file system that supports WAL (got {mode})")

    def _migrate(self) -> None:
        with self.transaction():
            found = self._db.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table' AND name = 'schema_version'"
            ).fetchone()
            if found is None:
                if self._db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]:
                    raise _refuse(
                        "path",
                        self.path,
                        "a railpilot ground store (this database has other tables)",
                    )
                # one statement at a time: executescript() would COMMIT our BEGIN
                for statement in _SCHEMA.split(";"):
                    if statement.strip():
                        self._db.execute(statement)
                self._db.execute(
                    "INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,)
                )
                return
            (version,) = self._db.execute("SELECT max(version) FROM schema_version").fetchone()
            if version is None or version > SCHEMA_VERSION:
                raise _refuse(
                    "schema_version",
                    version,
                    f"at most {SCHEMA_VERSION} (the database was written by a newer railpilot)",
                )
            # version < SCHEMA_VERSION: migrations go here, one step per version.

    # --- lifecycle ---------------------------------------------------------------------------

    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def schema_version(self) -> int:
        return int(self._db.execute("SELECT max(version) FROM schema_version").fetchone()[0])

    @property
    def journal_mode(self) -> str:
        return str(self._db.execute("PRAGMA journal_mode").fetchone()[0]).lower()

    @property
    def synchronous(self) -> str:
        # PRAGMA synchronous answers 0 OFF, 1 NORMAL, 2 FULL, 3 EXTRA
        level = int(self._db.execute("PRAGMA synchronous").fetchone()[0])
        return ("OFF", "NORMAL", "FULL", "EXTRA")[level]

    @contextmanager
    def transaction(self) -> Iterator[None]:
        """Everything inside commits together or not at all.

        Nested use is a savepoint: an exception leaving the inner block undoes only the
        inner block's writes (the outer block decides about the rest).
        """
        depth = self._depth
        try:
            self._db.execute("BEGIN IMMEDIATE" if depth == 0 else f"SAVEPOINT s{depth}")
        except sqlite3.Error as exc:
            raise StoreError(f"cannot start a transaction on {self.path} ({exc})") from None
        self._depth = depth + 1
        try:
            yield
        except BaseException:
            self._depth = depth
            if depth == 0:
                self._db.execute("ROLLBACK")
            else:
                self._db.execute(f"ROLLBACK TO s{depth}")
                self._db.execute(f"RELEASE s{depth}")
            raise
        self._depth = depth
        try:
            self._db.execute("COMMIT" if depth == 0 else f"RELEASE s{depth}")
        except sqlite3.Error as exc:
            if depth == 0 and self._db.in_transaction:
                self._db.execute("ROLLBACK")
            raise StoreError(f"cannot commit to {self.path} ({exc})") from None

    def _write(self, sql: str, params: tuple[Any, ...]) -> sqlite3.Cursor:
        try:
            return self._db.execute(sql, params)
        except sqlite3.Error as exc:
            raise StoreError(f"cannot write to {self.path} ({exc})") from None

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
            existing = self._tsr(tsr.session)
            if existing is not None:
                held, by = existing
                if held != tsr:
                    raise _refuse(
                        "tsr.session",
                        tsr.session,
                        f"a session not used yet (it holds {_describe(held)}, set by {by})",
                    )
                return
            self._write(
                "INSERT INTO tsrs (session, start_m, end_m, limit_mps, valid_from_s, "
                "valid_until_s, reason, actor, set_at_s) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
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
        self,
        train_id: int,
        message: TargetPoint | DispatchCommand,
        state: DeliveryState,
        *,
        at_s: float,
    ) -> None:
        """Keep a target point or dispatch command for a train, with its delivery state.

        A target point replaces the one under the same id (as the core does); a dispatch
        command number names one command for good (a different text is refused).
        """
        _check_id("train_id", train_id)
        _check_type("state", state, DeliveryState, f"a DeliveryState ({_names(DeliveryState)})")
        _check_time("at_s", at_s)
        if isinstance(message, TargetPoint):
            self._write_upsert(
                "INSERT INTO target_points (train_id, target_id, position_m, reason, state, "
                "updated_at_s) VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (train_id, target_id) DO "
                "UPDATE SET position_m = excluded.position_m, reason = excluded.reason, "
                "state = excluded.state, updated_at_s = excluded.updated_at_s",
                (
                    train_id,
                    message.target_id,
                    message.position_m,
                    message.reason.name,
                    state.name,
                    at_s,
                ),
            )
        elif isinstance(message, DispatchCommand):
            with self.transaction():
                row = self._db.execute(
                    "SELECT text FROM dispatch_commands WHERE train_id = ? AND command_number = ?",
                    (train_id, message.command_number),
                ).fetchone()
                if row is not None and row[0] != message.text:
                    raise _refuse(
                        "message.command_number",
                        message.command_number,
                        f"a command number not used yet for train {train_id}",
                    )
                self._write(
                    "INSERT INTO dispatch_commands (train_id, command_number, text, state, "
                    "updated_at_s) VALUES (?, ?, ?, ?, ?) ON CONFLICT (train_id, "
                    "command_number) DO UPDATE SET state = excluded.state, "
                    "updated_at_s = excluded.updated_at_s",
                    (train_id, message.command_number, message.text, state.name, at_s),
                )
        else:
            raise _refuse("message", message, "a TargetPoint or a DispatchCommand")

    def _write_upsert(self, sql: str, params: tuple[Any, ...]) -> None:
        with self.transaction():
            self._write(sql, params)

    def record_delivery_state(
        self,
        train_id: int,
        kind: type[TargetPoint] | type[DispatchCommand],
        ident: int,
        state: DeliveryState,
        *,
        at_s: float,
    ) -> None:
        """Update the state of a recorded target point or dispatch command."""
        _check_id("train_id", train_id)
        _check_type("state", state, DeliveryState, f"a DeliveryState ({_names(DeliveryState)})")
        _check_time("at_s", at_s)
        if kind is TargetPoint:
            table, column = "target_points", "target_id"
        elif kind is DispatchCommand:
            table, column = "dispatch_commands", "command_number"
        else:
            raise _refuse("kind", kind, "TargetPoint or DispatchCommand")
        if type(ident) is not int or not 0 <= ident <= _U32_MAX:
            raise _refuse("ident", ident, f"an integer in [0, {_U32_MAX}]")
        with self.transaction():
            cursor = self._write(
                f"UPDATE {table} SET state = ?, updated_at_s = ? "
                f"WHERE train_id = ? AND {column} = ?",
                (state.name, at_s, train_id, ident),
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
        self._write_upsert(
            "INSERT INTO trains (train_id, train_number, loco_number, driver_id, "
            "train_length_m, registered_at_s) VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (train_id) "
            "DO UPDATE SET train_number = excluded.train_number, loco_number = "
            "excluded.loco_number, driver_id = excluded.driver_id, train_length_m = "
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
            cursor = self._write(
                "INSERT INTO audit (at_s, actor, action, train_id, detail) VALUES (?, ?, ?, ?, ?)",
                (at_s, actor, action, train_id, text),
            )
        return int(cursor.lastrowid or 0)

    # --- reads -------------------------------------------------------------------------------

    def load(self) -> Snapshot:
        """Everything needed to rebuild the server's train records (final states included)."""
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
        targets: dict[int, dict[int, tuple[TargetPoint, DeliveryState]]] = {}
        for train_id, target_id, position_m, reason, state in self._read(
            "SELECT train_id, target_id, position_m, reason, state FROM target_points "
            "ORDER BY train_id, target_id"
        ):
            target = TargetPoint(
                target_id, position_m, _enum(TargetReason, reason, "target_points.reason")
            )
            targets.setdefault(train_id, {})[target_id] = (
                target,
                _enum(DeliveryState, state, "target_points.state"),
            )
        commands: dict[int, dict[int, tuple[DispatchCommand, DeliveryState]]] = {}
        for train_id, number, text, state in self._read(
            "SELECT train_id, command_number, text, state FROM dispatch_commands "
            "ORDER BY train_id, command_number"
        ):
            commands.setdefault(train_id, {})[number] = (
                DispatchCommand(number, text),
                _enum(DeliveryState, state, "dispatch_commands.state"),
            )
        trains = {}
        for train_id in sorted({*registrations, *states, *targets, *commands}):
            registration = registrations.get(train_id)
            trains[train_id] = StoredTrain(
                train_id,
                registration=None if registration is None else registration[0],
                registered_at_s=None if registration is None else registration[1],
                tsrs=states.get(train_id, {}),
                target_points=targets.get(train_id, {}),
                dispatch_commands=commands.get(train_id, {}),
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

    def _read(self, sql: str, params: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        try:
            return self._db.execute(sql, params).fetchall()
        except sqlite3.Error as exc:
            raise StoreError(f"cannot read {self.path} ({exc})") from None

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


def _describe(tsr: TsrSet) -> str:
    return (
        f"km {tsr.start_m / 1000:.3f}-{tsr.end_m / 1000:.3f} at {mps_to_kmh(tsr.limit_mps):.1f} "
        "km/h, "
        f"valid {tsr.valid_from_s:.0f}-{tsr.valid_until_s:.0f}"
    )
