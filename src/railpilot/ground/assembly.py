"""What a ground is made of, in one place: :class:`GroundParts`.

A ground is its line, its endpoints' configuration, the trains' keys, its store and,
where it re-times, what makes its retimer. Every ground (``ground serve``, a line run's
simulated or live ground, the load test, the demos) is built from one
:class:`GroundParts`: here the transport-free pieces (the dispatch core, the store's
writer, the :class:`~railpilot.ground.host.GroundHost`), in net/ground_app.py the live
server around them, in cosim/link_sim.py the simulated one. A transport adds only its
clock and its sockets or radio.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from railpilot.errors import ConfigError
from railpilot.line.model import RailLine
from railpilot.link import GroundConfig, KeyStore

from .dispatch import GroundDispatch
from .host import C, GroundHost, Note, Transport
from .journal import GroundJournal
from .online_retimer import OnlineRetimer
from .store import GroundStore


@dataclass(frozen=True)
class GroundParts:
    """The parts of one ground (module docstring).

    ``line``: the line it dispatches (None: a ground that only delivers what it is asked
    to, with no dispatch core); ``config``: its link endpoints' configuration; ``keys``:
    the trains' keys (None: no authentication); ``store``: where it keeps its records
    (None: in memory only); ``retimer``: makes its retimer, one per ground process (None:
    no re-timing).
    """

    config: GroundConfig
    line: RailLine | None = None
    keys: KeyStore | None = None
    store: GroundStore | None = None
    retimer: Callable[[], OnlineRetimer] | None = None

    def new_dispatch(self) -> GroundDispatch:
        """A fresh dispatch core (a ground process's; a restart makes another): a running
        info stays valid as long as the link's running-info timeout, and the core re-times
        where the ground does."""
        if self.line is None:
            raise ConfigError("line", None, "a line (a ground without one has no dispatch core)")
        timers = self.config.timers
        dispatch = GroundDispatch(self.line, validity_s=timers.cycle_s * timers.timeout_cycles)
        if self.retimer is not None:
            dispatch.retimer = self.retimer()
        return dispatch

    def new_journal(self) -> GroundJournal | None:
        """The writer to the store (None without one)."""
        return GroundJournal(self.store) if self.store is not None else None

    def new_host(
        self,
        transport: Transport[C],
        *,
        config: GroundConfig | None = None,
        journal: GroundJournal | None = None,
        note: Note | None = None,
    ) -> GroundHost[C]:
        """A ground process's host over ``transport``, with a fresh dispatch core if the
        ground has a line. ``config`` replaces the parts' (a restart's later replay
        floor); ``journal`` is kept across a restart (the store outlives the process)."""
        return GroundHost(
            self.config if config is None else config,
            transport,
            journal=journal if journal is not None else self.new_journal(),
            dispatch=None if self.line is None else self.new_dispatch(),
            note=note,
        )


__all__ = ["GroundParts"]
