"""``railpilot ground ...``, ``railpilot onboard ...`` and ``railpilot link ...``.

Parse, call :mod:`railpilot.net` / :mod:`railpilot.link`, print. Keys come only from a key
file with owner-only permissions (``--keys FILE``); they are never accepted on the command
line and never printed or logged. ``--json`` prints exactly one JSON object on stdout; logs
go to stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import errno
import json
import logging
import math
import os
import signal
import socket
import stat
import sys
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from railpilot.commands._common import json_line, log, print_json
from railpilot.errors import ConfigError
from railpilot.extras import require as require_extra
from railpilot.link.config import REPLAY_WINDOW_S
from railpilot.link.decode import FrameReport
from railpilot.link.decode_report import report_dict, report_text
from railpilot.link.errors import LinkConfigError
from railpilot.link.hex_text import DecodeInputError, holds_frame_start, looks_hex, parse_hex
from railpilot.units import kmh_to_mps, mps_to_kmh

if TYPE_CHECKING:
    from railpilot.web.token import DispatcherToken

DEFAULT_PORT = 7400
DEFAULT_ADMIN_PORT = 7401
#: ``ground serve --db``: in the working directory, like a log file (ground.store.DEFAULT_PATH)
DEFAULT_DB = "ground.db"
#: ``ground serve --http-host``: the dashboard answers only to these host names (web.app).
DEFAULT_HTTP_HOST = "127.0.0.1"
HTTP_HOSTS = ("127.0.0.1", "localhost")
#: ``ground serve --line``: the line the dashboard draws.
DEFAULT_LINE = "heavy-haul"


# --- argument helpers -------------------------------------------------------------------------


def _host_port(field: str, text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise LinkConfigError(field, text, "HOST:PORT with a port in [0, 65535]")
    return host.strip("[]"), int(port)


def _loopback(field: str, host: str) -> None:
    from railpilot.net.admin import LOOPBACK

    if host not in LOOPBACK:
        raise LinkConfigError(field, host, "a loopback address (127.0.0.1): test tool")


def _probability(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number in [0, 1]") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{value} is not in [0, 1]")
    return value


#: ``--seconds`` of the long-running commands: at most a year (omit it to run until stopped).
MAX_RUN_SECONDS = 366 * 86400.0


def _seconds(value: float | None) -> None:
    """Refuse a ``--seconds`` that is not a finite number in (0, MAX_RUN_SECONDS]; None
    (not given) runs until stopped."""
    if value is not None and not (math.isfinite(value) and 0.0 < value <= MAX_RUN_SECONDS):
        raise ConfigError(
            "--seconds",
            value,
            f"a finite number of seconds > 0 and <= {MAX_RUN_SECONDS:.0f} (366 days; omit "
            "it to run until stopped)",
        )


def _listen_error(option: str, value: Any, host: str, exc: Exception) -> ConfigError:
    """A listening socket that could not be opened, as an error naming the option."""
    if isinstance(exc, socket.gaierror) or not isinstance(exc, OSError) or not exc.errno:
        reason = str(getattr(exc, "strerror", None) or exc)
    else:  # asyncio's own message repeats the address: the system's reason only
        reason = os.strerror(exc.errno)
    if option == "--host":
        allowed = f"an address of this host to listen on ({reason})"
    else:
        allowed = f"a port in [0, 65535] free on {host} ({reason})"
    return ConfigError(option, value, allowed)


def _host_failed(exc: Exception) -> bool:
    """Whether a failed bind is the address's fault (not the port's)."""
    return isinstance(exc, socket.gaierror | UnicodeError) or getattr(exc, "errno", None) in (
        errno.EADDRNOTAVAIL,
        errno.EAFNOSUPPORT,
    )


def _keys(path: Path | None, no_auth: bool) -> Any:
    """Load the key file (refused when group/other may read it); None with --no-auth.
    Both given is refused: which of the two was meant is not ours to guess."""
    from railpilot.link import load_key_file

    if path is not None and no_auth:
        raise LinkConfigError(
            "--no-auth",
            f"with --keys {path}",
            "one or the other: --keys FILE for an authenticated link, --no-auth (without "
            "--keys) for an unauthenticated test link",
        )
    if path is None:
        if not no_auth:
            raise LinkConfigError(
                "--keys", None, "a key file (chmod 600), or --no-auth for a test link"
            )
        return None
    return load_key_file(path)


def _db_path(text: str) -> str:
    """Check ``--db`` before anything is written: ':memory:', or a file we may create or
    write in an existing directory (the WAL and shared-memory files go next to it)."""
    if text == ":memory:":
        return text
    path = Path(text)
    parent = path.parent
    if path.is_dir():
        problem = "a database file path, not a directory"
    elif not parent.is_dir():
        problem = f"a file in an existing directory ({parent} is not one)"
    elif path.exists() and (not path.is_file() or not os.access(path, os.R_OK | os.W_OK)):
        problem = "a regular file we may read and write"
    elif not os.access(parent, os.W_OK | os.X_OK):
        problem = f"a file in a directory we may write ({parent} is not)"
    else:
        return text
    raise ConfigError("--db", text, problem)


def _log_level(args: argparse.Namespace) -> None:
    from railpilot.net.logfmt import setup_logging

    setup_logging(getattr(logging, args.log_level.upper()))


def _add_log_level(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--log-level",
        default="info",
        choices=["debug", "info", "warning", "error"],
        help="stderr log level [info]",
    )


def _add_admin(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--admin-port",
        type=int,
        default=DEFAULT_ADMIN_PORT,
        help=f"admin port of the running server on 127.0.0.1 [{DEFAULT_ADMIN_PORT}]",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


def _run_async(main: Any) -> Any:
    """Run a coroutine; SIGINT/SIGTERM set the stop event it was given."""
    return asyncio.run(main)


async def _stop_on_signals() -> asyncio.Event:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError, RuntimeError):
            loop.add_signal_handler(sig, stop.set)
    return stop


# --- registration -------------------------------------------------------------------------------


def register(subparsers: argparse._SubParsersAction) -> None:
    _register_ground(subparsers)
    _register_onboard(subparsers)
    _register_link(subparsers)


def _register_ground(subparsers: argparse._SubParsersAction) -> None:
    ground = subparsers.add_parser(
        "ground",
        help="ground front server of the train-ground link (paper 001)",
        description="Run the ground front server, or talk to a running one over its admin "
        "port (line-delimited JSON on 127.0.0.1, see docs/link-operations.md).",
    )
    sub = ground.add_subparsers(dest="ground_command", metavar="ACTION")
    sub.required = True

    p = sub.add_parser(
        "serve",
        help="run the ground front server",
        description="Accept many trains, record registrations and running info, deliver "
        "TSRs/target points/dispatch commands with resend until acknowledged. Stops "
        "gracefully on SIGINT/SIGTERM. Timers are the defaults of docs/protocol.md section 9 "
        "(cycle 1 s); the onboard must use the same cycle.",
    )
    p.add_argument("--host", default="127.0.0.1", help="listen address [127.0.0.1]")
    p.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"link port, 0 = a free one (logged as event=listening ... port=N) [{DEFAULT_PORT}]",
    )
    p.add_argument("--keys", type=Path, help="key file (TOML, chmod 600) with per-train keys")
    p.add_argument("--no-auth", action="store_true", help="unauthenticated link (tests only)")
    p.add_argument("--ground-id", type=int, default=1, help="ground device id [1]")
    p.add_argument(
        "--admin-port",
        type=int,
        default=DEFAULT_ADMIN_PORT,
        help=f"admin port on 127.0.0.1, -1 = none [{DEFAULT_ADMIN_PORT}]",
    )
    p.add_argument(
        "--replay-window-s",
        type=float,
        default=REPLAY_WINDOW_S,
        help="frames timestamped more than this before the server started are refused as "
        f"replays (allowance for trains' clocks lagging the ground's) [{REPLAY_WINDOW_S:g}]",
    )
    p.add_argument(
        "--db",
        default=DEFAULT_DB,
        metavar="PATH|URL",
        help="store of TSRs, deliveries and the audit log, kept across restarts "
        "(docs/ground-store.md): a SQLite file, ':memory:' (keeps nothing), or a PostgreSQL "
        "URL postgresql://USER@HOST:PORT/DBNAME (password from ~/.pgpass or PGPASSWORD; one "
        f"given in the URL is used but never shown) [{DEFAULT_DB}]",
    )
    p.add_argument(
        "--http-port",
        type=int,
        metavar="PORT",
        help="serve the dispatcher dashboard on this port, 0 = a free one (docs/dashboard.md) "
        "[no dashboard]",
    )
    p.add_argument(
        "--http-host",
        default=DEFAULT_HTTP_HOST,
        help=f"dashboard address: loopback only ({', '.join(HTTP_HOSTS)}) [{DEFAULT_HTTP_HOST}]",
    )
    p.add_argument(
        "--dispatcher-token",
        metavar="TOKEN",
        help="token the dashboard asks for to set or cancel TSRs, at least 16 characters "
        "(visible to other users in the process list: prefer RAILPILOT_TOKEN or "
        "--token-file) [RAILPILOT_TOKEN, else --token-file, else a random one printed at "
        "start]",
    )
    p.add_argument(
        "--token-file",
        type=Path,
        metavar="PATH",
        help="read the dispatcher token from this file, which only its owner may read "
        "(mode 0600); when missing, it is created with a new token once the server is up, "
        "so the same token serves after a restart (RAILPILOT_TOKEN, when set, comes first)",
    )
    p.add_argument(
        "--line",
        default=DEFAULT_LINE,
        help="the line the ground dispatches (occupancy, target points, TSRs) and the "
        f"dashboard shows: a shipped name or a line TOML file [{DEFAULT_LINE}]",
    )
    p.add_argument("--seconds", type=float, help="stop after this many seconds (default: run)")
    _add_log_level(p)
    p.set_defaults(func=_ground_serve)

    # Each operation of the one schema (ground/operations.py) as a command; the fields are
    # passed on as typed and validated once, by the ground, as the admin port and the
    # dashboard's are.
    groups: dict[str, Any] = {}
    for words, op, description in OPERATION_COMMANDS:
        parent = sub
        if len(words) == 2:
            if words[0] not in groups:
                group = sub.add_parser(words[0], help=GROUP_HELP[words[0]])
                groups[words[0]] = group.add_subparsers(
                    dest=f"{words[0]}_command", metavar="ACTION"
                )
                groups[words[0]].required = True
            parent = groups[words[0]]
        p = parent.add_parser(words[-1], help=description, description=description)
        _add_operation_fields(p, op)
        if op == "tsr_set":
            p.add_argument(
                "--confirm",
                action="store_true",
                help="send it even over trains that already run above its limit there "
                "(without it, the ground lists them and sends nothing)",
            )
        _add_admin(p)
        p.set_defaults(func=_ground_admin, op=op)


#: (command words, operation, description) for ``railpilot ground ...``.
OPERATION_COMMANDS: tuple[tuple[tuple[str, ...], str, str], ...] = (
    (
        ("tsr", "set"),
        "tsr_set",
        "Set a TSR for the line: the ground delivers it to every "
        "train it concerns, now or when they register, resent until acknowledged.",
    ),
    (("tsr", "cancel"), "tsr_cancel", "Cancel a TSR on every train it went to."),
    (
        ("restriction", "set"),
        "restriction_set",
        "Declare a section fault or a lost switch "
        "indication: the signals protecting it show red and trains get target points.",
    ),
    (("restriction", "clear"), "restriction_clear", "Clear a declared restriction."),
    (
        ("target",),
        "target",
        "Send a target point by hand (the ground sends its own from "
        "occupancy and restrictions); the train's newest target id is in force.",
    ),
    (("dispatch",), "dispatch", "Send a dispatch command (text); resent until acknowledged."),
    (
        ("status",),
        "status",
        "Show trains, running info, deliveries, TSRs, restrictions and target points.",
    ),
)
GROUP_HELP = {
    "tsr": "set or cancel a temporary speed restriction",
    "restriction": "declare or clear a section fault / lost switch indication",
}
#: Help per field of the schema (ground/operations.py).
FIELD_HELP = {
    "start_km": "start km post [km]",
    "end_km": "end km post [km]",
    "limit_kmh": "speed limit [km/h]",
    "valid_from_min": "valid from, minutes from now [0]",
    "valid_until_min": "valid until, minutes from now",
    "reason": "why (kept in the ground's audit log)",
    "session": "TSR session number [the ground's next]",
    "trains": "train id (repeatable), or 'all' where allowed",
    "block": "block section id",
    "track": "up, down or both [both]",
    "id": "restriction id",
    "km": "red signal km post [km]",
    "text": "command text (UTF-8, <= 1000 bytes)",
    "command": "command number [the ground's next]",
}


def _add_operation_fields(p: argparse.ArgumentParser, op: str) -> None:
    from railpilot.ground.operations import FIELDS

    required, optional = FIELDS[op]
    for name in required + optional:
        need = " (required)" if name in required else ""
        if name == "trains":
            p.add_argument(
                "--train", action="append", dest="trains", metavar="ID", help=FIELD_HELP[name]
            )
        else:
            flag = "--" + name.replace("_", "-")
            p.add_argument(flag, dest=name, metavar="VALUE", help=FIELD_HELP[name] + need)


def _register_onboard(subparsers: argparse._SubParsersAction) -> None:
    onboard = subparsers.add_parser(
        "onboard",
        help="onboard endpoint of the train-ground link (paper 001)",
        description="Run one train's onboard endpoint.",
    )
    sub = onboard.add_subparsers(dest="onboard_command", metavar="ACTION")
    sub.required = True
    p = sub.add_parser(
        "run",
        help="connect, register and report a simulated run",
        description="Connect to the ground, register, send running info every cycle from a "
        "simulated trajectory, answer time checks, apply TSRs (extended by the train length) "
        "and target points; reconnect with backoff and jitter; on SIGINT/SIGTERM deregister "
        "and stop.",
    )
    p.add_argument("--server", required=True, help="ground HOST:PORT")
    p.add_argument("--train-id", type=int, required=True, help="train (device) id")
    p.add_argument("--keys", type=Path, help="key file (TOML, chmod 600) with this train's key")
    p.add_argument("--no-auth", action="store_true", help="unauthenticated link (tests only)")
    p.add_argument("--ground-id", type=int, default=1, help="ground device id [1]")
    p.add_argument("--length-m", type=float, default=2600.0, help="train length [m] [2600]")
    p.add_argument("--train-number", default="K1234", help="train number [K1234]")
    p.add_argument("--loco-number", default="SS4-0001", help="locomotive number [SS4-0001]")
    p.add_argument("--driver-id", type=int, default=1, help="driver id [1]")
    p.add_argument("--start-km", type=float, default=100.0, help="start km post [100]")
    p.add_argument("--speed-kmh", type=float, default=72.0, help="initial speed [72 km/h]")
    p.add_argument("--decel", type=float, default=0.0, help="braking [m/s^2], 0 = cruise")
    p.add_argument("--direction", choices=["up", "down"], default="up", help="[up]")
    p.add_argument("--seed", type=int, default=0, help="reconnect jitter seed [0]")
    p.add_argument("--seconds", type=float, help="stop after this many seconds (default: run)")
    p.add_argument("--json", action="store_true", help="print a JSON summary at the end")
    _add_log_level(p)
    p.set_defaults(func=_onboard_run)


def _register_link(subparsers: argparse._SubParsersAction) -> None:
    link = subparsers.add_parser(
        "link",
        help="link tools: decode, fault-injection proxy, load test",
        description="Tools for the train-ground link (docs/protocol.md).",
    )
    sub = link.add_subparsers(dest="link_command", metavar="TOOL")
    sub.required = True

    p = sub.add_parser(
        "decode",
        help="decode frames from hex or raw bytes",
        description="Decode every frame in FILE (or stdin) and show each check's verdict, "
        "a frame at a time. Input is raw bytes when it holds a frame start (bytes 0x7E 0x01: "
        "the header byte and the version byte), otherwise hex text (whitespace, ':', '0x' "
        "prefixes and '#' comments ignored); bad hex exits 2 naming its line and column. "
        "A frame cut off by the end of the input is reported as truncated.",
    )
    p.add_argument("file", nargs="?", default="-", help="input file, '-' = stdin [-]")
    p.add_argument("--keys", type=Path, help="key file (chmod 600) to verify MACs")
    form = p.add_mutually_exclusive_group()
    form.add_argument("--hex", action="store_true", help="input is hex text (no detection)")
    form.add_argument("--raw", action="store_true", help="input is raw bytes (no detection)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_link_decode)

    p = sub.add_parser(
        "proxy",
        help="fault-injection proxy (loopback only)",
        description="Forward a link through per-frame faults: drop, duplicate, reorder, "
        "corrupt, delay, inject, split. Loopback only. Stops on SIGINT/SIGTERM or after "
        "--seconds and prints what it did.",
    )
    p.add_argument("--listen", required=True, help="listen HOST:PORT (loopback)")
    p.add_argument("--upstream", required=True, help="ground HOST:PORT (loopback)")
    p.add_argument("--drop", type=_probability, default=0.0, help="frame drop probability")
    p.add_argument("--duplicate", type=_probability, default=0.0, help="duplicate probability")
    p.add_argument("--reorder", type=_probability, default=0.0, help="reorder probability")
    p.add_argument("--corrupt", type=_probability, default=0.0, help="bit-flip probability")
    p.add_argument("--delay", type=float, default=0.0, metavar="MS", help="delay frames [ms]")
    p.add_argument("--delay-p", type=_probability, default=1.0, help="share delayed [1]")
    p.add_argument(
        "--inject", metavar="FILE|HEX", help="wire bytes to insert once: a file's, or in hex"
    )
    p.add_argument("--inject-after", type=int, default=3, help="insert after N frames [3]")
    p.add_argument("--inject-direction", choices=["up", "down"], default="up", help="[up]")
    p.add_argument("--split", action="store_true", help="write frames in random pieces")
    p.add_argument(
        "--faults-on", choices=["both", "up", "down"], default="both", help="directions [both]"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed [0]")
    p.add_argument("--seconds", type=float, help="stop after this many seconds")
    p.add_argument("--json", action="store_true", help="print the counts as one JSON object")
    _add_log_level(p)
    p.set_defaults(func=_link_proxy)

    p = sub.add_parser(
        "loadtest",
        help="N trains against one server on loopback",
        description="Start a ground server and N onboard endpoints (in a child process) on "
        "loopback, 1 Hz running info with HMAC, one TSR broadcast; report latency and losses. "
        "The trains run along the heavy-haul line, both ways. With --dashboard the ground "
        "also serves the dispatcher dashboard and the page stays open in Debian's headless "
        "chromium (another process) for the whole run; the report then says how often the "
        "page updated and what each snapshot cost the server (docs/scaling.md).",
    )
    p.add_argument("--trains", type=int, default=100, help="number of trains [100]")
    p.add_argument("--seconds", type=float, default=10.0, help="run time [10]")
    p.add_argument("--seed", type=int, default=1, help="seed [1]")
    p.add_argument("--client-processes", type=int, default=1, help="onboard processes [1]")
    p.add_argument(
        "--dispatch",
        action="store_true",
        help="run the ground's dispatch core too, as ground serve does (TSR manager, "
        "occupancy, target points); --dashboard implies it",
    )
    p.add_argument(
        "--dashboard",
        action="store_true",
        help="serve the dashboard too, open it in headless chromium (/usr/bin/chromium)",
    )
    p.add_argument(
        "--screenshot", type=Path, metavar="PNG", help="with --dashboard: the page at the end"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_link_loadtest)


# --- ground -----------------------------------------------------------------------------------


def _ground_serve(args: argparse.Namespace) -> int:
    from railpilot.gc_tuning import freeze_startup
    from railpilot.ground.assembly import GroundParts
    from railpilot.ground.store import StoreError, is_postgres_url, open_store, redact_dsn
    from railpilot.link import GroundConfig
    from railpilot.net.admin import AdminServer
    from railpilot.net.ground_app import live_ground

    keys = _keys(args.keys, args.no_auth)
    config = GroundConfig(ground_id=args.ground_id, require_auth=keys is not None)
    if not 0 <= args.port <= 65535:
        raise LinkConfigError("--port", args.port, "0..65535")
    if args.admin_port != -1 and not 0 <= args.admin_port <= 65535:
        raise LinkConfigError("--admin-port", args.admin_port, "0..65535, or -1 = none")
    if not (math.isfinite(args.replay_window_s) and 0 <= args.replay_window_s <= 3600):
        raise LinkConfigError("--replay-window-s", args.replay_window_s, "0..3600 s")
    line = _load_line(args.line)
    dashboard = _dashboard_options(args)
    db = args.db if is_postgres_url(args.db) else _db_path(args.db)
    _log_level(args)
    # The store is opened before the server listens (it restores from it first); if the
    # server then cannot start, a store file this run created is removed again.
    created = [] if is_postgres_url(db) else _new_sqlite_files(db)
    try:
        store = open_store(db)
    except StoreError as exc:  # not a database, another schema, no WAL, no server ...
        _remove(created)
        allowed = (
            exc.allowed if exc.field in ("path", "db") else f"a railpilot ground store ({exc})"
        )
        # redact_dsn: a PostgreSQL URL's password is never shown
        raise ConfigError("--db", redact_dsn(db), allowed) from None
    started = False

    async def main() -> None:
        nonlocal started
        stop = await _stop_on_signals()
        dispatch = live_ground(
            GroundParts(config, line, keys, store),
            host=args.host,
            port=args.port,
            replay_window_s=args.replay_window_s,
        )
        server = dispatch.server
        http = None
        admin = None
        try:
            # Every port is bound before the link's server touches the store (it restores
            # from it, and notes that in its audit log): a busy port or an address that is
            # not this host's stops everything first. The dashboard answers 503 ("ground
            # starting") until the dispatch core has restored (ServerSource.starting).
            if dashboard is not None:
                http = await _start_dashboard(dispatch, args, dashboard[0])
            if args.admin_port != -1:
                admin = AdminServer(dispatch, port=args.admin_port)
                try:
                    await admin.start(serve=False)  # answers once the ground is ready
                except OSError as exc:
                    raise _listen_error("--admin-port", args.admin_port, "127.0.0.1", exc) from None
            try:
                await server.start()
            except (OSError, UnicodeError) as exc:  # a busy port, not an address of ours
                if _host_failed(exc):
                    raise _listen_error("--host", args.host, args.host, exc) from None
                raise _listen_error("--port", args.port, args.host, exc) from None
            dispatch.start()
            if admin is not None:
                await admin.serve()
            if http is not None and dashboard is not None:  # it shows the ground's state now
                _print_dashboard(args, http[0].port, *dashboard)
            started = True
            # Everything alive now lives as long as the process: out of the collector's
            # reach, so that its full collections stop walking it (railpilot/gc_tuning.py).
            freeze_startup()
            if args.seconds is not None:
                asyncio.get_running_loop().call_later(args.seconds, stop.set)
            await stop.wait()
        finally:
            if admin is not None:
                await admin.stop()
            dispatch.stop()
            if server.started_at_s is not None:
                await server.stop()
            if http is not None:
                http[0].should_exit = True
                await http[1]

    try:
        # After --db (a store that cannot be used is named first); like every failure
        # before the server runs, this closes the store and removes one this run created.
        _seconds(args.seconds)
        _run_async(main())
    finally:
        store.close()
        if not started:
            _remove(created)
    return 0


def _new_sqlite_files(db: str) -> list[Path]:
    """The files a SQLite store at ``db`` may create that do not exist yet (none when the
    store itself exists: a store that was there is never removed)."""
    if db == ":memory:" or os.path.lexists(db):
        return []
    names = (db, f"{db}-wal", f"{db}-shm", f"{db}-journal")
    return [Path(name) for name in names if not os.path.lexists(name)]


def _remove(paths: Iterable[Path]) -> None:
    """Remove the files this run created (the store of a server that did not start)."""
    for path in paths:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _load_line(name: str) -> Any:
    from railpilot.line.loader import load_line

    try:
        return load_line(name)
    except ConfigError as exc:
        raise ConfigError("--line", name, f"a line that loads ({exc})") from None


def _dashboard_options(args: argparse.Namespace) -> tuple[str, DispatcherToken] | None:
    """Check the dashboard's options before anything starts: ``(token, where the token
    comes from)``, or None without
    ``--http-port`` (then the other dashboard options are refused)."""
    if args.http_port is None:
        for option, value, default in (
            ("--http-host", args.http_host, DEFAULT_HTTP_HOST),
            ("--dispatcher-token", args.dispatcher_token, None),
            ("--token-file", args.token_file, None),
        ):
            if value != default:
                shown = "<hidden>" if option == "--dispatcher-token" else value
                raise ConfigError(option, shown, "to be given with --http-port (the dashboard)")
        return None
    if not 0 <= args.http_port <= 65535:
        raise ConfigError("--http-port", args.http_port, "0..65535 (0: a free one)")
    require_extra("web", "--http-port", args.http_port)
    from railpilot.web.token import dispatcher_token

    if args.http_host not in HTTP_HOSTS:
        raise ConfigError(
            "--http-host",
            args.http_host,
            f"a loopback host name ({', '.join(HTTP_HOSTS)}): the dashboard is not to be "
            "reached from other machines yet (docs/dashboard.md)",
        )
    # --dispatcher-token, else RAILPILOT_TOKEN, else --token-file, else a random one
    token = dispatcher_token(args.dispatcher_token, os.environ, args.token_file)
    return token.value, token


async def _start_dashboard(
    dispatch: Any, args: argparse.Namespace, token: str
) -> tuple[Any, asyncio.Task[None]]:
    """Serve the dashboard over the ground's dispatch in this loop (it answers 503 until
    the dispatch core has restored from the store)."""
    from railpilot.web.ground_source import ServerSource, serve_dashboard

    source = ServerSource(dispatch)
    try:
        return await serve_dashboard(source, token=token, host=args.http_host, port=args.http_port)
    except ConfigError as exc:
        raise ConfigError("--http-port", args.http_port, exc.allowed) from None


def _print_dashboard(
    args: argparse.Namespace, port: int, token: str, origin: DispatcherToken
) -> None:
    """The dashboard's address, once it shows the ground, and where its token is (the
    token itself when it was made up here and kept nowhere: printed once, never logged).
    A new token file is written here, so a start that fails leaves none behind."""
    origin.save()
    print(
        f"dashboard: http://{args.http_host}:{port}/  token: {origin.shown()}",
        file=sys.stderr,
        flush=True,
    )


def _ground_admin(args: argparse.Namespace) -> int:
    from railpilot.ground.operations import FIELDS
    from railpilot.net.admin import AdminError, admin_request

    if not 1 <= args.admin_port <= 65535:
        raise ConfigError(
            "--admin-port", args.admin_port, "the running server's admin port, in [1, 65535]"
        )
    # who asked, for the ground's audit log: the operator's login on this host
    request: dict[str, Any] = {"op": args.op, "actor": _login()}
    required, optional = FIELDS[args.op]
    for name in required + optional:
        value = getattr(args, name, None)
        if value is None:
            continue
        if name == "trains":
            value = "all" if value == ["all"] else [int(v) if v.isdigit() else v for v in value]
        request[name] = value
    if getattr(args, "confirm", False):
        request["confirm"] = True
    try:
        response = asyncio.run(admin_request(request, port=args.admin_port))
    except (OSError, TimeoutError, AdminError) as exc:
        log(f"railpilot: error: cannot reach the admin port 127.0.0.1:{args.admin_port} ({exc})")
        return 1
    if args.json:
        print_json(response)
    if response.get("warning"):
        _print_tsr_warning(response["warning"])
        return 2
    if not response.get("ok"):
        errors = response.get("errors") or {"request": response.get("error")}
        for field, message in errors.items():
            log(f"railpilot: error: {field}: {message}")
        return 2
    result = response["result"]
    if not args.json:
        if args.op == "status":
            _print_status(result)
        else:
            shown = {k: v for k, v in result.items() if k != "deliveries"}
            print(", ".join(f"{k} {v}" for k, v in shown.items()))
            for train, outcome in result.get("deliveries", {}).items():
                print(f"train {train}: {outcome}")
    outcomes: dict[str, str] = result.get("deliveries", {}) if args.op != "status" else {}
    refused = [t for t, r in outcomes.items() if r.startswith("error")]
    if refused:
        log(f"railpilot: error: refused for train(s) {', '.join(refused)}")
        return 2
    return 0


def _print_tsr_warning(warning: Mapping[str, Any]) -> None:
    """A TSR the ground did not send: the trains it would catch above its limit, one line
    each (ground/tsr_warning.py)."""
    trains = warning.get("trains", [])
    log(
        f"railpilot: warning: TSR not sent: {len(trains)} train(s) already above its limit of "
        f"{warning.get('limit_kmh')} km/h there or too close to slow down:"
    )
    for train in trains:
        log(f"  {train.get('text')}")
    log("railpilot: run it again with --confirm to send it anyway")


def _login() -> str:
    import getpass

    try:
        name = getpass.getuser()
    except (KeyError, OSError):  # no user name for this uid (a bare container)
        name = f"uid {os.getuid()}" if hasattr(os, "getuid") else "cli"
    return name[:64] if name.isprintable() and name.strip() else "cli"


def _print_status(status: dict[str, Any]) -> None:
    from railpilot.net.status_text import status_lines

    for line in status_lines(status, time.time()):
        print(line)


# --- onboard ----------------------------------------------------------------------------------


def _onboard_run(args: argparse.Namespace) -> int:
    from railpilot.link import OnboardConfig, TravelDirection
    from railpilot.net.client import OnboardClient, Trajectory

    host, port = _host_port("--server", args.server)
    keys = _keys(args.keys, args.no_auth)
    _seconds(args.seconds)
    _onboard_values(args)
    with _named_as_options(ONBOARD_OPTIONS):
        config = OnboardConfig(
            train_id=args.train_id,
            ground_id=args.ground_id,
            train_number=args.train_number,
            loco_number=args.loco_number,
            driver_id=args.driver_id,
            train_length_m=args.length_m,
            require_auth=keys is not None,
        )
    trajectory = Trajectory(
        start_m=args.start_km * 1000.0,
        speed_mps=kmh_to_mps(args.speed_kmh),
        decel_mps2=args.decel,
        direction=TravelDirection.UP if args.direction == "up" else TravelDirection.DOWN,
    )
    _log_level(args)

    async def main() -> OnboardClient:
        stop = await _stop_on_signals()
        client = OnboardClient(config, keys, host, port, trajectory=trajectory, seed=args.seed)
        await client.run(stop, duration_s=args.seconds)
        return client

    client = _run_async(main())
    summary = {
        "train_id": args.train_id,
        "connects": client.connects,
        "registrations": client.registrations,
        "active_tsrs": {
            str(s): {
                "start_km": t.start_m / 1000,
                "end_km": t.end_m / 1000,
                "zone_start_km": t.zone_start_m / 1000,
                "zone_end_km": t.zone_end_m / 1000,
                "limit_kmh": round(mps_to_kmh(t.limit_mps), 2),
            }
            for s, t in client.endpoint.active_tsrs.items()
        },
        "events": dict(client.events_seen),
    }
    if args.json:
        print_json(summary)
    return 0


@contextlib.contextmanager
def _named_as_options(options: Mapping[str, str]) -> Iterator[None]:
    """A :class:`LinkConfigError` about a setting the command line fills is raised again
    naming its option (``train_length_m`` -> ``--length-m``); others pass unchanged."""
    try:
        yield
    except LinkConfigError as exc:
        option = options.get(exc.field)
        if option is None:
            raise
        raise LinkConfigError(option, exc.value, exc.allowed) from None


#: ``onboard run`` option of each onboard setting / message field it fills.
ONBOARD_OPTIONS = {
    "train_id": "--train-id",
    "ground_id": "--ground-id",
    "train_number": "--train-number",
    "loco_number": "--loco-number",
    "driver_id": "--driver-id",
    "train_length_m": "--length-m",
}


def _onboard_values(args: argparse.Namespace) -> None:
    """Refuse, before anything starts, what the train's messages could not carry: the
    values go into every RegisterRequest and RunningInfo it sends (link/messages.py)."""
    from railpilot.link import RegisterRequest, RunningInfo, TravelDirection
    from railpilot.link.errors import MessageFieldError
    from railpilot.link.messages import MAX_POSITION_M, MAX_SPEED_MPS

    max_km = MAX_POSITION_M / 1000.0
    if not (math.isfinite(args.start_km) and 0.0 <= args.start_km <= max_km):
        raise LinkConfigError("--start-km", args.start_km, f"a finite km post in [0, {max_km:g}]")
    max_kmh = round(mps_to_kmh(MAX_SPEED_MPS), 6)
    if not (math.isfinite(args.speed_kmh) and 0.0 <= args.speed_kmh <= max_kmh):
        raise LinkConfigError(
            "--speed-kmh", args.speed_kmh, f"a finite speed in [0, {max_kmh:g}] km/h"
        )
    if not (math.isfinite(args.decel) and args.decel >= 0.0):
        raise LinkConfigError(
            "--decel", args.decel, "a finite deceleration >= 0 m/s^2 (0 = cruise)"
        )
    try:
        RegisterRequest(
            train_number=args.train_number,
            loco_number=args.loco_number,
            driver_id=args.driver_id,
            train_length_m=args.length_m,
        )
        RunningInfo(
            driver_id=args.driver_id,
            train_number=args.train_number,
            loco_number=args.loco_number,
            direction=TravelDirection.UP,
            speed_mps=min(kmh_to_mps(args.speed_kmh), MAX_SPEED_MPS),
            position_m=args.start_km * 1000.0,
        )
    except MessageFieldError as exc:
        option = ONBOARD_OPTIONS.get(exc.field, exc.field)
        value = getattr(args, option[2:].replace("-", "_"), exc.value)
        raise LinkConfigError(option, value, exc.allowed) from None


# --- link tools -------------------------------------------------------------------------------


def _read_input(name: str) -> bytes:
    if name == "-":
        return sys.stdin.buffer.read()
    try:
        return Path(name).read_bytes()
    except OSError as exc:
        raise DecodeInputError(name, f"not a readable file ({exc.strerror})") from None


#: Why input without a frame start was read as hex (shown with its first bad character).
_READ_AS_HEX = (
    "; the input holds no frame start (bytes 0x7E 0x01), so it was read as hex text: "
    "--raw reads it as raw bytes"
)


def _link_decode(args: argparse.Namespace) -> int:
    from railpilot.link import decode_stream

    # --keys is optional here (MACs are checked only with it); an unsafe key file is
    # refused before anything is read
    keys = _keys(args.keys, no_auth=args.keys is None)
    data = _read_input(args.file)
    if args.hex or (not args.raw and not holds_frame_start(data)):
        # Every input error is raised here, before anything is printed.
        data = parse_hex(data, hint="" if args.hex else _READ_AS_HEX)
    reports = decode_stream(data, keys)  # a generator: one report at a time
    if args.json:
        _write_json(reports, len(data), sys.stdout)
    else:
        _write_text(reports, sys.stdout)
    return 0


def _write_json(reports: Iterable[FrameReport], n_bytes: int, out: TextIO) -> None:
    """One JSON object, written a frame at a time (one frame per line).

    ``{"frames": [...], "count", "ok", "failed", "bytes", "truncated"}``; only one frame's
    report is held at a time, and the totals come last.
    """
    count = ok = 0
    truncated = False
    out.write('{\n  "frames": [')
    for report in reports:
        out.write(f"{',' if count else ''}\n    {json_line(report_dict(report))}")
        count += 1
        ok += report.ok
        truncated = truncated or report.truncated
    out.write("\n  ]" if count else "]")
    totals = {
        "count": count,
        "ok": ok,
        "failed": count - ok,
        "bytes": n_bytes,
        "truncated": truncated,
    }
    for key, value in totals.items():
        out.write(f',\n  "{key}": {json.dumps(value)}')
    out.write("\n}\n")


def _write_text(reports: Iterable[FrameReport], out: TextIO) -> None:
    """Each frame as soon as it is decoded: a header line, then a line per verdict."""
    count = 0
    for count, report in enumerate(reports, 1):
        out.write(report_text(count, report) + "\n")
    if not count:
        out.write("no frames found\n")


#: how a refusal of ``link proxy``'s options ends (it is no link endpoint)
PROXY_NOT_STARTED = "the proxy was not started"


def _link_proxy(args: argparse.Namespace) -> int:
    from railpilot.net.proxy import FaultProxy, ProxyOptions

    try:
        lhost, lport = _host_port("--listen", args.listen)
        uhost, uport = _host_port("--upstream", args.upstream)
        _loopback("--listen", lhost)
        _loopback("--upstream", uhost)
        inject = b"" if args.inject is None else _inject_bytes(args.inject)
    except LinkConfigError as exc:  # the proxy is no endpoint: say what did not happen
        raise LinkConfigError(
            exc.field, exc.value, exc.allowed, what_next=PROXY_NOT_STARTED
        ) from None
    _seconds(args.seconds)
    directions = ("up", "down") if args.faults_on == "both" else (args.faults_on,)
    options = ProxyOptions(
        drop=args.drop,
        duplicate=args.duplicate,
        reorder=args.reorder,
        corrupt=args.corrupt,
        delay_ms=args.delay,
        delay_p=args.delay_p,
        inject=inject,
        inject_after=args.inject_after,
        inject_direction=args.inject_direction,
        split=args.split,
        directions=directions,  # type: ignore[arg-type]
        seed=args.seed,
    )
    _log_level(args)

    async def main() -> dict[str, Any]:
        stop = await _stop_on_signals()
        proxy = FaultProxy(uhost, uport, options, host=lhost, port=lport)
        try:
            await proxy.start()
        except OSError as exc:  # a busy port, no IPv6 for ::1 ...
            raise _listen_error("--listen", args.listen, lhost, exc) from None
        if args.seconds is not None:
            asyncio.get_running_loop().call_later(args.seconds, stop.set)
        await stop.wait()
        await proxy.stop()
        return proxy.report()

    report = _run_async(main())
    if args.json:
        print_json(report)
    else:
        for direction in ("up", "down"):
            print(f"{direction}: {report[direction]}")
    return 0


#: What ``link proxy --inject`` takes (docs/link-operations.md, "Fault-injection proxy").
_INJECT_ALLOWED = (
    "a readable file, or wire bytes in hex (0-9 a-f A-F, whitespace, ':', '0x' prefixes)"
)


def _inject_bytes(value: str) -> bytes:
    """``--inject FILE|HEX``: the bytes of the file ``value`` names (parsed when they are hex
    text), else ``value`` itself when it is hex; anything else is refused, never injected
    as the characters of a mistyped file name."""

    def refused(reason: str) -> LinkConfigError:
        return LinkConfigError("--inject", value, f"{_INJECT_ALLOWED}; {reason}")

    try:
        mode: int | None = os.stat(value).st_mode
    except OSError as exc:  # a hex string longer than a file name may be is no file either
        if exc.errno not in (errno.ENOENT, errno.ENOTDIR, errno.ENAMETOOLONG):
            raise refused(f"it cannot be read ({exc.strerror})") from None
        mode = None
    if mode is None:
        data = value.encode("utf-8", "surrogateescape")
        if not looks_hex(data):
            raise refused("no such file, and not hex")
    elif not stat.S_ISREG(mode):
        raise refused("it is a directory" if stat.S_ISDIR(mode) else "it is not a regular file")
    else:
        try:
            data = Path(value).read_bytes()
        except OSError as exc:
            raise refused(f"the file cannot be read ({exc.strerror})") from None
        if not data:
            raise refused("the file is empty")
    if not looks_hex(data):
        return data
    return parse_hex(data, "--inject", what_next=PROXY_NOT_STARTED)


def _link_loadtest(args: argparse.Namespace) -> int:
    from railpilot.rigs.loadtest import (
        MAX_SECONDS,
        LoadtestOptions,
        check_dashboard,
        run_loadtest,
    )

    if args.screenshot is not None and not args.dashboard:
        raise ConfigError("--screenshot", str(args.screenshot), "to be given with --dashboard")
    if args.dashboard:
        require_extra("web", "--dashboard", "on")
    if not (math.isfinite(args.seconds) and 1.0 <= args.seconds <= MAX_SECONDS):
        raise ConfigError(
            "--seconds", args.seconds, f"a finite number of seconds in [1, {MAX_SECONDS:g}]"
        )
    # each field of LoadtestOptions is filled by the option of its name
    fields = ("trains", "seconds", "seed", "client_processes", "dispatch", "dashboard")
    with _named_as_options({f: "--" + f.replace("_", "-") for f in (*fields, "screenshot")}):
        options = LoadtestOptions(
            **{f: getattr(args, f) for f in fields},
            screenshot=None if args.screenshot is None else str(args.screenshot),
        )
    try:
        check_dashboard(options)
    except ConfigError as exc:
        raise ConfigError("--dashboard", "on", exc.allowed) from None
    log(
        f"load test: {options.trains} trains for {options.seconds} s on 127.0.0.1"
        + (" with the dashboard open in chromium" if options.dashboard else "")
        + " ..."
    )
    report = run_loadtest(options)
    if args.json:
        print_json(report)
    else:
        for key, value in report.items():
            print(f"{key}: {value}")
    return 0
