"""Trains and ground over the simulated radio (cosim/link_sim.py): the live system's
endpoints and dispatch core, in simulated time."""

from __future__ import annotations

import pytest

from railpilot.cosim.channel import ChannelModel, DeadZone, Outage
from railpilot.cosim.link_sim import LinkSim, SimTrain
from railpilot.errors import ConfigError
from railpilot.ground.operations import parse_operation
from railpilot.ground.store import Store
from railpilot.line.loader import load_line
from railpilot.link import DeliveryState, OnboardConfig, TargetReason, TravelDirection, TsrState
from railpilot.link.keys import seeded_test_keys as loadtest_keys
from railpilot.net.client import Trajectory

LINE = load_line("heavy-haul")
UP, DOWN = TravelDirection.UP, TravelDirection.DOWN
IDS = range(30001, 30007)


def config(train_id: int, length_m: float = 2600.0) -> OnboardConfig:
    return OnboardConfig(
        train_id=train_id,
        ground_id=1,
        train_number=f"K{train_id}",
        loco_number="HXD1-01",
        driver_id=train_id,
        train_length_m=length_m,
    )


def six_trains() -> list[SimTrain]:
    """Three up and three down, 15 km apart, at 20 m/s, coming up 10 s apart."""
    trains = []
    for k, train_id in enumerate(IDS):
        up = k % 2 == 0
        start = 100_000.0 + 15_000.0 * k if up else 300_000.0 - 15_000.0 * k
        mover = Trajectory(start_m=start, speed_mps=20.0, direction=UP if up else DOWN)
        trains.append(SimTrain(config(train_id), mover, start_s=10.0 * k))
    return trains


def set_tsr(sim: LinkSim, start_km: float, end_km: float) -> tuple[int, tuple[int, ...]]:
    fields = {"start_km": start_km, "end_km": end_km, "limit_kmh": 40, "valid_until_min": 60}
    op = parse_operation("tsr_set", {**fields, "reason": "works"}, line=LINE, now_s=sim.now_s)
    outcome = sim.operate(op, "d1")
    return outcome.result["session"], tuple(outcome.result["trains"])


def assert_applied_once_by(sim: LinkSim, session: int, concerned: tuple[int, ...]) -> None:
    """Every concerned train applied the TSR once, no other train at all; the ground holds
    it acknowledged (after a reconnect the ground asks again, RECONFIRMING, and the train,
    which already applies it, answers without applying it twice)."""
    for train_id in IDS:
        applied = sim.stats[train_id].tsr_applied[session]
        assert applied == (1 if train_id in concerned else 0), train_id
    for train_id in concerned:
        state = sim.records[train_id].tsrs[session].state
        assert state in (TsrState.ACTIVE, TsrState.RECONFIRMING)


def lossy(seed: int) -> LinkSim:
    channel = ChannelModel(loss=0.3, dead_zones=(DeadZone(150.0, 153.0),))
    return LinkSim(LINE, six_trains(), channel, loadtest_keys(seed, IDS), seed=seed)


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.slow
def test_a_tsr_reaches_every_concerned_train_exactly_once_through_loss_and_a_dead_zone(
    seed: int,
) -> None:
    sim = lossy(seed)
    sim.run_until(120.0)
    session, concerned = set_tsr(sim, 180.0, 182.0)
    assert concerned  # the up trains behind km 180 and the down trains beyond it
    sim.run_until(900.0)
    report = sim.link_report()
    assert report["channel"]["lost_random"] > 0 and report["link_failures"] > 0
    assert_applied_once_by(sim, session, concerned)


@pytest.mark.slow
def test_the_same_seed_gives_the_same_run_and_another_seed_another() -> None:
    def run(seed: int) -> tuple[object, ...]:
        sim = lossy(seed)
        sim.run_until(300.0)
        return (sim.link_report(), {i: s.as_dict() for i, s in sim.stats.items()}, sim.now_s)

    assert run(1) == run(1)
    assert run(1) != run(2)


def test_a_train_in_a_dead_zone_loses_its_link_and_registers_again_beyond_it() -> None:
    # 20 m/s through a 3 km zone: 150 s without radio, far more than the 3 s timeout
    mover = Trajectory(start_m=148_000.0, speed_mps=20.0, direction=UP)
    channel = ChannelModel(dead_zones=(DeadZone(150.0, 153.0),))
    sim = LinkSim(LINE, [SimTrain(config(30001), mover)], channel, loadtest_keys(0, IDS))
    sim.run_until(90.0)  # at km 149.8: registered, reporting
    assert sim.stats[30001].registrations == 1
    sim.run_until(200.0)  # at km 152: inside the zone
    stats = sim.stats[30001]
    assert stats.link_failures == 1 and 30001 not in sim.live
    assert sim.link_report()["channel"]["lost_dead_zone"] > 0
    sim.run_until(400.0)  # at km 156: out of it again
    assert stats.registrations == 2 and 30001 in sim.live
    assert stats.connect_attempts > stats.connects  # it tried inside the zone, in vain


