"""Local admin API of the ground server: line-delimited JSON over TCP on loopback only.

One request per line, one response per line (UTF-8 JSON objects). The socket binds to a
loopback address and refuses anything else: it is an operator's local control port, not
part of the train-ground link (there is no authentication on it beyond "you can reach
127.0.0.1 on this host").

A request is an operation of the one schema the admin port, the dashboard's HTTP API and
the command line share (ground/operations.py, docs/link-operations.md): ``"op"`` and the
operation's fields, in the dispatcher's units (km posts in km, km/h, minutes from now),
plus who asks (``"actor"``, default ``"admin"``, kept in the store's audit log) and, for
``tsr_set`` only, ``"confirm"`` (true or false, default false)::

    {"op": "status"}
    {"op": "tsr_set", "start_km": 12.3, "end_km": 13.1, "limit_kmh": 45,
     "valid_until_min": 60, "reason": "track work"}     # session?, trains?, valid_from_min?
    {"op": "tsr_cancel", "session": 7}
    {"op": "restriction_set", "block": "U1203", "reason": "section_fault"}
    {"op": "restriction_clear", "id": 1}
    {"op": "target", "trains": [1001], "km": 15.2, "reason": "train_ahead"}
    {"op": "dispatch", "trains": "all", "text": "hold at next station"}

Responses: ``{"ok": true, "result": {...}}`` or ``{"ok": false, "error": "...", "errors":
{field: message}}`` (nothing was done). A ``tsr_set`` over trains that already run above
its limit there, or too close to it to slow down (ground/tsr_warning.py), is not sent
unless it says ``"confirm": true``: the answer is ``ok: false`` with ``errors`` naming
``confirm`` and ``"warning": {"limit_kmh": ..., "trains": [{"train", "where", "km",
"speed_kmh", "over_limit_kmh", "distance_m", "report_age_s"}, ...]}``. A result's
``deliveries`` maps each train id to ``"sending"`` (connected; resent until acknowledged),
``"queued until the train registers"`` or ``"error: ..."``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from typing import Any

from railpilot.errors import RailpilotError
from railpilot.ground.operations import OperationError
from railpilot.ground.tsr_warning import TsrWarning, confirm_flag

from .dispatch_host import DispatchHost
from .logfmt import kv

log = logging.getLogger("railpilot.net.admin")

LOOPBACK = frozenset({"127.0.0.1", "::1", "localhost"})
MAX_LINE = 64 * 1024


class AdminError(RailpilotError):
    """A bad admin request or answer (names the field, the value and what is allowed)."""


def require_loopback(field: str, host: str) -> None:
    if host not in LOOPBACK:
        raise AdminError(f"{field} = {host!r} is not allowed: expected a loopback address")


class AdminServer:
    """Serves the operations (:data:`~railpilot.ground.operations.OPS`) of one ground."""

    def __init__(self, host_app: DispatchHost, *, host: str = "127.0.0.1", port: int = 0) -> None:
        require_loopback("admin host", host)
        self.host_app = host_app
        self.host = host
        self.port = port
        self._server: asyncio.Server | None = None

    async def start(self, *, serve: bool = True) -> tuple[str, int]:
        """Listen on the admin port and answer requests; with ``serve=False`` only bind
        (a busy port fails here) and answer once :meth:`serve` is called."""
        self._server = await asyncio.start_server(
            self._serve_client, self.host, self.port, limit=MAX_LINE, start_serving=False
        )
        self.port = int(self._server.sockets[0].getsockname()[1])
        if serve:
            await self.serve()
        return self.host, self.port

    async def serve(self) -> None:
        """Start answering requests on the port :meth:`start` bound."""
        assert self._server is not None, "start() first"
        await self._server.start_serving()
        kv(log, logging.INFO, "admin_listening", host=self.host, port=self.port)

    async def stop(self) -> None:
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._server.wait_closed(), 2.0)
            self._server = None

    async def _serve_client(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        try:
            while True:
                try:
                    line = await reader.readline()
                except (ValueError, asyncio.LimitOverrunError):
                    writer.write(_line({"ok": False, "error": f"request longer than {MAX_LINE}"}))
                    break
                if not line:
                    break
                if not line.strip():
                    continue
                writer.write(_line(await self.execute_line(line)))
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            writer.close()

    async def execute_line(self, line: bytes) -> dict[str, Any]:
        try:
            request = json.loads(line)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            return {"ok": False, "error": f"request is not JSON: {exc}"}
        return await self.execute(request)

    async def execute(self, request: Any) -> dict[str, Any]:
        """Run one request; never raises for a bad request (the error goes back)."""
        try:
            if not isinstance(request, dict):
                raise OperationError({"request": "expected a JSON object"})
            fields = dict(request)
            op = fields.pop("op", None)
            actor = fields.pop("actor", "admin")
            if not isinstance(actor, str) or not actor.strip() or len(actor) > 64:
                raise OperationError(
                    {"actor": f"{actor!r} is not allowed: expected a name of 1 to 64 characters"}
                )
            confirm = confirm_flag(fields, op)
            fields.pop("confirm", None)
            kv(log, logging.INFO, "admin_request", op=op, actor=actor)
            result = await self.host_app.execute(op, fields, actor.strip(), confirm=confirm)
            return {"ok": True, "result": result}
        except TsrWarning as exc:
            kv(log, logging.WARNING, "tsr_not_confirmed", trains=len(exc.trains))
            return {"ok": False, "error": str(exc), "errors": exc.errors, "warning": exc.view()}
        except OperationError as exc:
            return {"ok": False, "error": str(exc), "errors": exc.errors}


def _line(obj: dict[str, Any]) -> bytes:
    return json.dumps(obj, default=str).encode() + b"\n"


async def admin_request(
    request: dict[str, Any], *, host: str = "127.0.0.1", port: int, timeout_s: float = 10.0
) -> dict[str, Any]:
    """Send one request to a running server's admin port and return its response."""
    require_loopback("admin host", host)
    async with asyncio.timeout(timeout_s):
        reader, writer = await asyncio.open_connection(host, port, limit=64 * 1024 * 1024)
        try:
            writer.write(_line(request))
            await writer.drain()
            line = await reader.readline()
        finally:
            writer.close()
    if not line:
        raise AdminError(f"admin port {host}:{port} closed without an answer")
    response = json.loads(line)
    if not isinstance(response, dict):
        raise AdminError("admin answer is not a JSON object")
    return response
