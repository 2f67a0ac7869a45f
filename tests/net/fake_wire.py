"""An onboard client over an in-memory wire to a ground core, on a clock the test moves.

:class:`OnboardClient` is the real adapter; only its surroundings are stand-ins:

* :class:`VirtualClock` is the link's time, moved by hand; the event loop never waits on
  it (every span of it costs 0 s of wall time), so a reconnect delay or a window of
  10 s passes at once and nothing depends on how fast the machine is;
* :class:`ManualScheduler` never ticks by itself: a test calls ``client.on_tick(now)``
  when it wants the host's timer to fire, so whatever the client writes without a tick
  is what it does "at once";
* :func:`wire_to_ground` makes ``loop.create_connection`` hand the client a transport
  whose far end is a :class:`~railpilot.link.GroundEndpoint` (a fresh one per
  connection, sharing the train records, as a server's connections do).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from railpilot.link import (
    Event,
    FrameDecoder,
    FrameError,
    GroundConfig,
    GroundEndpoint,
    KeyStore,
    TrainRecord,
)
from railpilot.net.timers import LinkClock

T0 = 1_700_000_000.0
#: How far the virtual clock moves while bytes cross the wire [s].
WIRE_DELAY_S = 0.005


class VirtualClock(LinkClock):
    """A link clock that reads ``now_s`` and costs the event loop no wall time."""

    def __init__(self, start_s: float = T0) -> None:
        super().__init__()
        self.now_s = start_s

    def __call__(self) -> float:
        return self.now_s

    def wall_s(self, span_s: float) -> float:
        return 0.0

    def advance(self, span_s: float) -> None:
        self.now_s += span_s


class ManualScheduler:
    """Stands in for :class:`~railpilot.net.timers.TickScheduler`: remembers the deadline
    an item asks for, never calls ``on_tick`` itself."""

    def __init__(self, clock: LinkClock) -> None:
        self.clock = clock

    def schedule(self, item: Any, *, now_s: float | None = None) -> None:
        item.scheduled_s = item.next_deadline_s()

    def cancel(self, item: Any) -> None:
        item.scheduled_s = None


def message_types(data: bytes) -> list[int]:
    """The message type of every frame in ``data``."""
    return [f[4] for f in FrameDecoder().feed(data) if not isinstance(f, FrameError)]


class GroundWire(asyncio.Transport):
    """The client's transport: what it writes goes to a ground core, whose answer comes
    back on the next turn of the event loop, a little later on the virtual clock."""

    def __init__(
        self,
        protocol: asyncio.Protocol,
        ground: GroundEndpoint,
        clock: VirtualClock,
        log: list[tuple[str, bytes]],
    ) -> None:
        super().__init__()
        self.protocol = protocol
        self.ground = ground
        self.clock = clock
        self.log = log
        #: every event of the ground core, with the virtual time it came at
        self.ground_events: list[tuple[float, Event]] = []
        self._closed = False
        #: answers written by the ground core and not yet delivered; set when none is
        self._in_flight = 0
        self._quiet = asyncio.Event()
        self._quiet.set()

    def write(self, data: bytes) -> None:  # type: ignore[override]
        if self._closed:
            return
        self.log.append(("up", bytes(data)))
        self.clock.advance(WIRE_DELAY_S)
        now = self.clock()
        self.ground.receive_data(bytes(data), now)
        self.ground.tick(now)
        self.ground_events += [(now, event) for event in self.ground.events()]
        answer = self.ground.data_to_send()
        if answer:
            self._in_flight += 1
            self._quiet.clear()
            asyncio.get_running_loop().call_soon(self._deliver_answer, answer)

    async def quiet(self) -> None:
        """Until every answer of the ground is delivered, those the client's replies
        bring included."""
        await self._quiet.wait()

    def _deliver_answer(self, data: bytes) -> None:
        try:
            self._deliver(data)  # the client may write again: counted before this ends
        finally:
            self._in_flight -= 1
            if self._in_flight == 0:
                self._quiet.set()

    def inject(self, data: bytes) -> None:
        """Bytes from the ground's side that the ground core did not write (noise)."""
        self._deliver(data)

    def _deliver(self, data: bytes) -> None:
        if self._closed:
            return
        self.clock.advance(WIRE_DELAY_S)
        self.log.append(("down", data))
        self.protocol.data_received(data)

    def is_closing(self) -> bool:
        return self._closed

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self.ground.connection_lost(self.clock())
        asyncio.get_running_loop().call_soon(self.protocol.connection_lost, None)

    def abort(self) -> None:
        self.close()

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return default


def wire_to_ground(
    clock: VirtualClock,
    ground_config: GroundConfig,
    keys: KeyStore,
    log: list[tuple[str, bytes]],
) -> list[GroundWire]:
    """Make the running loop's ``create_connection`` open a :class:`GroundWire`; returns
    the list the wires are appended to, one per connection."""
    loop = asyncio.get_running_loop()
    records: dict[int, TrainRecord] = {}
    wires: list[GroundWire] = []

    async def create_connection(
        factory: Callable[[], asyncio.Protocol], host: str, port: int
    ) -> tuple[GroundWire, asyncio.Protocol]:
        protocol = factory()
        ground = GroundEndpoint(ground_config, keys, records)
        ground.connection_made(clock())
        wire = GroundWire(protocol, ground, clock, log)
        wires.append(wire)
        protocol.connection_made(wire)
        return wire, protocol

    loop.create_connection = create_connection  # type: ignore[method-assign,assignment]
    return wires
