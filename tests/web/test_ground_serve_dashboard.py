"""``railpilot ground serve --http-port``: the dashboard over the live ground, from the CLI.

Bad dashboard options exit 2 naming the option before anything starts; a served ground
prints the dashboard's address and token once, answers the API with that token, and stops
on SIGTERM.
"""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import pytest

from railpilot.cli import main

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
