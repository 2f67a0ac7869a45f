"""A starting ground server refuses frames from before its start (protocol.md 5.2)."""

from __future__ import annotations

import asyncio
import time

from railpilot.link import GroundConfig
from railpilot.net.server import GroundServer


def test_server_start_sets_the_replay_floor() -> None:
    async def main() -> float:
        server = GroundServer(
            GroundConfig(ground_id=1, require_auth=False), None, replay_window_s=2.5
        )
        before = time.time()
        await server.start()
        await server.stop()
        return server.config.not_before_s - before

    offset = asyncio.run(asyncio.wait_for(main(), timeout=10))
    assert -2.5 - 1.0 < offset <= -2.5 + 1e-3


def test_a_floor_given_in_the_config_is_kept() -> None:
    async def main() -> float:
        config = GroundConfig(ground_id=1, require_auth=False, not_before_s=1_700_000_000.0)
        server = GroundServer(config, None)
        await server.start()
        await server.stop()
        return server.config.not_before_s

    assert asyncio.run(asyncio.wait_for(main(), timeout=10)) == 1_700_000_000.0
