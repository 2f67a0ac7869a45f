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
"""

from __future__ import annotations

import asyncio
import hmac
import json
from collections.abc import Collection
from typing import Any

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
