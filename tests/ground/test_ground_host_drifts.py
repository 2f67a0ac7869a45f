"""The ground's rules are the same wherever the ground is hosted.

Each test drives one host (the co-simulation, or the dashboard's demo ground) through its
public entry points and asserts what the dispatch core and the live server do.
"""

from __future__ import annotations

import contextlib

from railpilot.cosim.channel import ChannelModel
from railpilot.cosim.demo_ground import DemoGround
from railpilot.cosim.link_sim import LinkSim, SimTrain
from railpilot.ground.dispatch import CancelTsrOn
from railpilot.line.loader import load_line
from railpilot.link import LinkError, OnboardConfig, TravelDirection
from railpilot.link.keys import seeded_test_keys
from railpilot.net.client import Trajectory

HEAVY_HAUL = load_line("heavy-haul")
#: A TSR as a dispatcher's form gives it (on the heavy-haul line, ahead of some trains).
TSR_FORM = {
    "start_km": "300",
    "end_km": "330",
    "limit_kmh": "40",
    "valid_until_min": "90",
    "reason": "sun kink check",
}


def _sim_with_a_train_not_yet_on_the_radio(train_id: int) -> LinkSim:
    config = OnboardConfig(
        train_id=train_id,
        ground_id=1,
        train_number=f"K{train_id}",
        loco_number="HXD1-01",
        driver_id=train_id,
        train_length_m=1300.0,
    )
    mover = Trajectory(start_m=100_000.0, speed_mps=20.0, direction=TravelDirection.UP)
    train = SimTrain(config, mover, start_s=3600.0)  # comes up in an hour
    return LinkSim(HEAVY_HAUL, [train], ChannelModel(), seeded_test_keys(0, [train_id]))


def test_the_cosimulation_undoes_the_record_of_a_refused_request() -> None:
    # The live server: a request the train's record refuses (a cancel of a session it
    # was never sent) must not invent a train that has never been heard of.
    sim = _sim_with_a_train_not_yet_on_the_radio(40001)
    sim.run_until(10.0)
    with contextlib.suppress(LinkError):  # refused: reported, never carried out
        sim.execute([CancelTsrOn(session=7, train_ids=(40001,), actor="d1")])
    assert 40001 not in sim.records


def _unconcerned_train(ground: DemoGround, concerned: set[int]) -> int:
    return next(t for t in ground.train_ids() if t not in concerned)


def test_the_demo_ground_sends_a_tsr_to_the_trains_it_names() -> None:
    # The core: a TSR's ``trains`` get it whatever the ground's view of their routes.
    probe = DemoGround(8, seed=3)
    concerned = {
        d["train"] for d in probe.set_tsr(TSR_FORM, "d1", probe.now_s())["ok"]["deliveries"]
    }
    named = _unconcerned_train(probe, concerned)
    ground = DemoGround(8, seed=3)
    result = ground.set_tsr({**TSR_FORM, "trains": str(named)}, "d1", ground.now_s())
    assert "ok" in result, result
    assert named in {d["train"] for d in result["ok"]["deliveries"]}


def test_the_demo_ground_takes_a_restriction_id_again_for_the_same_restriction() -> None:
    # The core: declaring the same restriction under the same id again is a repeat (a
    # dispatcher's resubmitted form), not a conflict.
    ground = DemoGround(8, seed=3)
    form = {"reason": "section_fault", "start_km": "200", "end_km": "202", "id": "9"}
    first = ground.set_restriction(form, "d1", ground.now_s())
    assert "ok" in first, first
    again = ground.set_restriction(form, "d1", ground.now_s())
    assert "ok" in again, again
    assert again["ok"]["id"] == first["ok"]["id"] == 9


def test_the_demo_ground_sends_all_only_to_the_trains_that_have_registered() -> None:
    # The core: a dispatch command for "all" goes to every train that has registered with
    # the ground, never to a train it has not heard of (the page would show a delivery
    # pending for ever to a train that cannot answer).
    ground = DemoGround(6, seed=3, off_radio=(1002,))
    registered = {t["id"] for t in ground.snapshot(ground.now_s())["trains"] if t["registered"]}
    assert 1002 not in registered and registered  # the train off the radio never registered
    result = ground.send_dispatch({"trains": "all", "text": "hold"}, "d1", ground.now_s())
    assert "ok" in result, result
    assert set(result["ok"]["trains"]) == registered
