"""The onboard endpoint over TCP: connect, register, report a simulated trajectory, obey TSRs.

Thin adapter (DESIGN habit 2) around one :class:`~railpilot.link.OnboardEndpoint` that lives
as long as the onboard unit, across reconnects (it keeps applied TSRs and replay
protection). The adapter:

* connects, hands ``connection_made`` to the core (which registers), and on every loss
  reconnects after ``endpoint.reconnect_delay_s(rng.random())`` - exponential backoff with
  jitter from a seeded generator, reset by a successful registration (docs/protocol.md 9);
* refreshes the running info from a :class:`Trajectory` before every tick, and when the
  registration is accepted, so that the first running info of every connection leaves at
  once with where the train is then; the core sends it every cycle while registered and
  answers time checks, TSRs (extended by one train length - the core does the extension),
  target points and dispatch commands itself;
* writes the summary of the frame rejections it held back when their window ends (its
  timer wakes for it: :class:`~railpilot.net.rejections.RejectionLog`);
* closes the socket on ``LinkFailed`` (the core has already given up on the link);
* on shutdown deregisters (MANUAL_SHUTDOWN), waits a bounded time for the confirmation,
  then closes.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
from collections import Counter
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import Any, Protocol

from railpilot.errors import ConfigError
from railpilot.link import (
    Deregistered,
    DeregisterReason,
    DispatchCommandReceived,
    Event,
    FrameDecoder,
    FrameError,
    FrameRejected,
    KeyStore,
    LinkFailed,
    MessageType,
    OnboardConfig,
    OnboardEndpoint,
    OnboardState,
    PlannedCurve,
    Registered,
    RegistrationRefused,
    RunningInfo,
    SequenceGap,
    TargetPointReceived,
    TimeChecked,
    TravelDirection,
    TsrApplied,
    TsrCancelled,
    TsrExpired,
    TsrRefused,
)
from railpilot.link.framing import ABSOLUTE_MAX_FRAME_LENGTH
from railpilot.units import mps_to_kmh

from .logfmt import kv
from .rejections import RejectionLog
from .timers import WALL_CLOCK, LinkClock, TickScheduler

log = logging.getLogger("railpilot.net.client")

#: ``listener(event, now_s)``: sees every event of the endpoint.
OnboardListener = Callable[[Event, float], None]


class Mover(Protocol):
    """Where a train is: ``state(elapsed_s)`` -> ``(position_m, speed_mps)`` at
    ``elapsed_s`` seconds after it started, and its ``direction``."""

    @property
    def direction(self) -> TravelDirection: ...

    def state(self, elapsed_s: float) -> tuple[float, float]: ...


@dataclass(frozen=True, slots=True)
class Trajectory:
    """A simple simulated run: constant speed, or a constant-deceleration braking curve.

    Position along the kilometrage [m] and speed [m/s] as functions of the time since the
    run started; with ``decel_mps2 > 0`` the train brakes from ``speed_mps`` to a stop and
    stays there. Travelling UP increases the km post, DOWN decreases it.
    """

    start_m: float = 100_000.0
    speed_mps: float = 20.0
    decel_mps2: float = 0.0
    direction: TravelDirection = TravelDirection.UP

    def state(self, elapsed_s: float) -> tuple[float, float]:
        """``(position_m, speed_mps)`` after ``elapsed_s`` seconds."""
        t = max(0.0, elapsed_s)
        if self.decel_mps2 > 0.0:
            t_stop = self.speed_mps / self.decel_mps2
            t = min(t, t_stop)
            speed = self.speed_mps - self.decel_mps2 * t
            travelled = self.speed_mps * t - 0.5 * self.decel_mps2 * t * t
        else:
            speed = self.speed_mps
            travelled = self.speed_mps * t
        sign = -1.0 if self.direction is TravelDirection.DOWN else 1.0
        position = min(max(self.start_m + sign * travelled, 0.0), 1e7)
        return position, speed


class _OnboardProtocol(asyncio.Protocol):
    """One TCP connection of the client; forwards everything to :class:`OnboardClient`."""

    def __init__(self, client: OnboardClient) -> None:
        self.client = client

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        sock = transport.get_extra_info("socket")
        if sock is not None and sock.family in (socket.AF_INET, socket.AF_INET6):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def data_received(self, data: bytes) -> None:
        self.client._on_data(data)

    def connection_lost(self, exc: Exception | None) -> None:
        self.client._on_connection_lost(exc)


class OnboardClient:
    """One train's onboard unit over TCP (loopback in this project's tools and tests).

    Parameters
    ----------
    config, keys
        For the :class:`~railpilot.link.OnboardEndpoint` (kept across reconnects).
    host, port
        The ground front server (or a proxy in front of it).
    trajectory
        Source of the running info: anything with a ``direction`` and ``state(elapsed_s)``
        -> ``(position_m, speed_mps)`` (a :class:`Trajectory`, a line run's train driver).
    trajectory_start_s
        When the trajectory's time 0 is [s since the epoch, on ``clock``]; default: when
        :meth:`run` is first called.
    seed
        Seed of the reconnect jitter generator.
    scheduler
        Shared timer (one for many clients in the load test); a private one by default.
    count_sent
        Count the message types this client put on the wire (load test bookkeeping).
    clock
        The link's time (the host's own by default, a scaled one in a live line run); a
        ``scheduler`` given must run on it.
    radio_up
        Whether the train's radio can reach the ground now (a live line run's channel
        model: a dead zone, an outage); while it cannot, a connection attempt fails at
        once, as a modem without coverage fails it. None: always.
    """

    def __init__(
        self,
        config: OnboardConfig,
        keys: KeyStore | None,
        host: str,
        port: int,
        *,
        trajectory: Mover | None = None,
        trajectory_start_s: float | None = None,
        seed: int = 0,
        scheduler: TickScheduler | None = None,
        connect_timeout_s: float = 5.0,
        count_sent: bool = False,
        clock: LinkClock = WALL_CLOCK,
        radio_up: Callable[[], bool] | None = None,
    ) -> None:
        if scheduler is not None and scheduler.clock is not clock:
            raise ConfigError("scheduler", scheduler.clock, f"a scheduler on the client's {clock}")
        self.clock = clock
        self.config = config
        self.endpoint = OnboardEndpoint(config, keys)
        self.host = host
        self.port = port
        self.trajectory: Mover = trajectory or Trajectory()
        self.rng = random.Random(seed)
        self.scheduler = scheduler if scheduler is not None else TickScheduler(clock=clock)
        self.connect_timeout_s = connect_timeout_s
        self.radio_up = radio_up
        self.scheduled_s: float | None = None
        self._transport: asyncio.Transport | None = None
        self._lost: asyncio.Event | None = None
        # rejection log lines of the current connection, rate-limited per check
        self._rejections = RejectionLog(log)
        self._deregistered: asyncio.Event | None = None
        self._registered = asyncio.Event()
        self._listeners: list[OnboardListener] = []
        self._t0_s = trajectory_start_s
        #: how the onboard says goodbye when :meth:`run` is stopped while registered
        self.leave_reason = DeregisterReason.MANUAL_SHUTDOWN
        self._tap = FrameDecoder(ABSOLUTE_MAX_FRAME_LENGTH) if count_sent else None
        #: Frames written to the socket per message type (only with ``count_sent``).
        self.sent_by_type: Counter[int] = Counter()
        self.connects = 0
        #: connections that ended in a failure at either end: the core's ``LinkFailed``, or
        #: a close from the other side of a connection the ground was heard on (the
        #: ground gave up, or went down); not a connection closed on shutdown, nor one a
        #: proxy closed at once because the ground refused it. The co-simulation counts
        #: the same (cosim/link_sim.py)
        self.link_failures = 0
        self._leaving = False  # shutting down: the last close is not a failure
        #: the core's (frames accepted, link failures) when the connection was made
        self._counts_at_connect = (0, 0)
        self.registrations = 0
        self.events_seen: Counter[str] = Counter()
        self.reconnect_delays_s: list[float] = []

    # --- public API ---------------------------------------------------------------------------

    def add_listener(self, listener: OnboardListener) -> None:
        self._listeners.append(listener)

    @property
    def state(self) -> OnboardState:
        return self.endpoint.state

    @property
    def connected(self) -> bool:
        return self._transport is not None

    async def wait_registered(self) -> None:
        """Wait until the train is registered on a live link (bound it with
        ``asyncio.timeout``)."""
        await self._registered.wait()

    def send(self, message: PlannedCurve) -> bool:
        """Send an application message now (a planned-curve report) if registered;
        False if not (nothing is kept for later)."""
        if self.state is not OnboardState.REGISTERED:
            return False
        now = self.clock()
        self.endpoint.send(message, now)
        self._after(now)
        return True

    def drop_connection(self) -> None:
        """Abort the current TCP connection (tests: simulate a radio loss)."""
        if self._transport is not None:
            self._transport.abort()

    async def run(self, stop: asyncio.Event, *, duration_s: float | None = None) -> None:
        """Connect, stay connected (reconnecting with backoff) until ``stop`` or duration."""
        loop = asyncio.get_running_loop()
        if self._t0_s is None:
            self._t0_s = self.clock()
        timer = None
        if duration_s is not None:
            timer = loop.call_later(self.clock.wall_s(duration_s), stop.set)
        self.scheduler.schedule(self)
        try:
            while not stop.is_set():
                if not await self._connect():
                    await self._pause(stop, "connect_failed")
                    continue
                assert self._lost is not None
                await first_of(stop.wait(), self._lost.wait())
                if self._lost.is_set():
                    await self._pause(stop, "connection_lost")
                else:
                    await self._shutdown()
        finally:
            if timer is not None:
                timer.cancel()
            self.scheduler.cancel(self)
            if self._transport is not None:
                self._transport.abort()

    # --- connection handling ----------------------------------------------------------------

    async def _connect(self) -> bool:
        loop = asyncio.get_running_loop()
        self._lost = asyncio.Event()
        if self.radio_up is not None and not self.radio_up():
            kv(log, logging.INFO, "connect_failed", train=self.config.train_id, error="no radio")
            return False
        try:
            async with asyncio.timeout(self.connect_timeout_s):
                transport, _ = await loop.create_connection(
                    lambda: _OnboardProtocol(self), self.host, self.port
                )
        except (OSError, TimeoutError) as exc:
            kv(log, logging.INFO, "connect_failed", train=self.config.train_id, error=exc)
            return False
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self._rejections = RejectionLog(log)
        self.connects += 1
        self._counts_at_connect = self._core_counts()
        now = self.clock()
        self.endpoint.connection_made(now)
        kv(log, logging.INFO, "connected", train=self.config.train_id, server=self._server())
        self._after(now)
        return True

    async def _pause(self, stop: asyncio.Event, why: str) -> None:
        delay = self.endpoint.reconnect_delay_s(self.rng.random())
        self.reconnect_delays_s.append(delay)
        kv(log, logging.INFO, why, train=self.config.train_id, reconnect_in_s=delay)
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.clock.wall_s(delay)):
                await stop.wait()

    async def _shutdown(self) -> None:
        """Deregister (``leave_reason``), wait a bounded time for the answer, then close."""
        self._leaving = True
        now = self.clock()
        if self.endpoint.state in (OnboardState.REGISTERED, OnboardState.REGISTERING):
            self._deregistered = asyncio.Event()
            self.endpoint.deregister(self.leave_reason, now)
            self._after(now)
            assert self._lost is not None
            # Two resend intervals give the core one resend before we give up.
            with contextlib.suppress(TimeoutError):
                resends = 2 * self.config.timers.resend_interval_s
                async with asyncio.timeout(self.clock.wall_s(resends)):
                    await first_of(self._deregistered.wait(), self._lost.wait())
        if self._transport is not None:
            self._transport.close()
        if self._lost is not None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(1.0):
                    await self._lost.wait()
        kv(log, logging.INFO, "shutdown", train=self.config.train_id)

    def _on_data(self, data: bytes) -> None:
        now = self.clock()
        before = self.endpoint.state
        self.endpoint.receive_data(data, now)
        if self.endpoint.state is OnboardState.REGISTERED and before is not OnboardState.REGISTERED:
            # Registration accepted: the first running info leaves in this same write, with
            # where the train is now (protocol.md 7), on every connection. Left to the timer
            # it would wait for the next tick, up to the scheduler's longest wait on a
            # first connection, where no running info is known yet.
            self._refresh_running_info(now)
            self.endpoint.tick(now)
        self._after(now)

    def _on_connection_lost(self, exc: Exception | None) -> None:
        now = self.clock()
        # the ground was heard on this connection, or the core gave up on it
        accepted, failures = self._core_counts()
        accepted_before, failures_before = self._counts_at_connect
        if not self._leaving and (accepted > accepted_before or failures > failures_before):
            self.link_failures += 1
        self._transport = None
        self._registered.clear()
        if self.endpoint.state is not OnboardState.DISCONNECTED:
            self.endpoint.connection_lost(now)
        self._rejections.close(train=self.config.train_id)
        kv(log, logging.INFO, "disconnected", train=self.config.train_id, error=exc or "")
        if self._lost is not None:
            self._lost.set()

    def _core_counts(self) -> tuple[int, int]:
        counters = self.endpoint.counters
        return counters.frames_accepted, counters.link_failures

    def _server(self) -> str:
        return f"{self.host}:{self.port}"

    # --- scheduler ----------------------------------------------------------------------------

    def next_deadline_s(self) -> float | None:
        deadlines = [self.endpoint.next_deadline_s(), self._rejections.next_deadline_s()]
        return min((d for d in deadlines if d is not None), default=None)

    def on_tick(self, now_s: float) -> None:
        self._refresh_running_info(now_s)
        self.endpoint.tick(now_s)
        self._rejections.tick(now_s, train=self.config.train_id)
        self._after(now_s, reschedule=False)

    def _refresh_running_info(self, now_s: float) -> None:
        """Give the core where the trajectory puts the train at ``now_s``."""
        assert self._t0_s is not None
        position, speed = self.trajectory.state(now_s - self._t0_s)
        c = self.config
        self.endpoint.update_running_info(
            RunningInfo(
                c.driver_id,
                c.train_number,
                c.loco_number,
                self.trajectory.direction,
                speed,
                position,
            )
        )

    def _after(self, now_s: float, *, reschedule: bool = True) -> None:
        data = self.endpoint.data_to_send()
        if data and self._transport is not None and not self._transport.is_closing():
            self._transport.write(data)
            if self._tap is not None:
                for frame in self._tap.feed(data):
                    if not isinstance(frame, FrameError):
                        self.sent_by_type[frame[4]] += 1
        for event in self.endpoint.events():
            self._handle(event, now_s)
        if reschedule:
            self.scheduler.schedule(self, now_s=now_s)

    def _handle(self, event: Event, now_s: float) -> None:
        train = self.config.train_id
        self.events_seen[type(event).__name__] += 1
        if isinstance(event, Registered):
            self.registrations += 1
            self._registered.set()
            kv(log, logging.INFO, "registered", train=train)
        elif isinstance(event, RegistrationRefused):
            kv(log, logging.WARNING, "registration_refused", train=train, result=event.result.name)
        elif isinstance(event, Deregistered):
            kv(log, logging.INFO, "deregistered", train=train, reason=event.reason.name)
            if self._deregistered is not None:
                self._deregistered.set()
        elif isinstance(event, TsrApplied):
            t = event.tsr
            kv(
                log,
                logging.INFO,
                "tsr_applied",
                train=train,
                session=t.session,
                start_m=t.start_m,
                end_m=t.end_m,
                zone_start_m=t.zone_start_m,
                zone_end_m=t.zone_end_m,
                extended_by_m=self.config.train_length_m,
                limit_kmh=round(mps_to_kmh(t.limit_mps), 2),
            )
        elif isinstance(event, TsrCancelled | TsrExpired):
            kv(log, logging.INFO, _snake(type(event).__name__), train=train, session=event.session)
        elif isinstance(event, TsrRefused):
            kv(
                log,
                logging.WARNING,
                "tsr_refused",
                train=train,
                session=event.session,
                result=event.result.name,
            )
        elif isinstance(event, TargetPointReceived):
            kv(
                log,
                logging.INFO,
                "target_point",
                train=train,
                target=event.target.target_id,
                position_m=event.target.position_m,
                reason=event.target.reason.name,
            )
        elif isinstance(event, DispatchCommandReceived):
            kv(
                log,
                logging.INFO,
                "dispatch_command",
                train=train,
                number=event.command.command_number,
                text=event.command.text,
            )
        elif isinstance(event, TimeChecked):
            kv(log, logging.DEBUG, "time_check", train=train, offset_s=event.offset_s)
        elif isinstance(event, FrameRejected):
            self._rejections.record(event, now_s, train=train)
        elif isinstance(event, SequenceGap):
            kv(log, logging.WARNING, "sequence_gap", train=train, lost=event.lost)
        elif isinstance(event, LinkFailed):
            kv(log, logging.WARNING, "link_failed", train=train, reason=event.reason)
            # no longer registered from now, not from when the socket's close comes
            # through: a wait_registered() in between would return for a dead link
            self._registered.clear()
            if self._transport is not None:
                self._transport.close()
        for listener in self._listeners:
            listener(event, now_s)

    def running_info_sent(self) -> int:
        """Running-info frames written to the socket (needs ``count_sent=True``)."""
        return self.sent_by_type[MessageType.RUNNING_INFO]


def _snake(name: str) -> str:
    return "".join("_" + c.lower() if c.isupper() else c for c in name).lstrip("_")


async def first_of(*aws: Coroutine[Any, Any, Any]) -> None:
    """Wait until the first of several coroutines finishes; cancel the rest."""
    tasks = [asyncio.ensure_future(a) for a in aws]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
