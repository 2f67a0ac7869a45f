"""The dashboard over the live ground server, with real trains, in headless chromium.

One asyncio loop in a background thread runs everything that owns state: the ground server
(loopback TCP, short timers), the dashboard (uvicorn in the same loop, over a
:class:`ServerSource`) and three onboard clients that register and report over real TCP.
The test thread only drives the browser (HTTP and WebSocket), so no server state is
touched from two threads. Waits are an event with a deadline (start-up) and Playwright's
polling ``expect``: no sleeps, no timed assertions.
"""

from __future__ import annotations

import asyncio
import struct
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from net.helpers import FAST, GROUND_ID, onboard_config
from railpilot.line.loader import load_line
from railpilot.link import GroundConfig, KeyStore, TravelDirection
from railpilot.net import GroundServer, OnboardClient, Trajectory
from railpilot.net.dispatch_host import DispatchHost
from railpilot.web.ground_source import ServerSource, serve_dashboard

from .conftest import START_DEADLINE_S, TOKEN, TSR_FORM, needs_chromium

pytestmark = [needs_chromium, pytest.mark.slow]

#: Longest wait for the page to show what the ground holds [ms] (acknowledgements travel
#: over TCP and are resent every 0.2 s: this is a deadline, not an expected time).
SHOWN_MS = 15_000
#: (train id, start km, direction, speed [m/s]). A TSR on km 300-330 concerns the first two
#: (one each way, both before it); the third is past it going UP, so it is spared.
TRAINS = (
    (2001, 290.0, TravelDirection.UP, 20.0),
    (2002, 345.0, TravelDirection.DOWN, 20.0),
    (2003, 400.0, TravelDirection.UP, 20.0),
)
CONCERNED = (2001, 2002)
LENGTH_M = 1500.0


@dataclass
class Live:
    """The running ground (in its thread) as the test sees it: a URL, and a way to stop."""

    url: str = ""
    ready: threading.Event = field(default_factory=threading.Event)
    error: BaseException | None = None
    loop: asyncio.AbstractEventLoop | None = None
    stop: asyncio.Event | None = None


async def _ground(live: Live) -> None:
    """Ground server + dashboard + three trains, until ``live.stop`` is set."""
    live.loop = asyncio.get_running_loop()
    live.stop = asyncio.Event()
    keys = KeyStore()
    for i, (train_id, *_) in enumerate(TRAINS):
        keys.add_key(train_id, 1, bytes((b + i) % 256 for b in range(32)))
    server = GroundServer(GroundConfig(ground_id=GROUND_ID, timers=FAST), keys)
    host = DispatchHost(server, load_line("heavy-haul"))
    source = ServerSource(host)
    _, port = await server.start()
    host.start()
    trains: list[asyncio.Task[None]] = []
    dashboard = serving = None
    try:
        dashboard, serving = await serve_dashboard(source, token=TOKEN, port=0)
        for train_id, km, travel, speed in TRAINS:
            config = onboard_config(train_id, length_m=LENGTH_M, loco_number="HXD1-01", driver_id=7)
            client = OnboardClient(
                config,
                keys,
                "127.0.0.1",
                port,
                trajectory=Trajectory(start_m=km * 1000.0, speed_mps=speed, direction=travel),
                seed=train_id,
            )
            trains.append(asyncio.create_task(client.run(live.stop)))
        live.url = f"http://127.0.0.1:{dashboard.port}/"
        live.ready.set()
        await live.stop.wait()
    finally:
        live.stop.set()
        async with asyncio.timeout(10.0):
            await asyncio.gather(*trains, return_exceptions=True)
            if dashboard is not None and serving is not None:
                dashboard.should_exit = True
                await serving
            await server.stop(timeout_s=2.0)


@pytest.fixture
def live() -> Iterator[Live]:
    """The live ground with its dashboard, in a thread of its own."""
    live = Live()

    def run() -> None:
        try:
            asyncio.run(_ground(live))
        except BaseException as exc:  # shown by the test, not lost in the thread
            live.error = exc
        finally:
            live.ready.set()

    thread = threading.Thread(target=run, name="ground", daemon=True)
    thread.start()
    assert live.ready.wait(START_DEADLINE_S), "the ground did not start in time"
    assert live.error is None and live.url, f"the ground failed to start: {live.error!r}"
    try:
        yield live
    finally:
        if live.loop is not None and live.stop is not None:
            live.loop.call_soon_threadsafe(live.stop.set)
        thread.join(START_DEADLINE_S)
        assert not thread.is_alive(), "the ground did not stop"
        assert live.error is None, f"the ground failed: {live.error!r}"


def _png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", header[16:24])
    return width, height


def test_dispatcher_sets_a_tsr_and_real_trains_acknowledge_it(
    live: Live, page: Page, tmp_path: Path
) -> None:
    page.goto(live.url)
    expect(page.locator("#status")).to_have_text("live", timeout=SHOWN_MS)
    rows = page.locator("#trains tbody tr[data-train]")
    expect(rows).to_have_count(len(TRAINS), timeout=SHOWN_MS)
    # every train registered and reporting: no link alarm (a train without a valid
    # running info has one), and each drawn on the line
    expect(page.locator("#alarms li[data-alarm]")).to_have_count(0, timeout=SHOWN_MS)
    expect(page.locator("#line .train text")).to_have_count(len(TRAINS), timeout=SHOWN_MS)

    page.fill("#token", TOKEN)
    page.click("#token-save")
    expect(page.locator("#token-state")).to_contain_text("token in use")
    for name, value in TSR_FORM.items():
        page.fill(f"#f-{name}", value)
    page.click("#tsr-submit")
    expect(page.locator("#tsr-result")).to_contain_text("TSR 1 set", timeout=SHOWN_MS)

    chips = page.locator('#tsrs [data-session="1"][data-train]')
    expect(chips).to_have_count(len(CONCERNED), timeout=SHOWN_MS)  # not the train past it
    for train in CONCERNED:
        chip = page.locator(f'#tsrs [data-session="1"][data-train="{train}"] .state')
        expect(chip).to_have_text("ACTIVE", timeout=SHOWN_MS)
    expect(page.locator("#line .tsr text", has_text="TSR 1 · 40")).not_to_have_count(0)

    path = tmp_path / "live.png"
    page.screenshot(path=path, full_page=True)
    width, _ = _png_size(path)
    assert width >= 1600
