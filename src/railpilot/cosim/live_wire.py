"""The live run's control wire (cosim/live.py): JSON lines over loopback TCP between the
run and its ground and train processes.

It is the rig's own wiring, not the train-ground link (that one is the EN 50159 safety
link of net/, with its frames, checks and timers). Over it the run says when the clock
starts and where the ground listens, and carries what the line's own equipment would: each
train's true position to the trackside once a second, and back the aspect of the signals
ahead (the cab signal, from the track circuits), a failure, the end of the run, and each
process's report at the end.

A process's first line is its hello, with the run's secret: the run hands each process it
starts the secret in the process's arguments, never over a socket, and takes no other
line from a connection whose hello does not carry it (any local program can reach a
loopback port, and this wire can stop trains, fail them and end the run).

A process that fails says so over the wire in one line (``op`` "failed", :func:`failure`)
and ends with no traceback (:func:`run_process`): the run stops at once and the command
prints that line. A port the ground cannot listen on carries its field and port too, so
the command names its own option.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import os
import sys
from collections.abc import Collection, Coroutine
from typing import Any

from railpilot.errors import ConfigError, RailpilotError, RunFailed

log = logging.getLogger(__name__)

#: the longest line on the wire (a train's report at the end: its sections and counters)
MAX_LINE = 16 * 1024 * 1024


async def send(writer: asyncio.StreamWriter, message: dict[str, Any]) -> None:
    """Write one message (a JSON object on one line)."""
    writer.write(json.dumps(message, separators=(",", ":")).encode() + b"\n")
    await writer.drain()


async def receive(reader: asyncio.StreamReader) -> dict[str, Any] | None:
    """The next message, or None when the other end has gone."""
    try:
        line = await reader.readline()
    except (ConnectionError, asyncio.IncompleteReadError, ValueError):
        return None
    if not line:
        return None
    message = json.loads(line)
    if not isinstance(message, dict):
        raise ValueError(f"control message {line[:80]!r} is not a JSON object")
    return message


def hello_name(
    hello: dict[str, Any] | None, secret: str, trains: Collection[int]
) -> int | str | None:
    """Who says hello: ``"ground"`` or the train's id, if ``hello`` is one (``op``
    "hello"), carries the run's ``secret`` and names the ground or one of ``trains``;
    otherwise None (the run closes that connection)."""
    if hello is None or hello.get("op") != "hello":
        return None
    given = hello.get("secret")
    if not isinstance(given, str) or not hmac.compare_digest(given.encode(), secret.encode()):
        return None
    role = hello.get("role")
    if role == "ground":
        return "ground"
    train = hello.get("train")
    if role == "train" and type(train) is int and train in trains:
        return train
    return None


async def connect(port: int) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """Open the wire to the run on 127.0.0.1:``port``."""
    return await asyncio.open_connection("127.0.0.1", port, limit=MAX_LINE)


class PortUnavailable(ConfigError):
    """A port a process of the run could not listen on: ``field`` (``"link_port"``,
    ``"admin_port"``, ``"http_port"``, ``"control_port"``) and the port asked for; the
    command names its own option for the field."""

    @classmethod
    def bind_failed(cls, field: str, port: int, exc: OSError) -> PortUnavailable:
        """From the bind's error: why, as the system says it (asyncio's own message
        repeats the address)."""
        reason = os.strerror(exc.errno) if exc.errno else str(exc)
        return cls(field, port, f"a port in [0, 65535] free on 127.0.0.1 ({reason})")


class Reported(Exception):
    """A process's failure, already told to the run over the wire."""


def error_line(exc: BaseException) -> str:
    """``exc`` in one line: a railpilot error's own message, any other with its type."""
    text = str(exc) if isinstance(exc, RailpilotError) else f"{type(exc).__name__}: {exc}"
    return " ".join(text.split()).rstrip(":") or type(exc).__name__


def failure(exc: BaseException) -> dict[str, Any]:
    """The wire's message for a process that failed with ``exc``."""
    message: dict[str, Any] = {"op": "failed", "error": error_line(exc)}
    if isinstance(exc, PortUnavailable):
        message |= {"field": exc.field, "port": exc.value, "allowed": exc.allowed}
    return message


def failure_error(name: str, message: dict[str, Any]) -> RailpilotError:
    """What the run raises for the ``failed`` message of its process ``name``."""
    if "field" in message:
        return ConfigError(str(message["field"]), message["port"], str(message["allowed"]))
    return RunFailed(f"the {name} process failed: {message['error']}")


def _log_failure(exc: BaseException) -> None:
    # the traceback only when the run's log level is debug: the run prints the error
    if log.isEnabledFor(logging.DEBUG):
        # here, not at the top: railpilot.net takes a second to import, and the ground
        # holds its ports before anything that slow (cosim/live_ground.py)
        from railpilot.net.logfmt import format_kv

        log.debug(format_kv("failed", error=error_line(exc)), exc_info=exc)


async def report_failure(writer: asyncio.StreamWriter, exc: BaseException) -> Reported:
    """Tell the run that this process failed with ``exc``; returns what to raise so that
    the process ends quietly (:func:`run_process`)."""
    _log_failure(exc)
    with contextlib.suppress(ConnectionError, RuntimeError):  # the run may be gone
        await send(writer, failure(exc))
    return Reported(error_line(exc))


def run_process(name: str, main: Coroutine[Any, Any, None]) -> None:
    """Run a process's ``main`` and end it without a traceback: a failure it reported
    over the wire exits 1 silently (the run prints it), one it could not report is one
    line on stderr; an interrupt (the terminal's Ctrl-C reaches every process of the
    run, and the run says so once) exits 130."""
    try:
        asyncio.run(main)
    except KeyboardInterrupt:
        sys.exit(130)
    except Reported:
        sys.exit(1)
    except Exception as exc:  # before the wire was open: nowhere else to say it
        _log_failure(exc)
        print(f"railpilot: error: the {name} process failed: {error_line(exc)}", file=sys.stderr)
        sys.exit(1)
