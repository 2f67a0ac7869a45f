"""Local admin API of the ground server: line-delimited JSON over TCP on loopback only.

One request per line, one response per line (UTF-8 JSON objects). The socket binds to a
loopback address and refuses anything else: it is an operator's local control port, not
part of the train-ground link (there is no authentication on it beyond "you can reach
127.0.0.1 on this host"). Units are the operator's: km posts in km, speeds in km/h.

Requests (``trains`` is a list of train ids or ``"all"`` = every train that has
registered at least once)::

    {"op": "status"}
    {"op": "tsr_set", "trains": [1001], "session": 7, "start_km": 12.3, "end_km": 13.1,
     "limit_kmh": 45, "valid_s": 3600}                        # optional "valid_from_s"
    {"op": "tsr_cancel", "trains": "all", "session": 7}
    {"op": "target", "trains": [1001], "target_id": 3, "km": 15.2, "reason": "TRAIN_AHEAD"}
    {"op": "dispatch", "trains": [1001], "command": 42, "text": "hold at next station"}

Every delivery request may name who asks (``"actor"``, default ``"admin"``) and a TSR why
(``"reason"``); both go to the ground store's audit log (docs/ground-store.md).

Responses: ``{"ok": true, "result": {...}}`` or ``{"ok": false, "error": "..."}``. For a
delivery, ``result.trains`` maps each train id to ``"sending"`` (connected; resent until
acknowledged), ``"queued until the train registers"`` or ``"error: ..."``. A delivery
naming a train without a key (authentication on), and a TSR whose start and end are the
same km post, are refused as a whole (``ok: false``) and nothing is sent.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import time
from typing import Any

from railpilot.errors import RailpilotError
from railpilot.link import DispatchCommand, LinkError, TargetPoint, TargetReason, TsrSet
from railpilot.units import kmh_to_mps

from .logfmt import kv
from .server import GroundServer

log = logging.getLogger("railpilot.net.admin")

LOOPBACK = frozenset({"127.0.0.1", "::1", "localhost"})
MAX_LINE = 64 * 1024
OPS = ("status", "tsr_set", "tsr_cancel", "target", "dispatch")


class AdminError(RailpilotError):
    """A bad admin request (names the field, the value and what is allowed)."""


def require_loopback(field: str, host: str) -> None:
    if host not in LOOPBACK:
        raise AdminError(f"{field} = {host!r} is not allowed: expected a loopback address")


def _number(req: dict[str, Any], name: str, lo: float, hi: float) -> float:
    value = req.get(name)
    if (
        not isinstance(value, int | float)
        or isinstance(value, bool)
        or not math.isfinite(value)
        or not lo <= value <= hi
    ):
        raise AdminError(f"{name} = {value!r} is not allowed: expected a number in [{lo}, {hi}]")
    return float(value)


def _text(req: dict[str, Any], name: str, default: str, max_len: int) -> str:
    value = req.get(name, default)
    if not isinstance(value, str) or len(value) > max_len or not value.isprintable():
        raise AdminError(
            f"{name} = {value!r} is not allowed: expected at most {max_len} printable characters"
        )
    return value


def _int(req: dict[str, Any], name: str, lo: int, hi: int) -> int:
    value = req.get(name)
    if type(value) is not int or not lo <= value <= hi:
        raise AdminError(f"{name} = {value!r} is not allowed: expected an integer in [{lo}, {hi}]")
    return value


class AdminServer:
    """Serves :data:`OPS` for one :class:`GroundServer`."""

    def __init__(self, ground: GroundServer, *, host: str = "127.0.0.1", port: int = 0) -> None:
        require_loopback("admin host", host)
        self.ground = ground
        self.host = host
        self.port = port
        self._server: asyncio.Server | None = None

    async def start(self) -> tuple[str, int]:
        self._server = await asyncio.start_server(
            self._serve_client, self.host, self.port, limit=MAX_LINE
        )
        self.port = int(self._server.sockets[0].getsockname()[1])
        kv(log, logging.INFO, "admin_listening", host=self.host, port=self.port)
        return self.host, self.port

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
                raise AdminError("request must be a JSON object")
            op = request.get("op")
            if op not in OPS:
                raise AdminError(f"op = {op!r} is not allowed: expected one of {', '.join(OPS)}")
            kv(log, logging.INFO, "admin_request", op=op)
            if op == "status":
                return {"ok": True, "result": self.ground.status()}
            trains = self._trains(request)
            actor = _text(request, "actor", "admin", 64)
            if not actor.strip():
                raise AdminError(f"actor = {actor!r} is not allowed: expected a name")
            g = self.ground
            if op == "tsr_set":
                valid_s = _number(request, "valid_s", 1.0, 30 * 86400.0)
                start = request.get("valid_from_s", time.time())
                if not isinstance(start, int | float) or isinstance(start, bool):
                    raise AdminError(f"valid_from_s = {start!r} is not allowed: expected epoch s")
                session = _int(request, "session", 1, 0xFFFF_FFFF)
                start_km = _number(request, "start_km", 0.0, 10_000.0)
                end_km = _number(request, "end_km", 0.0, 10_000.0)
                if round(start_km * 100_000) == round(end_km * 100_000):
                    # The train would answer INVALID (protocol.md 8.3): refuse it here.
                    raise AdminError(
                        f"end_km = {end_km!r} is not allowed: expected a km post at least "
                        f"1 cm away from start_km = {start_km!r} (a TSR needs a length)"
                    )
                tsr = TsrSet(
                    session,
                    start_km * 1000.0,
                    end_km * 1000.0,
                    kmh_to_mps(_number(request, "limit_kmh", 0.1, 360.0)),
                    float(start),
                    float(start) + valid_s,
                )
                reason = _text(request, "reason", "", 200)
                results = await g.paced(
                    lambda ids, item: g.set_tsr(ids, item, actor=actor, reason=reason), trains, tsr
                )
            elif op == "tsr_cancel":
                session = _int(request, "session", 1, 0xFFFF_FFFF)
                results = await g.paced(
                    lambda ids, item: g.cancel_tsr(ids, item, actor=actor), trains, session
                )
            elif op == "target":
                reason_name = str(request.get("reason", "OTHER")).upper().replace("-", "_")
                if reason_name not in TargetReason.__members__:
                    raise AdminError(
                        f"reason = {request.get('reason')!r} is not allowed: expected one of "
                        f"{', '.join(TargetReason.__members__)}"
                    )
                target = TargetPoint(
                    _int(request, "target_id", 0, 0xFFFF_FFFF),
                    _number(request, "km", 0.0, 10_000.0) * 1000.0,
                    TargetReason[reason_name],
                )
                results = await g.paced(
                    lambda ids, item: g.send_target_point(ids, item, actor=actor), trains, target
                )
            else:
                text = request.get("text")
                if not isinstance(text, str):
                    raise AdminError(f"text = {text!r} is not allowed: expected a string")
                command = DispatchCommand(_int(request, "command", 1, 0xFFFF_FFFF), text)
                results = await g.paced(
                    lambda ids, item: g.send_dispatch_command(ids, item, actor=actor),
                    trains,
                    command,
                )
            return {"ok": True, "result": {"trains": {str(t): r for t, r in results.items()}}}
        except (AdminError, LinkError) as exc:
            return {"ok": False, "error": str(exc)}

    def _trains(self, request: dict[str, Any]) -> list[int]:
        trains = request.get("trains")
        if trains == "all":
            known = self.ground.known_trains()
            if not known:
                raise AdminError(
                    "trains = 'all' is not allowed: expected at least one train that has "
                    "registered (none has yet)"
                )
            return known
        if (
            not isinstance(trains, list)
            or not trains
            or not all(type(t) is int and 1 <= t <= 0xFFFF_FFFF for t in trains)
        ):
            raise AdminError(
                f"trains = {trains!r} is not allowed: expected 'all' or a list of train ids "
                "in [1, 4294967295]"
            )
        ids = list(dict.fromkeys(trains))
        keys = self.ground.keys
        if self.ground.config.require_auth and keys is not None:
            # Such a train can never pass the MAC check, so it can never register and a
            # delivery would wait for it forever: refuse the whole request instead.
            keyless = [t for t in ids if keys.active(t) is None]
            if keyless:
                raise AdminError(
                    f"trains = {keyless!r} is not allowed: expected train ids that have a key "
                    "in the server's key file (authentication is on)"
                )
        return ids


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
