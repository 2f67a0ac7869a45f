"""The onboard sends its first RUNNING_INFO at once after its registration is accepted,
on every connection, the first included (docs/protocol.md 7: "the first RUNNING_INFO after
registering (sent at once)").

The client runs over an in-memory wire to a ground core on a virtual clock, and its timer
never fires by itself (fake_wire.py): a RUNNING_INFO written without a tick was sent in
answer to the acceptance, not by a later timer.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass

from railpilot.link import GroundConfig, MessageReceived, MessageType, Registered, RunningInfo
from railpilot.net import OnboardClient, Trajectory

from .fake_wire import T0, GroundWire, ManualScheduler, VirtualClock, message_types, wire_to_ground
from .helpers import FAST, GROUND_ID, SPEED_MPS, TRAIN_ID, make_keys, onboard_config, run

START_M = 4_000.0


@dataclass
class Connections:
    #: RUNNING_INFO frames written by the time the client reported each registration
    sent_at_registered: list[int]
    #: the uplink write that answered each REGISTER_RESPONSE
    answers: list[bytes]
    wires: list[GroundWire]


def _connect(times: int) -> Connections:
    """Run a client through ``times`` connections, each dropped once registered."""
    keys = make_keys()
    clock = VirtualClock()
    log: list[tuple[str, bytes]] = []
    sent_at_registered: list[int] = []
    wires: list[list[GroundWire]] = []

    async def main() -> None:
        config = GroundConfig(ground_id=GROUND_ID, timers=FAST)
        wires.append(wire_to_ground(clock, config, keys, log))
        client = OnboardClient(
            onboard_config(TRAIN_ID),
            keys,
            "127.0.0.1",
            1,
            trajectory=Trajectory(start_m=START_M, speed_mps=SPEED_MPS),
            trajectory_start_s=T0,
            scheduler=ManualScheduler(clock),  # type: ignore[arg-type]
            clock=clock,
            count_sent=True,
        )
        registered = asyncio.Event()

        def on_event(event: object, now_s: float) -> None:
            if isinstance(event, Registered):
                sent_at_registered.append(client.running_info_sent())
                registered.set()

        client.add_listener(on_event)
        stop = asyncio.Event()
        task = asyncio.create_task(client.run(stop))
        for n in range(times):
            registered.clear()
            await registered.wait()
            if n + 1 < times:
                client.drop_connection()
        stop.set()
        await task

    run(main())
    answers = _writes_after(log, MessageType.REGISTER_RESPONSE)
    return Connections(sent_at_registered, answers, wires[0])


def _writes_after(log: list[tuple[str, bytes]], mtype: int) -> list[bytes]:
    """The first uplink write after each downlink chunk holding ``mtype``."""
    out = []
    waiting = False
    for direction, data in log:
        if direction == "down" and mtype in message_types(data):
            waiting = True
        elif direction == "up" and waiting:
            out.append(data)
            waiting = False
    return out


def _running_infos(wire: GroundWire) -> list[tuple[float, RunningInfo]]:
    return [
        (now, e.message)
        for now, e in wire.ground_events
        if isinstance(e, MessageReceived) and isinstance(e.message, RunningInfo)
    ]


def test_first_connection_sends_running_info_on_acceptance() -> None:
    result = _connect(1)
    assert result.sent_at_registered == [1]
    assert MessageType.RUNNING_INFO in message_types(result.answers[0])


def test_every_reconnection_sends_running_info_on_acceptance() -> None:
    result = _connect(3)
    assert result.sent_at_registered == [1, 2, 3]
    assert len(result.answers) == 3
    for answer in result.answers:
        assert MessageType.RUNNING_INFO in message_types(answer)


def test_the_first_running_info_says_where_the_train_is_now() -> None:
    """Not the position of the last connection: the trajectory's, when it is sent."""
    result = _connect(2)
    assert len(result.wires) == 2
    for wire in result.wires:
        [(received_s, info)] = _running_infos(wire)
        # sent one wire delay before the ground read it, on the virtual clock
        sent_s = received_s - 0.005
        assert abs(info.position_m - (START_M + SPEED_MPS * (sent_s - T0))) < 0.01
