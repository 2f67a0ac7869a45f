"""Throughput of the link protocol core: running-info frames, encode + all checks + decode.

Each frame goes the full production path on one core: ``OnboardEndpoint`` builds and
encodes it (sequence, timestamp, echo, MAC, CRC, stuffing), ``GroundEndpoint`` decodes it
through the streaming decoder and every safety check and delivers the event. Frames are
fed one ``receive_data`` call each (one receive cycle per frame, the worst case).

Prints one JSON object on stdout: ``frames_per_s`` (unauthenticated link) and
``auth_frames_per_s`` (HMAC-SHA256), each the median of several repetitions.
"""

from __future__ import annotations

import json
import platform
import statistics
import sys
import time

from railpilot.link import (
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    Message,
    OnboardConfig,
    OnboardEndpoint,
    RunningInfo,
    TravelDirection,
)

TRAIN_ID = 1001
GROUND_ID = 1
FRAMES = 20_000
REPETITIONS = 5


def _pair(auth: bool) -> tuple[OnboardEndpoint, GroundEndpoint]:
    keys = KeyStore()
    keys.add_key(TRAIN_ID, 1, bytes(range(32)))
    onboard = OnboardEndpoint(
        OnboardConfig(
            train_id=TRAIN_ID,
            ground_id=GROUND_ID,
            train_number="K1234",
            loco_number="SS4-0123",
            driver_id=42,
            train_length_m=2600.0,
            require_auth=auth,
        ),
        keys if auth else None,
    )
    ground = GroundEndpoint(
        GroundConfig(ground_id=GROUND_ID, require_auth=auth), keys if auth else None
    )
    now = 1_700_000_000.0
    onboard.connection_made(now)
    ground.connection_made(now)
    ground.receive_data(onboard.data_to_send(), now)  # registration
    onboard.receive_data(ground.data_to_send(), now)
    list(onboard.events())
    list(ground.events())
    return onboard, ground


def frames_per_s(
    auth: bool, message: Message | None = None, *, downlink: bool = False, frames: int = FRAMES
) -> float:
    """Frames a second through one pair: ``message`` (default a running info) encoded by one
    end and received, checked and delivered by the other (``downlink``: ground to train)."""
    onboard, ground = _pair(auth)
    if message is None:
        message = RunningInfo(42, "K1234", "SS4-0123", TravelDirection.UP, 22.22, 123_456.78)
    sender, receiver = (ground, onboard) if downlink else (onboard, ground)
    # The exact path tick() takes for a periodic message (encode via the channel), without
    # tick()'s once-per-cycle pacing, which would measure the clock instead.
    queue = sender._queue
    now = 1_700_000_000.5
    accepted_before = receiver.counters.frames_accepted
    start = time.perf_counter()
    for _ in range(frames):
        queue(message, now)
        receiver.receive_data(sender.data_to_send(), now)
        for _event in receiver.events():  # a heartbeat is the link's own: no event
            pass
        now += 1e-5
    elapsed = time.perf_counter() - start
    delivered = receiver.counters.frames_accepted - accepted_before
    if delivered < frames:  # (the pair's set-up may leave one frame queued: it counts too)
        raise SystemExit(f"only {delivered} of {frames} frames accepted: benchmark invalid")
    return frames / elapsed


def main() -> None:
    plain = [frames_per_s(False) for _ in range(REPETITIONS)]
    auth = [frames_per_s(True) for _ in range(REPETITIONS)]
    result = {
        "frames_per_s": round(statistics.median(plain)),
        "auth_frames_per_s": round(statistics.median(auth)),
        "frames_per_repetition": FRAMES,
        "repetitions": REPETITIONS,
        "goal_frames_per_s": 50_000,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    print(json.dumps(result))
    print(
        f"plain runs: {[round(x) for x in plain]}, auth runs: {[round(x) for x in auth]}",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
