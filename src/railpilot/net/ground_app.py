"""A live ground from its parts: the server, and the dispatch core on it.

Every live ground (``ground serve``, a live line run's ground, the load test, the demos)
is built here from one :class:`~railpilot.ground.assembly.GroundParts` (line, config, keys,
store, retimer), with the clock and the address that only a live ground has.
"""

from __future__ import annotations

from railpilot.errors import ConfigError
from railpilot.ground.assembly import GroundParts
from railpilot.link.config import REPLAY_WINDOW_S

from .dispatch_host import DispatchHost
from .server import GroundServer
from .timers import WALL_CLOCK, LinkClock


def ground_server(
    parts: GroundParts,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    clock: LinkClock = WALL_CLOCK,
    replay_window_s: float = REPLAY_WINDOW_S,
    backlog: int = 1024,
) -> GroundServer:
    """The link's server of the ground ``parts`` describe (its dispatch core is not
    attached: :func:`live_ground` does that)."""
    return GroundServer(
        parts.config,
        parts.keys,
        host=host,
        port=port,
        backlog=backlog,
        replay_window_s=replay_window_s,
        store=parts.store,
        clock=clock,
    )


def live_ground(
    parts: GroundParts,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    clock: LinkClock = WALL_CLOCK,
    replay_window_s: float = REPLAY_WINDOW_S,
    backlog: int = 1024,
) -> DispatchHost:
    """The ground ``parts`` describe, live: its server (``.server``) with the dispatch core
    on it. Start it with ``await host.server.start()`` then ``host.start()``."""
    if parts.line is None:
        raise ConfigError("parts.line", None, "a line (the dispatch core dispatches one)")
    server = ground_server(
        parts,
        host=host,
        port=port,
        clock=clock,
        replay_window_s=replay_window_s,
        backlog=backlog,
    )
    return DispatchHost(server, parts.line, dispatch=parts.new_dispatch())


__all__ = ["ground_server", "live_ground"]
