"""Range checks on the wire integers, at the limit and one past it."""

from __future__ import annotations

import pytest

from railpilot.link.codec import MAX_EPOCH_US, decode_body, encode_body
from railpilot.link.errors import BodyError
from railpilot.link.messages import MessageType, TimeCheck


def test_time_check_at_the_epoch_limit_decodes() -> None:
    body = MAX_EPOCH_US.to_bytes(8, "big")
    assert decode_body(MessageType.TIME_CHECK, body) == TimeCheck(MAX_EPOCH_US / 1e6)


def test_time_one_microsecond_past_the_limit_is_rejected() -> None:
    # as a float, limit + 1 us rounds to exactly the limit: the check must be on the integer
    body = (MAX_EPOCH_US + 1).to_bytes(8, "big")
    with pytest.raises(BodyError, match="ground_time_s"):
        decode_body(MessageType.TIME_CHECK, body)


def test_time_check_round_trips() -> None:
    message = TimeCheck(1_700_000_000.123456)
    assert decode_body(MessageType.TIME_CHECK, encode_body(message)) == message
