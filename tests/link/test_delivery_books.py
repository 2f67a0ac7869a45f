"""The journal commits every delivery change of a long day, though a step looks only at
what may still change (ground/journal.py ``GroundJournal._changes``)."""

from __future__ import annotations

from pathlib import Path

from railpilot.ground.journal import GroundJournal, target_point_request
from railpilot.ground.store import Store
from railpilot.link import (
    DeliveryState,
    GroundEndpoint,
    TargetPoint,
    TargetReason,
    TrainRecord,
)
from railpilot.link.messages import MessageType

from .helpers import TRAIN_ID, FakeLink, frame_type, registered_link


class DropAcks:
    """Drops the train's target-point acknowledgements while ``dropping``."""

    def __init__(self) -> None:
        self.dropping = False

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        if not self.dropping:
            return frames
        return [w for w in frames if frame_type(w) != MessageType.TARGET_POINT_ACK]


def _send(journal: GroundJournal, link: FakeLink, target: TargetPoint) -> None:
    """The ground sends ``target`` as the live ground does: committed, then sent."""

    def apply(dest: GroundEndpoint | TrainRecord, now_s: float) -> None:
        if isinstance(dest, GroundEndpoint):
            dest.send_target_point(target, now_s)
        else:
            dest.add_target_point(target)

    record = link.records[TRAIN_ID]
    journal.commit_request(
        record, TRAIN_ID, target_point_request(target, "test"), apply, link.now_s
    )
    apply(link.ground, link.now_s)


def _run(journal: GroundJournal, link: FakeLink, seconds: float) -> None:
    """Run the link, committing each step as the ground does."""
    end = link.now_s + seconds
    while link.now_s < end - 1e-9:
        link.now_s += 0.1
        seen = len(link.ground_events)
        link.step()
        journal.commit_step(link.records[TRAIN_ID], link.ground_events[seen:], link.now_s)


def _stored_targets(store: Store) -> dict[int, tuple[TargetPoint, DeliveryState]]:
    return dict(store.load().trains[TRAIN_ID].target_points)


def _books(record: TrainRecord) -> dict[int, tuple[TargetPoint, DeliveryState]]:
    return {i: (d.message, d.state) for i, d in record.target_points.items()}


def test_every_acknowledgement_of_a_long_day_is_committed(tmp_path: Path) -> None:
    drop = DropAcks()
    link = registered_link(uplink=drop)
    store = Store(tmp_path / "ground.db")
    journal = GroundJournal(store)
    journal.commit_step(link.records[TRAIN_ID], list(link.ground_events), link.now_s)
    targets = [TargetPoint(i, 1_000.0 * i, TargetReason.TRAIN_AHEAD) for i in range(1, 41)]
    # acknowledged at once, then the last ones' acknowledgements are lost for a while:
    # they stay pending, are resent, and are acknowledged once the losses end
    for target in targets:
        drop.dropping = target.target_id > 34
        _send(journal, link, target)
        _run(journal, link, 0.5)
    record = link.records[TRAIN_ID]
    pending = {i for i, d in record.target_points.items() if d.state is DeliveryState.PENDING}
    assert pending == set(range(35, 41))
    assert _stored_targets(store) == _books(record)

    drop.dropping = False
    _run(journal, link, 3.0)  # resent and acknowledged now
    assert all(d.state is DeliveryState.ACKNOWLEDGED for d in record.target_points.values())
    assert _stored_targets(store) == _books(record)
    assert not record.unacknowledged["target_point"]
    store.close()


def test_a_restored_journal_commits_the_acknowledgements_still_due(tmp_path: Path) -> None:
    drop = DropAcks()
    link = registered_link(uplink=drop)
    store = Store(tmp_path / "ground.db")
    journal = GroundJournal(store)
    for i in range(1, 11):
        drop.dropping = i > 6
        _send(journal, link, TargetPoint(i, 500.0 * i, TargetReason.TRAIN_AHEAD))
        _run(journal, link, 0.5)

    # the ground restarts from its store alone
    restored = GroundJournal(store)
    records, summary = restored.restore(store.load(), link.now_s, link.now_s)
    assert summary["pending"] == 4 and summary["acknowledged"] == 6
    record = records[TRAIN_ID]
    assert set(record.unacknowledged["target_point"]) == {7, 8, 9, 10}
    link.records.clear()
    link.records.update(records)
    link.onboard.connection_lost(link.now_s)
    link.ground.connection_lost(link.now_s)
    drop.dropping = False
    link.ground = GroundEndpoint(link.ground_cfg, link.keys, link.records)
    link.connect()
    _run(restored, link, 3.0)  # registers again: the pending ones are resent and acked
    assert all(d.state is DeliveryState.ACKNOWLEDGED for d in record.target_points.values())
    assert _stored_targets(store) == _books(record)
    store.close()
