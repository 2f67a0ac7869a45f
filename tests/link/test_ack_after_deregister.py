"""An acknowledgement that crossed the train's DEREGISTER_REQUEST still closes its delivery."""

from __future__ import annotations

from railpilot.link import DeregisterReason, TsrAcknowledged, TsrSet
from railpilot.link.ground import GroundState, TsrState

from .helpers import T0, TRAIN_ID, registered_link


def test_tsr_ack_arriving_after_the_deregistration_is_accepted() -> None:
    link = registered_link()
    now = link.now_s
    link.ground.set_tsr(TsrSet(1, 500.0, 900.0, 10.0, T0, T0 + 3600.0), now)
    tsr_set = link.ground.data_to_send()  # in flight towards the train ...
    link.onboard.deregister(DeregisterReason.SHUNTING_MODE, now)
    deregister = link.onboard.data_to_send()  # ... while the train says goodbye
    link.onboard.receive_data(tsr_set, now)  # the train applies it and acknowledges
    ack = link.onboard.data_to_send()
    link.ground.receive_data(deregister + ack, now + 0.01)
    events = list(link.ground.events())
    assert link.ground.state is GroundState.DEREGISTERED
    assert TsrAcknowledged(TRAIN_ID, 1) in events
    assert link.records[TRAIN_ID].tsrs[1].state is TsrState.ACTIVE
