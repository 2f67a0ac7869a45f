"""What the dashboard reads and asks of the ground: the :class:`DashboardSource` protocol.

The web app (app.py) is a thin adapter: it asks a source for JSON-ready snapshots, hands
the dispatcher's forms (TSRs, restrictions, dispatch commands) to it and pushes the snapshots over a
WebSocket. The source owns the ground's state and its clock; the app never interprets a
snapshot. Two sources exist:

- :class:`railpilot.cosim.demo_ground.DemoGround`: a deterministic line full of scripted trains
  around the real ground host (in the co-simulation), for the tests and the demo;
- :class:`railpilot.web.ground_source.ServerSource`: the live ground server
  (net/server.py), in its event loop (docs/dashboard.md, "The live ground").

Snapshot (``snapshot(now_s)``), in the dispatcher's units (km posts in km, speeds in km/h,
times in s of the ground clock)::

    {"now_s": float, "version": int,
     "line": {"name", "start_km", "end_km",
              "stations": [{"id", "name", "km"}],
              "signals": [{"id", "km", "direction": "up"|"down", "kind", "block",
                           "aspect": "red"|"green"}]},
     "blocks": [{"id", "direction", "start_km", "end_km", "state": "occupied"|"restricted",
                 "trains": [train id, ...], "reason": str|None}],   # the blocks not free
     "trains": [{"id", "number", "registered", "length_km", "km", "speed_kmh", "direction",
                 "valid", "info_age_s", "mrsp_kmh", "deviation_s",
                 "link": {"connected", "timeouts", "failures",
                 "rejections": {check: count}}, "target": {...}|None, "alarms": [kind]}],
     "tsrs": [{"session", "start_km", "end_km", "limit_kmh", "valid_from_s",
               "valid_until_s", "reason", "set_by", "state",
               "deliveries": [{"train", "number", "state"}]}],
     "restrictions": [{"id", "reason", "block"|None, "start_km", "end_km",
                       "track": "up"|"down"|"both", "blocks": [block id, ...]}],
     "dispatch": [{"command", "train", "number", "text", "state"}],
     "graph": {"from_s", "to_s", "trains": [{"id", "number", "direction",
                                             "plan": [[t_s, km], ...],
                                             "actual": [[t_s, km], ...]}]},
     "alarms": [{"kind": "link"|"overspeed", "train", "number", "text"}]}

:mod:`railpilot.web.view` builds each part from the ground's own objects, so every source
produces the same shape.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

#: The TSR form's fields, as the page posts them (strings or numbers): those of the
#: ground's ``tsr_set`` operation (ground/operations.py, one schema for the page, the admin
#: port and the CLI) in the dispatcher's units: km posts [km], the limit [km/h] and the
#: validity window in minutes from now.
TSR_FORM_FIELDS = (
    "start_km",
    "end_km",
    "limit_kmh",
    "valid_from_min",
    "valid_until_min",
    "reason",
)


#: The restriction form's fields: those of the ground's ``restriction_set`` operation,
#: the reason (``section_fault`` or ``switch_indication_lost``) and either a block section
#: id or a km span with its track (``up``, ``down`` or ``both``).
RESTRICTION_FORM_FIELDS = ("reason", "block", "start_km", "end_km", "track")

#: The dispatch command form's fields: those of the ground's ``dispatch`` operation, the
#: train ids (``"101, 102"``, or ``"all"``: every train that has registered) and the text.
DISPATCH_FORM_FIELDS = ("trains", "text")


@runtime_checkable
class DashboardSource(Protocol):
    """The ground as the dashboard sees it (module docstring).

    Every method is called from the web server's event loop and must return quickly; a
    source updated from another thread guards its state itself (DemoGround holds a lock).

    Optional: ``starting() -> str | None``, why the source cannot be shown yet (the live
    ground until it has restored from its store), or None; while it gives a reason the app
    answers 503 and closes the WebSocket (app.py). A source without it is always ready.
    """

    def now_s(self) -> float:
        """The ground clock [s] (epoch seconds; simulated in the demo)."""
        ...

    def version(self) -> int:
        """A counter bumped by every change the page should see; the app pushes a new
        snapshot when it changes, and at least every second in any case."""
        ...

    def snapshot(self, now_s: float) -> dict[str, Any]:
        """The whole picture at ``now_s`` [s], JSON-ready (module docstring)."""
        ...

    def set_tsr(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        """Validate and set a line TSR from the form's ``fields`` (:data:`TSR_FORM_FIELDS`).

        Returns ``{"ok": {tsr view}}`` or ``{"errors": {field: message}}``, each message
        naming the value and what is allowed, in the form's units.
        """
        ...

    def cancel_tsr(self, session: int, actor: str, now_s: float) -> dict[str, Any]:
        """Cancel TSR ``session``: ``{"ok": {tsr view}}`` or ``{"errors": {"session": ...}}``."""
        ...

    def set_restriction(
        self, fields: Mapping[str, Any], actor: str, now_s: float
    ) -> dict[str, Any]:
        """Declare a restriction (a section fault, a lost switch indication) from the form's
        ``fields`` (:data:`RESTRICTION_FORM_FIELDS`; blank ones left out): the signals
        protecting its blocks go red and trains are held before them. ``{"ok": {restriction
        view}}`` or ``{"errors": {field: message}}``."""
        ...

    def clear_restriction(self, ident: int, actor: str, now_s: float) -> dict[str, Any]:
        """Clear restriction ``ident``: ``{"ok": {"id": ident}}`` or ``{"errors": {"id": ...}}``."""
        ...

    def send_dispatch(self, fields: Mapping[str, Any], actor: str, now_s: float) -> dict[str, Any]:
        """Validate and send a dispatch command from the form's ``fields``
        (:data:`DISPATCH_FORM_FIELDS`): ``{"ok": {"command": number, "trains": [id, ...]}}``
        or ``{"errors": {field: message}}``. Each train acknowledges it on its own; the
        snapshot's ``dispatch`` rows show where each delivery stands."""
        ...
