"""Rate-limited logging of frame rejections, per connection and per check.

A peer that does not speak the protocol (or an attacker spraying bytes) can make every
frame a rejection; one WARNING line each would let it fill the disk (10 MiB of random bytes
once wrote 40,775 lines). :class:`RejectionLog` writes the first ``burst`` rejections of
each check per ``interval_s`` window in full, counts the rest, and says how many it held
back in one summary line when the window ends and when the connection closes. The endpoint
counters (``LinkCounters.rejected``) stay exact whatever is logged; the summary's numbers
are exact too.

Pure bookkeeping: time is passed in, the logger is given; nothing here reads a clock. A
window ends when something brings a time at or past its end: the next rejection (of any
check), or :meth:`RejectionLog.tick` from the host's timer, which
:meth:`RejectionLog.next_deadline_s` tells when to fire. A peer that floods and then falls
silent is thus summarised when its window ends, not only when the connection closes.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass

from railpilot.link import FrameRejected

from .logfmt import kv

#: Rejections of one check logged in full per window, per connection.
DEFAULT_BURST = 5
#: Length of a window [s]; a summary of what was held back closes each one.
DEFAULT_INTERVAL_S = 10.0


@dataclass
class _Window:
    started_s: float
    logged: int = 0
    suppressed: int = 0


class RejectionLog:
    """Frame-rejection log lines of one connection, at most ``burst`` per check and window."""

    def __init__(
        self,
        logger: logging.Logger,
        *,
        burst: int = DEFAULT_BURST,
        interval_s: float = DEFAULT_INTERVAL_S,
    ) -> None:
        if burst < 0 or not interval_s > 0:
            raise ValueError(f"burst = {burst}, interval_s = {interval_s}: expected >= 0, > 0")
        self._log = logger
        self._burst = burst
        self._interval_s = interval_s
        self._windows: dict[str, _Window] = {}
        #: Every rejection seen, per check (exact, whatever was logged).
        self.total: Counter[str] = Counter()
        #: Rejections counted but not logged line by line, per check (exact).
        self.suppressed: Counter[str] = Counter()

    def record(self, event: FrameRejected, now_s: float, **context: object) -> None:
        """One rejected frame: logged in full, or counted for the window's summary."""
        check = event.check.value
        self.total[check] += 1
        self.tick(now_s, **context)
        window = self._windows.get(check)
        if window is None:
            window = self._windows[check] = _Window(now_s)
        if window.logged < self._burst:
            window.logged += 1
            kv(
                self._log,
                logging.WARNING,
                "frame_rejected",
                **context,
                check=check,
                detail=event.detail,
                claimed_type=event.message_type,
                claimed_source=event.source_id,
                claimed_seq=event.sequence,
            )
        else:
            window.suppressed += 1
            self.suppressed[check] += 1

    def tick(self, now_s: float, **context: object) -> None:
        """Close every window that has ended by ``now_s``, with its summary line if it held
        rejections back; the next rejection of that check opens a new window."""
        for check, window in sorted(self._windows.items()):
            if now_s - window.started_s >= self._interval_s:
                self._summarise(check, window, **context)
                del self._windows[check]

    def next_deadline_s(self) -> float | None:
        """When the earliest window holding rejections back ends (its summary is due), or
        None when no summary is pending: the host's timer calls :meth:`tick` then."""
        ends = [w.started_s + self._interval_s for w in self._windows.values() if w.suppressed]
        return min(ends, default=None)

    def close(self, **context: object) -> None:
        """The connection is gone: summarise every open window, then the exact totals."""
        for check, window in sorted(self._windows.items()):
            self._summarise(check, window, **context)
        self._windows.clear()
        if self.suppressed:
            kv(
                self._log,
                logging.WARNING,
                "frame_rejections_total",
                **context,
                rejected=sum(self.total.values()),
                logged=sum(self.total.values()) - sum(self.suppressed.values()),
                by_check=",".join(f"{c}:{n}" for c, n in sorted(self.total.items())),
            )

    def _summarise(self, check: str, window: _Window, **context: object) -> None:
        if window.suppressed:
            kv(
                self._log,
                logging.WARNING,
                "frame_rejections_suppressed",
                **context,
                check=check,
                suppressed=window.suppressed,
                window_s=self._interval_s,
            )
            window.suppressed = 0
