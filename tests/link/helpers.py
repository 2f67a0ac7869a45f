"""Shared fixtures for the link tests: keys, configs, a fake clock and a fake link.

The fake link joins an onboard and a ground endpoint with in-memory byte pipes. Between
them each direction can pass through a *frame filter* (a function from the list of frames
sent in one step to the list delivered: drop, duplicate, reorder, corrupt, inject) and a
*segmenter* that cuts the byte stream at arbitrary (seeded) boundaries, like TCP may.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field

from railpilot.link import (
    Event,
    Frame,
    FrameDecoder,
    FrameError,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    LinkFailed,
    LinkTimers,
    OnboardConfig,
    OnboardEndpoint,
    RunningInfo,
    TrainRecord,
    TravelDirection,
    encode_frame,
    parse_frame,
    stuff,
    unstuff,
)

T0 = 1_700_000_000.0  # 2023-11-14T22:13:20Z, the epoch of every fake clock here
TRAIN_ID = 1001
OTHER_TRAIN_ID = 2002
GROUND_ID = 1
KEY_1 = bytes(range(32))
KEY_2 = bytes(range(100, 132))
OTHER_TRAIN_KEY = bytes(range(200, 232))

#: a key file: two trains, one with two keys and an active key id, one with one key
KEY_FILE = f"""
[[train]]
id = 1001
active_key = 2
[train.keys]
1 = "{KEY_1.hex()}"
2 = "{KEY_2.hex()}"

