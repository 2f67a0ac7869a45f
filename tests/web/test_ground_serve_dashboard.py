"""``railpilot ground serve --http-port``: the dashboard over the live ground, from the CLI.

Bad dashboard options exit 2 naming the option before anything starts; a served ground
prints the dashboard's address and token once, answers the API with that token, and stops
on SIGTERM.
"""

from __future__ import annotations

import asyncio
import json
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from railpilot.cli import main
from railpilot.ground.store import open_store
from railpilot.link import TsrSet

BASE = ["ground", "serve", "--no-auth", "--port", "0", "--admin-port", "-1", "--db", ":memory:"]


@pytest.mark.parametrize(
    ("extra", "option", "allowed"),
    [
        (["--http-port", "70000"], "--http-port", "0..65535"),
        (["--http-port", "-1"], "--http-port", "0..65535"),
        (["--http-port", "0", "--http-host", "0.0.0.0"], "--http-host", "a loopback host"),
        (["--http-port", "0", "--dispatcher-token", "short"], "--dispatcher-token", "16"),
        (["--http-port", "0", "--dispatcher-token", "has a space in it"], "--dispatcher-token", ""),
        (["--dispatcher-token", "x" * 20], "--dispatcher-token", "with --http-port"),
        (["--http-host", "localhost"], "--http-host", "with --http-port"),
        (["--http-port", "0", "--line", "no-such-line"], "--line", "a shipped line"),
    ],
)
def test_a_bad_dashboard_option_exits_2_naming_it(
    extra: list[str], option: str, allowed: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*BASE, *extra]) == 2
    out, err = capsys.readouterr()
    assert f"{option} = " in err and allowed in err
    assert "dashboard:" not in out + err  # nothing started
    assert "x" * 20 not in err and "has a space" not in err  # a token is never shown


def test_a_busy_http_port_exits_2_naming_it(capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        argv = [*BASE, "--http-port", str(port), "--seconds", "5"]
        # in a thread: after a browser test, Playwright's sync API leaves an event loop
        # marked running in the main thread, and the command runs asyncio.run
        with ThreadPoolExecutor(1) as pool:
            assert pool.submit(main, argv).result(timeout=30.0) == 2
    err = capsys.readouterr().err
    assert f"--http-port = {port} is not allowed: expected a port free on 127.0.0.1" in err


def _request(url: str, body: dict[str, Any] | None = None, token: str = "") -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    request = urllib.request.Request(url, data=data, method="GET" if data is None else "POST")
    request.add_header("Content-Type", "application/json")
    if token:
        request.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(request, timeout=10.0) as answer:
            return answer.status, json.loads(answer.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


@pytest.mark.slow
def test_serve_prints_the_dashboard_and_its_token_once_and_stops_on_sigterm() -> None:
    cmd = [sys.executable, "-m", "railpilot.cli", *BASE, "--http-port", "0", "--seconds", "60"]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    try:
        assert proc.stderr is not None
        found = None
        deadline = time.monotonic() + 20.0
        while found is None and time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            lines.append(line)
            found = re.fullmatch(r"dashboard: (http://127\.0\.0\.1:\d+/)  token: (\S+)\n", line)
        assert found is not None, "".join(lines)
        url, token = found.groups()
        assert len(token) >= 16

        status, snapshot = _request(url + "api/snapshot")
        assert status == 200 and snapshot["line"]["name"] == "heavy-haul"
        assert snapshot["trains"] == [] and snapshot["tsrs"] == []
        form = {
            "start_km": "300",
            "end_km": "330",
            "limit_kmh": "40",
            "valid_until_min": "60",
            "reason": "check",
        }
        assert _request(url + "api/tsr", form)[0] == 401
        status, answer = _request(url + "api/tsr", form, token)
        assert status == 200, answer
        assert answer["ok"]["session"] == 1 and answer["ok"]["deliveries"] == []  # no trains
        status, answer = _request(url + "api/tsr", {**form, "limit_kmh": "400"}, token)
        assert status == 422 and "limit_kmh" in answer["errors"]

        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15.0) == 0
        rest = proc.stderr.read()
        assert token not in rest and sum(token in line for line in lines) == 1
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=5.0)


