"""A train process of a live line run (cosim/live.py; docs/line-run.md "Live").

One train: its onboard driving system and simulation core (the co-simulation's
:class:`~railpilot.cosim.driver.TrainDriver`, unchanged) and its onboard unit on the real
link (:class:`~railpilot.net.client.OnboardClient` over TCP to the ground's server), all on
the run's clock. Over the control wire (cosim/live_wire.py) it tells the trackside where
it truly is each whole second, and hears back its cab signal, a failure, the end.

The scenario's radio (cosim/channel.py) stands between the onboard unit and the ground:
the train's :class:`~railpilot.cosim.channel.RadioChannel`, seeded as the co-simulation
seeds it, decides in a :class:`~railpilot.net.proxy.FaultProxy` in this process whether
each packet is lost and how long it travels, from where the train is and the run's
clock; and where it has no radio, the onboard's connection attempts fail.

The simulation core compiles (numba) when it first runs; that is done before the process
says it is ready, so the run's clock never waits for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

from railpilot.link import DeregisterReason, Event, OnboardConfig, OnboardState, TsrApplied
from railpilot.net.client import OnboardClient, first_of
from railpilot.net.logfmt import setup_logging
from railpilot.net.proxy import Direction, FaultProxy
from railpilot.net.server import counters_dict
from railpilot.net.timers import LinkClock

from .channel import RadioChannel
from .driver import TrainDriver
from .line_run import WATCH_S, line_keys, line_train
from .live_wire import connect, receive, report_failure, run_process, send
from .scenario import LineScenario, load_line_scenario

#: how much of its first section a train process drives before it says it is ready [s]:
#: enough to compile the simulation core and fill the route caches
WARM_UP_S = 120.0


@dataclass(frozen=True)
class TrainArgs:
    """What the run tells a train process when it starts it."""

    control_port: int
    scenario_path: str
    seed: int
    train_id: int
    #: the run's control-wire secret (cosim/live_wire.py)
    secret: str
    #: the level of its log on stderr (``logging.WARNING``...)
    log_level: int = logging.WARNING


class ChannelRadio:
    """A train's :class:`RadioChannel` on its live link: what the proxy and the onboard
    unit ask of the radio, answered on the run's ``clock`` from where the train's head is
    (``position``, km post [m]: for a driven train, as far as it has been driven, as the
    co-simulation's odometry gives it)."""

    def __init__(
        self, channel: RadioChannel, clock: LinkClock, position: Callable[[], float]
    ) -> None:
        self.channel = channel
        self.clock = clock
        self.position = position

    def up(self) -> bool:
        """Whether the train can reach the ground now (no dead zone, no outage)."""
        return self.channel.up(self.clock(), self.position())

    def packet_delay_s(self, direction: Direction) -> float | None:
        """The packet sent now: how long it travels [s of wall clock], None if lost."""
        now = self.clock()
        arrival = self.channel.transmit(direction, now, self.position())
        return None if arrival is None else self.clock.wall_s(arrival - now)


def run(args: TrainArgs) -> None:
    """The process's entry point (multiprocessing, spawn)."""
    setup_logging(args.log_level)
    run_process(f"train {args.train_id}", _main(args))


async def _main(args: TrainArgs) -> None:
    scenario = load_line_scenario(args.scenario_path)
    service = next(s for s in scenario.services if s.train_id == args.train_id)
    warm, _ = line_train(scenario, service, True)
    warm.at(service.stops[0].departure_s + WARM_UP_S)
    driver, config = line_train(scenario, service, True)
    reader, writer = await connect(args.control_port)
    hello = {"op": "hello", "role": "train", "train": args.train_id, "secret": args.secret}
    await send(writer, hello)
    try:
        await _drive(args, scenario, driver, config, reader, writer)
    except Exception as exc:
        raise await report_failure(writer, exc) from None
    finally:
        writer.close()


async def _drive(
    args: TrainArgs,
    scenario: LineScenario,
    driver: TrainDriver,
    config: OnboardConfig,
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
) -> None:
    """The train on the run's clock, from the run's start to its end."""
    epoch = scenario.epoch_s
    start = await receive(reader)
    if start is None:
        return
    clock = LinkClock(start["speedup"], epoch, start["wall_origin_s"])
    applied: Counter[int] = Counter()
    # seeded as LinkSim seeds the train's channel; outages count from the run's start
    channel = RadioChannel(scenario.channel, args.seed, args.train_id, epoch)
    radio = ChannelRadio(channel, clock, lambda: driver.at_last()[0])
    proxy = FaultProxy("127.0.0.1", start["link_port"], radio=radio)
    _, radio_port = await proxy.start()

    def on_event(event: Event, now_s: float) -> None:
        if isinstance(event, TsrApplied):
            applied[event.tsr.session] += 1
        driver.on_event(event, now_s)

    client = OnboardClient(
        config,
        line_keys(scenario, args.seed),
        "127.0.0.1",
        radio_port,
        trajectory=driver,
        trajectory_start_s=epoch + driver.power_on_s,
        seed=args.seed * 100_003 + args.train_id,
        clock=clock,
        radio_up=radio.up,
    )
    client.add_listener(on_event)
    client.leave_reason = DeregisterReason.LEAVING_MAIN_LINE
    stop = asyncio.Event()
    ended = asyncio.Event()  # the run is over

    def now_t() -> float:
        return clock() - epoch

    async def sleep_until(t: float) -> None:
        await asyncio.sleep(max(clock.wall_s(t - now_t()), 0.0))

    def recover() -> None:
        driver.recover(now_t())

    async def listen() -> None:
        while (message := await receive(reader)) is not None:
            op = message["op"]
            if op == "cab":
                driver.cab_signal(message["red_m"], message["sight_m"], now_t())
            elif op == "fail":
                driver.fail(now_t())
                loop = asyncio.get_running_loop()
                loop.call_later(clock.wall_s(message["stand_s"]), recover)
            elif op == "stop":
                break
        ended.set()

    listener = asyncio.create_task(listen())
    await first_of(sleep_until(driver.power_on_s), ended.wait())
    link = asyncio.create_task(client.run(stop))
    t = math.ceil(now_t() / WATCH_S) * WATCH_S
    while not ended.is_set():
        await first_of(sleep_until(t), ended.wait())
        if ended.is_set():
            break
        head, speed = driver.at(t)
        if client.state is OnboardState.REGISTERED:
            # the planned-curve report, asked for each second as the co-simulation's
            # onboard tick does
            report = driver.planned_curve_report(t)
            if report is not None:
                client.send(report)
        await send(
            writer,
            {
                "op": "seen",
                "t": t,
                "head_m": head,
                "speed_mps": speed,
                "next_stop_m": driver.next_stop_m(),
                "finished": driver.finished,
            },
        )
        if driver.finished:
            # it leaves the line: it says so to the ground (once its link is up) and goes
            while client.state is not OnboardState.REGISTERED and not ended.is_set():
                pause = asyncio.sleep(clock.wall_s(WATCH_S))
                await first_of(client.wait_registered(), ended.wait(), pause)
            break
        t += WATCH_S
    stop.set()
    await link
    await proxy.stop()
    await send(
        writer,
        {
            "op": "result",
            "train": args.train_id,
            "sections": [dataclasses.asdict(s) for s in driver.sections],
            "finished": driver.finished,
            "red_signal_stops": driver.red_signal_stops,
            "running_times_received": driver.running_times_received,
            "running_times": [[*pair, t] for pair, t in driver.running_times.items()],
            "tsr_applied": {str(k): v for k, v in applied.items()},
            "onboard": counters_dict([client.endpoint.counters]),
            # the connections that reached the ground, as the co-simulation counts them:
            # while the ground is down the proxy (the train's radio) is refused and closes
            # the onboard's connection at once
            "connects": proxy.upstream_connections,
            "registrations": client.registrations,
            "link_failures": client.link_failures,
            "channel": channel.counters.as_dict(),
            "active_tsrs": sorted(client.endpoint.active_tsrs),
        },
    )
    await ended.wait()
    listener.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await listener