def test_a_follower_is_held_at_the_signal_behind_its_leaders_tail() -> None:
    leader = SimTrain(config(30001, 800.0), Trajectory(start_m=303_000.0, speed_mps=0.0))
    follower = SimTrain(config(30002, 800.0), Trajectory(start_m=295_000.0, speed_mps=0.0))
    sim = LinkSim(LINE, [leader, follower], ChannelModel(), loadtest_keys(0, IDS))
    sim.run_until(30.0)
    target = sim.onboard[30002].target_point
    assert target is not None and target.reason is TargetReason.TRAIN_AHEAD
    tail_m = 303_000.0 - 800.0
    (block,) = [b for b in LINE.block_sections_for(UP) if b.start_m <= tail_m < b.end_m]
    assert target.position_m == block.start_m
    (delivery,) = sim.records[30002].target_points.values()
    assert delivery.state is DeliveryState.ACKNOWLEDGED
    assert sim.onboard[30001].target_point is None


def test_bad_train_lists_are_refused_naming_the_field() -> None:
    keys = loadtest_keys(0, IDS)
    with pytest.raises(ConfigError) as info:
        LinkSim(LINE, [], ChannelModel(), keys)
    assert info.value.field == "trains"
    twice = [SimTrain(config(30001), Trajectory()), SimTrain(config(30001), Trajectory())]
    with pytest.raises(ConfigError) as info:
        LinkSim(LINE, twice, ChannelModel(), keys)
    assert info.value.field == "trains" and info.value.value == [30001]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.slow
def test_a_ground_killed_with_deliveries_pending_resumes_them_from_its_store(seed: int) -> None:
    channel = ChannelModel(loss=0.5)
    with Store(":memory:") as store:
        sim = LinkSim(LINE, six_trains(), channel, loadtest_keys(seed, IDS), seed=seed, store=store)
        sim.run_until(120.0)
        session, concerned = set_tsr(sim, 180.0, 182.0)
        # killed at once: every TsrSet just sent is in flight (or lost), none acknowledged
        pending = {t: sim.records[t].tsrs[session].state for t in concerned}
        assert set(pending.values()) == {TsrState.PENDING_SET}
        sim.restart_ground(30.0)
        assert sim.records == {} and not sim.ground_up
        sim.run_until(900.0)
        (restart,) = sim.restarts
        assert restart["restored"]["pending_set"] == len(concerned)
        assert_applied_once_by(sim, session, concerned)
        for train_id in concerned:
            assert session in sim.onboard[train_id].active_tsrs
        # the restarted dispatch core still knows the TSR, and cancels it everywhere
        op = parse_operation("tsr_cancel", {"session": session}, line=LINE, now_s=sim.now_s)
        outcome = sim.operate(op, "d1")
        assert sorted(outcome.result["trains"]) == sorted(concerned)
        sim.run_until(1200.0)
        for train_id in concerned:
            assert sim.records[train_id].tsrs[session].state is TsrState.CANCELLED
            assert session not in sim.onboard[train_id].active_tsrs


def test_a_restart_needs_a_store() -> None:
    sim = LinkSim(
        LINE, [SimTrain(config(30001), Trajectory())], ChannelModel(), loadtest_keys(0, IDS)
    )
    with pytest.raises(ConfigError) as info:
        sim.restart_ground(10.0)
    assert info.value.field == "store"


def test_a_train_that_leaves_with_its_link_down_deregisters_when_it_is_back() -> None:
    # Stopped at its destination during a radio outage: it cannot say it has left. Without
    # a deregistration the ground keeps it where it last reported, for ever (a block held
    # against the trains behind), so it says so as soon as it has registered again.
    start = 1_800_000_000.0
    channel = ChannelModel(outages=(Outage(20.0, 200.0),))  # from the start of the run
    mover = Trajectory(start_m=100_000.0, speed_mps=0.0)
    train = SimTrain(config(30001), mover)
    sim = LinkSim(LINE, [train], channel, loadtest_keys(0, IDS), start_s=start)
    sim.run_until(150.0)
    assert 30001 not in sim.live  # the link has failed in the outage
    sim.retire(30001)
    assert 30001 not in sim.retired
    sim.run_until(600.0)
    assert 30001 in sim.retired
    assert not sim.dispatch.registry.state(30001, sim.now_s).registered
    assert sim.dispatch.registry.reports() == []  # nothing left to occupy a block
    attempts = sim.stats[30001].connect_attempts
    sim.run_until(1200.0)
    assert sim.stats[30001].connect_attempts == attempts  # gone for good
