"""The dispatcher dashboard: an HTTP + WebSocket adapter over the ground (docs/dashboard.md).

- :mod:`~railpilot.web.source`: what the page needs of the ground (:class:`DashboardSource`);
  the TSR form's fields are those of the ground's ``tsr_set`` operation (ground/operations.py);
- :mod:`~railpilot.web.view`: the snapshot's parts from the ground's own objects;
- :mod:`~railpilot.web.app`: the Starlette app (routes, token, WebSocket pushes);
- :mod:`~railpilot.web.ground_source`: the live ground as the page sees it;
- the demo ground (:mod:`railpilot.cosim.demo_ground`): the real ground over the simulated
  radio with scripted trains, for the tests and the demo.

The page itself (static/) is plain SVG and JavaScript, no build step and nothing fetched
from elsewhere.
"""

from __future__ import annotations

from .app import DEFAULT_HOST, create_app, server_config
from .source import TSR_FORM_FIELDS, DashboardSource

__all__ = ["DEFAULT_HOST", "TSR_FORM_FIELDS", "DashboardSource", "create_app", "server_config"]
