"""A ground that has just started refuses frames timestamped before it started."""

from __future__ import annotations

from railpilot.link import (
    GroundEndpoint,
    OnboardEndpoint,
    TimestampRejected,
    TrainRegistered,
)

from .helpers import T0, TRAIN_ID, ground_config, make_keys, onboard_config


def _opening_frames_sent_at(now_s: float) -> bytes:
    """What an onboard sends to open a connection at ``now_s``: HEARTBEAT, REGISTER_REQUEST.

    A scratch ground answers the HEARTBEAT, so the request echoes a ground timestamp.
    """
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    scratch = GroundEndpoint(ground_config(), make_keys(), {})
    onboard.connection_made(now_s)
    scratch.connection_made(now_s)
    sent = onboard.data_to_send()
    scratch.receive_data(sent, now_s)
    onboard.receive_data(scratch.data_to_send(), now_s)
    return sent + onboard.data_to_send()


def test_a_register_request_recorded_before_the_restart_is_refused() -> None:
    recorded = _opening_frames_sent_at(T0)  # an attacker's recording
    ground = GroundEndpoint(ground_config(not_before_s=T0 + 60.0), make_keys(), {})
    ground.connection_made(T0 + 120.0)  # ground restarted at T0+70
    ground.receive_data(recorded, T0 + 120.0)
    events = list(ground.events())
    assert any(isinstance(e, TimestampRejected) for e in events)
    assert not any(isinstance(e, TrainRegistered) for e in events)


def test_a_fresh_register_request_after_the_restart_is_accepted() -> None:
    now = T0 + 120.0
    ground = GroundEndpoint(ground_config(not_before_s=T0 + 60.0), make_keys(), {})
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    ground.connection_made(now)
    onboard.connection_made(now)
    events = []
    for _ in range(3):  # HEARTBEAT, challenge, REGISTER_REQUEST, RESPONSE
        ground.receive_data(onboard.data_to_send(), now)
        events += list(ground.events())
        onboard.receive_data(ground.data_to_send(), now)
    assert [e.train_id for e in events if isinstance(e, TrainRegistered)] == [TRAIN_ID]
