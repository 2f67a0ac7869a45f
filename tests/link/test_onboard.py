"""Onboard endpoint behaviour: registration, deregistration, time check, TSR handling."""

from __future__ import annotations

import pytest

from railpilot.link import (
    Deregistered,
    DeregisterReason,
    DispatchCommand,
    DispatchCommandReceived,
    GroundEndpoint,
    LinkFailed,
    LocalProtocolError,
    MessageReceived,
    OnboardEndpoint,
    OnboardState,
    PeriodicTimedOut,
    PlannedCurve,
    Registered,
    RegistrationRefused,
    RunningInfo,
    TargetPoint,
    TargetPointAcknowledged,
    TargetPointReceived,
    TargetReason,
    TimeCheck,
    TimeChecked,
    TravelDirection,
    TsrApplied,
    TsrCancelled,
    TsrExpired,
    TsrRefused,
    TsrSet,
    TsrSetResult,
)
from railpilot.link.messages import MessageType

from .helpers import (
    T0,
    FakeLink,
    OnceFilter,
    frame_type,
    ground_config,
    header_of,
    make_keys,
    onboard_config,
    registered_link,
    running_info,
    split_frames,
)


def tsr(session: int = 1, start_m: float = 10_000.0, end_m: float = 12_000.0) -> TsrSet:
    return TsrSet(session, start_m, end_m, 12.5, T0, T0 + 3600.0)


def sent_types(frames: list[bytes]) -> list[int]:
    return [header_of(f).message_type for f in frames]


def test_first_frame_is_a_heartbeat_and_registration_waits_for_the_ground() -> None:
    # protocol.md 6.16: HEARTBEAT (echo 0) first; REGISTER_REQUEST only once a ground frame
    # was accepted, echoing it (5.3), so a withheld request can never take effect later
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    ground = GroundEndpoint(ground_config(), make_keys())
    onboard.connection_made(T0)
    ground.connection_made(T0)
    first = split_frames(onboard.data_to_send())
    assert sent_types(first) == [MessageType.HEARTBEAT]
    assert header_of(first[0]).echo_timestamp_us == 0
    onboard.tick(T0 + 1.5)  # nothing heard: heartbeats only, however long it waits
    assert set(sent_types(split_frames(onboard.data_to_send()))) == {MessageType.HEARTBEAT}
    ground.receive_data(b"".join(first), T0 + 1.5)
    challenge = ground.data_to_send()
    assert sent_types(split_frames(challenge)) == [MessageType.HEARTBEAT]
    onboard.receive_data(challenge, T0 + 1.6)
    request = split_frames(onboard.data_to_send())
    assert sent_types(request) == [MessageType.REGISTER_REQUEST]
    assert (
        header_of(request[0]).echo_timestamp_us
        == header_of(split_frames(challenge)[0]).timestamp_us
    )
    assert onboard.state is OnboardState.REGISTERING


def test_no_frame_but_a_heartbeat_ever_carries_echo_zero() -> None:
    sent: list[bytes] = []

    def record(frames: list[bytes]) -> list[bytes]:
        sent.extend(frames)
        return frames

    link = FakeLink(uplink=record, segment_seed=3)
    link.onboard.update_running_info(running_info(1_000.0))
    link.connect()
    link.run(3.0)
    link.onboard.deregister(DeregisterReason.SHUNTING_MODE, link.now_s)
    link.run(1.0)
    headers = [header_of(f) for f in sent]
    assert {h.message_type for h in headers} >= {
        MessageType.REGISTER_REQUEST,
        MessageType.RUNNING_INFO,
        MessageType.DEREGISTER_REQUEST,
    }
    zero_echo = [h for h in headers if h.echo_timestamp_us == 0]
    # only the opening HEARTBEAT, sent before anything of the ground was heard
    assert [(h.message_type, h.sequence) for h in zero_echo] == [(MessageType.HEARTBEAT, 0)]


def test_accepted_registration_raises_registered_once() -> None:
    link = registered_link()
    assert link.onboard.state is OnboardState.REGISTERED
    assert len(link.events_of("onboard", Registered)) == 1


def test_refused_registration_is_retried_every_resend_interval() -> None:
    link = FakeLink(ground_cfg=ground_config(accepted_trains=frozenset({555})))
    requests: list[bytes] = []
    link.uplink = lambda frames: (
        requests.extend(f for f in frames if header_of(f).message_type == 0x01) or frames
    )
    link.connect()
    link.run(5.0)
    assert len(requests) == 3  # at 0 s, 2 s and 4 s with resend_interval_s = 2
    assert len(link.events_of("onboard", RegistrationRefused)) == 3
    assert link.onboard.state is OnboardState.REGISTERING


