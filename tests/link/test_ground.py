"""Ground endpoint behaviour: registration, supervision, deliveries, keys."""

from __future__ import annotations

import itertools

import pytest

from railpilot.link import (
    DeregisterReason,
    DispatchAcknowledged,
    DispatchCommand,
    FrameRejected,
    GroundEndpoint,
    GroundState,
    LinkFailed,
    LocalProtocolError,
    MessageReceived,
    PeriodicTimedOut,
    RegisterResult,
    RunningInfo,
    StateRejected,
    TargetPoint,
    TargetPointAcknowledged,
    TargetReason,
    TimeCheck,
    TimeOffsetReport,
    TrainDeregistered,
    TrainRegistered,
    TsrAcknowledged,
    TsrApplied,
    TsrCancelAcknowledged,
    TsrRefusedByTrain,
    TsrSet,
    TsrSetAck,
    TsrSetResult,
    TsrState,
    encode_body,
)
from railpilot.link.frame import parse_frame
from railpilot.link.framing import unstuff
from railpilot.link.ground import TrainRecord
from railpilot.link.messages import MessageType, RegisterResponse

from .helpers import (
    KEY_2,
    T0,
    TRAIN_ID,
    FakeLink,
    OnceFilter,
    ground_config,
    header_of,
    make_keys,
    registered_link,
    rewrite,
    running_info,
    split_frames,
)


def tsr(session: int = 1) -> TsrSet:
    return TsrSet(session, 10_000.0, 12_000.0, 12.5, T0, T0 + 3600.0)


def reconnect(link: FakeLink) -> None:
    link.onboard.connection_lost(link.now_s)
    link.ground.connection_lost(link.now_s)
    link.run(1.0)
    link.ground = link._new_ground()
    link.connect()
    link.run(0.5)


def test_registration_binds_the_connection_to_the_train() -> None:
    link = registered_link()
    assert link.ground.state is GroundState.REGISTERED
    assert link.ground.train_id == TRAIN_ID
    assert [e.train_id for e in link.events_of("ground", TrainRegistered)] == [TRAIN_ID]
    assert link.records[TRAIN_ID].registered


def test_train_not_in_the_accepted_set_is_refused() -> None:
    link = FakeLink(ground_cfg=ground_config(accepted_trains=frozenset({555})))
    responses: list[object] = []
    link.downlink = lambda frames: (
        responses.extend(header_of(f).body for f in frames if header_of(f).message_type == 0x02)
        or frames
    )
    link.connect()
    link.step()
    assert responses == [encode_body(RegisterResponse(RegisterResult.UNKNOWN_TRAIN))]
    assert link.ground.state is GroundState.AWAITING_REGISTRATION
    assert not link.events_of("ground", TrainRegistered)


def test_resent_register_request_is_answered_without_registering_twice() -> None:
    link = FakeLink()
    link.downlink = OnceFilter(MessageType.REGISTER_RESPONSE, lambda w: [])
    link.connect()
    link.run(3.0)
    assert len(link.events_of("ground", TrainRegistered)) == 1


def test_deregistration_marks_the_train_and_reports_the_reason() -> None:
    link = registered_link()
    link.onboard.deregister(DeregisterReason.MANUAL_SHUTDOWN, link.now_s)
    link.run(0.5)
    assert link.events_of("ground", TrainDeregistered) == [
        TrainDeregistered(TRAIN_ID, DeregisterReason.MANUAL_SHUTDOWN)
    ]
    assert not link.records[TRAIN_ID].registered
    assert link.ground.state is GroundState.DEREGISTERED


def test_time_check_is_sent_at_registration_and_every_interval() -> None:
    link = registered_link()
    link.run(125.0, dt_s=0.5)
    reports = [
        e.message
        for e in link.events_of("ground", MessageReceived)
        if isinstance(e.message, TimeOffsetReport)
    ]
    assert len(reports) == 3  # at 0 s, 60 s and 120 s
    assert link.records[TRAIN_ID].time_offset_s == 0.0


def test_running_info_is_held_between_cycles_then_invalid_after_timeout() -> None:
    link = registered_link()
    link.onboard.update_running_info(running_info(1000.0))
    link.run(1.0)
    link.uplink = lambda frames: []
    link.run(2.5)
    held = link.ground.held_value(MessageType.RUNNING_INFO)
    assert held is not None and held.valid and held.message == running_info(1000.0)
    link.run(2.0)
    assert not held.valid
    assert not link.records[TRAIN_ID].running_info.valid
    timed_out = {e.message_type for e in link.events_of("ground", PeriodicTimedOut)}
    assert timed_out <= {MessageType.RUNNING_INFO, MessageType.HEARTBEAT} and timed_out
    assert len(link.events_of("ground", LinkFailed)) == 1
    assert link.ground.state is GroundState.FAILED


