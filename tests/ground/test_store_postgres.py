"""The ground store on PostgreSQL: what only it has - several front servers on one
database, a password to keep out of sight, a server that may drop the connection.

Every test runs against a real server (tests/ground/postgres.py: Debian's PostgreSQL on
127.0.0.1, a fresh database per test; skipped where it is not installed). What both
backends share is tested on both in test_store.py.
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable
from contextlib import suppress
from typing import Any

import psycopg
import pytest
from psycopg.conninfo import conninfo_to_dict

from railpilot.ground.store import (
    SCHEMA_VERSION,
    GroundStore,
    StoreError,
    open_store,
    redact_dsn,
)
from railpilot.ground.store_postgres import APPLICATION_NAME, SCHEMA_LOCK, PostgresStore
from railpilot.link import DeliveryState, DispatchCommand, GroundConfig, TsrSet, TsrState
from railpilot.net.server import GroundServer

from .postgres import PostgresServer

T0 = 1_700_000_000.0
TSR = TsrSet(21, 5_000.0, 6_000.0, 40 / 3.6, T0, T0 + 3600.0)
OTHER_TSR = TsrSet(21, 7_000.0, 8_000.0, 60 / 3.6, T0, T0 + 3600.0)
_P = DeliveryState.PENDING
#: bound of every wait for what another connection does (each a poll, never a sleep)
WAIT_S = 20.0


def _password(dsn: str) -> str:
    return str(conninfo_to_dict(dsn)["password"])


def _dbname(dsn: str) -> str:
    return dsn.rsplit("/", 1)[1]


def _poll(condition: Callable[[], bool], what: str) -> None:
    """Ask again until ``condition()`` holds (AssertionError after WAIT_S)."""
    timed_out = threading.Event()
    deadline = threading.Timer(WAIT_S, timed_out.set)
    deadline.start()
    try:
        # each question is a round trip to the server: a moment between them
        while not condition():
            assert not timed_out.wait(0.01), f"timed out waiting for {what}"
    finally:
        deadline.cancel()


def _waiting_for_a_lock(server: PostgresServer, dsn: str) -> int:
    """How many connections to the test's database wait for a lock."""
    ((waiting,),) = server.execute(
        "SELECT count(*) FROM pg_stat_activity "
        f"WHERE wait_event_type = 'Lock' AND datname = '{_dbname(dsn)}'"
    )
    return int(waiting)


def _terminate_the_stores(server: PostgresServer, dsn: str) -> None:
    """What a server restart or a DBA does to the store's connection (and waits for it)."""
    killed = server.execute(
        "SELECT pg_terminate_backend(pid, 10000) FROM pg_stat_activity "
        f"WHERE datname = '{_dbname(dsn)}' AND application_name = '{APPLICATION_NAME}'"
    )
    assert killed == [(True,)]


class _Worker(threading.Thread):
    """One call in a thread of its own: another front server doing it at the same time."""

    def __init__(self, call: Callable[[], Any]) -> None:
        super().__init__(daemon=True)
        self.call = call
        self.result: Any = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.result = self.call()
        except BaseException as exc:
            self.error = exc

    def finish(self) -> Any:
        self.join(WAIT_S)
        assert not self.is_alive(), "the other front server never finished"
        return self.result


# --- the password -------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("dsn", "shown"),
    [
        (
            "postgresql://ground:s3cret@db.example:5432/railpilot",
            "postgresql://ground@db.example:5432/railpilot",
        ),
        (
            "postgres://ground:s3/cr@t@db/railpilot?sslmode=require",
            "postgres://ground@db/railpilot?sslmode=require",
        ),
        (
            "postgresql://ground@db/railpilot?password=s3cret&sslmode=require",
            "postgresql://ground@db/railpilot?sslmode=require",
        ),
        (
            "postgresql://db/railpilot?sslmode=require&password=s3cret",
            "postgresql://db/railpilot?sslmode=require",
        ),
        ("postgresql://ground:s3cret@[::1/x", "postgresql://ground@[::1/x"),  # libpq refuses it
        (
            "host=db user=ground password='s3 cret' dbname=railpilot",
            "host=db user=ground dbname=railpilot",
        ),
        ("postgresql://ground@db/railpilot", "postgresql://ground@db/railpilot"),
    ],
)
def test_redact_dsn_drops_the_password_wherever_it_is(dsn: str, shown: str) -> None:
    assert redact_dsn(dsn) == shown


def test_the_password_is_neither_in_path_nor_in_status(postgres_dsn: str) -> None:
    password = _password(postgres_dsn)
    assert password and f":{password}@" in postgres_dsn  # the test server's URLs carry one
    with open_store(postgres_dsn) as store:
        assert type(store) is PostgresStore
        assert store.path == postgres_dsn.replace(f":{password}@", "@")
        server = GroundServer(GroundConfig(ground_id=1, require_auth=False), store=store)
        assert server.status()["store"] == store.path
    with open_store(postgres_dsn.replace("postgresql://", "postgres://", 1)) as store:
        assert type(store) is PostgresStore and password not in store.path


