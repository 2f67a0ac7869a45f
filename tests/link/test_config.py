"""Configuration validation and the reconnect backoff."""

from __future__ import annotations

import pytest

from railpilot.link import (
    LinkConfigError,
    LinkTimers,
    OnboardEndpoint,
    reconnect_delay_s,
)

from .helpers import onboard_config


def test_default_timers_are_the_documented_ones() -> None:
    t = LinkTimers()
    assert (t.cycle_s, t.timeout_cycles, t.resend_interval_s, t.max_round_trip_s) == (
        1.0,
        3,
        2.0,
        3.0,
    )


def test_round_trip_bound_must_exceed_the_cycle() -> None:
    with pytest.raises(LinkConfigError, match="max_round_trip_s"):
        LinkTimers(cycle_s=2.0, max_round_trip_s=2.0)


def test_cycle_outside_its_range_names_the_field_and_range() -> None:
    with pytest.raises(LinkConfigError, match=r"timers.cycle_s = 0.01 .*\[0.05, 60.0\]"):
        LinkTimers(cycle_s=0.01)


def test_timeout_cycles_must_be_an_integer() -> None:
    with pytest.raises(LinkConfigError, match="timeout_cycles"):
        LinkTimers(timeout_cycles=2.5)  # type: ignore[arg-type]


def test_ground_id_equal_to_train_id_is_refused() -> None:
    with pytest.raises(LinkConfigError, match="ground_id"):
        onboard_config(ground_id=1001)


def test_auth_required_without_a_key_for_the_train_is_refused() -> None:
    with pytest.raises(LinkConfigError, match="keys"):
        OnboardEndpoint(onboard_config(), None)


def test_unauthenticated_onboard_needs_no_keys() -> None:
    OnboardEndpoint(onboard_config(require_auth=False), None)


@pytest.mark.parametrize(
    ("attempt", "fraction", "expected"),
    [
        (0, 0.0, 1.0),
        (1, 0.0, 2.0),
        (3, 0.0, 8.0),
        (10, 0.0, 30.0),
        (2, 0.5, 3.0),
        (2, 0.999, 2.002),
    ],
)
def test_backoff_doubles_is_capped_and_jitter_shortens(
    attempt: int, fraction: float, expected: float
) -> None:
    assert reconnect_delay_s(attempt, LinkTimers(), fraction) == pytest.approx(expected)


def test_backoff_refuses_a_random_fraction_outside_unit_interval() -> None:
    with pytest.raises(LinkConfigError, match="random_fraction"):
        reconnect_delay_s(0, LinkTimers(), 1.0)
