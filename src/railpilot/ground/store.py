"""The ground store's SQLite backend (:class:`Store`) and the choice of a backend from
``ground serve --db`` (:func:`open_store`).

Everything both backends share - :class:`~railpilot.ground.store_core.GroundStore` with its
validation and SQL, the snapshot types, :class:`StoreError`, :func:`redact_dsn` - lives in
:mod:`railpilot.ground.store_core` (the module docstring there describes the store) and is
importable from here too. The PostgreSQL backend
(:class:`~railpilot.ground.store_postgres.PostgresStore`) builds on that shared part, so
this module imports it only when a PostgreSQL URL is opened, and it never imports this one.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

from railpilot.extras import install_hint
from railpilot.ground.store_core import (
    DEFAULT_PATH,
    MEMORY,
    POSTGRES_SCHEMES,
    SCHEMA_VERSION,
    SYNCHRONOUS,
    AuditEntry,
    Cursor,
    GroundStore,
    Snapshot,
    StoredTrain,
    StoredTsr,
    StoreError,
    _refuse,
    is_postgres_url,
    redact_dsn,
)

__all__ = [
    "DEFAULT_PATH",
    "MEMORY",
    "POSTGRES_SCHEMES",
    "SCHEMA_VERSION",
    "SYNCHRONOUS",
    "AuditEntry",
    "Cursor",
    "GroundStore",
    "Snapshot",
    "Store",
    "StoreError",
    "StoredTrain",
    "StoredTsr",
    "is_postgres_url",
    "open_store",
    "redact_dsn",
]


# --- SQLite ------------------------------------------------------------------------------------


class Store(GroundStore):
    """SQLite store of the ground (WAL, ``synchronous=FULL`` by default).

    Parameters
    ----------
    path
        Database file (created with its schema if missing), or ``":memory:"``.
    synchronous
        ``"FULL"`` (default: every commit survives a power loss) or ``"NORMAL"`` (survives
        a crash of the process only); see the module docstring.
    """

    _FIELD = "path"
    # IMMEDIATE takes the write lock at once: a transaction never fails half-way on
    # upgrading a read lock another connection also holds.
    _BEGIN_WRITE = "BEGIN IMMEDIATE"
    # deferred: in WAL mode one snapshot from the first read to the end, blocking no writer
    _BEGIN_READ = "BEGIN"
    _COLUMN_TYPES: ClassVar[Mapping[str, str]] = {
        "int": "INTEGER",
        "real": "REAL",
        "seq_key": "INTEGER PRIMARY KEY AUTOINCREMENT",
    }
    _DB_ERRORS = (sqlite3.Error,)

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
        super().__init__(text)
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

    def _execute(self, sql: str, params: Sequence[Any] = ()) -> Cursor:
        return self._db.execute(sql, params)

    def _object_names(self) -> set[str]:
        # every table, index, view and trigger: a database with any of them is not empty
        return {row[0] for row in self._read("SELECT name FROM sqlite_master")}

    def close(self) -> None:
        self._db.close()

    @property
    def journal_mode(self) -> str:
        return str(self._db.execute("PRAGMA journal_mode").fetchone()[0]).lower()

    @property
    def synchronous(self) -> str:
        # PRAGMA synchronous answers 0 OFF, 1 NORMAL, 2 FULL, 3 EXTRA
        level = int(self._db.execute("PRAGMA synchronous").fetchone()[0])
        return ("OFF", "NORMAL", "FULL", "EXTRA")[level]


# --- choosing a backend ------------------------------------------------------------------------


def open_store(target: str | Path = DEFAULT_PATH) -> GroundStore:
    """The store ``ground serve --db TARGET`` uses: a PostgreSQL URL
    (``postgresql://`` or ``postgres://``) opens :class:`PostgresStore`, anything else is a
    SQLite file (or ``":memory:"``) for :class:`Store`."""
    if not is_postgres_url(target):
        return Store(target)
    try:
        from railpilot.ground.store_postgres import PostgresStore
    except ModuleNotFoundError as exc:
        if exc.name is None or not exc.name.startswith("psycopg"):
            raise
        raise _refuse(
            "db",
            redact_dsn(str(target)),
            f"railpilot's 'postgres' extra installed (psycopg): {install_hint('postgres')}",
        ) from None
    return PostgresStore(str(target))
