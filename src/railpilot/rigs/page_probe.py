"""The dispatcher page in headless chromium, in a process of its own, counting its renders.

Used by ``railpilot link loadtest --dashboard``: the ground server and its dashboard run in
the load test's process; this child (``spawn``) drives Debian's chromium through Playwright
for Python, so neither the browser nor its Python driver shares the server's event loop.

The page counts what it draws itself (``window.railpilot``, web/static/dashboard.js): one
render per snapshot applied, with its wall-clock time and how long it took. The child opens
the page, waits for its first render, says ``ready``, waits for ``stop``, then sends back
the page's counters, the page's errors and (if asked) a screenshot's path.

Protocol over the pipe (parent -> child / child -> parent)::

    child:  {"ready": True} | {"error": "..."}
    parent: "stop"
    child:  {"renders": ..., "render_at_ms": [...], "render_ms": [...], "paint_ms": [...],
             "versions": [...], "trains_shown": ..., "errors": [...], "screenshot": ...}
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

#: Longest wait for the page's first render [ms] (a deadline, not an expected time).
FIRST_RENDER_MS = 60_000
#: How much lower the browser's priority is than the server's (``nice``).
PROBE_NICENESS = 10
#: A dispatcher's wide screen.
VIEWPORT = {"width": 1600, "height": 1000}
#: What the page exposes (web/static/dashboard.js, ``window.railpilot``).
READ_PROBE = """() => {
  const p = window.railpilot;
  return {
    renders: p.renders,
    render_at_ms: p.at.slice(),
    render_ms: p.renderMs.slice(),
    paint_ms: p.paintMs.slice(),
    versions: p.versions.slice(),
    trains_shown: document.querySelectorAll("#line .train").length,
    rows: document.querySelectorAll("#trains tbody tr[data-train]").length,
  };
}"""


@dataclass(frozen=True, slots=True)
class ProbeOptions:
    url: str
    #: The browser (Debian's chromium; nothing is downloaded) and its flags.
    executable: str
    flags: tuple[str, ...]
    #: Write a screenshot of the viewport here at the end (PNG), if given.
    screenshot: str | None = None


def probe_main(options: ProbeOptions, conn: Connection) -> None:
    """Entry point of the probe process (see the module docstring)."""
    errors: list[str] = []
    # A dispatcher's browser runs on the dispatcher's desk, not on the ground server. Here
    # it shares the server's cores, so it runs at a lower priority (chromium inherits
    # it): the page still has to keep up (updates_per_s), but it does not take the
    # server's turn. docs/scaling.md.
    os.nice(PROBE_NICENESS)
    try:
        from playwright.sync_api import sync_playwright

        with sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path=options.executable, args=list(options.flags)
            )
            try:
                page = browser.new_page(viewport=VIEWPORT)  # type: ignore[arg-type]
                page.on("pageerror", lambda exc: errors.append(f"page error: {exc}"))
                page.on(
                    "console",
                    lambda msg: (
                        errors.append(f"console: {msg.text}") if msg.type == "error" else None
                    ),
                )
                page.goto(options.url)
                page.wait_for_function(
                    "() => window.railpilot && window.railpilot.renders > 0",
                    timeout=FIRST_RENDER_MS,
                )
                conn.send({"ready": True})
                conn.recv()  # "stop"; chromium keeps drawing meanwhile
                result: dict[str, Any] = page.evaluate(READ_PROBE)
                result["status"] = page.locator("#status").text_content()
                if options.screenshot:
                    page.screenshot(path=options.screenshot)
                result["screenshot"] = options.screenshot
            finally:
                browser.close()
        result["errors"] = errors
        conn.send(result)
    except Exception as exc:  # reported by the load test, not lost in the child
        conn.send({"error": f"{type(exc).__name__}: {exc}", "errors": errors})
    finally:
        conn.close()
