"""A live line run (``railpilot line run``) given a port that another program holds: one
line naming the option and the port, exit 2, nothing written, no traceback (cosim/live.py;
docs/line-run.md, "Live")."""

from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from railpilot.cli import main
from railpilot.cosim.live import LiveOptions, _LiveRun
from railpilot.cosim.live_wire import (
    MAX_LINE,
    PortUnavailable,
    connect,
    failure,
    report_failure,
    run_process,
    send,
)
from railpilot.cosim.scenario import load_line_scenario

SCENARIO = Path(__file__).parents[2] / "examples" / "line_short_day.toml"

#: a deadline for a run that hangs (the command answers long before it), not a timing
DEADLINE_S = 600.0


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A loopback port another program listens on for the test's length."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as holder:
        holder.bind(("127.0.0.1", 0))
        holder.listen(1)
        yield int(holder.getsockname()[1])


@pytest.mark.parametrize("option", ["--http-port", "--link-port", "--admin-port", "--control-port"])
def test_a_busy_port_is_one_line_naming_the_option_and_nothing_is_written(
    tmp_path: Path, busy_port: int, option: str
) -> None:
    # a process of its own: the run's ground and trains are processes, and what they
    # print reaches the same terminal
    out = tmp_path / "out"
    command = [sys.executable, "-m", "railpilot.cli", "line", "run", str(SCENARIO)]
    command += [option, str(busy_port), "--out", str(out)]
    done = subprocess.run(command, capture_output=True, text=True, timeout=DEADLINE_S)
    lines = done.stderr.splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("railpilot: error: ")
    assert option in lines[0] and str(busy_port) in lines[0]
    assert "in use" in lines[0]
    assert "Traceback" not in done.stderr and done.stdout == ""
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    ("first", "second"),
    [("--http-port", "--link-port"), ("--admin-port", "--control-port")],
)
def test_one_port_for_two_options_is_refused_before_anything_starts(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    first: str,
    second: str,
) -> None:
    import railpilot.cosim.live as live

    def refuse(*args: object, **kwargs: object) -> None:
        raise AssertionError("the live run started although its ports collide")

    monkeypatch.setattr(live, "run_live", refuse)
    argv = ["line", "run", str(SCENARIO), first, "47001", second, "47001"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and second in err and first in err and "47001" in err


def test_a_process_that_fails_tells_the_run_in_one_line_and_prints_nothing(
    capfd: pytest.CaptureFixture[str],
) -> None:
    """A ground or train process's error (cosim/live_wire.py): one line on the wire, exit
    1, no traceback on the terminal (the run prints the line)."""
    with socket.create_server(("127.0.0.1", 0)) as run:
        port = int(run.getsockname()[1])

        async def process() -> None:
            _, writer = await connect(port)
            try:
                raise RuntimeError("the store\nis not there")
            except Exception as exc:
                raise await report_failure(writer, exc) from None

        with pytest.raises(SystemExit) as ended:
            run_process("ground", process())
        connection, _ = run.accept()
        with connection, connection.makefile(encoding="utf-8") as wire:
            line = wire.readline()
    assert ended.value.code == 1
    assert json.loads(line) == {"op": "failed", "error": "RuntimeError: the store is not there"}
    assert capfd.readouterr().err == ""


def test_a_process_that_fails_before_its_wire_is_open_prints_one_line(
    capfd: pytest.CaptureFixture[str],
) -> None:
    async def process() -> None:
        raise ValueError("no\nscenario")

    with pytest.raises(SystemExit) as ended:
        run_process("train 101", process())
    assert ended.value.code == 1
    err = capfd.readouterr().err
    assert err == "railpilot: error: the train 101 process failed: ValueError: no scenario\n"


@pytest.mark.parametrize(
    ("message", "expected"),
    [
        (failure(RuntimeError("boom")), "the ground process failed: RuntimeError: boom"),
        (
            failure(PortUnavailable.bind_failed("http_port", 8080, OSError(98, "in use"))),
            "http_port = 8080 is not allowed: expected a port in [0, 65535] free on 127.0.0.1",
        ),
    ],
)
def test_the_run_stops_at_a_process_s_failure(message: dict[str, object], expected: str) -> None:
    """The run's side of the wire (cosim/live.py ``_accept``): a process's ``failed`` line
    becomes the run's failure at once, a port's naming its field and port."""
    run = _LiveRun(load_line_scenario(SCENARIO), str(SCENARIO), LiveOptions(), "unused.db")

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        run.hello = {"ground": loop.create_future()}
        run.hello |= {i: loop.create_future() for i in run.services}
        server = await asyncio.start_server(run._accept, "127.0.0.1", 0, limit=MAX_LINE)
        port = int(server.sockets[0].getsockname()[1])
        async with server, asyncio.timeout(10.0):
            _, writer = await connect(port)
            await send(writer, {"op": "hello", "role": "ground", "secret": run.secret})
            await send(writer, message)
            await run.failed.wait()
            writer.close()

    asyncio.run(scenario())
    assert run.failure is not None and str(run.failure).startswith(expected)