def test_lost_register_response_is_recovered_by_resending_the_request() -> None:
    link = FakeLink()
    link.downlink = OnceFilter(MessageType.REGISTER_RESPONSE, lambda w: [])
    link.connect()
    link.run(3.0)
    assert link.onboard.state is OnboardState.REGISTERED
    assert len(link.events_of("onboard", Registered)) == 1


def test_onboard_registers_again_after_every_reconnect() -> None:
    link = registered_link(auto_reconnect=True)
    for _ in range(2):
        link.onboard.connection_lost(link.now_s)
        link.ground.connection_lost(link.now_s)
        link.ground = link._new_ground()
        link.connect()
        link.run(1.0)
    assert len(link.events_of("onboard", Registered)) == 3
    assert link.onboard.state is OnboardState.REGISTERED


@pytest.mark.parametrize("reason", list(DeregisterReason))
def test_deregistration_is_confirmed_with_its_reason(reason: DeregisterReason) -> None:
    link = registered_link()
    link.onboard.deregister(reason, link.now_s)
    link.run(0.5)
    assert link.events_of("onboard", Deregistered) == [Deregistered(reason)]
    assert link.onboard.state is OnboardState.DEREGISTERED


def test_deregistration_is_resent_until_confirmed() -> None:
    link = registered_link()
    link.downlink = OnceFilter(MessageType.DEREGISTER_RESPONSE, lambda w: [])
    link.onboard.deregister(DeregisterReason.LEAVING_MAIN_LINE, link.now_s)
    link.run(3.0)
    assert len(link.events_of("onboard", Deregistered)) == 1
    assert link.onboard.counters.resends == 1


def test_running_info_stops_after_deregistration() -> None:
    link = registered_link()
    link.onboard.update_running_info(running_info(1000.0))
    link.onboard.deregister(DeregisterReason.SHUNTING_MODE, link.now_s)
    link.run(0.5)
    before = len(link.events_of("ground", MessageReceived))
    link.run(3.0)
    assert len(link.events_of("ground", MessageReceived)) == before


def test_register_again_after_deregistration() -> None:
    link = registered_link()
    link.onboard.deregister(DeregisterReason.SHUNTING_MODE, link.now_s)
    link.run(0.5)
    link.onboard.register(link.now_s)
    link.run(0.5)
    assert link.onboard.state is OnboardState.REGISTERED
    assert len(link.events_of("onboard", Registered)) == 2


def test_running_info_is_sent_every_cycle_while_registered() -> None:
    link = registered_link()
    link.onboard.update_running_info(running_info(1000.0))
    link.run(5.0)
    infos = [e for e in link.ground_events if isinstance(e, MessageReceived)]
    assert sum(isinstance(e.message, RunningInfo) for e in infos) == 5


def test_running_info_leaves_with_the_heartbeat_in_one_write() -> None:
    # One write a cycle, not two (protocol.md 7): the first RUNNING_INFO restarts the
    # heartbeat's cycle, and from then on both fall due in the same tick.
    link = registered_link()
    writes: list[list[int]] = []

    def record(frames: list[bytes]) -> list[bytes]:
        writes.append([frame_type(f) for f in frames])
        return frames

    link.uplink = record
    link.onboard.update_running_info(running_info(1000.0))
    link.run(10.0)
    assert writes == [[MessageType.HEARTBEAT, MessageType.RUNNING_INFO]] * 10
    assert not link.events_of("ground", LinkFailed)


def test_planned_curve_is_delivered_to_the_ground() -> None:
    link = registered_link()
    curve = PlannedCurve(1, 2, 600.0, 900.0)
    link.onboard.send(curve, link.now_s)
    link.run(0.1)
    assert curve in [e.message for e in link.events_of("ground", MessageReceived)]


def test_sending_before_registration_is_a_local_protocol_error() -> None:
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    with pytest.raises(LocalProtocolError, match="not allowed in state DISCONNECTED"):
        onboard.send(PlannedCurve(1, 2, 1.0, 1.0), T0)
    assert onboard.data_to_send() == b""


def test_receive_data_before_connecting_is_a_local_protocol_error() -> None:
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    with pytest.raises(LocalProtocolError):
        onboard.receive_data(b"\x7e\x01", T0)


