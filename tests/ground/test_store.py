"""The ground store: round trips, schema version, audit order, bad input - on both
backends (``sqlite``: a file; ``postgres``: a fresh database on the test server of
tests/ground/postgres.py, skipped where PostgreSQL is not installed), plus what only
SQLite has (WAL, a file path). PostgreSQL's own: test_store_postgres.py."""

from __future__ import annotations

import sqlite3
from contextlib import closing
from pathlib import Path

import pytest

from railpilot.ground.store import (
    SCHEMA_VERSION,
    GroundStore,
    Store,
    StoreError,
    is_postgres_url,
    open_store,
)
from railpilot.link import (
    DeliveryState,
    DispatchCommand,
    RegisterRequest,
    TargetPoint,
    TargetReason,
    TsrSet,
    TsrState,
)

T0 = 1_700_000_000.0
TSR = TsrSet(21, 5_000.0, 6_000.0, 40 / 3.6, T0, T0 + 3600.0)


@pytest.fixture(params=["sqlite", "postgres"])
def target(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """Where a store is kept (``open_store`` picks the backend from it)."""
    if request.param == "sqlite":
        return str(tmp_path / "ground.db")
    dsn: str = request.getfixturevalue("postgres_dsn")
    return dsn


def _behind_the_store(target: str, sql: str) -> None:
    """One statement run past the store, as a DBA or a newer railpilot would."""
    if is_postgres_url(target):
        import psycopg

        with psycopg.connect(target, autocommit=True) as db:
            db.execute(sql.encode())
    else:
        with closing(sqlite3.connect(target)) as db, db:
            db.execute(sql)


def _filled(store: GroundStore) -> None:
    store.record_tsr(TSR, actor="dispatcher-7", reason="track work", at_s=T0)
    store.record_tsr_state(1001, 21, TsrState.ACTIVE, at_s=T0 + 1)
    store.record_tsr_state(1002, 21, TsrState.PENDING_SET, at_s=T0 + 1)
    store.record_delivery(1001, TargetPoint(3, 7_500.0, TargetReason.TRAIN_AHEAD), _P, at_s=T0)
    store.record_delivery(1001, DispatchCommand(42, "hold at Datong"), _P, at_s=T0)
    store.record_registration(1001, RegisterRequest("K1001", "SS4-0001", 7, 600.0), at_s=T0)


_P = DeliveryState.PENDING
_A = DeliveryState.ACKNOWLEDGED


def test_a_sqlite_store_is_in_wal_mode_with_full_sync_and_the_current_schema(
    tmp_path: Path,
) -> None:
    with Store(tmp_path / "ground.db") as store:
        assert store.journal_mode == "wal"
        assert store.synchronous == "FULL"
        assert store.schema_version == SCHEMA_VERSION
    with Store(tmp_path / "normal.db", synchronous="NORMAL") as store:
        assert store.synchronous == "NORMAL"


def test_everything_written_is_loaded_back_after_reopening(target: str) -> None:
    with open_store(target) as store:
        _filled(store)
    with open_store(target) as store:
        assert store.schema_version == SCHEMA_VERSION
        snapshot = store.load()
    stored = snapshot.tsrs[21]
    assert stored.tsr == TSR  # floats round-trip exactly (REAL, DOUBLE PRECISION)
    assert (stored.actor, stored.reason, stored.set_at_s) == ("dispatcher-7", "track work", T0)
    assert stored.cancelled_at_s is None
    first, second = snapshot.trains[1001], snapshot.trains[1002]
    assert first.tsrs == {21: TsrState.ACTIVE} and second.tsrs == {21: TsrState.PENDING_SET}
    assert first.target_points == {3: (TargetPoint(3, 7_500.0, TargetReason.TRAIN_AHEAD), _P)}
    assert first.dispatch_commands == {42: (DispatchCommand(42, "hold at Datong"), _P)}
    assert first.registration == RegisterRequest("K1001", "SS4-0001", 7, 600.0)
    assert first.registered_at_s == T0
    assert second.registration is None and second.registered_at_s is None


def test_states_are_updated_in_place(target: str) -> None:
    with open_store(target) as store:
        _filled(store)
        store.record_tsr_state(1002, 21, TsrState.ACTIVE, at_s=T0 + 2)
        store.record_tsr_state(1001, 21, TsrState.PENDING_CANCEL, at_s=T0 + 3)
        store.record_tsr_cancel(21, actor="dispatcher-8", at_s=T0 + 3)
        store.record_tsr_cancel(21, actor="dispatcher-9", at_s=T0 + 4)  # the first stays
        store.record_delivery_state(1001, TargetPoint, 3, DeliveryState.ACKNOWLEDGED, at_s=T0)
        store.record_delivery_state(1001, DispatchCommand, 42, DeliveryState.ACKNOWLEDGED, at_s=T0)
        snapshot = store.load()
    assert snapshot.trains[1001].tsrs == {21: TsrState.PENDING_CANCEL}
    assert snapshot.trains[1002].tsrs == {21: TsrState.ACTIVE}
    assert (snapshot.tsrs[21].cancelled_at_s, snapshot.tsrs[21].cancelled_by) == (
        T0 + 3,
        "dispatcher-8",
    )
    first = snapshot.trains[1001]
    assert first.target_points[3][1] is DeliveryState.ACKNOWLEDGED
    assert first.dispatch_commands[42][1] is DeliveryState.ACKNOWLEDGED


def test_a_new_target_point_under_the_same_id_replaces_the_old(target: str) -> None:
    with open_store(target) as store:
        _filled(store)
        store.record_delivery_state(1001, TargetPoint, 3, DeliveryState.ACKNOWLEDGED, at_s=T0)
        moved = TargetPoint(3, 9_000.0, TargetReason.SECTION_FAULT)
        store.record_delivery(1001, moved, _P, at_s=T0 + 5)
        assert store.load().trains[1001].target_points == {3: (moved, _P)}


def test_the_same_tsr_again_is_a_no_op_but_a_reused_session_is_refused(target: str) -> None:
    with open_store(target) as store:
        store.record_tsr(TSR, actor="dispatcher-7", reason="track work", at_s=T0)
        store.record_tsr(TSR, actor="someone-else", reason="", at_s=T0 + 9)
        assert store.load().tsrs[21].actor == "dispatcher-7"
        other = TsrSet(21, 5_000.0, 6_000.0, 60 / 3.6, T0, T0 + 3600.0)
        with pytest.raises(StoreError, match=r"tsr.session = 21 is not allowed: expected a sess"):
            store.record_tsr(other, actor="dispatcher-7", at_s=T0)
        assert store.load().tsrs[21].tsr == TSR


def test_a_dispatch_command_number_names_one_text_for_good(target: str) -> None:
    with open_store(target) as store:
        _filled(store)
        with pytest.raises(StoreError, match=r"message\.command_number = 42 is not allowed"):
            store.record_delivery(1001, DispatchCommand(42, "other text"), _P, at_s=T0)


def test_the_audit_log_keeps_the_order_of_writing(target: str) -> None:
    with open_store(target) as store:
        first = store.audit("tsr_set", actor="dispatcher-7", at_s=T0 + 5, train_id=1001)
        store.audit(
            "tsr_acknowledged",
            actor="train 1001",
            at_s=T0 + 1,  # an earlier clock reading: the order is still that of writing
            train_id=1001,
            detail={"session": 21},
        )
        store.audit("tsr_set", actor="dispatcher-7", at_s=T0 + 6, train_id=1002)
        log = store.audit_log()
        assert [e.action for e in log] == ["tsr_set", "tsr_acknowledged", "tsr_set"]
        assert [e.seq for e in log] == [first, first + 1, first + 2]
        assert log[1].detail == {"session": 21} and log[1].actor == "train 1001"
        assert [e.train_id for e in store.audit_log(train_id=1002)] == [1002]
        assert [e.action for e in store.audit_log(after_seq=first)] == [
            "tsr_acknowledged",
            "tsr_set",
        ]


def test_a_transaction_commits_together_or_not_at_all(target: str) -> None:
    with open_store(target) as store:
        store.record_tsr(TSR, actor="dispatcher-7", at_s=T0)
        with pytest.raises(StoreError), store.transaction():
            store.record_tsr_state(1001, 21, TsrState.PENDING_SET, at_s=T0)
            store.audit("tsr_set", actor="dispatcher-7", at_s=T0, train_id=1001)
            store.record_tsr_state(1001, 99, TsrState.PENDING_SET, at_s=T0)  # no such TSR
        assert store.load().trains == {} and store.audit_log() == []
        with store.transaction():
            store.record_tsr_state(1001, 21, TsrState.PENDING_SET, at_s=T0)
            with pytest.raises(StoreError), store.transaction():  # a savepoint
                store.audit("x", actor="a", at_s=T0)
                store.audit("", actor="a", at_s=T0)
        assert store.load().trains[1001].tsrs == {21: TsrState.PENDING_SET}
        assert store.audit_log() == []


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda s: s.record_tsr_state(0, 21, TsrState.ACTIVE, at_s=T0), "train_id = 0 is not"),
        (lambda s: s.record_tsr_state(1, 21, "ACTIVE", at_s=T0), "state = 'ACTIVE' is not"),
        (lambda s: s.record_tsr_state(1, 22, TsrState.ACTIVE, at_s=T0), "session = 22 is not"),
        (lambda s: s.record_tsr(TSR, actor="", at_s=T0), "actor = '' is not"),
        (lambda s: s.record_tsr(TSR, actor="a\nb", at_s=T0), "actor = 'a\\\\nb' is not"),
        (lambda s: s.record_tsr(TSR, actor="a", at_s=float("nan")), "at_s = nan is not"),
        (lambda s: s.record_tsr(TSR, actor="a", reason="x" * 201, at_s=T0), "reason = 'xx"),
        (lambda s: s.record_delivery(1, TSR, _P, at_s=T0), "message = TsrSet"),
        (
            lambda s: s.record_delivery_state(1, TargetPoint, 3, _P, at_s=T0),
            "ident = 3 is not allowed: expected a TargetPoint recorded for train 1 first",
        ),
        (lambda s: s.audit("x", actor="a", at_s=T0, detail={"v": float("inf")}), "detail = "),
        (lambda s: s.audit("x", actor="a", at_s=-1.0), "at_s = -1.0 is not"),
    ],
)
def test_bad_input_is_refused_naming_the_field_and_nothing_is_written(
    target: str, call: object, message: str
) -> None:
    with open_store(target) as store:
        store.record_tsr(TSR, actor="dispatcher-7", at_s=T0)
        before = (store.load(), store.audit_log())
        with pytest.raises(StoreError, match=message) as raised:
            call(store)  # type: ignore[operator]
        assert "is not allowed: expected" in str(raised.value)
        assert str(raised.value).endswith("; nothing was written")
        assert (store.load(), store.audit_log()) == before