[[train]]
id = 2002
[train.keys]
7 = "{KEY_2.hex()}"
"""

FrameFilter = Callable[[list[bytes]], list[bytes]]


def make_keys() -> KeyStore:
    """Keys for TRAIN_ID (key id 1) and OTHER_TRAIN_ID (also key id 1, another key)."""
    keys = KeyStore()
    keys.add_key(TRAIN_ID, 1, KEY_1)
    keys.add_key(OTHER_TRAIN_ID, 1, OTHER_TRAIN_KEY)
    return keys


def onboard_config(**overrides: object) -> OnboardConfig:
    values: dict[str, object] = {
        "train_id": TRAIN_ID,
        "ground_id": GROUND_ID,
        "train_number": "K1234",
        "loco_number": "SS4-0123",
        "driver_id": 42,
        "train_length_m": 2600.0,
    }
    values.update(overrides)
    return OnboardConfig(**values)  # type: ignore[arg-type]


def ground_config(**overrides: object) -> GroundConfig:
    values: dict[str, object] = {"ground_id": GROUND_ID}
    values.update(overrides)
    return GroundConfig(**values)  # type: ignore[arg-type]


def running_info(position_m: float, speed_mps: float = 20.0) -> RunningInfo:
    return RunningInfo(42, "K1234", "SS4-0123", TravelDirection.UP, speed_mps, position_m)


def split_frames(data: bytes) -> list[bytes]:
    """Wire bytes -> list of wire frames (each header byte + stuffed frame)."""
    out = []
    for item in FrameDecoder().feed(data):
        assert not isinstance(item, FrameError), item
        out.append(stuff(item))
    return out


def segment(data: bytes, rng: random.Random, max_segment: int = 37) -> list[bytes]:
    """Cut ``data`` at random boundaries (1..max_segment bytes per piece)."""
    pieces = []
    i = 0
    while i < len(data):
        n = rng.randint(1, max_segment)
        pieces.append(data[i : i + n])
        i += n
    return pieces


def passthrough(frames: list[bytes]) -> list[bytes]:
    return frames


@dataclass
class FakeLink:
    """Onboard <-> ground over an in-memory link with a fake clock.

    ``segment_seed=None`` delivers each step's bytes in one ``receive_data`` call; an int
    cuts them into random segments with that seed. ``onboard_clock_ahead_s`` sets the
    onboard's clock that far ahead of the ground's (``now_s`` is the ground's clock). On
    ``LinkFailed`` the link (if ``auto_reconnect``) closes both ends and reconnects after
    ``reconnect_after_s`` with a fresh ground endpoint that shares the train records, as a
    real server would.
    """

    keys: KeyStore = field(default_factory=make_keys)
    onboard_cfg: OnboardConfig = field(default_factory=onboard_config)
    ground_cfg: GroundConfig = field(default_factory=ground_config)
    segment_seed: int | None = None
    auto_reconnect: bool = False
    reconnect_after_s: float = 1.0
    now_s: float = T0
    onboard_clock_ahead_s: float = 0.0
    uplink: FrameFilter = passthrough
    downlink: FrameFilter = passthrough

    def __post_init__(self) -> None:
        self.onboard = OnboardEndpoint(self.onboard_cfg, self.keys)
        self.records: dict[int, TrainRecord] = {}
        self.ground = self._new_ground()
        self.onboard_events: list[Event] = []
        self.ground_events: list[Event] = []
        self.grounds: list[GroundEndpoint] = [self.ground]
        self._rng = random.Random(self.segment_seed)
        self._reconnect_at: float | None = None
        self.reconnects = 0

    def _new_ground(self) -> GroundEndpoint:
        return GroundEndpoint(self.ground_cfg, self.keys, self.records)

    @property
    def onboard_now_s(self) -> float:
        return self.now_s + self.onboard_clock_ahead_s

    def _clock_of(self, endpoint: OnboardEndpoint | GroundEndpoint) -> float:
        return self.onboard_now_s if endpoint is self.onboard else self.now_s

    def connect(self) -> None:
        self.onboard.connection_made(self.onboard_now_s)
        self.ground.connection_made(self.now_s)

    def _deliver(
        self, data: bytes, to: OnboardEndpoint | GroundEndpoint, filt: FrameFilter
    ) -> None:
        if not data or not to.connected:
            return
        wire = b"".join(filt(split_frames(data)))
        now_s = self._clock_of(to)
        if self.segment_seed is None:
            to.receive_data(wire, now_s)
        else:
            for piece in segment(wire, self._rng):
                to.receive_data(piece, now_s)

    def step(self) -> None:
        """Tick both ends at the current time and carry the bytes both ways."""
        if self._reconnect_at is not None and self.now_s >= self._reconnect_at:
            self._reconnect_at = None
            self.ground = self._new_ground()
            self.grounds.append(self.ground)
            self.connect()
            self.reconnects += 1
        # a few exchanges so that answers to answers also travel (the set-up takes four:
        # onboard HEARTBEAT, ground HEARTBEAT, REGISTER_REQUEST, REGISTER_RESPONSE)
        for _ in range(5):
            self.onboard.tick(self.onboard_now_s)
            self.ground.tick(self.now_s)
            up = self.onboard.data_to_send()
            down = self.ground.data_to_send()
            self._deliver(up, self.ground, self.uplink)
            self._deliver(down, self.onboard, self.downlink)
        self._collect()

    def _collect(self) -> None:
        failed = False
        for ev in self.onboard.events():
            self.onboard_events.append(ev)
            failed |= isinstance(ev, LinkFailed)
        for ev in self.ground.events():
            self.ground_events.append(ev)
            failed |= isinstance(ev, LinkFailed)
        if failed and self.auto_reconnect and self.onboard.connected:
            self.onboard.connection_lost(self.onboard_now_s)
            self.ground.connection_lost(self.now_s)
            self._reconnect_at = self.now_s + self.reconnect_after_s

    def run(self, seconds: float, dt_s: float = 0.1) -> None:
        end = self.now_s + seconds
        while self.now_s < end - 1e-9:
            self.now_s += dt_s
            self.step()

    def events_of(self, side: str, kind: type) -> list:  # type: ignore[type-arg]
        events = self.onboard_events if side == "onboard" else self.ground_events
        return [e for e in events if isinstance(e, kind)]


def registered_link(**kwargs: object) -> FakeLink:
    """A fake link whose train is registered, after 0.1 s of fake time."""
    link = FakeLink(**kwargs)  # type: ignore[arg-type]
    link.connect()
    link.step()
    return link


def timers(**overrides: float) -> LinkTimers:
    return LinkTimers(**overrides)  # type: ignore[arg-type]


# --- frame surgery (what a fault or an attacker does to a frame) ------------------------------


def frame_type(wire: bytes) -> int:
    """Message type code of one wire frame."""
    return unstuff(wire[1:])[4]


def rewrite(wire: bytes, key: bytes | None = KEY_1, key_id: int = 1, **changes: object) -> bytes:
    """Re-encode a wire frame with some header fields or the body changed.

    The MAC (under ``key``; none when ``key`` is None) and the CRC are recomputed, so only
    the check that looks at the changed field can notice.
    """
    frame = parse_frame(unstuff(wire[1:]))
    fields: dict[str, object] = {
        "message_type": frame.message_type,
        "source_id": frame.source_id,
        "destination_id": frame.destination_id,
        "sequence": frame.sequence,
        "timestamp_us": frame.timestamp_us,
        "echo_timestamp_us": frame.echo_timestamp_us,
        "body": frame.body,
    }
    fields.update(changes)
    return encode_frame(**fields, key_id=key_id if key else 0, key=key)  # type: ignore[arg-type]


def header_of(wire: bytes) -> Frame:
    return parse_frame(unstuff(wire[1:]))


class OnceFilter:
    """Apply ``action`` to the ``nth`` (0-based) frame of ``mtype``; pass all others."""

    def __init__(self, mtype: int, action: Callable[[bytes], list[bytes]], nth: int = 0) -> None:
        self.mtype = mtype
        self.action = action
        self.nth = nth
        self.seen = 0
        self.done = False

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        out: list[bytes] = []
        for wire in frames:
            if not self.done and frame_type(wire) == self.mtype:
                if self.seen == self.nth:
                    self.done = True
                    out.extend(self.action(wire))
                    continue
                self.seen += 1
            out.append(wire)
        return out
