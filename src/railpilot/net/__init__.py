"""Asyncio adapters around the link protocol core (:mod:`railpilot.link`).

Every socket, clock read and sleep of the link lives in this package (DESIGN habit 11);
the core only turns bytes into events and back (habit 1). Each adapter is thin (habit 2):
it feeds received bytes to an endpoint, ticks it from one shared timer
(:class:`~railpilot.net.timers.TickScheduler`), writes what the endpoint wants written and
passes its events on.

* :mod:`~railpilot.net.server` - the ground front server (many trains at once);
* :mod:`~railpilot.net.admin` - the server's local admin API (line-delimited JSON);
* :mod:`~railpilot.net.client` - the onboard endpoint with a simulated trajectory;
* :mod:`~railpilot.net.proxy` - a per-frame fault-injection proxy for threat tests.

The load test that drives them (N trains against one server) is a rig:
:mod:`railpilot.rigs.loadtest`.

Only loopback addresses are used by the tools and tests here.
"""

from __future__ import annotations

import logging

from .client import OnboardClient, Trajectory
from .proxy import FaultProxy, ProxyOptions
from .server import GroundServer
from .timers import TickScheduler

# A library does not print by default: the CLI (or the application) installs handlers.
logging.getLogger("railpilot.net").addHandler(logging.NullHandler())

__all__ = [
    "FaultProxy",
    "GroundServer",
    "OnboardClient",
    "ProxyOptions",
    "TickScheduler",
    "Trajectory",
]