def test_a_bad_sqlite_path_is_refused(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match=r"path = .* not a directory"):
        Store(tmp_path)
    with pytest.raises(StoreError, match=r"path = .* an existing directory"):
        Store(tmp_path / "missing" / "ground.db")
    foreign = tmp_path / "notes.txt"
    foreign.write_text("not a database, but a text file long enough to have a header\n" * 20)
    with pytest.raises(StoreError, match=r"path = .*notes\.txt"):
        Store(foreign)
    assert foreign.read_text().startswith("not a database")
    with pytest.raises(StoreError, match="synchronous = 'OFF' is not allowed"):
        Store(tmp_path / "x.db", synchronous="OFF")
    assert not (tmp_path / "x.db").exists()


def test_a_store_written_by_a_newer_railpilot_is_refused(target: str) -> None:
    with open_store(target):
        pass
    _behind_the_store(target, f"UPDATE schema_version SET version = {SCHEMA_VERSION + 1}")
    with pytest.raises(StoreError, match=f"schema_version = {SCHEMA_VERSION + 1} is not allowed"):
        open_store(target)


def test_a_database_of_something_else_is_refused_and_left_alone(target: str) -> None:
    _behind_the_store(target, "CREATE TABLE t (x INTEGER)")
    with pytest.raises(StoreError, match=r"(path|db) = .* a railpilot ground store") as raised:
        open_store(target)
    assert raised.value.field == ("db" if is_postgres_url(target) else "path")
    _behind_the_store(target, "INSERT INTO t (x) VALUES (1)")  # still there, untouched