def test_newest_running_info_of_one_receive_cycle_is_delivered_alone() -> None:
    link = registered_link()
    pending = b""
    for km in (1, 2, 3):
        link.onboard.update_running_info(running_info(km * 1000.0))
        link.onboard.tick(link.now_s + km * 1.0)  # one running info per 1 s cycle
        pending += link.onboard.data_to_send()
    link.ground.receive_data(pending, link.now_s + 3.0)
    infos = [e.message for e in link.ground.events() if isinstance(e, MessageReceived)]
    assert [i.position_m for i in infos if isinstance(i, RunningInfo)] == [3000.0]
    assert link.ground.counters.superseded == 2


def test_tsr_set_while_the_train_is_offline_is_delivered_after_registration() -> None:
    link = FakeLink()
    link.records[TRAIN_ID] = TrainRecord(TRAIN_ID)
    link.records[TRAIN_ID].add_tsr(tsr())
    link.connect()
    link.run(0.5)
    assert len(link.events_of("onboard", TsrApplied)) == 1
    assert link.events_of("ground", TsrAcknowledged) == [TsrAcknowledged(TRAIN_ID, 1)]


def test_active_tsr_is_reconfirmed_silently_after_a_reconnect() -> None:
    link = registered_link()
    link.ground.set_tsr(tsr(), link.now_s)
    link.run(0.5)
    reconnect(link)
    assert link.ground.tsr_state(1) is TsrState.ACTIVE
    assert len(link.events_of("ground", TsrAcknowledged)) == 1
    assert len(link.events_of("onboard", TsrApplied)) == 1
    assert link.ground.counters.frames_received > 0


def test_refused_tsr_is_reported_and_not_resent() -> None:
    link = registered_link()
    link.ground.set_tsr(TsrSet(1, 500.0, 500.0, 10.0, T0, T0 + 60), link.now_s)
    link.run(5.0)
    assert link.events_of("ground", TsrRefusedByTrain) == [
        TsrRefusedByTrain(TRAIN_ID, 1, TsrSetResult.INVALID)
    ]
    assert link.ground.tsr_state(1) is TsrState.REFUSED
    assert link.ground.counters.resends == 0


def test_cancel_acknowledgement_ends_the_session() -> None:
    link = registered_link()
    link.ground.set_tsr(tsr(), link.now_s)
    link.run(0.5)
    link.ground.cancel_tsr(1, link.now_s)
    link.run(0.5)
    [ack] = link.events_of("ground", TsrCancelAcknowledged)
    assert ack.session == 1
    assert link.ground.tsr_state(1) is TsrState.CANCELLED


def test_unacknowledged_tsr_is_resent_every_interval() -> None:
    link = registered_link()
    link.uplink = lambda frames: [f for f in frames if header_of(f).message_type != 0x31]
    link.ground.set_tsr(tsr(), link.now_s)
    link.run(3.0)  # resend interval 2 s, link timeout after 4 s
    assert link.ground.counters.resends == 1
    assert link.ground.tsr_state(1) is TsrState.PENDING_SET


def test_tsr_validity_end_stops_delivery() -> None:
    link = registered_link()
    link.downlink = lambda frames: [f for f in frames if header_of(f).message_type != 0x30]
    link.ground.set_tsr(TsrSet(1, 500.0, 900.0, 10.0, T0, T0 + 1.0), link.now_s)
    link.run(1.5)
    assert link.ground.tsr_state(1) is TsrState.EXPIRED


def test_acknowledgement_for_a_session_never_sent_is_a_state_rejection() -> None:
    link = registered_link()
    link.uplink = OnceFilter(
        MessageType.HEARTBEAT,
        lambda w: [
            rewrite(
                w,
                message_type=MessageType.TSR_SET_ACK,
                body=encode_body(TsrSetAck(99, TsrSetResult.APPLIED)),
            )
        ],
    )
    link.run(1.0)
    assert [type(e) for e in link.ground_events if isinstance(e, FrameRejected)] == [StateRejected]


