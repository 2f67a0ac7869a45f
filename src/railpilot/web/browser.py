"""Debian's chromium for Playwright: where it is and how it is started (no browser download).

One place for the tests (tests/web/conftest.py) and the report's screenshot
(reproduce/dashboard.py).
"""

from __future__ import annotations

from pathlib import Path

#: Debian's chromium (``apt-get install chromium``; .ci/run installs it).
CHROMIUM = Path("/usr/bin/chromium")
#: Headless, no sandbox (containers), nothing fetched from the network.
CHROMIUM_FLAGS: tuple[str, ...] = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)