def test_open_store_picks_the_backend_from_the_target(tmp_path: Path) -> None:
    with open_store(tmp_path / "ground.db") as store:
        assert type(store) is Store and store.path == str(tmp_path / "ground.db")
    with open_store(":memory:") as store:
        assert type(store) is Store
    assert is_postgres_url("postgresql://ground@db/railpilot")
    assert is_postgres_url("POSTGRES://ground@db/railpilot")
    assert not is_postgres_url("ground.db") and not is_postgres_url("postgresql.db")


#: Where schema 1 kept the target points and the dispatch commands: a table each (types
#: both backends take).
_SCHEMA_1_TABLES = (
    "CREATE TABLE target_points (train_id BIGINT NOT NULL, target_id BIGINT NOT NULL, "
    "position_m DOUBLE PRECISION NOT NULL, reason TEXT NOT NULL, state TEXT NOT NULL, "
    "updated_at_s DOUBLE PRECISION NOT NULL, PRIMARY KEY (train_id, target_id))",
    "CREATE TABLE dispatch_commands (train_id BIGINT NOT NULL, command_number BIGINT NOT NULL, "
    "text TEXT NOT NULL, state TEXT NOT NULL, updated_at_s DOUBLE PRECISION NOT NULL, "
    "PRIMARY KEY (train_id, command_number))",
)