#: Longest wait for the ground in a thread to get somewhere [s] (a deadline, not a sleep).
DEADLINE_S = 30.0
STARTING = "ground starting: restoring from the store"


def test_the_dashboard_shows_nothing_before_the_ground_has_restored_its_store(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A dashboard asked while the ground restores answers 503 "ground starting", not an
    empty line (no trains, no TSRs) that looks like the truth; once restored, it shows the
    store's TSR. The restore is held until the test has asked (events, no sleeps)."""
    import railpilot.commands.link as link_commands
    import railpilot.web.ground_source as ground_source
    from railpilot.net.dispatch_host import DispatchHost
    from railpilot.net.server import GroundServer

    db = tmp_path / "ground.db"
    store = open_store(str(db))
    now = time.time()
    kept = TsrSet(7, 300_000.0, 330_000.0, 40 / 3.6, now, now + 3600.0)
    store.record_tsr(kept, actor="dispatcher", reason="kept across restarts", at_s=now)
    store.close()

    holding, release, restored = threading.Event(), threading.Event(), threading.Event()
    server_start, host_start = GroundServer.start, DispatchHost.start

    async def held(self: GroundServer) -> Any:  # every port is bound; nothing restored yet
        holding.set()
        await asyncio.to_thread(release.wait, DEADLINE_S)  # the loop runs on meanwhile
        return await server_start(self)

    def noted(self: DispatchHost) -> None:
        host_start(self)
        restored.set()

    ports: list[int] = []
    serve = ground_source.serve_dashboard

    async def serve_noting_the_port(*args: Any, **kwargs: Any) -> Any:
        http, task = await serve(*args, **kwargs)
        ports.append(http.port)
        return http, task

    stop: dict[str, Any] = {}

    async def stop_event() -> asyncio.Event:  # the thread's ground stops when told
        stop["loop"], stop["event"] = asyncio.get_running_loop(), asyncio.Event()
        return stop["event"]

    monkeypatch.setattr(GroundServer, "start", held)
    monkeypatch.setattr(DispatchHost, "start", noted)
    monkeypatch.setattr(ground_source, "serve_dashboard", serve_noting_the_port)
    monkeypatch.setattr(link_commands, "_stop_on_signals", stop_event)
    token = "test-dispatcher-token-0123456789"
    argv = [
        *BASE[:-1],  # the store is the file
        str(db),
        "--http-port",
        "0",
        "--dispatcher-token",
        token,
    ]
    # in a thread, as above (Playwright may leave the main thread's loop marked running)
    with ThreadPoolExecutor(1) as pool:
        served = pool.submit(main, argv)
        try:
            assert holding.wait(DEADLINE_S), "the ground did not get to its restore"
            url = f"http://127.0.0.1:{ports[0]}/"
            starting = (503, {"errors": {"ground": STARTING}})
            assert _request(url + "api/snapshot") == starting
            form = {"start_km": "10", "end_km": "12", "limit_kmh": "40", "valid_until_min": "60"}
            assert _request(url + "api/tsr", {**form, "reason": "x"}, token) == starting
            assert "dashboard:" not in capsys.readouterr().err  # not announced yet

            release.set()
            assert restored.wait(DEADLINE_S), "the ground did not restore"
            status, snapshot = _request(url + "api/snapshot")
            assert status == 200
            assert [t["session"] for t in snapshot["tsrs"]] == [7]
            assert f"dashboard: {url}" in capsys.readouterr().err
        finally:
            release.set()
            if "event" in stop:
                stop["loop"].call_soon_threadsafe(stop["event"].set)
            assert served.result(timeout=DEADLINE_S) == 0