def test_a_bad_dsn_is_refused_naming_db_without_the_password(postgres_dsn: str) -> None:
    # bound, never listening: a connection to it is refused at once
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as closed:
        closed.bind(("127.0.0.1", 0))
        cases = {
            postgres_dsn.replace(_password(postgres_dsn), "wrong-s3cret"): (
                "password authentication failed"
            ),
            postgres_dsn.rsplit("/", 1)[0] + "/no_such_db": 'database "no_such_db" does not exist',
            f"postgresql://postgres:s3cret@127.0.0.1:{closed.getsockname()[1]}/x": (
                "Connection refused"
            ),
            # libpq's own message would quote the whole URL, password and all
            "postgresql://postgres:s3cret@[::1/x": "a PostgreSQL URL postgresql://USER@HOST",
        }
        for dsn, expected in cases.items():
            with pytest.raises(StoreError) as raised:
                open_store(dsn)
            error = raised.value
            assert (error.field, error.value) == ("db", redact_dsn(dsn))
            assert expected in error.allowed, error
            assert "s3cret" not in str(error) and "s3cret" not in error.allowed


def test_ground_serve_takes_a_postgresql_url_and_never_shows_its_password(
    postgres_dsn: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from railpilot.cli import main

    password = _password(postgres_dsn)
    serve = ["ground", "serve", "--no-auth", "--port", "0", "--admin-port", "-1", "--db"]
    assert main([*serve, postgres_dsn, "--seconds", "0.1"]) == 0
    out, err = capsys.readouterr()
    assert password not in out + err
    assert f"store={redact_dsn(postgres_dsn)}" in err  # its "restored" log line
    with open_store(postgres_dsn) as store:
        assert [e.action for e in store.audit_log()] == ["restored"]

    wrong = postgres_dsn.replace(password, "wrong-s3cret")
    assert main([*serve, wrong, "--seconds", "0"]) == 2
    out, err = capsys.readouterr()
    assert f"--db = '{redact_dsn(wrong)}' is not allowed: expected a PostgreSQL server" in err
    assert "password authentication failed" in err
    assert "s3cret" not in out + err and "Traceback" not in err


# --- durability -------------------------------------------------------------------------------


def test_a_commit_waits_for_the_flush_whatever_the_database_default(
    postgres_server: PostgresServer, postgres_dsn: str
) -> None:
    def synchronous_commit() -> str:
        with PostgresStore(postgres_dsn) as store:
            return store.synchronous_commit

    assert synchronous_commit() == "on"  # PostgreSQL's default
    name = _dbname(postgres_dsn)
    postgres_server.execute(f'ALTER DATABASE "{name}" SET synchronous_commit = off')
    assert synchronous_commit() == "on"
    postgres_server.execute(f'ALTER DATABASE "{name}" SET synchronous_commit = local')
    assert synchronous_commit() == "local"  # it flushes too: kept as the DBA chose


# --- several front servers on one database ------------------------------------------------


def test_two_front_servers_see_each_others_commits_and_nothing_of_a_failed_transaction(
    postgres_dsn: str,
) -> None:
    with open_store(postgres_dsn) as first, open_store(postgres_dsn) as second:
        first.record_tsr(TSR, actor="dispatcher-7", at_s=T0)
        assert second.load().tsrs[21].tsr == TSR

        with first.transaction():
            first.record_tsr_state(1001, 21, TsrState.PENDING_SET, at_s=T0)
            first.audit("tsr_set", actor="dispatcher-7", at_s=T0, train_id=1001)
            assert second.load().trains == {} and second.audit_log() == []  # not yet
        assert second.load().trains[1001].tsrs == {21: TsrState.PENDING_SET}

        with pytest.raises(StoreError, match="session = 99 is not allowed"), first.transaction():
            first.record_tsr_state(1002, 21, TsrState.PENDING_SET, at_s=T0)
            first.audit("tsr_set", actor="dispatcher-7", at_s=T0, train_id=1002)
            first.record_tsr_state(1002, 99, TsrState.PENDING_SET, at_s=T0)  # no such TSR
        for store in (first, second):
            assert 1002 not in store.load().trains
            assert [e.train_id for e in store.audit_log()] == [1001]

        # one audit sequence for both, in the order of writing (a number the failed
        # transaction drew stays unused)
        seq = second.audit("registered", actor="train 1003", at_s=T0, train_id=1003)
        assert [e.train_id for e in first.audit_log()] == [1001, 1003]
        assert first.audit_log()[-1].seq == seq


#: (first front server's write, the same number written otherwise by a second, its refusal)
RACES: dict[str, tuple[Callable[[GroundStore], None], Callable[[GroundStore], None], str]] = {
    "tsr-session": (
        lambda store: store.record_tsr(TSR, actor="dispatcher-7", at_s=T0),
        lambda store: store.record_tsr(OTHER_TSR, actor="dispatcher-8", at_s=T0),
        "tsr.session = 21 is not allowed: expected a session not used yet",
    ),
    "dispatch-command-number": (
        lambda store: store.record_delivery(1001, DispatchCommand(42, "hold"), _P, at_s=T0),
        lambda store: store.record_delivery(1001, DispatchCommand(42, "go"), _P, at_s=T0),
        "message.command_number = 42 is not allowed",
    ),
}


class _Abandon(Exception):
    """Leaves a transaction by an exception: it is rolled back."""


@pytest.mark.parametrize("race", RACES)
@pytest.mark.parametrize("first_ends_with", ["commit", "rollback"])
def test_a_front_server_writing_a_number_another_is_writing_waits_and_sees_who_won(
    postgres_server: PostgresServer, postgres_dsn: str, race: str, first_ends_with: str
) -> None:
    first_write, second_write, refusal = RACES[race]
    with open_store(postgres_dsn) as first, open_store(postgres_dsn) as second:
        other = _Worker(lambda: second_write(second))
        with suppress(_Abandon), first.transaction():
            first_write(first)
            other.start()
            _poll(
                lambda: _waiting_for_a_lock(postgres_server, postgres_dsn) == 1,
                "the second front server to wait for the first's transaction",
            )
            assert other.is_alive()
            if first_ends_with == "rollback":
                raise _Abandon
        other.finish()
        snapshot = first.load()
    if first_ends_with == "commit":  # the first won: the second is refused, as one server
        assert isinstance(other.error, StoreError) and refusal in str(other.error)
    else:  # the first left nothing: the second's write stands
        assert other.error is None
    if race == "tsr-session":
        expected = TSR if first_ends_with == "commit" else OTHER_TSR
        assert snapshot.tsrs[21].tsr == expected
    else:
        text = "hold" if first_ends_with == "commit" else "go"
        assert snapshot.trains[1001].dispatch_commands[42][0].text == text


def test_front_servers_starting_together_create_the_schema_once(
    postgres_server: PostgresServer, postgres_dsn: str
) -> None:
    with psycopg.connect(postgres_dsn, autocommit=True) as holder:
        # hold the schema lock so that both stores reach it before either creates anything
        holder.execute("SELECT pg_advisory_lock(%s)", (SCHEMA_LOCK,))
        starting = [_Worker(lambda: PostgresStore(postgres_dsn)) for _ in range(2)]
        for worker in starting:
            worker.start()
        _poll(
            lambda: _waiting_for_a_lock(postgres_server, postgres_dsn) == 2,
            "both stores to wait for the schema lock",
        )
        holder.execute("SELECT pg_advisory_unlock(%s)", (SCHEMA_LOCK,))
        stores = [worker.finish() for worker in starting]
        versions = holder.execute("SELECT version FROM schema_version").fetchall()
    assert [worker.error for worker in starting] == [None, None]
    assert versions == [(SCHEMA_VERSION,)]
    for store in stores:
        store.record_tsr(TSR, actor="dispatcher-7", at_s=T0)  # both work
        store.close()


# --- a connection the server drops ------------------------------------------------------------


def test_a_dropped_connection_is_opened_again_and_its_transaction_fails_whole(
    postgres_server: PostgresServer, postgres_dsn: str
) -> None:
    with open_store(postgres_dsn) as store:
        store.record_tsr(TSR, actor="dispatcher-7", at_s=T0)
        _terminate_the_stores(postgres_server, postgres_dsn)  # between two transactions
        store.record_tsr_state(1001, 21, TsrState.ACTIVE, at_s=T0)  # on a new connection
        assert store.load().trains[1001].tsrs == {21: TsrState.ACTIVE}

        with pytest.raises(StoreError, match="cannot start a transaction"), store.transaction():
            store.record_tsr_state(1002, 21, TsrState.ACTIVE, at_s=T0)
            _terminate_the_stores(postgres_server, postgres_dsn)  # in the middle of one
            store.audit("tsr_set", actor="dispatcher-7", at_s=T0, train_id=1002)
        assert 1002 not in store.load().trains and store.audit_log() == []


def test_a_commit_after_a_failed_statement_is_reported_not_silently_rolled_back(
    postgres_dsn: str,
) -> None:
    with open_store(postgres_dsn) as store:
        with pytest.raises(StoreError, match=r"cannot commit .* rolled back"), store.transaction():
            store.audit("x", actor="a", at_s=T0)
            # a statement of the outer transaction itself (no savepoint) that fails:
            # PostgreSQL then answers COMMIT with ROLLBACK
            with pytest.raises(StoreError, match="division by zero"):
                store._read("SELECT 1 / 0")
        assert store.audit_log() == []
