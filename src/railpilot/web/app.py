"""The dispatcher dashboard: a Starlette app over a :class:`DashboardSource` (docs/dashboard.md).

A thin adapter (DESIGN habit 2): it serves the page, asks the source for snapshots, hands
the dispatcher's forms to it and pushes snapshots over a WebSocket. It decides
nothing about trains or TSRs; the only clock it reads is the event loop's, to pace the
pushes.

Routes
------
- ``GET /``: the page (static/index.html; its script and style under ``/static``);
- ``GET /api/snapshot``: the current snapshot (JSON; the shared one the pushes send, below);
- ``POST /api/tsr``: set a TSR from the form's fields (JSON object); one over trains
  already above its limit answers 422 with the ``warning`` and is sent only with
  ``confirm: true``;
- ``POST /api/tsr/{session}/cancel``: cancel a TSR;
- ``POST /api/dispatch``: send a dispatch command from the form's fields (JSON object);
- ``POST /api/restriction``: declare a restriction (a section fault, a lost switch
  indication) from the form's fields; ``POST /api/restriction/{id}/clear``: clear it;
- ``WS /ws``: a snapshot when the source's version changes, and at least every second.

What the pushes cost the ground: the app runs in the ground server's event loop
(web/ground_source.py), where every millisecond spent on a snapshot is a millisecond every
train's frames wait (docs/scaling.md). So:

- one snapshot serves every open page: it is built (and encoded) once per change, and a
  page that asks within :data:`POLL_INTERVAL_S` of it gets the same text, its first
  ``GET /api/snapshot`` included;
- a changed snapshot waits after the previous one for what that cost to build and encode
  divided by :data:`LOOP_SHARE` (at least :data:`POLL_INTERVAL_S`, at most
  :data:`MAX_GAP_SHARE` of ``push_interval_s``): the pushes take about ``LOOP_SHARE`` of
  the loop, however large the fleet, and a changing ground still reaches the page more
  than once per ``push_interval_s``;
- the JSON text is encoded a slice at a time (:data:`ENCODE_SLICE` list items), letting
  the loop run between slices and between building and encoding, so the trains' frames
  wait for one slice, not for the whole snapshot.

Each push is recorded in ``app.state.pushes`` (the last :data:`PUSH_RECORDS`, as
:class:`Push`: when, how long the snapshot took to build and to encode, its size), so a
tool can see what the page costs the ground's event loop (``railpilot link loadtest
--dashboard``).

A source may not be ready to be shown yet: the live ground's, until it has restored from
its store (web/ground_source.py). While its optional ``starting()`` gives a reason, the
snapshot and the ``POST`` routes answer 503 with ``{"errors": {"ground": reason}}`` and
``Retry-After``, and the WebSocket closes with code 1013 (try again later) and the reason,
which the page shows while it retries; the page and its files are served all along.

The ``POST`` routes need ``Authorization: Bearer <token>`` (else 401); a rejected form
is 422 with ``{"errors": {field: message}}``. Reading needs no token: the page binds to
127.0.0.1 by default (:data:`DEFAULT_HOST`), answers only to the host names in
``allowed_hosts`` (against DNS rebinding) and refuses a WebSocket opened by another
origin (a page of another site cannot read the line through the user's browser).
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import uvicorn
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from railpilot.errors import ConfigError
from railpilot.gc_tuning import collection_paused
from railpilot.web.token import MIN_TOKEN_CHARS

from .source import DashboardSource

#: Where the dashboard listens unless told otherwise: this host only.
DEFAULT_HOST = "127.0.0.1"
#: The host names the app answers to by default (those of DEFAULT_HOST).
LOCAL_HOSTS = ("127.0.0.1", "localhost")
#: A snapshot goes out at least this often [s], and the source's version is looked at
#: this often [s].
PUSH_INTERVAL_S = 1.0
POLL_INTERVAL_S = 0.1
#: The share of the event loop the pushes may take (module docstring): a changed snapshot
#: waits at least ``cost / LOOP_SHARE`` after the previous one.
LOOP_SHARE = 0.1
#: ... but a changed snapshot never waits longer than this share of the push interval.
MAX_GAP_SHARE = 0.8
#: Lists longer than this are encoded this many items at a time, the loop running between.
ENCODE_SLICE = 100
#: Largest request body [bytes] (the form is a few hundred).
MAX_BODY_BYTES = 16 * 1024
#: How many pushes ``app.state.pushes`` keeps.
PUSH_RECORDS = 10_000


@dataclass(frozen=True, slots=True)
class Push:
    """One WebSocket push: when (the event loop's clock [s]), the snapshot's build and JSON
    encoding times [s] and its size [bytes]."""

    at_s: float
    build_s: float
    encode_s: float
    size_bytes: int


STATIC = Path(str(resources.files("railpilot.web") / "static"))


def _dumps(obj: Any) -> str:
    """JSON as the page reads it (no NaN or infinity: a source bug shows here)."""
    return json.dumps(obj, allow_nan=False, separators=(",", ":"))


async def dumps_sliced(obj: Any, slice_items: int = ENCODE_SLICE) -> tuple[str, float]:
    """``_dumps(obj)``, the same text, encoded a slice at a time: dicts with string keys
    key by key and lists ``slice_items`` items at a time, yielding to the event loop after
    each slice. Returns the text and the time spent encoding [s] (the loop's clock; the
    time others ran in between is not counted)."""
    loop = asyncio.get_running_loop()
    spent = 0.0

    async def encode(value: Any) -> str:
        nonlocal spent
        if isinstance(value, dict) and value and all(type(k) is str for k in value):
            items = [f"{_dumps(k)}:{await encode(v)}" for k, v in value.items()]
            return "{" + ",".join(items) + "}"
        if isinstance(value, list) and len(value) > slice_items:
            pieces = []
            for i in range(0, len(value), slice_items):
                t0 = loop.time()
                pieces.append(_dumps(value[i : i + slice_items])[1:-1])
                spent += loop.time() - t0
                await asyncio.sleep(0)
            return "[" + ",".join(pieces) + "]"
        t0 = loop.time()
        text = _dumps(value)
        spent += loop.time() - t0
        return text

    text = await encode(obj)
    return text, spent


def _json(obj: Any, status_code: int = 200, headers: dict[str, str] | None = None) -> Response:
    return Response(_dumps(obj), status_code, headers, media_type="application/json")


def create_app(
    source: DashboardSource,
    *,
    token: str,
    actor: str = "dispatcher",
    allowed_hosts: Sequence[str] | None = LOCAL_HOSTS,
    push_interval_s: float = PUSH_INTERVAL_S,
) -> Starlette:
    """The dashboard over ``source``.

    Parameters
    ----------
    source
        The ground (:class:`~railpilot.web.source.DashboardSource`).
    token
        The dispatcher token the write routes require (at least
        :data:`MIN_TOKEN_CHARS` characters, no spaces).
    actor
        Who the token stands for in the audit log (``set_by`` of a TSR).
    allowed_hosts
        Host names the app answers to (default: 127.0.0.1 and localhost); ``None``: any
        (only when binding to another interface on purpose).
    push_interval_s
        Longest time between two WebSocket pushes [s].
    """
    if not isinstance(token, str) or len(token) < MIN_TOKEN_CHARS or token != token.strip():
        raise ConfigError(
            "token",
            "<hidden>",
            f"a string of at least {MIN_TOKEN_CHARS} characters without surrounding spaces "
            "(e.g. secrets.token_urlsafe(16))",
        )
    if " " in token:
        raise ConfigError("token", "<hidden>", "a token without spaces")
    if not isinstance(actor, str) or not actor.strip():
        raise ConfigError("actor", actor, "a non-empty name")
    if not (0 < push_interval_s <= 60):
        raise ConfigError("push_interval_s", push_interval_s, "a time in (0, 60] s")
    expected = f"Bearer {token}".encode()

    def authorized(request: Request) -> bool:
        given = request.headers.get("authorization", "").encode("utf-8", "replace")
        return hmac.compare_digest(given, expected)

    def unauthorized() -> Response:
        return _json(
            {"errors": {"token": "a dispatcher token is needed: the one the server printed"}},
            401,
            {"WWW-Authenticate": "Bearer"},
        )

    async def json_body(request: Request) -> tuple[Any, Response | None]:
        body = await request.body()
        if len(body) > MAX_BODY_BYTES:
            error = f"a request body of at most {MAX_BODY_BYTES} bytes"
            return None, _json({"errors": {"form": error}}, 413)
        try:
            return (json.loads(body) if body else {}), None
        except (UnicodeDecodeError, json.JSONDecodeError):
            return None, _json({"errors": {"form": "the request body is not JSON"}}, 400)

    source_starting = getattr(source, "starting", None)

    def not_ready() -> str | None:
        """Why the source is not ready to be shown (module docstring), or None."""
        return None if source_starting is None else source_starting()

    def unavailable() -> Response | None:
        """503 while the source is not ready to be shown, else None."""
        reason = not_ready()
        if reason is None:
            return None
        return _json({"errors": {"ground": reason}}, 503, {"Retry-After": "1"})

    def answer(result: dict[str, Any]) -> Response:
        if "errors" in result:
            # a TSR over trains already above its limit: the list, for the page to confirm
            warning = {"warning": result["warning"]} if "warning" in result else {}
            return _json({"errors": result["errors"], **warning}, 422)
        return _json(result)

    async def page(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-cache"})

    async def snapshot(request: Request) -> Response:
        if (refused := unavailable()) is not None:
            return refused
        # the shared snapshot, built and encoded a slice at a time as the pushes are: a
        # page that opens (a browser's first fetch) must not hold the trains' frames for
        # a whole snapshot either
        _, text = await shared.text(source.version())
        return Response(text, media_type="application/json")

    async def form(request: Request, handle: Callable[..., dict[str, Any]]) -> Response:
        """A form's request: the token, the source ready, a JSON object; ``handle``'s answer."""
        if not authorized(request):
            return unauthorized()
        if (refused := unavailable()) is not None:
            return refused
        fields, error = await json_body(request)
        if error is not None:
            return error
        if not isinstance(fields, dict):
            return _json({"errors": {"form": "expected a JSON object of the form's fields"}}, 422)
        return answer(handle(fields, actor, source.now_s()))

    async def set_tsr(request: Request) -> Response:
        return await form(request, source.set_tsr)

    async def send_dispatch(request: Request) -> Response:
        return await form(request, source.send_dispatch)

    async def set_restriction(request: Request) -> Response:
        return await form(request, source.set_restriction)

    async def clear_restriction(request: Request) -> Response:
        return await numbered(request, "id", "a restriction id", source.clear_restriction)

    async def numbered(
        request: Request, field: str, what: str, handle: Callable[..., dict[str, Any]]
    ) -> Response:
        """A request about one numbered thing (``field`` in the path): ``handle``'s answer."""
        if not authorized(request):
            return unauthorized()
        if (refused := unavailable()) is not None:
            return refused
        raw = request.path_params[field]
        if not raw.isdigit() or not 1 <= int(raw) <= 0xFFFF_FFFF:
            return _json({"errors": {field: f"{raw!r} is not {what}"}}, 422)
        return answer(handle(int(raw), actor, source.now_s()))

    async def cancel_tsr(request: Request) -> Response:
        return await numbered(request, "session", "a TSR session number", source.cancel_tsr)

    async def updates(websocket: WebSocket) -> None:
        origin = websocket.headers.get("origin")
        if origin is not None and urlsplit(origin).netloc != websocket.headers.get("host"):
            await websocket.close(code=1008)  # policy violation: another site's page
            return
        await websocket.accept()
        if (reason := not_ready()) is not None:  # 1013: try again later (the page does)
            await websocket.close(code=1013, reason=reason)
            return
        closed = asyncio.Event()

        async def read() -> None:
            # The page sends nothing; reading is how a close is noticed.
            try:
                while (await websocket.receive())["type"] != "websocket.disconnect":
                    pass
            finally:
                closed.set()

        reader = asyncio.create_task(read())
        loop = asyncio.get_running_loop()
        sent_version: int | None = None
        sent_at = -float("inf")  # when the last push began
        try:
            while not closed.is_set():
                version = source.version()
                since = loop.time() - sent_at
                changed = version != sent_version and since >= shared.min_gap_s
                if changed or since >= push_interval_s:
                    sent_at = loop.time()
                    sent_version, text = await shared.text(version)
                    await websocket.send_text(text)
                # wake up for the next periodic push on time, else look again soon
                due = sent_at + push_interval_s - loop.time()
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(closed.wait(), max(0.0, min(POLL_INTERVAL_S, due)))
        except (WebSocketDisconnect, RuntimeError, OSError):
            pass  # the page went away between two pushes
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await reader

    hosts = list(allowed_hosts) if allowed_hosts is not None else ["*"]
    pushes: deque[Push] = deque(maxlen=PUSH_RECORDS)
    shared = _SharedSnapshot(source, pushes, push_interval_s)
    app = Starlette(
        routes=[
            Route("/", page),
            Route("/api/snapshot", snapshot),
            Route("/api/tsr", set_tsr, methods=["POST"]),
            Route("/api/tsr/{session}/cancel", cancel_tsr, methods=["POST"]),
            Route("/api/dispatch", send_dispatch, methods=["POST"]),
            Route("/api/restriction", set_restriction, methods=["POST"]),
            Route("/api/restriction/{id}/clear", clear_restriction, methods=["POST"]),
            WebSocketRoute("/ws", updates),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ],
        middleware=[Middleware(TrustedHostMiddleware, allowed_hosts=hosts)],
    )
    app.state.pushes = pushes
    return app


class _SharedSnapshot:
    """The last snapshot as JSON text, shared by every open page (module docstring)."""

    def __init__(
        self, source: DashboardSource, pushes: deque[Push], push_interval_s: float
    ) -> None:
        self.source = source
        self.pushes = pushes
        self.push_interval_s = push_interval_s
        self.lock = asyncio.Lock()
        self.version: int | None = None
        self.built_at = -float("inf")
        self.last = ""
        #: A changed snapshot waits this long after the previous one [s].
        self.min_gap_s = POLL_INTERVAL_S

    async def text(self, version: int) -> tuple[int, str]:
        """``(version, text)`` of a snapshot at least as new as ``version``."""
        async with self.lock:  # one build at a time; the others reuse it
            loop = asyncio.get_running_loop()
            if self.version == version and loop.time() - self.built_at < POLL_INTERVAL_S:
                return version, self.last
            version = self.source.version()
            t0 = loop.time()
            # The snapshot's containers die young instead of being promoted by the
            # collections that would run between its slices (railpilot/gc_tuning.py).
            with collection_paused():
                build = getattr(self.source, "snapshot_async", None)
                if build is not None:  # a source that yields to the loop while it builds
                    snap = await build(self.source.now_s())
                else:
                    snap = self.source.snapshot(self.source.now_s())
                build_s = loop.time() - t0
                await asyncio.sleep(0)  # the trains' frames go first
                text, encode_s = await dumps_sliced(snap)
                del snap
            self.pushes.append(Push(t0, build_s, encode_s, len(text)))
            self.version, self.built_at, self.last = version, loop.time(), text
            cost = build_s + encode_s
            longest = MAX_GAP_SHARE * self.push_interval_s
            self.min_gap_s = min(longest, max(POLL_INTERVAL_S, cost / LOOP_SHARE))
            return version, text


def server_config(app: Starlette, *, host: str = DEFAULT_HOST, port: int = 8080) -> uvicorn.Config:
    """The uvicorn configuration the dashboard runs under (``port=0``: any free port).

    Serve it with ``uvicorn.Server(config).serve()`` in the ground's event loop, or in a
    thread of its own (tests/web/).
    """
    return uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level="warning",
        access_log=False,
        lifespan="off",
        timeout_graceful_shutdown=5,  # open WebSockets get this long [s] to close
        ws="websockets-sansio",
        # No permessage-deflate: compressing a 1000-train snapshot (~0.6 MB) takes tens
        # of ms in the ground's event loop, in one piece; the page is on the dispatch
        # centre's network (docs/scaling.md).
        ws_per_message_deflate=False,
    )


class ThreadedServer(uvicorn.Server):
    """uvicorn's server for a background thread: ``ready`` is set once it has started or
    given up (``started`` tells which), so a caller waits on an event, not a sleep."""

    def __init__(self, config: uvicorn.Config) -> None:
        super().__init__(config)
        self.ready = threading.Event()

    async def startup(self, sockets: Any = None) -> None:
        try:
            await super().startup(sockets)
        finally:
            self.ready.set()

    def run_in_thread(self) -> None:
        """The thread's target: serve, and never leave a waiter hanging."""
        try:
            self.run()
        finally:
            self.ready.set()
