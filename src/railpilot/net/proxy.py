"""A per-frame fault-injection TCP proxy for the EN 50159 threat tests (loopback only).

``client -> proxy -> upstream`` (the onboard side is the client, the ground the upstream).
Each direction runs the received bytes through the core's
:class:`~railpilot.link.FrameDecoder`, so faults act on whole *frames*, not on TCP
segments, and then re-stuffs and writes them:

=============  ===================================================================
``drop``       P: the frame is deleted                                (deletion)
``duplicate``  P: the frame is sent twice                             (repetition)
``reorder``    P: the frame is held back and sent after the next one  (resequencing)
``corrupt``    P: one random bit of the frame is flipped (not the header byte) (corruption)
``delay_ms``   every frame (or a share ``delay_p`` of them) is held back; order is kept,
               as on a TCP stream                                     (delay)
``inject``     raw wire bytes written once, after ``inject_after`` frames in
               ``inject_direction``                          (insertion / masquerade)
``split``      each frame is written in random pieces (separate TCP segments)
=============  ===================================================================

Bytes that are not part of a frame are dropped and counted (``garbage_bytes``). Every
decision comes from a generator seeded with ``seed`` (one per connection and direction), so
a run is repeatable up to TCP timing. The proxy counts everything it did.

A :class:`PacketRadio` given to the proxy decides, besides, for each *packet* (the whole
frames one read brought: what one endpoint wrote at one instant) whether it is lost and how
long it travels: a live line run puts the scenario's radio channel there
(cosim/live_train.py). Its delay adds to ``delay_ms``; order is kept.
"""

from __future__ import annotations

import asyncio
import logging
import random
import socket
import time
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any, Literal, Protocol

from railpilot.link import FrameDecoder, FrameError, stuff
from railpilot.link.errors import LinkConfigError
from railpilot.link.framing import ABSOLUTE_MAX_FRAME_LENGTH

from .logfmt import kv

log = logging.getLogger("railpilot.net.proxy")

Direction = Literal["up", "down"]
#: How long a frame held for reordering waits for a successor before it is sent anyway [s].
REORDER_HOLD_MAX_S = 0.5


class PacketRadio(Protocol):
    """What a radio does to a packet going ``direction`` ("up": client to upstream)."""

    def packet_delay_s(self, direction: Direction) -> float | None:
        """How long the packet sent now travels [s of wall clock]; None: it is lost."""
        ...


def _check_p(name: str, value: float) -> None:
    if not isinstance(value, int | float) or not 0.0 <= value <= 1.0:
        raise LinkConfigError(f"proxy.{name}", value, "a probability in [0, 1]")


@dataclass(frozen=True, slots=True)
class ProxyOptions:
    """What the proxy does to each frame (probabilities per frame, in [0, 1])."""

    drop: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    corrupt: float = 0.0
    delay_ms: float = 0.0
    #: Share of frames that get ``delay_ms`` (1 = all).
    delay_p: float = 1.0
    #: Raw wire bytes to insert (e.g. a forged frame), once per connection.
    inject: bytes = b""
    inject_after: int = 3
    inject_direction: Direction = "up"
    #: Write each frame in random pieces, each its own TCP segment.
    split: bool = False
    #: Which directions the drop/duplicate/reorder/corrupt/delay faults apply to.
    directions: tuple[Direction, ...] = ("up", "down")
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("drop", "duplicate", "reorder", "corrupt", "delay_p"):
            _check_p(name, getattr(self, name))
        if not isinstance(self.delay_ms, int | float) or not 0.0 <= self.delay_ms <= 60_000.0:
            raise LinkConfigError("proxy.delay_ms", self.delay_ms, "0..60000 ms")
        if type(self.inject_after) is not int or self.inject_after < 0:
            raise LinkConfigError("proxy.inject_after", self.inject_after, "an integer >= 0")
        if self.inject_direction not in ("up", "down"):
            raise LinkConfigError("proxy.inject_direction", self.inject_direction, "up or down")
        if not set(self.directions) <= {"up", "down"}:
            raise LinkConfigError("proxy.directions", self.directions, "a subset of (up, down)")


