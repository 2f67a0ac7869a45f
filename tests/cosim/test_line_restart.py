"""A ground restart mid-run on the whole line: the co-simulated ground keeps its
TSRs, deliveries and audit log in its store as the live ground does
(ground/journal.py), is killed as ``kill -9`` would kill it, and starts again from the
store alone. Nothing is lost and nothing is applied twice: asserted from the store's audit
log, the ground's state and the trains' own state (their onboard endpoints and what the
trackside saw them do).
"""

from __future__ import annotations

import copy
from collections import Counter

import pytest

from railpilot.cosim.line_run import run_line
from railpilot.cosim.scenario import line_scenario_from_mapping
from railpilot.errors import ScenarioError
from railpilot.link import TsrState

from .test_line_run import BASE

# line days with a ground restart
pytestmark = pytest.mark.slow

RESTART = copy.deepcopy(BASE)
RESTART["events"] = [
    # before any train has registered: the TSR concerns no train yet, so only the store's
    # line TSR table remembers it across the restart
    {
        "at_min": 0.0,
        "op": "tsr_set",
        "start_km": 20.0,
        "end_km": 22.0,
        "limit_kmh": 50,
        "valid_until_min": 120,  # beyond the run's end: still in force on board at the end
        "reason": "before any train",
    },
    # the ground is killed right after this TSR left for train 101: its frame is in flight,
    # not acknowledged
    {
        "at_min": 4.0,
        "op": "tsr_set",
        "start_km": 14.0,
        "end_km": 17.0,
        "limit_kmh": 40,
        "valid_until_min": 80,
        "reason": "track work",
    },
    {"at_min": 4.0, "op": "ground_restart", "down_min": 1.0},
    # the restarted ground still knows TSR 2 and can cancel it
    {"at_min": 30.0, "op": "tsr_cancel", "session": 2},
]


@pytest.fixture(scope="module")
def restarted():
    return run_line(line_scenario_from_mapping(RESTART))


def test_the_ground_went_down_with_a_delivery_pending(restarted):
    (restart,) = restarted.restarts
    assert restart["down_at_s"] == 240.0 and restart["up_at_s"] == 300.0
    # what the restarted ground read back: both TSRs, train 101's delivery of TSR 2 still
    # waiting for its acknowledgement, TSR 1 acknowledged
    restored = restart["restored"]
    assert restored["tsrs"] == 2
    assert restored["pending_set"] == 1 and restored["active"] == 1
    restored_at = [e for e in restarted.audit_log if e.action == "restored"]
    assert len(restored_at) == 1 and restored_at[0].at_s == restarted.scenario.epoch_s + 300.0


def test_every_train_applied_each_tsr_exactly_once(restarted):
    # 102 and 103 registered only after the restart: they got TSR 1, which no train had
    # when the ground went down, from the store's line TSR table
    for train_id in (101, 102, 103):
        assert restarted.tsr_applied[train_id] == {1: 1, 2: 1}, train_id
    kpis = restarted.kpis()
    assert kpis["tsr_violations"] == 0, restarted.tsr_violations
    assert kpis["target_points_passed"] == 0, restarted.signals_passed_at_red
    assert kpis["tsr_applied_twice"] == 0


def test_the_audit_log_shows_each_delivery_acknowledged_once_per_train(restarted):
    log = restarted.audit_log
    acks = Counter((e.train_id, e.detail["session"]) for e in log if e.action == "tsr_acknowledged")
    # acknowledged, never refused; 101 acknowledged TSR 2 after the restart, when the
    # ground resent it (its frame was lost with the ground)
    assert {k for k in acks} == {(t, s) for t in (101, 102, 103) for s in (1, 2)}
    assert not [e for e in log if e.action == "tsr_refused_by_train"]
    ack_2_by_101 = [
        e.at_s
        for e in log
        if e.action == "tsr_acknowledged" and e.train_id == 101 and e.detail["session"] == 2
    ]
    assert min(ack_2_by_101) >= restarted.scenario.epoch_s + 300.0
    # the dispatcher set each TSR once; the ground's resends are not new requests
    assert Counter(e.detail["session"] for e in log if e.action == "tsr_set") == {1: 3, 2: 3}


def test_the_restarted_ground_cancelled_the_tsr_it_still_knew(restarted):
    cancel = next(e for e in restarted.events if e["event"] == "tsr_cancel")
    assert cancel["result"]["trains"] == [101, 102, 103]
    store = restarted.ground_store
    assert store is not None
    assert store.tsrs[2].cancelled_at_s == restarted.scenario.epoch_s + 1800.0
    assert store.tsrs[1].cancelled_at_s is None
    for train_id in (101, 102, 103):
        held = store.trains[train_id].tsrs
        assert held[2] is TsrState.CANCELLED
        # a train that registers again (to say it leaves the line) is asked to reconfirm
        # what it holds and may leave before it has: RECONFIRMING, still held on board
        assert held[1] in (TsrState.ACTIVE, TsrState.RECONFIRMING)
        cancelled = [
            e
            for e in restarted.audit_log
            if e.action == "tsr_cancel_acknowledged" and e.train_id == train_id
        ]
        assert [e.detail["session"] for e in cancelled] == [2]


def test_the_trains_still_hold_what_the_ground_says_they_hold(restarted):
    # the trains' own state, at the end of the run: TSR 1 in force on board, TSR 2 gone
    for train_id in (101, 102, 103):
        onboard = restarted.onboard_tsrs[train_id]
        assert set(onboard) == {1}, (train_id, onboard)


def test_a_restart_needs_a_store_and_a_running_ground():
    mapping = copy.deepcopy(RESTART)
    mapping["events"] = [{"at_min": 1.0, "op": "ground_restart", "down_min": -1.0}]
    with pytest.raises(ScenarioError, match=r"events\[0\]\.down_min"):
        line_scenario_from_mapping(mapping)
    mapping["events"] = [{"at_min": 1.0, "op": "ground_restart", "down_minutes": 1.0}]
    with pytest.raises(ScenarioError, match="down_minutes"):
        line_scenario_from_mapping(mapping)
