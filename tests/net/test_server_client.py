"""Ground server and onboard client over real loopback TCP: one behaviour per test."""

from __future__ import annotations

import asyncio

from railpilot.link import (
    Deregistered,
    OnboardState,
    Registered,
    TimeChecked,
    TrainDeregistered,
    TrainRegistered,
    TsrAcknowledged,
    TsrApplied,
    TsrCancelAcknowledged,
    TsrCancelled,
    TsrState,
)

from .helpers import LENGTH_M, SPEED_MPS, TRAIN_ID, rig, run, tsr, until


def test_train_registers_and_running_info_reaches_the_ground() -> None:
    async def scenario() -> None:
        async with rig() as r:
            client = r.clients[0]
            await until(lambda: len(r.running_infos()) >= 3)
            assert r.ground_of(TrainRegistered)[0].train_id == TRAIN_ID
            assert client.state is OnboardState.REGISTERED
            infos = [e.message for e in r.running_infos()]
            assert all(i.speed_mps == SPEED_MPS for i in infos)
            # The simulated train moves forward: positions never go back.
            positions = [i.position_m for i in infos]
            assert positions == sorted(positions) and positions[-1] > positions[0]
            status = r.server.status()["trains"][0]
            assert status["registered"] and status["running_info"]["count"] >= 3

    run(scenario())


def test_onboard_answers_the_time_check() -> None:
    async def scenario() -> None:
        async with rig() as r:
            await until(
                lambda: (
                    TRAIN_ID in r.server.records
                    and r.server.records[TRAIN_ID].time_offset_s is not None
                )
            )
            assert r.onboard_of(TRAIN_ID, TimeChecked)
            # Same machine clock: the measured offset is only the one-way delay.
            assert abs(r.server.records[TRAIN_ID].time_offset_s or 0.0) < 1.0

    run(scenario())


def test_tsr_is_applied_once_extended_by_train_length_and_acknowledged() -> None:
    async def scenario() -> None:
        async with rig() as r:
            await until(lambda: len(r.running_infos()) >= 2)  # direction known: UP
            r.server.set_tsr([TRAIN_ID], tsr(7, 5_000.0, 6_000.0))
            await until(lambda: bool(r.ground_of(TsrAcknowledged)))
            await asyncio.sleep(0.5)  # several resend intervals: nothing is applied again
            applied = r.onboard_of(TRAIN_ID, TsrApplied)
            assert len(applied) == 1
            zone = applied[0].tsr
            assert (zone.zone_start_m, zone.zone_end_m) == (5_000.0, 6_000.0 + LENGTH_M)
            assert r.server.records[TRAIN_ID].tsrs[7].state is TsrState.ACTIVE

    run(scenario())


def test_tsr_cancel_is_applied_and_acknowledged() -> None:
    async def scenario() -> None:
        async with rig() as r:
            await until(lambda: bool(r.running_infos()))
            r.server.set_tsr([TRAIN_ID], tsr(8))
            await until(lambda: bool(r.ground_of(TsrAcknowledged)))
            r.server.cancel_tsr([TRAIN_ID], 8)
            await until(lambda: bool(r.ground_of(TsrCancelAcknowledged)))
            assert len(r.onboard_of(TRAIN_ID, TsrCancelled)) == 1
            assert 8 not in r.clients[0].endpoint.active_tsrs
            assert r.server.records[TRAIN_ID].tsrs[8].state is TsrState.CANCELLED

    run(scenario())


def test_tsr_for_an_offline_train_waits_and_is_delivered_after_registration() -> None:
    async def scenario() -> None:
        async with rig(start=False) as r:
            outcome = r.server.set_tsr([TRAIN_ID], tsr(9))
            assert outcome[TRAIN_ID].startswith("queued")
            r.start(r.clients[0])
            await until(lambda: bool(r.ground_of(TsrAcknowledged)))
            assert len(r.onboard_of(TRAIN_ID, TsrApplied)) == 1

    run(scenario())


def test_client_reconnects_and_registers_again_after_the_server_drops_it() -> None:
    async def scenario() -> None:
        async with rig() as r:
            client = r.clients[0]
            await until(lambda: bool(r.running_infos()))
            r.server.set_tsr([TRAIN_ID], tsr(10))
            await until(lambda: bool(r.ground_of(TsrAcknowledged)))
            r.server.live[TRAIN_ID].close("test: drop the train")
            await until(lambda: client.registrations >= 2)
            assert client.connects >= 2
            assert len(r.ground_of(TrainRegistered)) >= 2
            # After re-registration the ground asks the train to confirm the active TSR;
            # the train confirms it without applying it a second time.
            await until(lambda: r.server.records[TRAIN_ID].tsrs[10].state is TsrState.ACTIVE)
            assert len(r.onboard_of(TRAIN_ID, TsrApplied)) == 1
            assert client.reconnect_delays_s  # the backoff was used

    run(scenario())


def test_reconnect_delays_come_from_the_seeded_backoff() -> None:
    async def scenario() -> list[float]:
        async with rig() as r:
            client = r.clients[0]
            await until(lambda: client.registrations >= 1)
            await r.server.stop(timeout_s=1.0)  # ground gone: connects fail, backoff grows
            await until(lambda: len(client.reconnect_delays_s) >= 4)
            return client.reconnect_delays_s[:4]

    first, second = run(scenario()), run(scenario())
    assert first == second  # same seed, same jitter
    # Exponential backoff: 0.05 * 2**k with up to 50 % jitter off.
    for k, delay in enumerate(first):
        assert 0.05 * 2**k * 0.5 <= delay <= 0.05 * 2**k


def test_onboard_shutdown_deregisters_on_the_ground() -> None:
    async def scenario() -> None:
        async with rig() as r:
            client = r.clients[0]
            await until(lambda: client.registrations >= 1)
            r.stop.set()
            await asyncio.wait_for(asyncio.gather(*r.tasks), 5.0)
            assert r.onboard_of(TRAIN_ID, Deregistered)
            assert r.ground_of(TrainDeregistered)
            assert not r.server.records[TRAIN_ID].registered

    run(scenario())


def test_server_shutdown_closes_every_connection() -> None:
    async def scenario() -> None:
        async with rig(TRAIN_ID, 2002) as r:
            await until(lambda: all(c.registrations for c in r.clients))
            await r.server.stop(timeout_s=2.0)
            assert r.server.status()["connections"] == 0
            await until(lambda: not any(c.connected for c in r.clients))
            assert all(c.endpoint.state is not OnboardState.REGISTERED for c in r.clients)

    run(scenario())


def test_many_trains_share_one_server() -> None:
    ids = tuple(range(3001, 3011))

    async def scenario() -> None:
        async with rig(*ids) as r:
            await until(lambda: len(r.server.live) == len(ids))
            await until(lambda: {e.source_id for e in r.running_infos()} == set(ids))
            assert {e.train_id for e in r.ground_of(TrainRegistered)} == set(ids)
            assert all(r.onboard_of(t, Registered) for t in ids)

    run(scenario())