class _Pipe:
    """One direction of one proxied connection."""

    def __init__(
        self,
        proxy: FaultProxy,
        direction: Direction,
        rng: random.Random,
        out: asyncio.Transport,
    ) -> None:
        self.proxy = proxy
        self.direction = direction
        self.options = proxy.options
        self.faulty = direction in proxy.options.directions
        self.rng = rng
        self.out = out
        self.stats = proxy.stats[direction]
        self.decoder = FrameDecoder(ABSOLUTE_MAX_FRAME_LENGTH)
        self.frames = 0
        self.injected = False
        self.held: bytes | None = None
        self._held_timer: asyncio.TimerHandle | None = None
        self.queue: deque[tuple[float, bytes]] = deque()
        self._last_release_s = 0.0
        self._queue_timer: asyncio.TimerHandle | None = None
        self.closed = False
        #: the radio's delay of the packet whose frames are being passed on [s]
        self.radio_delay_s = 0.0

    def feed(self, data: bytes) -> None:
        before = self.decoder.bytes_discarded
        frames = []
        for item in self.decoder.feed(data):
            if isinstance(item, FrameError):
                self.stats["framing_errors"] += 1
                continue
            frames.append(item)
        self.stats["garbage_bytes"] += self.decoder.bytes_discarded - before
        radio = self.proxy.radio
        if radio is not None and frames:
            self.stats["radio_packets"] += 1
            delay_s = radio.packet_delay_s(self.direction)
            if delay_s is None:
                self.stats["radio_lost"] += len(frames)
                return
            self.radio_delay_s = delay_s
        for frame in frames:
            self._frame(frame)

    def close(self) -> None:
        self.closed = True
        for timer in (self._held_timer, self._queue_timer):
            if timer is not None:
                timer.cancel()

    def _frame(self, frame: bytes) -> None:
        o = self.options
        self.frames += 1
        self.stats["frames"] += 1
        rng = self.rng
        if self.faulty:
            # Draw every decision for every frame so one option's value does not shift the
            # random stream of the others.
            drop, corrupt, dup, reorder, delay = (rng.random() for _ in range(5))
            if drop < o.drop:
                self.stats["dropped"] += 1
                self._maybe_inject()
                return
            if corrupt < o.corrupt:
                self.stats["corrupted"] += 1
                frame = _flip_bit(frame, rng)
            wire = stuff(frame)
            copies = 2 if dup < o.duplicate else 1
            if copies == 2:
                self.stats["duplicated"] += 1
            delayed = o.delay_ms > 0.0 and delay < o.delay_p
            if reorder < o.reorder and self.held is None:
                self.stats["reordered"] += 1
                self.held = wire * copies
                loop = asyncio.get_running_loop()
                self._held_timer = loop.call_later(REORDER_HOLD_MAX_S, self._release_held)
            else:
                self._emit(wire * copies, delayed)
                self._release_held()
        else:
            self._emit(stuff(frame), False)
        self._maybe_inject()

    def _maybe_inject(self) -> None:
        o = self.options
        if (
            o.inject
            and not self.injected
            and self.direction == o.inject_direction
            and self.frames >= o.inject_after
        ):
            self.injected = True
            self.stats["injected"] += 1
            self._emit(o.inject, False)

    def _release_held(self) -> None:
        if self._held_timer is not None:
            self._held_timer.cancel()
            self._held_timer = None
        if self.held is not None:
            held, self.held = self.held, None
            self._emit(held, False)

    def _emit(self, wire: bytes, delayed: bool) -> None:
        """Send now, or queue behind earlier delayed frames (a TCP stream keeps order)."""
        now = time.monotonic()
        release = now + self.radio_delay_s
        if delayed:
            release += self.options.delay_ms / 1000.0
            self.stats["delayed"] += 1
        release = max(release, self._last_release_s)
        self._last_release_s = release
        if not self.queue and release <= now:
            self._write(wire)
            return
        self.queue.append((release, wire))
        if self._queue_timer is None:
            self._arm()

    def _arm(self) -> None:
        loop = asyncio.get_running_loop()
        release = self.queue[0][0]
        self._queue_timer = loop.call_later(max(0.0, release - time.monotonic()), self._drain)

    def _drain(self) -> None:
        self._queue_timer = None
        now = time.monotonic()
        while self.queue and self.queue[0][0] <= now:
            self._write(self.queue.popleft()[1])
        if self.queue and not self.closed:
            self._arm()

    def _write(self, wire: bytes) -> None:
        if self.closed or self.out.is_closing():
            return
        if self.options.split and len(wire) > 1:
            pieces = 0
            i = 0
            while i < len(wire):
                n = self.rng.randint(1, max(1, len(wire) // 3))
                self.out.write(wire[i : i + n])
                i += n
                pieces += 1
            self.stats["segments"] += pieces
        else:
            self.out.write(wire)
            self.stats["segments"] += 1


def _flip_bit(frame: bytes, rng: random.Random) -> bytes:
    data = bytearray(frame)
    i = rng.randrange(len(data))
    data[i] ^= 1 << rng.randrange(8)
    return bytes(data)


class _Side(asyncio.Protocol):
    def __init__(self, pair: _Pair, side: Direction) -> None:
        self.pair = pair
        self.side = side  # "up": bytes received here travel up (this is the client side)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def data_received(self, data: bytes) -> None:
        pipe = self.pair.pipes.get(self.side)
        if pipe is not None:
            pipe.feed(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.pair.close()


class _Pair:
    """A client connection and its upstream connection."""

    def __init__(self, proxy: FaultProxy, index: int) -> None:
        self.proxy = proxy
        self.index = index
        self.client: asyncio.Transport | None = None
        self.upstream: asyncio.Transport | None = None
        self.pipes: dict[Direction, _Pipe] = {}
        self.closed = False

    def connected(self, client: asyncio.Transport, upstream: asyncio.Transport) -> None:
        seed = self.proxy.options.seed
        self.client, self.upstream = client, upstream
        self.pipes = {
            "up": _Pipe(self.proxy, "up", random.Random(f"{seed}:{self.index}:up"), upstream),
            "down": _Pipe(self.proxy, "down", random.Random(f"{seed}:{self.index}:down"), client),
        }
        client.resume_reading()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        for pipe in self.pipes.values():
            pipe.close()
        for transport in (self.client, self.upstream):
            if transport is not None:
                transport.close()
        self.proxy._pairs.discard(self)


class _ClientSide(_Side):
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        assert isinstance(transport, asyncio.Transport)
        # Hold the client's bytes until the upstream connection exists.
        transport.pause_reading()
        self.pair.client = transport
        self.pair.proxy._connect_upstream(self.pair, transport)


class FaultProxy:
    """The proxy server. ``await proxy.start()`` returns the bound ``(host, port)``."""

    def __init__(
        self,
        upstream_host: str,
        upstream_port: int,
        options: ProxyOptions | None = None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        radio: PacketRadio | None = None,
    ) -> None:
        self.upstream = (upstream_host, upstream_port)
        self.options = options or ProxyOptions()
        #: decides each packet's loss and travel time (module docstring); None: no radio
        self.radio = radio
        self.host = host
        self.port = port
        self.stats: dict[Direction, Counter[str]] = {"up": Counter(), "down": Counter()}
        #: connections accepted from the client side
        self.connections = 0
        #: of those, the ones that reached the upstream server (a server that is down
        #: refuses the proxy, which then closes the client's connection at once)
        self.upstream_connections = 0
        self._pairs: set[_Pair] = set()
        self._server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self) -> tuple[str, int]:
        loop = asyncio.get_running_loop()

        def factory() -> _ClientSide:
            pair = _Pair(self, self.connections)
            self.connections += 1
            self._pairs.add(pair)
            return _ClientSide(pair, "up")

        self._server = await loop.create_server(factory, self.host, self.port)
        self.port = int(self._server.sockets[0].getsockname()[1])
        kv(
            log,
            logging.INFO,
            "proxy_listening",
            listen=f"{self.host}:{self.port}",
            upstream=f"{self.upstream[0]}:{self.upstream[1]}",
        )
        return self.host, self.port

    def _connect_upstream(self, pair: _Pair, client: asyncio.Transport) -> None:
        async def connect() -> None:
            loop = asyncio.get_running_loop()
            try:
                upstream, _ = await loop.create_connection(
                    lambda: _Side(pair, "down"), *self.upstream
                )
            except OSError as exc:
                kv(log, logging.WARNING, "upstream_failed", error=exc)
                pair.close()
                return
            assert isinstance(upstream, asyncio.Transport)
            if pair.closed:
                upstream.close()
                return
            self.upstream_connections += 1
            pair.connected(client, upstream)

        task = asyncio.get_running_loop().create_task(connect())
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def close_connections(self) -> None:
        """Cut every proxied connection (both sides), keep listening."""
        for pair in list(self._pairs):
            pair.close()

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
        self.close_connections()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> FaultProxy:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    def report(self) -> dict[str, Any]:
        """What the proxy did, per direction (JSON-ready)."""
        return {
            "connections": self.connections,
            "upstream_connections": self.upstream_connections,
            "up": dict(sorted(self.stats["up"].items())),
            "down": dict(sorted(self.stats["down"].items())),
        }