def test_a_schema_1_store_opens_with_its_deliveries(target: str) -> None:
    position_m = 7_500.0 + 1 / 3  # no decimal writes it exactly: it must come back bit for bit
    open_store(target).close()
    for sql in (
        *_SCHEMA_1_TABLES,
        f"INSERT INTO target_points VALUES (1001, 3, {position_m!r}, 'TRAIN_AHEAD', 'PENDING', 1)",
        "INSERT INTO dispatch_commands VALUES (1001, 42, 'hold at Datong', 'ACKNOWLEDGED', 2)",
        "DROP TABLE deliveries",
        "UPDATE schema_version SET version = 1",
    ):
        _behind_the_store(target, sql)
    with open_store(target) as store:
        assert store.schema_version == SCHEMA_VERSION
        train = store.load().trains[1001]
        assert train.target_points == {
            3: (TargetPoint(3, position_m, TargetReason.TRAIN_AHEAD), DeliveryState.PENDING)
        }
        assert train.dispatch_commands == {
            42: (DispatchCommand(42, "hold at Datong"), DeliveryState.ACKNOWLEDGED)
        }
        # the command number still names its command for good
        store.record_delivery(1001, DispatchCommand(42, "hold at Datong"), _A, at_s=T0)
        with pytest.raises(StoreError, match="command_number = 42 is not allowed"):
            store.record_delivery(1001, DispatchCommand(42, "go on"), _P, at_s=T0)
    with open_store(target) as store:  # migrated once: opened again, nothing changes
        assert store.load().trains[1001].target_points[3][0].position_m == position_m
