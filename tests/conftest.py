"""Session-wide test ordering.

Playwright's sync API (tests/web/, the dashboard in Debian's chromium) leaves an event loop
marked as running in the main thread for the rest of the session, after which
``asyncio.run`` fails in every later test. The browser tests therefore run last, whatever
order the test paths are given in (``pytest tests/web tests/net`` would otherwise break
tests/net). Under pytest-xdist (``make test``: ``-n auto``) each worker is handed the
items in this order, so on each worker too the browser tests come after the rest.
"""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    def uses_a_browser(item: pytest.Item) -> bool:
        fixtures = getattr(item, "fixturenames", ())
        return "page" in fixtures or item.get_closest_marker("browser") is not None

    items.sort(key=uses_a_browser)  # stable: the order within each group is kept
