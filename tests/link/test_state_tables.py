"""The transition tables themselves, without bytes: completeness and strictness."""

from __future__ import annotations

import pytest

from railpilot.link import LocalProtocolError, StateError
from railpilot.link.endpoint import transition
from railpilot.link.ground import (
    DELIVERY_TRANSITIONS,
    TSR_TRANSITIONS,
    DeliveryInput,
    DeliveryState,
    GroundInput,
    GroundState,
    TsrInput,
    TsrState,
)
from railpilot.link.ground import (
    TRANSITIONS as GROUND_TRANSITIONS,
)
from railpilot.link.onboard import TRANSITIONS as ONBOARD_TRANSITIONS
from railpilot.link.onboard import OnboardInput, OnboardState


def reachable(table: dict, start: object) -> set:  # type: ignore[type-arg]
    seen = {start}
    frontier = [start]
    while frontier:
        state = frontier.pop()
        for (src, _), dst in table.items():
            if src == state and dst not in seen:
                seen.add(dst)
                frontier.append(dst)
    return seen


def test_every_onboard_state_is_reachable_from_disconnected() -> None:
    assert reachable(dict(ONBOARD_TRANSITIONS), OnboardState.DISCONNECTED) == set(OnboardState)


def test_every_ground_state_is_reachable_from_awaiting_registration() -> None:
    assert reachable(dict(GROUND_TRANSITIONS), GroundState.AWAITING_REGISTRATION) == set(
        GroundState
    )


def test_every_tsr_state_is_reachable_from_pending_set() -> None:
    assert reachable(dict(TSR_TRANSITIONS), TsrState.PENDING_SET) == set(TsrState)


@pytest.mark.parametrize("state", [s for s in OnboardState if s is not OnboardState.DISCONNECTED])
def test_onboard_connection_loss_is_handled_in_every_connected_state(state: OnboardState) -> None:
    assert ONBOARD_TRANSITIONS[(state, OnboardInput.CONNECTION_LOST)] is OnboardState.DISCONNECTED


@pytest.mark.parametrize("state", [s for s in GroundState if s is not GroundState.CLOSED])
def test_ground_connection_loss_is_handled_in_every_open_state(state: GroundState) -> None:
    assert GROUND_TRANSITIONS[(state, GroundInput.CONNECTION_LOST)] is GroundState.CLOSED


def test_closed_ground_endpoint_has_no_way_out() -> None:
    assert not [key for key in GROUND_TRANSITIONS if key[0] is GroundState.CLOSED]


def test_failed_onboard_accepts_no_received_message() -> None:
    received = {i for i in OnboardInput if i.name.startswith("RECV_")}
    assert not [k for k in ONBOARD_TRANSITIONS if k[0] is OnboardState.FAILED and k[1] in received]


def test_missing_transition_caused_by_the_peer_is_a_state_error() -> None:
    with pytest.raises(StateError, match="RECV_DISPATCH"):
        transition(
            ONBOARD_TRANSITIONS, OnboardState.REGISTERING, OnboardInput.RECV_DISPATCH, remote=True
        )


def test_missing_transition_caused_locally_is_a_local_protocol_error() -> None:
    with pytest.raises(LocalProtocolError, match="SEND"):
        transition(ONBOARD_TRANSITIONS, OnboardState.REGISTERING, OnboardInput.SEND, remote=False)


def test_tsr_acknowledgement_moves_pending_set_to_active() -> None:
    assert TSR_TRANSITIONS[(TsrState.PENDING_SET, TsrInput.ACK_APPLIED)] is TsrState.ACTIVE


def test_reregistration_asks_for_active_tsrs_to_be_confirmed_again() -> None:
    assert TSR_TRANSITIONS[(TsrState.ACTIVE, TsrInput.REREGISTERED)] is TsrState.RECONFIRMING


@pytest.mark.parametrize("state", [TsrState.CANCELLED, TsrState.REFUSED, TsrState.EXPIRED])
def test_final_tsr_states_tolerate_late_acknowledgements(state: TsrState) -> None:
    for late in (TsrInput.ACK_APPLIED, TsrInput.ACK_REFUSED, TsrInput.CANCEL_ACK):
        assert TSR_TRANSITIONS[(state, late)] is state


def test_cancelling_a_cancelled_tsr_is_refused_locally() -> None:
    with pytest.raises(LocalProtocolError):
        transition(TSR_TRANSITIONS, TsrState.CANCELLED, TsrInput.CANCEL_REQUESTED, remote=False)


def test_tsr_table_covers_every_remote_input_in_every_state() -> None:
    remote = (TsrInput.ACK_APPLIED, TsrInput.ACK_REFUSED)
    timers = (TsrInput.REREGISTERED, TsrInput.VALIDITY_ENDED)
    for state in TsrState:
        for trigger in (*remote, *timers):
            assert (state, trigger) in TSR_TRANSITIONS, (state, trigger)


def test_delivery_table_is_complete() -> None:
    assert {(s, i) for s in DeliveryState for i in DeliveryInput} == set(DELIVERY_TRANSITIONS)
