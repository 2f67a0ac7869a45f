"""The ground process of a live line run (cosim/live.py; docs/line-run.md "Live").

The ground as ``railpilot ground serve`` runs it, built from the same parts
(net/ground_app.py), on the run's clock: the link's front server with its store (an
SQLite file) and the dispatch application with the run's retimer, the admin port
the run's dispatcher speaks to, and the dashboard. It is started (and, for a ground
restart, killed with SIGKILL and started again on the same ports and store) by the run.

The ports the user chose are held (listened on) the moment the process starts, before its
slow imports and long before the run's clock starts: a busy one is told to the run over
the control wire at once (:class:`~railpilot.cosim.live_wire.PortUnavailable`), and the
run stops before any train starts. A port that cannot be bound later (a restart's, taken
meanwhile by another program) is told the same way.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from dataclasses import dataclass
from typing import Any

from .live_wire import (
    PortUnavailable,
    connect,
    receive,
    report_failure,
    run_process,
    send,
)

#: the ports a ground process listens on, by their field in :class:`GroundArgs`
PORT_FIELDS = ("link_port", "http_port", "admin_port")


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
    #: the level of its log on stderr (``logging.WARNING``...)
    log_level: int = logging.WARNING


def run(args: GroundArgs) -> None:
    """The process's entry point (multiprocessing, spawn)."""
    if args.log_level <= logging.DEBUG:
        # at once, for a traceback of the ports' holding too; otherwise after it (the
        # import takes a second)
        from railpilot.net.logfmt import setup_logging

        setup_logging(args.log_level)
    run_process("ground", _main(args))


def hold_ports(ports: dict[str, int]) -> list[socket.socket]:
    """Listen on each port of ``ports`` (field -> port) that is not 0 on 127.0.0.1, as the
    ground's servers will; a port another program listens on is a
    :class:`PortUnavailable` naming its field. Close the sockets just before the servers
    bind."""
    held: list[socket.socket] = []
    try:
        for field, port in ports.items():
            if port == 0:
                continue  # any free one, found when the server binds
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            held.append(sock)
            # as the servers bind: a port whose last connections are in TIME_WAIT is free
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind(("127.0.0.1", port))
                sock.listen(1)
            except OSError as exc:
                raise PortUnavailable.bind_failed(field, port, exc) from None
    except BaseException:
        release(held)
        raise
    return held


def release(held: list[socket.socket]) -> None:
    for sock in held:
        sock.close()
    held.clear()


async def _main(args: GroundArgs) -> None:
    reader, writer = await connect(args.control_port)
    await send(writer, {"op": "hello", "role": "ground", "secret": args.secret})
    held: list[socket.socket] = []
    try:
        if args.start_at_s is None:
            # the first start: the ports are free until the run's clock starts, and a
            # restart's must stay closed through its down time (the trains are refused)
            held = hold_ports({field: getattr(args, field) for field in PORT_FIELDS})
            await send(writer, {"op": "held"})
        await _serve(args, reader, writer, held)
    except Exception as exc:
        raise await report_failure(writer, exc) from None
    finally:
        release(held)
        writer.close()


async def _serve(
    args: GroundArgs,
    reader: asyncio.StreamReader,
    writer: asyncio.StreamWriter,
    held: list[socket.socket],
) -> None:
    # imported only now: they take a second or two, and the ports are held first
    from railpilot.ground.assembly import GroundParts
    from railpilot.ground.store import open_store
    from railpilot.link import GroundConfig
    from railpilot.net.admin import AdminServer
    from railpilot.net.ground_app import live_ground
    from railpilot.net.logfmt import setup_logging
    from railpilot.net.timers import LinkClock
    from railpilot.onboard.drive import train_preset
    from railpilot.web.ground_source import ServerSource, serve_dashboard

    from .line_run import line_keys
    from .retimer_factory import retimer_factory
    from .scenario import load_line_scenario

    setup_logging(args.log_level)
    scenario = load_line_scenario(args.scenario_path)
    keys = line_keys(scenario, args.seed)
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
    release(held)  # the servers take the ports over
    http, http_task = await _bound(
        "http_port",
        args.http_port,
        serve_dashboard(
            ServerSource(dispatch, categories=categories), token=args.token, port=args.http_port
        ),
    )
    await _bound("link_port", args.link_port, server.start())
    dispatch.start()
    admin = AdminServer(dispatch, port=args.admin_port)
    await _bound("admin_port", args.admin_port, admin.start())
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


async def _bound(field: str, port: int, binding: Any) -> Any:
    """Await a server's ``binding`` (its start); a port it cannot listen on is a
    :class:`PortUnavailable` naming ``field``."""
    from railpilot.errors import ConfigError

    try:
        return await binding
    except OSError as exc:
        raise PortUnavailable.bind_failed(field, port, exc) from None
    except ConfigError as exc:
        if exc.field != field:  # the dashboard's bind names its port so
            raise
        raise PortUnavailable(field, port, exc.allowed) from None
