"""The ground server's admin API (line-delimited JSON on 127.0.0.1)."""

from __future__ import annotations

import pytest

from railpilot.link import TsrApplied, TsrCancelled
from railpilot.net.admin import AdminError, AdminServer, admin_request

from .helpers import LENGTH_M, TRAIN_ID, rig, run, until


def test_status_lists_the_registered_train_with_its_running_info() -> None:
    async def scenario() -> None:
        async with rig() as r:
            admin = AdminServer(r.server)
            _, port = await admin.start()
            await until(lambda: bool(r.running_infos()))
            answer = await admin_request({"op": "status"}, port=port)
            await admin.stop()
            assert answer["ok"]
            (train,) = answer["result"]["trains"]
            assert train["train_id"] == TRAIN_ID and train["registered"]
            assert train["running_info"]["speed_kmh"] == pytest.approx(54.0)

    run(scenario())


def test_tsr_set_and_cancel_through_the_admin_api_reach_the_train() -> None:
    async def scenario() -> None:
        async with rig() as r:
            admin = AdminServer(r.server)
            _, port = await admin.start()
            await until(lambda: bool(r.running_infos()))
            request = {
                "op": "tsr_set",
                "trains": "all",
                "session": 5,
                "start_km": 5.0,
                "end_km": 6.0,
                "limit_kmh": 40,
                "valid_s": 600,
            }
            answer = await admin_request(request, port=port)
            assert answer == {"ok": True, "result": {"trains": {str(TRAIN_ID): "sending"}}}
            await until(lambda: bool(r.onboard_of(TRAIN_ID, TsrApplied)))
            applied = r.onboard_of(TRAIN_ID, TsrApplied)[0].tsr
            assert applied.zone_end_m == 6_000.0 + LENGTH_M
            cancel = {"op": "tsr_cancel", "trains": [TRAIN_ID], "session": 5}
            assert (await admin_request(cancel, port=port))["ok"]
            await until(lambda: bool(r.onboard_of(TRAIN_ID, TsrCancelled)))
            await admin.stop()

    run(scenario())


@pytest.mark.parametrize(
    ("request_", "needle"),
    [
        ({"op": "reboot"}, "op = 'reboot' is not allowed"),
        ({"op": "tsr_cancel", "trains": [TRAIN_ID], "session": 0}, "session = 0"),
        ({"op": "tsr_cancel", "trains": "some", "session": 1}, "trains = 'some'"),
        (
            {
                "op": "tsr_set",
                "trains": [TRAIN_ID],
                "session": 1,
                "start_km": 1,
                "end_km": 2,
                "limit_kmh": 999,
                "valid_s": 60,
            },
            "limit_kmh = 999",
        ),
        ({"op": "target", "trains": [TRAIN_ID], "target_id": 1, "km": 3, "reason": "x"}, "reason"),
    ],
)
def test_bad_requests_get_an_error_naming_the_field(request_: dict, needle: str) -> None:
    async def scenario() -> dict:
        async with rig(start=False) as r:
            admin = AdminServer(r.server)
            _, port = await admin.start()
            answer = await admin_request(request_, port=port)
            await admin.stop()
            return answer

    answer = run(scenario())
    assert answer["ok"] is False and needle in answer["error"]


def test_admin_refuses_a_non_loopback_address() -> None:
    async def scenario() -> None:
        async with rig(start=False) as r:
            with pytest.raises(AdminError, match="loopback"):
                AdminServer(r.server, host="0.0.0.0")

    run(scenario())