def test_reusing_a_tsr_session_for_another_restriction_is_refused() -> None:
    link = registered_link()
    link.ground.set_tsr(tsr(), link.now_s)
    with pytest.raises(LocalProtocolError, match="session 1"):
        link.ground.set_tsr(TsrSet(1, 0.0, 5.0, 5.0, T0, T0 + 60), link.now_s)


def test_acked_deliveries_cannot_be_sent_through_send() -> None:
    link = registered_link()
    with pytest.raises(LocalProtocolError, match="set_tsr"):
        link.ground.send(tsr(), link.now_s)


def test_time_check_can_be_sent_on_demand() -> None:
    link = registered_link()
    link.ground.send(TimeCheck(link.now_s), link.now_s)
    assert [header_of(f).message_type for f in split_frames(link.ground.data_to_send())] == [
        MessageType.TIME_CHECK
    ]


def test_dispatch_command_acknowledgement_is_reported_once() -> None:
    link = registered_link()
    link.ground.send_dispatch_command(DispatchCommand(3, "stop at Suning North"), link.now_s)
    link.run(1.0)
    assert link.events_of("ground", DispatchAcknowledged) == [DispatchAcknowledged(TRAIN_ID, 3)]


def test_target_point_acknowledgement_is_reported() -> None:
    link = registered_link()
    link.ground.send_target_point(TargetPoint(8, 55_000.0, TargetReason.SECTION_FAULT), link.now_s)
    link.run(0.5)
    [ack] = link.events_of("ground", TargetPointAcknowledged)
    assert ack.target_id == 8


def test_deliveries_before_any_train_is_known_are_refused() -> None:
    ground = GroundEndpoint(ground_config(), make_keys())
    with pytest.raises(LocalProtocolError, match="no train"):
        ground.set_tsr(tsr(), T0)


def test_key_rotation_keeps_the_link_up() -> None:
    link = registered_link()
    link.onboard.update_running_info(running_info(1000.0))
    link.run(2.0)
    link.keys.add_key(TRAIN_ID, 2, KEY_2)  # installed at both ends (shared store here)
    link.keys.set_active(TRAIN_ID, 2)
    link.run(2.0)
    link.keys.remove_key(TRAIN_ID, 1)
    link.run(2.0)
    assert not [e for e in link.ground_events + link.onboard_events if isinstance(e, FrameRejected)]
    assert not link.events_of("ground", LinkFailed)
    assert header_of(link.onboard._channel.encode(running_info(1.0), link.now_s)).key_id == 2
    infos = [
        e for e in link.events_of("ground", MessageReceived) if isinstance(e.message, RunningInfo)
    ]
    assert len(infos) == 6


def test_onboard_and_ground_with_separate_stores_rotate_in_either_order() -> None:
    from railpilot.link import OnboardEndpoint

    from .helpers import onboard_config

    onboard_keys, ground_keys = make_keys(), make_keys()
    link = FakeLink(keys=ground_keys)
    link.onboard = OnboardEndpoint(onboard_config(), onboard_keys)
    link.connect()
    link.onboard.update_running_info(running_info(1000.0))
    link.run(1.0)
    for store in (onboard_keys, ground_keys):
        store.add_key(TRAIN_ID, 2, KEY_2)
    onboard_keys.set_active(TRAIN_ID, 2)  # onboard first: ground still sends with key 1
    link.run(2.0)
    ground_keys.set_active(TRAIN_ID, 2)
    link.run(2.0)
    assert not [e for e in link.ground_events + link.onboard_events if isinstance(e, FrameRejected)]
    assert link.ground.state is GroundState.REGISTERED


def test_ground_heartbeats_every_cycle() -> None:
    # section 9: the ground sends a HEARTBEAT every cycle_s (1 s), on the fake clock
    link = registered_link()
    sent_at: list[float] = []

    def record(frames: list[bytes]) -> list[bytes]:
        for wire in frames:
            frame = parse_frame(unstuff(wire[1:]))
            if frame.message_type == MessageType.HEARTBEAT:
                sent_at.append(link.now_s)
        return frames

    link.downlink = record
    step = 0.1
    link.run(10.0, dt_s=step)
    gaps = [b - a for a, b in itertools.pairwise(sent_at)]
    assert len(sent_at) >= 9
    # at the first tick at or after each cycle's deadline: within one fake-clock step
    assert max(gaps) <= link.ground_cfg.timers.cycle_s + step + 1e-6
