"""The live run's control wire takes lines only from the processes the run started: their
hello carries the run's secret (cosim/live_wire.py)."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest

from railpilot.cosim.live import LiveOptions, _LiveRun
from railpilot.cosim.live_wire import MAX_LINE, connect, hello_name, send
from railpilot.cosim.scenario import load_line_scenario

SECRET = "s3cret-of-this-run"
TRAINS = (101, 102)


@pytest.mark.parametrize(
    ("hello", "name"),
    [
        ({"op": "hello", "role": "ground", "secret": SECRET}, "ground"),
        ({"op": "hello", "role": "train", "train": 102, "secret": SECRET}, 102),
    ],
)
def test_a_process_of_the_run_is_named_by_its_hello(hello: dict[str, Any], name: object) -> None:
    assert hello_name(hello, SECRET, TRAINS) == name


@pytest.mark.parametrize(
    "hello",
    [
        None,  # the connection closed before a line
        {"op": "seen", "role": "ground", "secret": SECRET},  # not a hello
        {"op": "hello", "role": "ground"},  # no secret
        {"op": "hello", "role": "ground", "secret": "guess"},
        {"op": "hello", "role": "ground", "secret": SECRET + "x"},
        {"op": "hello", "role": "ground", "secret": 12345},
        {"op": "hello", "role": "train", "train": 999, "secret": SECRET},  # not a train of it
        {"op": "hello", "role": "train", "train": "101", "secret": SECRET},
        {"op": "hello", "role": "train", "train": True, "secret": SECRET},
        {"op": "hello", "role": "train", "secret": SECRET},
        {"op": "hello", "role": "dispatcher", "secret": SECRET},
    ],
)
def test_anything_else_is_refused(hello: dict[str, Any] | None) -> None:
    assert hello_name(hello, SECRET, TRAINS) is None


def test_a_stranger_on_the_run_s_wire_is_closed_and_its_lines_never_read() -> None:
    """The live run's own accept (cosim/live.py): a connection with the wrong secret is
    closed after its hello, whatever it sends next; a train of the run is heard."""
    path = Path(__file__).parents[2] / "examples" / "line_live_short.toml"
    run = _LiveRun(load_line_scenario(path), str(path), LiveOptions(), "unused.db")
    train = next(iter(run.services))

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        run.hello = {"ground": loop.create_future()}
        run.hello |= {i: loop.create_future() for i in run.services}
        run.reported = {i: loop.create_future() for i in run.services}
        server = await asyncio.start_server(run._accept, "127.0.0.1", 0, limit=MAX_LINE)
        port = int(server.sockets[0].getsockname()[1])
        async with server, asyncio.timeout(10.0):
            for hello in (
                {"op": "hello", "role": "ground", "secret": "guess"},
                {"op": "hello", "role": "train", "train": train},
            ):
                reader, writer = await connect(port)
                await send(writer, hello)
                await send(writer, {"op": "seen", "t_s": 1.0, "finished": False})
                assert await reader.read() == b""  # the run closed it
                writer.close()
            garbage_reader, garbage = await connect(port)
            garbage.write(b"\xff not json\n")
            assert await garbage_reader.read() == b""
            garbage.close()
            assert not any(f.done() for f in run.hello.values())
            _, ours = await connect(port)
            hello = {"op": "hello", "role": "train", "train": train, "secret": run.secret}
            await send(ours, hello)
            await send(ours, {"op": "seen", "t_s": 2.0, "finished": False})
            # its report at the end: the run sets `reported` when it reads it, after the
            # lines before it
            await send(ours, {"op": "result", "train": train})
            await run.hello[train]
            await run.reported[train]
            ours.close()

    asyncio.run(scenario())
    assert run.seen == {train: {"op": "seen", "t_s": 2.0, "finished": False}}
    assert not run.hello["ground"].done()
