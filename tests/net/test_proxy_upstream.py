"""What the fault proxy counts when its upstream server is down and when it is up, over real
loopback TCP. A live line run reports as a train's connects the connections its proxy (the
train's radio) got through to the ground, as the co-simulation counts them
(cosim/live_train.py); while the ground is down the onboard's connection to the proxy
succeeds and is closed at once. Waits are bounded (helpers.run); nothing is timed.
"""

from __future__ import annotations

import asyncio

from railpilot.net import FaultProxy

from .helpers import run


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
