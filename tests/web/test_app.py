"""The dashboard's HTTP and WebSocket routes over the demo ground (Starlette's TestClient)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from typing import Any

import pytest
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from railpilot.cosim.demo_ground import DemoGround
from railpilot.errors import ConfigError
from railpilot.link.ground import TsrState
from railpilot.web.app import STATIC, create_app

from .conftest import DISPATCH_FORM, STARTING, TOKEN, TSR_FORM, StartingGround

AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def client(ground: DemoGround) -> Iterator[TestClient]:
    app = create_app(ground, token=TOKEN, allowed_hosts=["testserver"])
    with TestClient(app) as c:
        yield c


def _errors(response: Any) -> dict[str, str]:
    assert response.status_code == 422, response.text
    errors = response.json()["errors"]
    assert isinstance(errors, dict)
    return errors


def _refused_and_unchanged(
    client: TestClient, route: str, form: dict[str, str], part: str
) -> dict[str, str]:
    """POST ``form`` to ``route``: its errors (a 422), the snapshot's ``part`` unchanged."""
    before = client.get("/api/snapshot").json()[part]
    errors = _errors(client.post(route, json=form, headers=AUTH))
    assert client.get("/api/snapshot").json()[part] == before
    return errors


# --- the page


def test_page_and_its_files_are_served_locally(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    assert "text/html" in page.headers["content-type"]
    for name in ("dashboard.js", "dashboard.css"):
        assert f"/static/{name}" in page.text
        assert client.get(f"/static/{name}").status_code == 200


def test_the_page_loads_nothing_from_elsewhere() -> None:
    # No CDN, no fonts, no build step: every URL in the page's files is local.
    for path in STATIC.iterdir():
        text = path.read_text()
        assert not re.search(r"(src|href)\s*=\s*[\"']?(https?:)?//", text), path.name
        assert "import " not in text or path.suffix != ".js", path.name


# --- the snapshot


def test_snapshot_has_every_part_in_the_dispatchers_units(client: TestClient) -> None:
    response = client.get("/api/snapshot")
    assert response.status_code == 200
    snap = response.json()
    assert set(snap) == {
        "now_s", "version", "line", "blocks", "trains", "tsrs", "restrictions", "dispatch",
        "graph", "alarms",
    }  # fmt: skip
    line = snap["line"]
    assert (line["name"], line["start_km"], line["end_km"]) == ("heavy-haul", 0.0, 590.0)
    assert len(line["stations"]) == 20
    assert {s["aspect"] for s in line["signals"]} == {"red", "green"}
    assert len(snap["trains"]) == 24
    train = snap["trains"][0]
    assert {"id", "number", "km", "speed_kmh", "direction", "valid", "mrsp_kmh", "link"} <= set(
        train
    )
    assert set(train["link"]) == {"connected", "timeouts", "failures", "rejections"}
    assert {t["direction"] for t in snap["trains"]} == {"up", "down"}
    assert {a["kind"] for a in snap["alarms"]} == {"link", "overspeed"}
    assert [t["session"] for t in snap["tsrs"]] == [1]
    # the demo's section fault: one block, whose blocks are the restricted ones
    (fault,) = snap["restrictions"]
    assert fault["reason"] == "section_fault" and fault["blocks"] == [fault["block"]]
    restricted = [b for b in snap["blocks"] if b["state"] == "restricted"]
    assert [b["id"] for b in restricted] == fault["blocks"]
    assert (fault["start_km"], fault["end_km"]) == (
        restricted[0]["start_km"],
        restricted[0]["end_km"],
    )
    assert len(snap["graph"]["trains"]) == 24
    json.dumps(snap, allow_nan=False)  # strict JSON: the page's JSON.parse reads it


def test_a_red_signal_protects_a_block_that_is_not_free(client: TestClient) -> None:
    snap = client.get("/api/snapshot").json()
    held = {b["id"] for b in snap["blocks"]}
    for signal in snap["line"]["signals"]:
        assert (signal["aspect"] == "red") == (signal["block"] in held), signal


# --- writing needs the token


@pytest.mark.parametrize(
    "headers",
    [{}, {"Authorization": "Bearer wrong-token-wrong-token"}, {"Authorization": TOKEN}],
    ids=["none", "wrong", "not bearer"],
)
def test_writing_without_the_token_is_401(client: TestClient, headers: dict[str, str]) -> None:
    for url, form in (
        ("/api/tsr", TSR_FORM),
        ("/api/tsr/1/cancel", {}),
        ("/api/dispatch", DISPATCH_FORM),
        ("/api/restriction", {"reason": "section_fault", "block": "up-040"}),
        ("/api/restriction/1/clear", {}),
    ):
        response = client.post(url, json=form, headers=headers)
        assert response.status_code == 401
        assert response.headers["www-authenticate"] == "Bearer"
        assert "token" in response.json()["errors"]
    snap = client.get("/api/snapshot").json()
    assert [t["session"] for t in snap["tsrs"]] == [1]
    assert DISPATCH_FORM["text"] not in {row["text"] for row in snap["dispatch"]}


def test_a_short_token_is_refused() -> None:
    with pytest.raises(ConfigError, match="token"):
        create_app(DemoGround(2), token="short")


def test_another_host_name_is_refused(ground: DemoGround) -> None:
    # A page that rebinds its own name to 127.0.0.1 still sends its own Host: refused.
    with TestClient(create_app(ground, token=TOKEN), base_url="http://evil.example") as c:
        assert c.get("/api/snapshot").status_code == 400


# --- the form


def test_bad_values_are_422_with_a_message_per_field(client: TestClient) -> None:
    fields = {**TSR_FORM, "start_km": "abc", "end_km": "700", "reason": " ", "valid_until_min": ""}
    errors = _errors(client.post("/api/tsr", json=fields, headers=AUTH))
    assert set(errors) == {"start_km", "end_km", "reason", "valid_until_min"}
    assert "'abc'" in errors["start_km"] and "number" in errors["start_km"]
    assert errors["end_km"].startswith("700 is not allowed") and "0 to 590" in errors["end_km"]
    assert errors["valid_until_min"].startswith("required")
    assert errors["reason"].startswith("required")


@pytest.mark.parametrize(
    ("change", "field", "says"),
    [
        ({"end_km": "290"}, "end_km", "above start_km = 300"),
        ({"limit_kmh": "0"}, "limit_kmh", "at most 360 km/h"),
        ({"valid_from_min": "30", "valid_until_min": "20"}, "valid_until_min", "valid_from_min"),
        ({"valid_from_min": "-5"}, "valid_from_min", "0 to 43200"),
        ({"colour": "red"}, "colour", "not a field"),
    ],
)
def test_the_rules_of_a_line_tsr_name_the_form_field(
    client: TestClient, change: dict[str, str], field: str, says: str
) -> None:
    errors = _errors(client.post("/api/tsr", json={**TSR_FORM, **change}, headers=AUTH))
    assert list(errors) == [field]
    assert says in errors[field]


def test_a_body_that_is_not_a_json_object_is_refused(client: TestClient) -> None:
    assert client.post("/api/tsr", content=b"{", headers=AUTH).status_code == 400
    assert "form" in _errors(client.post("/api/tsr", json=[1, 2], headers=AUTH))


def test_set_then_cancel(client: TestClient, ground: DemoGround) -> None:
    # the demo's trains run at 75 km/h where the 40 km/h TSR would hold: asked first
    warned = client.post("/api/tsr", json=TSR_FORM, headers=AUTH)
    assert warned.status_code == 422 and "confirm" in warned.json()["errors"]
    assert warned.json()["warning"]["trains"]
    assert [t["session"] for t in client.get("/api/snapshot").json()["tsrs"]] == [1]
    response = client.post("/api/tsr", json={**TSR_FORM, "confirm": True}, headers=AUTH)
    assert response.status_code == 200, response.text
    tsr = response.json()["ok"]
    assert (tsr["session"], tsr["start_km"], tsr["end_km"], tsr["limit_kmh"]) == (2, 300, 330, 40)
    assert tsr["set_by"] == "dispatcher"
    assert tsr["valid_until_s"] - tsr["valid_from_s"] == 90 * 60
    trains = [d["train"] for d in tsr["deliveries"]]
    assert len(trains) >= 3
    assert {d["state"] for d in tsr["deliveries"]} == {"PENDING_SET"}

    ground.advance(10.0)  # every connected train acknowledges within 5 s
    after = next(t for t in client.get("/api/snapshot").json()["tsrs"] if t["session"] == 2)
    states = {d["train"]: d["state"] for d in after["deliveries"]}
    failed = 1016  # the train whose link failed: its delivery waits
    assert states == {t: "PENDING_SET" if t == failed else "ACTIVE" for t in trains}

    cancelled = client.post("/api/tsr/2/cancel", headers=AUTH)
    assert cancelled.status_code == 200, cancelled.text
    assert cancelled.json()["ok"]["state"] == "CANCELLED"
    ground.advance(10.0)
    assert {ground.delivery_state(2, t) for t in trains if t != failed} == {TsrState.CANCELLED}
    assert ground.delivery_state(2, failed) is TsrState.PENDING_CANCEL


def test_cancelling_an_unknown_session_is_422(client: TestClient) -> None:
    assert "session" in _errors(client.post("/api/tsr/9/cancel", headers=AUTH))
    assert "session" in _errors(client.post("/api/tsr/x/cancel", headers=AUTH))


# --- the WebSocket


def test_websocket_pushes_a_snapshot_and_again_when_it_changes(
    client: TestClient, ground: DemoGround
) -> None:
    with client.websocket_connect("/ws") as ws:
        first = ws.receive_json()
        assert first["version"] == ground.version()
        assert len(first["trains"]) == 24
        ground.advance(1.0)
        # The next push may be a periodic one sent before the change was seen; the change
        # comes within a few pushes (one at least every second), counted, not timed.
        versions = []
        while ground.version() not in versions and len(versions) < 3:
            versions.append(ws.receive_json()["version"])
        assert ground.version() in versions


def test_websocket_from_another_origin_is_refused(client: TestClient) -> None:
    with (
        pytest.raises(WebSocketDisconnect) as refused,
        client.websocket_connect("/ws", headers={"origin": "http://evil.example"}),
    ):
        pass
    assert refused.value.code == 1008


# --- a source not ready to be shown (the live ground before its restore)


def test_a_source_that_is_starting_is_503_and_closes_the_websocket(ground: DemoGround) -> None:
    source = StartingGround(ground)
    with TestClient(create_app(source, token=TOKEN, allowed_hosts=["testserver"])) as client:
        assert client.get("/").status_code == 200  # the page, which then waits and retries
        version = ground.version()
        starting = {"errors": {"ground": STARTING}}
        for response in (
            client.get("/api/snapshot"),
            client.post("/api/tsr", json=TSR_FORM, headers=AUTH),
            client.post("/api/tsr/1/cancel", headers=AUTH),
            client.post("/api/dispatch", json=DISPATCH_FORM, headers=AUTH),
            client.post("/api/restriction", json={"reason": "section_fault"}, headers=AUTH),
            client.post("/api/restriction/1/clear", headers=AUTH),
        ):
            assert response.status_code == 503 and response.json() == starting
            assert response.headers["retry-after"] == "1"
        assert ground.version() == version  # no TSR was set
        with client.websocket_connect("/ws") as ws, pytest.raises(WebSocketDisconnect) as closed:
            ws.receive_json()
        assert closed.value.code == 1013 and closed.value.reason == starting["errors"]["ground"]
        source.ready = True
        assert client.get("/api/snapshot").json()["version"] == ground.version()
        with client.websocket_connect("/ws") as ws:
            assert ws.receive_json()["version"] == ground.version()


# --- dispatch commands


def test_a_dispatch_command_goes_to_each_train_named(
    client: TestClient, ground: DemoGround
) -> None:
    before = client.get("/api/snapshot").json()["dispatch"]
    response = client.post("/api/dispatch", json=DISPATCH_FORM, headers=AUTH)
    assert response.status_code == 200, response.text
    number = response.json()["ok"]["command"]
    assert response.json()["ok"]["trains"] == [1001, 1002]
    assert number == max(row["command"] for row in before) + 1
    rows = [r for r in client.get("/api/snapshot").json()["dispatch"] if r["command"] == number]
    assert [(r["train"], r["text"], r["state"]) for r in rows] == [
        (1001, DISPATCH_FORM["text"], "PENDING"),
        (1002, DISPATCH_FORM["text"], "PENDING"),
    ]


def test_a_dispatch_command_to_all_goes_to_every_train(client: TestClient) -> None:
    response = client.post("/api/dispatch", json={"trains": "all", "text": "x"}, headers=AUTH)
    assert response.status_code == 200, response.text
    assert len(response.json()["ok"]["trains"]) == 24


@pytest.mark.parametrize(
    ("form", "field", "says"),
    [
        ({"trains": "", "text": "hold"}, "trains", "a list of train ids"),
        ({"trains": "K101", "text": "hold"}, "trains", "a list of train ids"),
        ({"trains": "9999", "text": "hold"}, "trains", "train ids that have a key"),
        ({"trains": "1001", "text": ""}, "text", "text"),
        ({"trains": "1001", "text": "x" * 1001}, "text", "at most 1000"),
        ({"trains": "1001"}, "text", ""),
        ({"trains": "1001", "text": "hold", "when": "now"}, "when", "not a field of dispatch"),
    ],
)
def test_a_bad_dispatch_command_is_422_naming_the_field_and_sends_nothing(
    client: TestClient, form: dict[str, str], field: str, says: str
) -> None:
    errors = _refused_and_unchanged(client, "/api/dispatch", form, "dispatch")
    assert field in errors and says in errors[field], errors


# --- declared restrictions


def test_a_restriction_on_a_km_span_holds_its_blocks_at_red_until_cleared(
    client: TestClient,
) -> None:
    form = {"reason": "switch_indication_lost", "start_km": "250", "end_km": "251", "track": "up"}
    response = client.post("/api/restriction", json=form, headers=AUTH)
    assert response.status_code == 200, response.text
    declared = response.json()["ok"]
    assert (declared["reason"], declared["block"], declared["track"]) == (
        "switch_indication_lost",
        None,
        "up",
    )
    assert (declared["start_km"], declared["end_km"]) == (250.0, 251.0)
    snap = client.get("/api/snapshot").json()
    up_blocks = {b["id"]: b for b in snap["blocks"] if b["direction"] == "up"}
    # every block it holds is an UP block sharing more than a point with km 250-251
    assert declared["blocks"]
    for block_id in declared["blocks"]:
        block = up_blocks[block_id]
        assert block["state"] == "restricted"
        assert block["start_km"] < 251.0 and block["end_km"] > 250.0
    signals = {s["block"]: s["aspect"] for s in snap["line"]["signals"] if s["block"]}
    assert all(signals[b] == "red" for b in declared["blocks"] if b in signals)
    assert declared["id"] in {r["id"] for r in snap["restrictions"]}

    cleared = client.post(f"/api/restriction/{declared['id']}/clear", headers=AUTH)
    assert cleared.json() == {"ok": {"id": declared["id"]}}
    snap = client.get("/api/snapshot").json()
    assert declared["id"] not in {r["id"] for r in snap["restrictions"]}
    still = {b["id"] for b in snap["blocks"] if b["state"] == "restricted"}
    assert not still & set(declared["blocks"])
    assert "id" in _errors(client.post(f"/api/restriction/{declared['id']}/clear", headers=AUTH))


@pytest.mark.parametrize(
    ("form", "field", "says"),
    [
        ({"reason": "rain", "block": "up-040"}, "reason", "section_fault"),
        ({"reason": "section_fault"}, "block", "either a block section id or start_km"),
        ({"reason": "section_fault", "block": "up-040", "start_km": "1", "end_km": "2"}, "block",
         "not both"),
        ({"reason": "section_fault", "block": "Z9"}, "block", "a block section of line"),
        ({"reason": "section_fault", "start_km": "251", "end_km": "250"}, "end_km", "above"),
        ({"reason": "section_fault", "start_km": "1", "end_km": "2", "track": "left"}, "track",
         "up"),
        ({"reason": "section_fault", "start_km": "x", "end_km": "2"}, "start_km", "'x'"),
        ({"reason": "section_fault", "block": "up-040", "when": "now"}, "when", "not a field"),
    ],
)  # fmt: skip
def test_a_bad_restriction_is_422_naming_the_field_and_changes_nothing(
    client: TestClient, form: dict[str, str], field: str, says: str
) -> None:
    errors = _refused_and_unchanged(client, "/api/restriction", form, "restrictions")
    assert field in errors and says in errors[field], errors


def test_clearing_an_unknown_restriction_is_422(client: TestClient) -> None:
    assert "id" in _errors(client.post("/api/restriction/99/clear", headers=AUTH))
    assert "id" in _errors(client.post("/api/restriction/x/clear", headers=AUTH))
