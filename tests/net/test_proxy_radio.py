"""A radio in the fault proxy and in front of the onboard's connection attempts, over real
loopback TCP (what a live line run puts between a train and the ground: cosim/live_train.py).

The radios here are scripted: each test says what every packet meets, and checks what the
ground and the train saw. Waits are bounded polls (helpers.until); nothing is timed.
"""

from __future__ import annotations

import itertools

from railpilot.link import LinkFailed, OnboardState
from railpilot.net import OnboardClient, Trajectory

from .helpers import FAST, TRAIN_ID, onboard_config, rig, run, until


class ScriptedRadio:
    """Loses every packet going a direction in ``lost``; delays the others by the next
    of ``delays_s`` (cycled)."""

    def __init__(self, delays_s: tuple[float, ...] = (0.0,)) -> None:
        self.lost: set[str] = set()
        self.delays = itertools.cycle(delays_s)
        self.asked = {"up": 0, "down": 0}

    def packet_delay_s(self, direction: str) -> float | None:
        self.asked[direction] += 1
        return None if direction in self.lost else next(self.delays)


def test_packets_the_radio_loses_never_reach_the_ground_and_the_link_times_out() -> None:
    radio = ScriptedRadio()
    radio.lost.add("up")

    async def scenario() -> None:
        async with rig(radio=radio) as r:
            await until(lambda: bool(r.onboard_of(TRAIN_ID, LinkFailed)))
            assert r.proxy is not None
            up = r.proxy.stats["up"]
            assert up["radio_lost"] >= 1
            assert up["radio_packets"] == radio.asked["up"] >= 1
            assert up["frames"] == 0  # nothing lost was passed on
            assert r.server.counters()["frames_received"] == 0
            assert r.clients[0].registrations == 0
            # the train's core gave up on a link the ground never heard: a failure
            await until(lambda: r.clients[0].link_failures >= 1)

    run(scenario())


def test_the_radio_s_delays_never_reorder_a_direction() -> None:
    # every other packet 0.15 s on the way, the next none, a cycle (0.1 s) later: passed
    # on when each arrives, every second packet would overtake the one before it and the
    # ground would reject that one as reordered
    radio = ScriptedRadio(delays_s=(0.15, 0.0))

    async def scenario() -> None:
        async with rig(radio=radio) as r:
            await until(lambda: len(r.running_infos()) >= 12)
            stamps = [e.timestamp_us for e in r.running_infos()]
            assert stamps == sorted(set(stamps))
            counters = r.server.counters()
            assert counters["reorders"] == counters["repeats"] == 0
            assert counters["rejected"].get("sequence", 0) == 0
            assert r.proxy is not None and r.proxy.stats["up"]["radio_lost"] == 0

    run(scenario())


def test_no_connection_is_opened_while_the_radio_is_down() -> None:
    covered = False

    async def scenario() -> None:
        async with rig(start=False) as r:
            client = OnboardClient(
                onboard_config(TRAIN_ID, timers=FAST),
                r.keys,
                "127.0.0.1",
                r.port,
                trajectory=Trajectory(start_m=4_000.0, speed_mps=15.0),
                radio_up=lambda: covered,
            )
            r.clients.append(client)
            r.start(client)
            await until(lambda: len(client.reconnect_delays_s) >= 3)
            assert client.connects == 0
            assert r.server.open_connections() == {}
            assert r.server.counters()["frames_received"] == 0
            nonlocal covered
            covered = True
            await until(lambda: client.state is OnboardState.REGISTERED)
            assert client.connects == 1

    run(scenario())
