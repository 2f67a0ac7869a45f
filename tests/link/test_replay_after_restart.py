"""A ground that has just started refuses frames timestamped before it started."""

from __future__ import annotations

from railpilot.link import (
    GroundEndpoint,
    OnboardEndpoint,
    TimestampRejected,
    TrainRegistered,
)

from .helpers import T0, TRAIN_ID, ground_config, make_keys, onboard_config


def _register_request_sent_at(now_s: float) -> bytes:
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    onboard.connection_made(now_s)
    return onboard.data_to_send()


def _ground_events(not_before_s: float, data: bytes, now_s: float) -> list[object]:
    ground = GroundEndpoint(ground_config(not_before_s=not_before_s), make_keys(), {})
    ground.connection_made(now_s)
    ground.receive_data(data, now_s)
    return list(ground.events())


def test_a_register_request_recorded_before_the_restart_is_refused() -> None:
    recorded = _register_request_sent_at(T0)  # an attacker's recording
    events = _ground_events(T0 + 60.0, recorded, T0 + 120.0)  # ground restarted at T0+70
    assert any(isinstance(e, TimestampRejected) for e in events)
    assert not any(isinstance(e, TrainRegistered) for e in events)


def test_a_fresh_register_request_after_the_restart_is_accepted() -> None:
    fresh = _register_request_sent_at(T0 + 120.0)
    events = _ground_events(T0 + 60.0, fresh, T0 + 120.0)
    assert [e.train_id for e in events if isinstance(e, TrainRegistered)] == [TRAIN_ID]
