"""Fixtures of the dashboard tests: a made-up ground, the app over it, and Debian's chromium.

The browser tests use Playwright for Python with the system's chromium (Debian package
``chromium``, installed by .ci/run): no browser is downloaded. pytest-playwright's
``browser_type_launch_args`` is overridden to point at it.
"""

from __future__ import annotations

import contextlib
import copy
import copyreg
import threading
import types
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from railpilot.cosim.demo_ground import MIN_WARMUP_S, DemoGround
from railpilot.web.app import ThreadedServer, create_app, server_config
from railpilot.web.browser import CHROMIUM, CHROMIUM_FLAGS

#: The dispatcher token of every test.
TOKEN = "test-dispatcher-token-0123456789"
#: A valid TSR form, as a dispatcher fills it in (text fields, as the page sends them).
TSR_FORM = {
    "start_km": "300",
    "end_km": "330",
    "limit_kmh": "40",
    "valid_from_min": "0",
    "valid_until_min": "90",
    "reason": "sun kink check",
}
#: A valid dispatch command form (text fields, as the page sends them).
DISPATCH_FORM = {"trains": "1001, 1002", "text": "Hold at the next station for 10 min"}
#: Longest wait for the server to start [s] (a deadline, not a sleep).
START_DEADLINE_S = 20.0
#: The browser tests' skip where Debian's chromium is missing.
needs_chromium = pytest.mark.skipif(
    not CHROMIUM.exists(),
    reason=f"Debian's chromium is not installed at {CHROMIUM} (apt-get install chromium; "
    ".ci/run does it): the browser tests need it",
)


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args: dict[str, Any]) -> dict[str, Any]:
    """pytest-playwright's launch arguments, with Debian's chromium and its flags."""
    return {
        **browser_type_launch_args,
        "executable_path": str(CHROMIUM),
        "args": list(CHROMIUM_FLAGS),
    }


@pytest.fixture(scope="session")
def browser_context_args(browser_context_args: dict[str, Any]) -> dict[str, Any]:
    """A dispatcher's wide screen."""
    return {**browser_context_args, "viewport": {"width": 1600, "height": 1000}}


# copy.deepcopy of a ground copies the read-only views of its line and link tables too
copyreg.pickle(types.MappingProxyType, lambda view: (types.MappingProxyType, (dict(view),)))


@pytest.fixture(scope="session")
def _warmed_up_ground() -> DemoGround:
    return DemoGround(24, seed=0, warmup_s=MIN_WARMUP_S)


@pytest.fixture
def ground(_warmed_up_ground: DemoGround) -> DemoGround:
    """The heavy-haul line with 24 trains, at the demo ground's start (after the shortest
    warm-up: every scripted incident has happened): a copy of one built once, each test its
    own (tests/web/test_demo.py checks a copy runs as a ground built afresh)."""
    return copy.deepcopy(_warmed_up_ground)


@dataclass
class Served:
    url: str
    ground: DemoGround


@pytest.fixture
def served(ground: DemoGround) -> Iterator[Served]:
    """The dashboard over ``ground`` on 127.0.0.1, an ephemeral port, in a thread."""
    with serve(ground) as url:
        yield Served(url, ground)


@contextlib.contextmanager
def serve(source: Any) -> Iterator[str]:
    """The dashboard over ``source`` on 127.0.0.1, an ephemeral port, in a thread: its URL."""
    server = ThreadedServer(server_config(create_app(source, token=TOKEN), port=0))
    thread = threading.Thread(target=server.run_in_thread, name="dashboard", daemon=True)
    thread.start()
    assert server.ready.wait(START_DEADLINE_S), "the dashboard did not start in time"
    assert server.started, "the dashboard failed to start (see the log above)"
    host, port = server.servers[0].sockets[0].getsockname()[:2]
    assert host == "127.0.0.1"
    try:
        yield f"http://127.0.0.1:{port}/"
    finally:
        server.should_exit = True
        thread.join(START_DEADLINE_S)
        assert not thread.is_alive(), "the dashboard did not stop"


#: What the live ground's dashboard says until it has restored (web.ground_source).
STARTING = "ground starting: restoring from the store"


class StartingGround:
    """The demo ground behind a source that cannot be shown until ``ready`` is set, as the
    live ground's until it has restored from its store (``ServerSource.starting``)."""

    def __init__(self, ground: DemoGround) -> None:
        self.ground = ground
        self.ready = False

    def starting(self) -> str | None:
        return None if self.ready else STARTING

    def __getattr__(self, name: str) -> Any:
        return getattr(self.ground, name)


@pytest.fixture(scope="session")
def base_url() -> None:
    """No base URL: each test opens the URL it served. (This also stands in for
    pytest-playwright's own fallback fixture, which pytest 9 warns is deprecated.)"""
    return None