def test_time_check_reports_the_onboard_clock_offset() -> None:
    link = registered_link()
    ground_time = link.now_s
    link.ground.send(TimeCheck(ground_time), ground_time)
    data = link.ground.data_to_send()
    link.onboard.receive_data(data, ground_time + 0.25)
    checked = [e for e in link.onboard.events() if isinstance(e, TimeChecked)]
    assert checked == [TimeChecked(ground_time, pytest.approx(0.25))]
    assert link.onboard.time_offset_s == pytest.approx(0.25)


def test_ground_heartbeat_timeout_fails_the_link_after_the_threshold() -> None:
    link = registered_link()
    link.downlink = lambda frames: []
    link.run(3.5)  # 3 missed cycles: still within the threshold
    assert not link.events_of("onboard", LinkFailed)
    link.run(0.6)
    assert [e.message_type for e in link.events_of("onboard", PeriodicTimedOut)] == [
        MessageType.HEARTBEAT
    ]
    assert len(link.events_of("onboard", LinkFailed)) == 1
    assert link.onboard.state is OnboardState.FAILED


def test_reconnect_delay_grows_and_resets_after_registration() -> None:
    link = registered_link()
    onboard = link.onboard
    delays = [onboard.reconnect_delay_s(0.0) for _ in range(7)]
    assert delays == [1.0, 2.0, 4.0, 8.0, 16.0, 30.0, 30.0]
    onboard.connection_lost(link.now_s)
    link.ground = link._new_ground()
    link.connect()
    link.step()
    assert onboard.reconnect_delay_s(0.0) == 1.0


# --- TSR handling on the train -------------------------------------------------------------


@pytest.mark.parametrize(
    ("direction", "zone"),
    [
        (TravelDirection.UP, (10_000.0, 14_600.0)),
        (TravelDirection.DOWN, (7_400.0, 12_000.0)),
        (TravelDirection.UNKNOWN, (7_400.0, 14_600.0)),
    ],
)
def test_tsr_is_extended_by_one_train_length_on_the_exit_side(
    direction: TravelDirection, zone: tuple[float, float]
) -> None:
    link = registered_link()
    link.onboard.update_running_info(RunningInfo(42, "K1", "L1", direction, 10.0, 5000.0))
    link.ground.set_tsr(tsr(start_m=12_000.0, end_m=10_000.0), link.now_s)
    link.run(0.1)
    [applied] = link.events_of("onboard", TsrApplied)
    assert (applied.tsr.zone_start_m, applied.tsr.zone_end_m) == zone


def test_resent_tsr_is_applied_only_once() -> None:
    link = registered_link()
    link.uplink = OnceFilter(MessageType.TSR_SET_ACK, lambda w: [])  # first ack lost
    link.ground.set_tsr(tsr(), link.now_s)
    link.run(3.0)
    assert len(link.events_of("onboard", TsrApplied)) == 1
    assert link.ground.counters.resends == 1
    assert list(link.onboard.active_tsrs) == [1]


@pytest.mark.parametrize(
    ("bad", "result"),
    [
        (TsrSet(1, 500.0, 500.0, 10.0, T0, T0 + 60.0), TsrSetResult.INVALID),
        (TsrSet(1, 500.0, 900.0, 10.0, T0, T0 - 60.0), TsrSetResult.INVALID),
        (TsrSet(1, 500.0, 900.0, 10.0, T0 - 120.0, T0 - 60.0), TsrSetResult.EXPIRED),
    ],
)
def test_implausible_tsr_is_refused_and_not_applied(bad: TsrSet, result: TsrSetResult) -> None:
    link = registered_link()
    link.ground.set_tsr(bad, link.now_s)
    link.run(0.1)
    assert link.events_of("onboard", TsrRefused) == [TsrRefused(1, result)]
    assert not link.events_of("onboard", TsrApplied)


def test_tsr_expires_at_the_end_of_its_validity() -> None:
    link = registered_link()
    link.ground.set_tsr(TsrSet(1, 500.0, 900.0, 10.0, T0, T0 + 2.0), link.now_s)
    link.run(1.0)
    assert not link.events_of("onboard", TsrExpired)
    link.run(1.5)
    assert link.events_of("onboard", TsrExpired) == [TsrExpired(1)]
    assert link.onboard.active_tsrs == {}


