"""A TSR over a train already running faster than its limit: the admin port and the CLI
warn and send nothing unless the request confirms it (ground/tsr_warning.py)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections.abc import AsyncIterator
from typing import Any

import pytest

from railpilot.cli import main
from railpilot.ground.tsr_warning import INSIDE
from railpilot.line.loader import load_line
from railpilot.link import TsrApplied
from railpilot.net.admin import AdminServer, admin_request
from railpilot.net.dispatch_host import DispatchHost
from railpilot.units import mps_to_kmh

from .helpers import FAST, SPEED_MPS, TRAIN_ID, rig, run, until

LINE = load_line("heavy-haul")
# reports stay valid 5 s (50 cycles of 0.1 s): a busy machine must not make the train's
# position unknown between two of its reports
TIMERS = dataclasses.replace(FAST, timeout_cycles=50)
SPEED_KMH = float(mps_to_kmh(SPEED_MPS))  # the test train's speed (54 km/h)
# the train runs UP from km 4: km 3-5 holds its head and tail
OVER_THE_TRAIN = {
    "op": "tsr_set",
    "start_km": 3.0,
    "end_km": 5.0,
    "valid_until_min": 10,
    "reason": "track work",
}


def tsr(limit_kmh: float, **more: Any) -> dict[str, Any]:
    return {**OVER_THE_TRAIN, "limit_kmh": limit_kmh, **more}


@contextlib.asynccontextmanager
async def _admin_port() -> AsyncIterator[tuple[Any, DispatchHost, int]]:
    """The test train's rig with a dispatch host and its admin port, once the ground has
    the train's first report: ``(rig, host, admin port)``."""
    async with rig(timers=TIMERS) as r:
        host = DispatchHost(r.server, LINE)
        host.start()
        admin = AdminServer(host)
        _, port = await admin.start()
        try:
            await until(lambda: bool(r.running_infos()))
            yield r, host, port
        finally:
            await admin.stop()
            host.stop()


def test_a_tsr_below_a_trains_speed_is_warned_about_and_sent_once_confirmed() -> None:
    async def scenario() -> None:
        async with _admin_port() as (r, host, port):
            answer = await admin_request(tsr(SPEED_KMH - 14), port=port)
            assert answer["ok"] is False
            assert set(answer["errors"]) == {"confirm"}
            (train,) = answer["warning"]["trains"]
            assert train["train"] == TRAIN_ID and train["where"] == INSIDE
            assert train["speed_kmh"] == pytest.approx(SPEED_KMH)
            assert train["over_limit_kmh"] == pytest.approx(14.0)
            assert host.dispatch.tsrs.tsrs() == ()  # nothing set, nothing sent
            assert r.server.records[TRAIN_ID].tsrs == {}
            answer = await admin_request(tsr(SPEED_KMH - 14, confirm=True), port=port)
            assert answer["ok"] is True and answer["result"]["trains"] == [TRAIN_ID]
            await until(lambda: bool(r.onboard_of(TRAIN_ID, TsrApplied)))

    run(scenario())


def test_a_tsr_no_train_runs_faster_than_is_sent_without_asking() -> None:
    async def scenario() -> None:
        async with _admin_port() as (_, _host, port):
            answer = await admin_request(tsr(SPEED_KMH + 10), port=port)
            assert answer["ok"] is True and "warning" not in answer

    run(scenario())


@pytest.mark.parametrize(
    ("request_", "needle"),
    [
        (tsr(40, confirm="yes"), "'yes' is not allowed: expected true or false"),
        ({"op": "status", "confirm": True}, "expected confirm only with tsr_set"),
    ],
)
def test_a_bad_confirm_is_refused_naming_it(request_: dict[str, Any], needle: str) -> None:
    async def scenario() -> dict[str, Any]:
        async with rig(timers=TIMERS, start=False) as r:
            host = DispatchHost(r.server, LINE)
            host.start()
            answer = await AdminServer(host).execute(request_)
            host.stop()
            return answer

    answer = run(scenario())
    assert answer["ok"] is False and needle in answer["errors"]["confirm"]


def test_the_cli_prints_one_line_per_train_and_exits_2_unless_confirmed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    def argv(port: int, *more: str) -> list[str]:
        return [
            *("ground", "tsr", "set", "--start-km", "3", "--end-km", "5"),
            *("--limit-kmh", "40", "--valid-until-min", "10", "--reason", "works"),
            *("--admin-port", str(port), *more),
        ]

    async def scenario() -> tuple[int, int, int]:
        async with _admin_port() as (_, host, port):
            refused = await asyncio.to_thread(main, argv(port))
            sets = len(host.dispatch.tsrs.tsrs())
            confirmed = await asyncio.to_thread(main, argv(port, "--confirm"))
            return refused, sets, confirmed

    refused, sets, confirmed = run(scenario())
    assert (refused, sets, confirmed) == (2, 0, 0)
    err = capsys.readouterr().err
    assert "TSR not sent: 1 train(s)" in err
    assert f"  train {TRAIN_ID}: inside at km " in err
    assert "--confirm" in err
