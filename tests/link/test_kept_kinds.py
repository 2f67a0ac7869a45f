"""The one description of an acknowledged ground-to-train message (``ACK``, ``KEY``,
``KIND``, ``REPLACES`` on its class) and what the link derives from it."""

from __future__ import annotations

import dataclasses

import pytest

from railpilot.link import (
    ANSWERS,
    KEPT_KINDS,
    MESSAGE_CLASSES,
    DeliveryAcknowledged,
    DispatchAck,
    DispatchCommand,
    LinkDirection,
    LocalProtocolError,
    TargetPoint,
    TargetPointAck,
    TargetPointResult,
    TargetReason,
    TrainRecord,
    TsrSet,
    acknowledgement,
    event_name,
    key_of,
)

ACKNOWLEDGED = [cls for cls in MESSAGE_CLASSES.values() if cls.ACK is not None]


@pytest.mark.parametrize("cls", ACKNOWLEDGED, ids=lambda c: c.__name__)
def test_an_acknowledged_message_goes_down_its_answer_up_both_carrying_the_key(
    cls: type,
) -> None:
    ack = cls.ACK
    assert cls.DIRECTION is LinkDirection.DOWNLINK
    assert ack.DIRECTION is LinkDirection.UPLINK
    assert ANSWERS[ack] is cls
    names = {f.name for f in dataclasses.fields(cls)}
    assert cls.KEY in names
    assert cls.KEY in {f.name for f in dataclasses.fields(ack)}


@pytest.mark.parametrize("kind", KEPT_KINDS)
def test_a_kept_kind_is_acknowledged_and_its_answer_defaults_to_the_positive_one(
    kind: str,
) -> None:
    cls = KEPT_KINDS[kind]
    assert kind == cls.KIND and cls.ACK is not None
    others = [f for f in dataclasses.fields(cls.ACK) if f.name != cls.KEY]
    assert all(f.default is not dataclasses.MISSING for f in others)


def test_the_kept_kinds_include_the_target_points_and_the_dispatch_commands_in_wire_order() -> None:
    kinds = list(KEPT_KINDS)
    assert kinds.index("target_point") < kinds.index("dispatch_command")
    assert [cls.TYPE for cls in KEPT_KINDS.values()] == sorted(c.TYPE for c in KEPT_KINDS.values())
    assert TargetPoint.REPLACES and not DispatchCommand.REPLACES


def test_acknowledgement_is_the_ack_with_the_key_and_the_positive_answer() -> None:
    assert acknowledgement(DispatchCommand(5, "hold")) == DispatchAck(5)
    target = TargetPoint(9, 1_000.0, TargetReason.TRAIN_AHEAD)
    assert acknowledgement(target) == TargetPointAck(9, TargetPointResult.ACCEPTED)
    assert key_of(DispatchAck(5)) == 5 == key_of(DispatchCommand(5, "hold"))
    with pytest.raises(TypeError, match="DispatchAck is not acknowledged"):
        acknowledgement(DispatchAck(5))


def test_a_record_keeps_every_kind_in_a_book_and_refuses_what_is_not_kept() -> None:
    record = TrainRecord(1001)
    assert [kind for kind, _ in record.delivery_books()] == list(KEPT_KINDS)
    with pytest.raises(LocalProtocolError, match="TsrSet is not kept"):
        record.add(TsrSet(1, 0.0, 10.0, 10.0, 0.0, 10.0))
    with pytest.raises(LocalProtocolError, match=r"'running_info'.*not kept kinds"):
        TrainRecord(1001, books={"running_info": {}})


def test_a_kept_message_replaces_or_is_refused_under_a_used_key() -> None:
    record = TrainRecord(1001)
    record.add(TargetPoint(1, 100.0, TargetReason.TRAIN_AHEAD))
    moved = TargetPoint(1, 200.0, TargetReason.TRAIN_AHEAD)
    record.add(moved)
    assert record.target_points[1].message == moved
    record.add(DispatchCommand(3, "hold"))
    with pytest.raises(LocalProtocolError, match="dispatch command 3 already queued"):
        record.add(DispatchCommand(3, "go"))


def test_a_kind_without_an_event_of_its_own_is_named_after_its_kind() -> None:
    event = DeliveryAcknowledged(1001, "driver_notice", 4, TargetPointResult.ACCEPTED)
    assert event_name(event) == "DriverNoticeAcknowledged"
