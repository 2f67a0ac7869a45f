"""The ground store on a PostgreSQL server, for a dispatch centre.

The same store as the SQLite one - every method, refusal, audit entry and the snapshot
come from :class:`~railpilot.ground.store_core.GroundStore` - on a server several ground
processes may share. What differs, and why:

* **Connection**: psycopg 3 in autocommit mode; the transactions are ours, explicit
  ``BEGIN ... COMMIT`` and savepoints, as in SQLite. A connection the server dropped
  (restart, failover, ``pg_terminate_backend``) is opened again when the next
  transaction begins; a transaction it broke fails with a :class:`StoreError` (and
  PostgreSQL kept nothing of it).
* **Isolation**: writes run at ``READ COMMITTED``, set explicitly so a database default
  cannot change it. The shared SQL does every check-then-write in one statement
  (``INSERT ... ON CONFLICT``, ``UPDATE ... WHERE``), which PostgreSQL evaluates against
  the latest committed row and which locks that row to the commit: two front servers
  setting the same TSR session wait for each other, and the second is refused (or finds
  the same restriction) - no serialization failures to retry. :meth:`load` reads in one
  ``REPEATABLE READ READ ONLY`` transaction: one snapshot of every table.
* **Durability**: ``synchronous_commit`` is ``on`` by default, so ``COMMIT`` returns only
  once the commit record is flushed to the server's disk (and to synchronous standbys,
  if any). A role or database default of ``off`` is raised back to ``on`` for our
  session; ``local``, ``remote_write`` and ``remote_apply`` flush locally too and are
  kept.
* **Schema**: ``BIGINT`` ids (up to 2^32-1), ``DOUBLE PRECISION`` values (floats round
  trip exactly), an identity column for ``audit.seq``; created in the connection's
  current schema under an advisory lock, so front servers starting together do not race.
* **Secrets**: :attr:`path` is the URL without its password, and no error message quotes
  it (libpq's own parse errors may: they are not passed on).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any, ClassVar, Final

import psycopg
from psycopg.conninfo import conninfo_to_dict, make_conninfo

from railpilot.ground.store_core import Cursor, GroundStore, _refuse, redact_dsn

#: libpq gives up on an unreachable server after this long (unless the URL says).
CONNECT_TIMEOUT_S: Final = 10
#: How a dispatch centre's DBA sees us in pg_stat_activity (unless the URL says).
APPLICATION_NAME: Final = "railpilot-ground"
#: ``synchronous_commit`` values that flush the commit locally before COMMIT returns.
DURABLE_COMMIT: Final = ("on", "local", "remote_write", "remote_apply")
#: pg_advisory_xact_lock key held while the schema is checked or created ("rpground").
SCHEMA_LOCK = 0x7270_6772_6F75_6E64


@cache
def _placeholders(sql: str) -> str:
    # The shared SQL uses sqlite3's "?"; psycopg's is "%s". No shared statement holds a
    # literal "?" or "%".
    return sql.replace("?", "%s")


class PostgresStore(GroundStore):
    """The ground store in a PostgreSQL database.

    Parameters
    ----------
    dsn
        libpq connection URL (``postgresql://USER@HOST:PORT/DBNAME``) or ``key=value``
        string. The schema is created in the connection's current schema if it is empty.
        Keep the password out of it (``~/.pgpass``, ``PGPASSWORD``); if it is there, it is
        used but never shown.
    """

    _FIELD = "db"
    _BEGIN_WRITE = "BEGIN ISOLATION LEVEL READ COMMITTED"
    _BEGIN_READ = "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY"
    _COLUMN_TYPES: ClassVar[Mapping[str, str]] = {
        "int": "BIGINT",
        "real": "DOUBLE PRECISION",
        "seq_key": "BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY",
    }
    _DB_ERRORS = (psycopg.Error,)

    def __init__(self, dsn: str) -> None:
        super().__init__(redact_dsn(dsn))
        try:
            params = conninfo_to_dict(dsn)
        except psycopg.Error:
            raise _refuse(
                "db",
                self.path,
                "a PostgreSQL URL postgresql://USER@HOST:PORT/DBNAME that libpq parses",
            ) from None
        password = params.get("password")
        self._password = str(password) if password else None
        defaults: dict[str, str | int] = {
            "connect_timeout": CONNECT_TIMEOUT_S,
            "application_name": APPLICATION_NAME,
        }
        self._conninfo = make_conninfo(
            dsn, **{key: value for key, value in defaults.items() if key not in params}
        )
        try:
            self._db = self._connect()
        except psycopg.Error as exc:
            raise _refuse(
                "db", self.path, f"a PostgreSQL server that takes the connection ({self._say(exc)})"
            ) from None
        try:
            self._migrate()
        except BaseException:
            self._db.close()
            raise

    def _connect(self) -> psycopg.Connection[Any]:
        db = psycopg.connect(self._conninfo, autocommit=True)
        try:
            if db.execute("SHOW synchronous_commit").fetchall()[0][0] not in DURABLE_COMMIT:
                db.execute("SET synchronous_commit TO on")
        except BaseException:
            db.close()
            raise
        return db

    def _say(self, exc: Exception) -> str:
        """libpq's message on one line, without the password should it quote it."""
        text = " ".join(str(exc).split())
        return text.replace(self._password, "***") if self._password else text

    # --- what GroundStore needs --------------------------------------------------------------

    def _execute(self, sql: str, params: Sequence[Any] = ()) -> Cursor:
        cursor = self._db.execute(_placeholders(sql), params or None)
        if sql == "COMMIT" and cursor.statusmessage == "ROLLBACK":
            # PostgreSQL answers COMMIT of a transaction a failed statement aborted with a
            # silent ROLLBACK: nothing of it was kept, which the caller must hear.
            raise psycopg.errors.InFailedSqlTransaction(
                "a statement had failed: the transaction was rolled back"
            )
        return cursor

    def _object_names(self) -> set[str]:
        return {
            row[0]
            for row in self._read(
                "SELECT table_name FROM information_schema.tables "
                "WHERE table_schema = current_schema()"
            )
        }

    def _begin(self, sql: str) -> None:
        # A connection is found lost only when used. Lost (``broken``), not closed by us
        # (close() stays final): nothing of this transaction has run yet, so it starts
        # again on a new connection.
        if self._db.broken:
            self._reconnect()
        try:
            self._execute(sql)
        except psycopg.OperationalError:
            if not self._db.broken:
                raise
            self._reconnect()
            self._execute(sql)

    def _reconnect(self) -> None:
        self._db.close()  # frees what is left of the lost one
        self._db = self._connect()

    def _lock_schema(self) -> None:
        self._read("SELECT pg_advisory_xact_lock(?)", (SCHEMA_LOCK,))

    def close(self) -> None:
        self._db.close()

    @property
    def synchronous_commit(self) -> str:
        """The session's ``synchronous_commit`` (one of :data:`DURABLE_COMMIT`)."""
        return str(self._read("SHOW synchronous_commit")[0][0])
