"""Under 30 % frame loss through the proxy, every TSR is applied exactly once on
the train and acknowledged on the ground (real loopback TCP, seeded proxy)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from railpilot.link import TsrAcknowledged, TsrApplied, TsrState
from railpilot.net import ProxyOptions

from .helpers import FAST, rig, run, tsr, until

TRAINS = (4001, 4002, 4003)
# 30 % loss both ways makes six missed heartbeats in a row likely enough over a run to
# trip the supervision now and then; a longer tolerance keeps the run about delivery.
LOSSY = replace(FAST, timeout_cycles=10)


@pytest.mark.parametrize("seed", [11, 12])
@pytest.mark.slow
def test_every_tsr_is_applied_exactly_once_and_acknowledged_under_30_percent_loss(
    seed: int,
) -> None:
    async def scenario() -> None:
        async with rig(*TRAINS, proxy=ProxyOptions(drop=0.3, seed=seed), timers=LOSSY) as r:
            await until(lambda: all(c.registrations for c in r.clients), 10.0)
            sessions = (21, 22)
            for session in sessions:
                r.server.set_tsr(TRAINS, tsr(session, 1_000.0 * session, 1_000.0 * session + 500))
            await until(lambda: len(r.ground_of(TsrAcknowledged)) == len(TRAINS) * 2, 10.0)
            # the link goes on for a few more resend intervals (counted in the frames each
            # way, six link cycles of every train, not in seconds): still applied once
            assert r.proxy is not None
            stats = r.proxy.stats
            later = {way: stats[way]["frames"] + 6 * len(TRAINS) for way in ("up", "down")}
            await until(lambda: all(stats[w]["frames"] >= n for w, n in later.items()), 10.0)
            for train in TRAINS:
                applied = [e.tsr.session for e in r.onboard_of(train, TsrApplied)]
                assert sorted(applied) == sorted(sessions), (train, applied)
                for session in sessions:
                    assert r.server.records[train].tsrs[session].state is TsrState.ACTIVE
            assert r.proxy.stats["down"]["dropped"] > 0 and r.proxy.stats["up"]["dropped"] > 0

    run(scenario(), timeout_s=30.0)
