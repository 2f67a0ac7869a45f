"""The ground server's admin API (line-delimited JSON on 127.0.0.1)."""

from __future__ import annotations

import time

import pytest

from railpilot.line.loader import load_line
from railpilot.link import DeregisterReason, TrainDeregistered, TsrApplied, TsrCancelled
from railpilot.net.admin import AdminError, AdminServer, admin_request
from railpilot.net.dispatch_host import DispatchHost
from railpilot.net.server import GroundServer

from .helpers import LENGTH_M, TRAIN_ID, rig, run, until

LINE = load_line("heavy-haul")


def admin_of(server: GroundServer) -> AdminServer:
    """The admin port over the ground's dispatch on the heavy-haul line (as ground serve)."""
    host = DispatchHost(server, LINE)
    host.start()
    return AdminServer(host)


def test_status_lists_the_registered_train_with_its_running_info() -> None:
    async def scenario() -> None:
        async with rig() as r:
            admin = admin_of(r.server)
            _, port = await admin.start()
            await until(lambda: bool(r.running_infos()))
            answer = await admin_request({"op": "status"}, port=port)
            await admin.stop()
            assert answer["ok"]
            (train,) = answer["result"]["trains"]
            assert train["train_id"] == TRAIN_ID and train["registered"]
            assert train["connected"] and train["state"] == "REGISTERED"
            assert train["running_info"]["speed_kmh"] == pytest.approx(54.0)

    run(scenario())


def test_status_shows_a_deregistered_train_still_connected() -> None:
    async def scenario() -> None:
        async with rig() as r:
            admin = admin_of(r.server)
            _, port = await admin.start()
            await until(lambda: bool(r.running_infos()))
            (client,) = r.clients
            now = time.time()
            client.endpoint.deregister(DeregisterReason.SHUNTING_MODE, now)
            client._after(now)
            await until(lambda: bool(r.ground_of(TrainDeregistered)))
            (train,) = (await admin_request({"op": "status"}, port=port))["result"]["trains"]
            # protocol.md 8.2: the connection stays up (heartbeats) while deregistered
            assert train["connected"] is True and train["state"] == "DEREGISTERED"
            assert train["registered"] is False
            # a delivery now waits in the record until the train registers again
            request = {"op": "dispatch", "trains": [TRAIN_ID], "command": 9, "text": "x"}
            answer = await admin_request(request, port=port)
            queued = {str(TRAIN_ID): "queued until the train registers"}
            assert answer["result"] == {"command": 9, "trains": [TRAIN_ID], "deliveries": queued}
            client.drop_connection()
            await until(lambda: not r.server.open_connections())
            status = (await admin_request({"op": "status"}, port=port))["result"]
            (train,) = status["trains"]
            assert train["connected"] is False and train["state"] is None
            await admin.stop()

    run(scenario())


def test_tsr_set_and_cancel_through_the_admin_api_reach_the_train() -> None:
    async def scenario() -> None:
        async with rig() as r:
            admin = admin_of(r.server)
            _, port = await admin.start()
            await until(lambda: bool(r.running_infos()))
            # the train runs up from km 4: the ground finds it concerned by km 5-6
            request = {
                "op": "tsr_set",
                "session": 5,
                "start_km": 5.0,
                "end_km": 6.0,
                "limit_kmh": 40,
                "valid_until_min": 10,
                "reason": "track work",
            }
            answer = await admin_request(request, port=port)
            # the ground pins "10 minutes from now" on its own clock and says when
            result = answer["result"]
            valid_from, valid_until = result.pop("valid_from_s"), result.pop("valid_until_s")
            assert valid_until - valid_from == pytest.approx(10 * 60.0)
            assert answer == {
                "ok": True,
                "result": {
                    "session": 5,
                    "trains": [TRAIN_ID],
                    "deliveries": {str(TRAIN_ID): "sending"},
                },
            }
            await until(lambda: bool(r.onboard_of(TRAIN_ID, TsrApplied)))
            applied = r.onboard_of(TRAIN_ID, TsrApplied)[0].tsr
            assert applied.zone_end_m == 6_000.0 + LENGTH_M
            cancel = {"op": "tsr_cancel", "session": 5}
            assert (await admin_request(cancel, port=port))["ok"]
            await until(lambda: bool(r.onboard_of(TRAIN_ID, TsrCancelled)))
            await admin.stop()

    run(scenario())


TSR = {"start_km": 1, "end_km": 2, "limit_kmh": 40, "valid_until_min": 1, "reason": "works"}


@pytest.mark.parametrize(
    ("request_", "needle"),
    [
        ({"op": "reboot"}, "op: 'reboot' is not allowed"),
        ({"op": ["tsr_set"]}, "op: ['tsr_set'] is not allowed"),  # it crashed the request
        ({"op": {"tsr_set": 1}}, "op: {'tsr_set': 1} is not allowed"),
        ({"op": "tsr_cancel", "session": 0}, "session: 0 is not allowed"),
        ({"op": "tsr_cancel", "session": 1, "trains": [TRAIN_ID]}, "'trains' is not a field"),
        ({"op": "tsr_set", **TSR, "limit_kmh": 999}, "limit_kmh: 999 is not allowed"),
        ({"op": "tsr_set", **TSR, "valid_s": 60}, "'valid_s' is not a field of tsr_set"),
        ({"op": "target", "trains": [TRAIN_ID], "km": 3, "reason": "x"}, "reason: 'x'"),
        (
            {"op": "tsr_set", **TSR, "start_km": 120.5, "end_km": 120.500001},
            "end_km: 120.500001 is not allowed: expected a km post at least 1 cm above",
        ),
        (
            {"op": "tsr_set", **TSR, "trains": [TRAIN_ID, 4242]},
            "trains: [4242] is not allowed: expected train ids that have a key",
        ),
        ({"op": "dispatch", "trains": [4242], "text": "x"}, "trains: [4242] is not allowed"),
        ({"op": "status", "actor": ""}, "actor: '' is not allowed"),
    ],
)
def test_bad_requests_get_an_error_naming_the_field(request_: dict, needle: str) -> None:
    async def scenario() -> dict:
        async with rig(start=False) as r:
            admin = admin_of(r.server)
            _, port = await admin.start()
            answer = await admin_request(request_, port=port)
            await admin.stop()
            return answer

    answer = run(scenario())
    assert answer["ok"] is False and needle in answer["error"]
    field = needle.split(":")[0]
    if not field.startswith("'"):
        assert field in answer["errors"]  # the page and the CLI show it next to the field


def test_a_refused_request_delivers_to_no_train_and_invents_none() -> None:
    async def scenario() -> None:
        async with rig(start=False) as r:
            admin = admin_of(r.server)
            _, port = await admin.start()
            request = {"op": "tsr_set", **TSR, "trains": [TRAIN_ID, 4242]}
            assert (await admin_request(request, port=port))["ok"] is False
            assert r.server.records == {}  # not even the train that has a key got it
            await admin.stop()

    run(scenario())


def test_admin_refuses_a_non_loopback_address() -> None:
    async def scenario() -> None:
        async with rig(start=False) as r:
            with pytest.raises(AdminError, match="loopback"):
                AdminServer(DispatchHost(r.server, LINE), host="0.0.0.0")

    run(scenario())
