"""The ground process of a live line run (cosim/live.py; docs/line-run.md "Live").

The ground as ``railpilot ground serve`` runs it, built from the same parts
(net/ground_app.py), on the run's clock: the link's front server with its store (an
SQLite file) and the dispatch application with the run's retimer, the admin port
the run's dispatcher speaks to, and the dashboard. It is started (and, for a ground
restart, killed with SIGKILL and started again on the same ports and store) by the run.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass

from railpilot.ground.assembly import GroundParts
from railpilot.ground.store import open_store
from railpilot.link import GroundConfig
from railpilot.net.admin import AdminServer
from railpilot.net.ground_app import live_ground
from railpilot.net.timers import LinkClock
from railpilot.onboard.drive import train_preset
from railpilot.web.ground_source import ServerSource, serve_dashboard

from .line_run import line_keys
from .live_wire import connect, receive, send
from .retimer_factory import retimer_factory
from .scenario import load_line_scenario


@dataclass(frozen=True)
class GroundArgs:
    """What the run tells a ground process when it starts it."""

    control_port: int
    scenario_path: str
    seed: int
    store_path: str
    token: str
    #: the run's control-wire secret (cosim/live_wire.py)
    secret: str
    #: the ports (0: any free one, the first start; a restart takes the same again)
    link_port: int = 0
    http_port: int = 0
    admin_port: int = 0
    #: when it opens its store and listens [s since the start of the run] (a restart's
    #: end of the down time); None: at once
    start_at_s: float | None = None


def run(args: GroundArgs) -> None:
    """The process's entry point (multiprocessing, spawn)."""
    logging.basicConfig(level=logging.WARNING)
    asyncio.run(_main(args))


async def _main(args: GroundArgs) -> None:
    scenario = load_line_scenario(args.scenario_path)
    keys = line_keys(scenario, args.seed)
    reader, writer = await connect(args.control_port)
    await send(writer, {"op": "hello", "role": "ground", "secret": args.secret})
    start = await receive(reader)
    if start is None:
        return
    clock = LinkClock(start["speedup"], scenario.epoch_s, start["wall_origin_s"])
    if args.start_at_s is not None:
        wait = clock.wall_s(scenario.epoch_s + args.start_at_s - clock())
        await asyncio.sleep(max(wait, 0.0))
    store = open_store(args.store_path)
    retimings: list[dict[str, object]] = []
    parts = GroundParts(
        GroundConfig(ground_id=1, require_auth=True),
        scenario.line,
        keys,
        store,
        retimer_factory(scenario, retimings),
    )
    dispatch = live_ground(parts, port=args.link_port, clock=clock)
    server = dispatch.server
    # the registration does not carry a train's category; the run's scenario does
    categories = {s.train_id: train_preset(s.kind).category for s in scenario.services}
    http, http_task = await serve_dashboard(
        ServerSource(dispatch, categories=categories), token=args.token, port=args.http_port
    )
    await server.start()
    dispatch.start()
    admin = AdminServer(dispatch, port=args.admin_port)
    await admin.start()
    await send(
        writer,
        {
            "op": "up",
            "at_s": clock() - scenario.epoch_s,
            "link_port": server.port,
            "http_port": http.port,
            "admin_port": admin.port,
            "restored": server.restored,
        },
    )
    while (message := await receive(reader)) is not None and message["op"] != "stop":
        pass
    await send(writer, {"op": "counters", "counters": server.counters(), "retiming": retimings})
    await admin.stop()
    dispatch.stop()
    await server.stop(timeout_s=1.0)
    http.should_exit = True
    await http_task
    store.close()
    writer.close()