def test_tsr_expiry_uses_the_clock_offset_of_the_time_check() -> None:
    # the onboard's clock runs 8 s ahead of the ground's and the time check at registration
    # measured it: a TSR valid until ground time T stays applied until the onboard's clock
    # reads T + 8 s, although the onboard's own clock passed T at once
    link = registered_link(onboard_clock_ahead_s=8.0)
    assert link.onboard.time_offset_s == pytest.approx(8.0)
    link.ground.set_tsr(TsrSet(1, 500.0, 900.0, 10.0, T0, link.now_s + 2.0), link.now_s)
    link.run(1.5)  # past valid_until on the onboard's own clock, not on the ground's
    assert not link.events_of("onboard", TsrExpired)
    assert 1 in link.onboard.active_tsrs
    link.run(1.0)
    assert link.events_of("onboard", TsrExpired) == [TsrExpired(1)]


def test_cancel_removes_the_tsr_once() -> None:
    link = registered_link()
    link.ground.set_tsr(tsr(), link.now_s)
    link.run(0.5)
    link.uplink = OnceFilter(MessageType.TSR_CANCEL_ACK, lambda w: [])
    link.ground.cancel_tsr(1, link.now_s)
    link.run(3.0)
    assert link.events_of("onboard", TsrCancelled) == [TsrCancelled(1)]
    assert link.onboard.active_tsrs == {}


def test_cancel_that_overtakes_its_set_keeps_the_set_from_ever_applying() -> None:
    link = registered_link()
    link.downlink = OnceFilter(MessageType.TSR_SET, lambda w: [])  # the set is lost
    link.ground.set_tsr(tsr(), link.now_s)
    link.ground.cancel_tsr(1, link.now_s)
    link.run(5.0)
    assert not link.events_of("onboard", TsrApplied)
    assert 1 not in link.onboard.active_tsrs


def test_dispatch_command_is_delivered_once_however_often_resent() -> None:
    link = registered_link()
    link.uplink = OnceFilter(MessageType.DISPATCH_ACK, lambda w: [])
    command = DispatchCommand(77, "限速 45 km/h 至 K123+400")
    link.ground.send_dispatch_command(command, link.now_s)
    link.run(3.0)
    assert link.events_of("onboard", DispatchCommandReceived) == [DispatchCommandReceived(command)]


def test_target_point_is_delivered_again_only_when_it_changes() -> None:
    link = registered_link()
    first = TargetPoint(5, 30_000.0, TargetReason.TRAIN_AHEAD)
    moved = TargetPoint(5, 31_000.0, TargetReason.TRAIN_AHEAD)
    link.ground.send_target_point(first, link.now_s)
    link.run(0.5)
    link.ground.send_target_point(first, link.now_s)
    link.run(0.5)
    link.ground.send_target_point(moved, link.now_s)
    link.run(0.5)
    received = [e.target for e in link.events_of("onboard", TargetPointReceived)]
    assert received == [first, moved]
    assert link.onboard.target_points[5] == moved


def test_an_older_target_point_arriving_late_changes_nothing() -> None:
    # protocol.md 8.4: the first copy of target 5 is lost; the ground has moved the
    # target on (a clear, id 6) before its resend of 5 arrives
    link = registered_link()
    link.downlink = OnceFilter(MessageType.TARGET_POINT, lambda w: [])
    held = TargetPoint(5, 30_000.0, TargetReason.TRAIN_AHEAD)
    clear = TargetPoint(6, 590_000.0, TargetReason.OTHER)
    link.ground.send_target_point(held, link.now_s)
    link.run(0.5)
    link.ground.send_target_point(clear, link.now_s)
    link.run(0.5)
    assert 5 not in link.onboard.target_points  # lost, not yet resent
    link.run(3.0)  # the resend of 5 arrives now, after 6
    assert link.onboard.target_points[5] == held
    received = [e.target for e in link.events_of("onboard", TargetPointReceived)]
    assert received == [clear]
    assert link.onboard.target_point == clear
    acknowledged = [e.target_id for e in link.events_of("ground", TargetPointAcknowledged)]
    assert sorted(acknowledged) == [5, 6]


def test_unauthenticated_link_works_when_auth_is_not_required() -> None:
    link = FakeLink(
        keys=None,  # type: ignore[arg-type]
        onboard_cfg=onboard_config(require_auth=False),
        ground_cfg=ground_config(require_auth=False),
    )
    link.connect()
    link.onboard.update_running_info(running_info(1000.0))
    link.run(2.0)
    assert link.onboard.state is OnboardState.REGISTERED
    assert any(isinstance(e, MessageReceived) for e in link.ground_events)


def test_next_deadline_is_the_next_heartbeat_or_earlier() -> None:
    link = registered_link()
    deadline = link.onboard.next_deadline_s()
    assert deadline is not None and link.now_s < deadline <= link.now_s + 1.0
