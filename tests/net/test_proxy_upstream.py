"""What a train's connects and link failures count when its proxy (the train's radio in a live
line run) cannot reach the ground, and when the ground closes a link, over real loopback
TCP. A live line run reports as a train's connects the connections its proxy got through
to the ground, and as its link failures the connections that ended in a failure at either
end, as the co-simulation counts them (cosim/live_train.py); while the ground is down the
onboard's connection to the proxy succeeds and is closed at once, which is neither. Waits
are bounded (helpers.run, helpers.until); nothing is timed.
"""

from __future__ import annotations

import asyncio

from railpilot.net import FaultProxy, OnboardClient, ProxyOptions, Trajectory

from .helpers import TRAIN_ID, make_keys, onboard_config, rig, run, until


def test_only_connections_that_reach_the_upstream_server_count() -> None:
    async def scenario() -> None:
        reached = asyncio.Event()

        async def accept(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            reached.set()
            writer.close()

        # a port with nothing listening on it: the ground down
        server = await asyncio.start_server(accept, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        server.close()
        await server.wait_closed()
        async with FaultProxy("127.0.0.1", port) as proxy:
            host, proxy_port = proxy.host, proxy.port
            reader, writer = await asyncio.open_connection(host, proxy_port)
            assert await reader.read() == b""  # accepted, then closed by the proxy
            writer.close()
            assert (proxy.connections, proxy.upstream_connections) == (1, 0)
            # the ground up again on its port
            server = await asyncio.start_server(accept, "127.0.0.1", port)
            async with server:
                reader, writer = await asyncio.open_connection(host, proxy_port)
                await reached.wait()
                assert await reader.read() == b""  # the server closed it, through the proxy
                writer.close()
            assert (proxy.connections, proxy.upstream_connections) == (2, 1)
            assert proxy.report()["upstream_connections"] == 1

    run(scenario())


def test_a_train_whose_proxy_the_ground_refuses_connects_to_nothing_and_fails_nothing() -> None:
    async def scenario() -> None:
        server = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        server.close()
        await server.wait_closed()  # the ground down
        async with FaultProxy("127.0.0.1", port) as proxy:
            client = OnboardClient(
                onboard_config(TRAIN_ID),
                make_keys(),
                proxy.host,
                proxy.port,
                trajectory=Trajectory(start_m=4_000.0, speed_mps=15.0),
                seed=1,
            )
            stop = asyncio.Event()
            task = asyncio.create_task(client.run(stop))
            await until(lambda: proxy.connections >= 3)  # it tried, and tried again
            stop.set()
            await task
            assert proxy.upstream_connections == 0
            assert client.link_failures == 0

    run(scenario())


def test_a_link_the_other_side_closes_is_a_failure_and_a_shutdown_is_not() -> None:
    async def scenario() -> None:
        async with rig(proxy=ProxyOptions()) as r:
            client = r.clients[0]
            await until(lambda: client.registrations == 1)
            assert r.proxy is not None
            r.proxy.close_connections()  # as the ground closes a link it gave up on
            await until(lambda: client.registrations == 2)
            # the train's core did not give up: the close came from the other side
            assert client.events_seen["LinkFailed"] == 0
            assert client.link_failures == 1
            assert r.proxy.upstream_connections == 2
        # the rig's end shut the train down (deregistered, closed): not a failure
        assert client.link_failures == 1

    run(scenario())
