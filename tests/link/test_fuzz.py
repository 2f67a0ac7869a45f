"""Fuzzing the decoder with 100,000 random and mutated inputs (seeded).

Nothing may raise except the documented :class:`FrameError` family (from the stateless
``parse_frame``/``decode_body``); the streaming decoder, the decode tool and the endpoints
must not raise at all; the decoder buffer stays within its bound after every read.
"""

from __future__ import annotations

import random

import pytest

from railpilot.link import (
    FrameDecoder,
    FrameError,
    GroundEndpoint,
    MessageReceived,
    OnboardEndpoint,
    TsrApplied,
    decode_body,
    decode_stream,
    encode_body,
    encode_frame,
    parse_frame,
)
from railpilot.link.messages import (
    DispatchCommand,
    Heartbeat,
    RunningTime,
    RunningTimes,
    StationStop,
    StationStops,
    TargetPoint,
    TargetReason,
    TsrSet,
    TsrSetAck,
    TsrSetResult,
)

from .helpers import GROUND_ID, KEY_1, T0, TRAIN_ID, ground_config, make_keys, onboard_config
from .helpers import running_info as info

INPUTS = 100_000
SEED = 20_161_008


def corpus() -> list[bytes]:
    messages = [
        Heartbeat(),
        info(123_456.78),
        TsrSet(126, 1000.0, 2000.0, 12.5, T0, T0 + 60),
        TsrSetAck(0x7E7E, TsrSetResult.APPLIED),
        DispatchCommand(5, "限速 ~ \x7e"),
        StationStops((StationStop(1, 5.0, 60.0), StationStop(0x7E, 1260.0, 30.0))),
        RunningTimes((RunningTime(1, 2, 600.0),)),
        TargetPoint(3, 777.0, TargetReason.TRAIN_AHEAD),
    ]
    frames = []
    for i, m in enumerate(messages):
        for key in (None, KEY_1):
            frames.append(
                encode_frame(
                    m.TYPE,
                    TRAIN_ID,
                    GROUND_ID,
                    i,
                    1_700_000_000_000_000 + i,
                    0,
                    encode_body(m),
                    1 if key else 0,
                    key,
                )
            )
    return frames


def mutate(rng: random.Random, frames: list[bytes]) -> bytes:
    data = bytearray(rng.choice(frames))
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(6)
        i = rng.randrange(len(data)) if data else 0
        if op == 0 and data:
            data[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            data.insert(i, rng.choice((0x7E, 0x00, 0xFF, rng.randrange(256))))
        elif op == 2 and data:
            del data[i]
        elif op == 3:
            data = data[: rng.randrange(len(data) + 1)]
        elif op == 4:
            data += rng.choice(frames)
        else:
            data[i:i] = b"\x7e" * rng.randint(1, 3)
    return bytes(data)


def random_bytes(rng: random.Random) -> bytes:
    alphabet = (0x7E, 0x7E, 0x01, 0x00, 0x20, 0x50)
    return bytes(
        rng.choice(alphabet) if rng.random() < 0.3 else rng.randrange(256)
        for _ in range(rng.randint(0, 120))
    )


@pytest.mark.slow
def test_decoder_survives_100k_random_and_mutated_inputs() -> None:
    rng = random.Random(SEED)
    frames = corpus()
    decoder = FrameDecoder()
    ground = GroundEndpoint(ground_config(), make_keys())
    ground.connection_made(T0)
    onboard = OnboardEndpoint(onboard_config(), make_keys())
    onboard.connection_made(T0)
    parsed = errors = 0
    for n in range(INPUTS):
        data = mutate(rng, frames) if rng.random() < 0.6 else random_bytes(rng)
        for item in decoder.feed(data):
            if isinstance(item, FrameError):
                errors += 1
                continue
            try:
                frame = parse_frame(item)
                decode_body(frame.message_type, frame.body)
                parsed += 1
            except FrameError:
                errors += 1
        assert decoder.buffered_bytes <= decoder.max_buffered_bytes
        if n % 20 == 0:
            ground.receive_data(data, T0 + n * 1e-3)
            onboard.receive_data(data, T0 + n * 1e-3)
        if n % 50 == 0:
            for report in decode_stream(data):
                assert report.verdicts
    # The fuzzer reached both the accepting and the rejecting paths.
    assert parsed > 1000 and errors > 1000
    # Nothing of this reached the applications as data.
    assert not [e for e in ground.events() if isinstance(e, MessageReceived)]
    assert not [e for e in onboard.events() if isinstance(e, MessageReceived | TsrApplied)]
