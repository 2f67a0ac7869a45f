"""The demo ground: the real ground host over the simulated radio, with scripted trains."""

from __future__ import annotations

import copy
import json

import pytest

from railpilot.cosim.demo_ground import MIN_WARMUP_S, DemoGround
from railpilot.errors import ConfigError
from railpilot.link.ground import TsrState
from railpilot.web.source import DashboardSource

from .conftest import TSR_FORM


def test_it_is_a_dashboard_source(ground: DemoGround) -> None:
    assert isinstance(ground, DashboardSource)


def test_the_same_seed_gives_the_same_line() -> None:
    a, b = (DemoGround(10, seed=4, warmup_s=MIN_WARMUP_S) for _ in range(2))
    a.advance(30.0)
    b.advance(30.0)
    assert json.dumps(a.snapshot(a.now_s())) == json.dumps(b.snapshot(b.now_s()))


def test_time_moves_only_when_advanced(ground: DemoGround) -> None:
    start, version = ground.now_s(), ground.version()
    assert ground.snapshot(start)["now_s"] == start
    ground.advance(2.5)
    assert (ground.now_s(), ground.version()) == (start + 2.5, version + 1)
    with pytest.raises(ConfigError, match="dt_s"):
        ground.advance(-1.0)


def test_the_demo_line_has_its_incidents(ground: DemoGround) -> None:
    snap = ground.snapshot(ground.now_s())
    alarms = {(a["kind"], a["train"]) for a in snap["alarms"]}
    assert alarms == {("overspeed", ground.overspeeding), ("link", ground.link_lost)}
    # the ground's own target points: the faulted train stands before the section fault
    # (every other train's target, if any, is the red signal behind the train ahead)
    held = {t["id"]: (t["target"]["reason"], t["speed_kmh"]) for t in snap["trains"] if t["target"]}
    assert held.pop(ground.faulted) == ("SECTION_FAULT", 0.0)
    assert {reason for reason, _ in held.values()} <= {"TRAIN_AHEAD"}
    assert [b["state"] for b in snap["blocks"]].count("restricted") == 1
    assert snap["dispatch"][0]["train"] == ground.faulted


def test_a_tsr_goes_pending_then_active_train_by_train(ground: DemoGround) -> None:
    result = ground.set_tsr({**TSR_FORM, "confirm": True}, "d1", ground.now_s())
    session = result["ok"]["session"]
    trains = [d["train"] for d in result["ok"]["deliveries"]]
    assert {ground.delivery_state(session, t) for t in trains} == {TsrState.PENDING_SET}
    seen: list[set[int]] = []
    for _ in range(6):
        ground.advance(1.0)
        seen.append({t for t in trains if ground.delivery_state(session, t) is TsrState.ACTIVE})
    assert seen[0] != seen[-1]  # one after another, as each slow radio answers
    assert seen[-1] == set(trains) - {ground.link_lost}  # the train without a link never answers


def test_an_invalid_form_changes_nothing(ground: DemoGround) -> None:
    version = ground.version()
    result = ground.set_tsr({**TSR_FORM, "limit_kmh": "-3"}, "d1", ground.now_s())
    assert list(result) == ["errors"] and "limit_kmh" in result["errors"]
    assert [t["session"] for t in ground.snapshot(ground.now_s())["tsrs"]] == [1]
    assert ground.version() == version


def test_a_copy_of_a_ground_runs_as_one_built_afresh(ground: DemoGround) -> None:
    """The other tests get copies of one warmed-up ground (conftest.py): a copy, advanced,
    shows what a ground built afresh shows, and the one it was copied from is untouched."""
    copied = copy.deepcopy(ground)
    fresh = DemoGround(24, seed=0, warmup_s=MIN_WARMUP_S)
    before = json.dumps(ground.snapshot(ground.now_s()), sort_keys=True, default=str)
    for each in (copied, fresh):
        each.advance(60.0)
    snapshots = [
        json.dumps(g.snapshot(g.now_s()), sort_keys=True, default=str) for g in (copied, fresh)
    ]
    assert snapshots[0] == snapshots[1]
    assert json.dumps(ground.snapshot(ground.now_s()), sort_keys=True, default=str) == before
