"""What keeps the dashboard cheap for the ground's event loop at a thousand trains
(docs/scaling.md), each checked against the slow, obvious way: the MRSP read at one point,
the JSON encoded a slice at a time, and the record of every push."""

from __future__ import annotations

import asyncio
import json
import math
import random
from collections.abc import Iterator

import pytest
from starlette.testclient import TestClient

from railpilot.cosim.demo_ground import DemoGround
from railpilot.errors import ConfigError
from railpilot.line.loader import load_line
from railpilot.line.model import DOWN, UP
from railpilot.link.events import AppliedTsr
from railpilot.link.messages import TravelDirection, TsrSet
from railpilot.web import view
from railpilot.web.app import Push, _dumps, create_app, dumps_sliced

from .conftest import TOKEN

LENGTH_M = 2600.0


def _tsrs(rng: random.Random, edges: list[float], travel: TravelDirection) -> list[AppliedTsr]:
    tsrs = []
    for session in range(1, rng.randint(0, 3) + 1):
        start = rng.choice(edges) if rng.random() < 0.3 else rng.uniform(0.0, 590_000.0)
        tsr = TsrSet(
            session,
            start,
            start + rng.uniform(1.0, 5000.0),
            rng.uniform(5.0, 30.0),
            rng.choice([0.0, 100.0, 200.0]),
            rng.choice([150.0, 300.0]),
        )
        tsrs.append(AppliedTsr.of(tsr, LENGTH_M, travel))
    return tsrs


@pytest.mark.parametrize("travel", [UP, DOWN])
def test_mrsp_at_a_point_is_the_full_profiles(travel: TravelDirection) -> None:
    line = load_line("heavy-haul")
    category = line.categories[0] if travel is UP else line.categories[-1]
    static = view.static_profile(line, category, travel)
    edges = static.edges_m.tolist()
    rng = random.Random(7)
    for _ in range(2000):
        tsrs = _tsrs(rng, edges, travel)
        zone_ends = [x for t in tsrs for x in (t.zone_start_m, t.zone_end_m)] or [0.0]
        # inside, outside, exactly at a static edge, exactly at a TSR zone's end
        head = rng.choice(
            [rng.uniform(-100.0, 591_000.0), rng.choice(edges), rng.choice(zone_ends)]
        )
        # before, during, at the start and at the (exclusive) end of the TSRs' validity
        now = rng.choice([50.0, 100.0, 150.0, 200.0, 300.0])
        fast = view.mrsp_at(static, tsrs, travel, head, now)
        full = view.mrsp_at_full(static, tsrs, travel, head, now)
        assert fast == full, (head, now, tsrs)


def test_mrsp_at_refuses_what_the_full_profile_refuses() -> None:
    static = view.static_profile(load_line("heavy-haul"), "freight_loaded", UP)
    with pytest.raises(ConfigError, match="direction"):
        view.mrsp_at(static, [], TravelDirection.UNKNOWN, 1000.0, 0.0)
    with pytest.raises(ConfigError, match="position_m"):
        view.mrsp_at(static, [], UP, math.nan, 0.0)


@pytest.mark.parametrize(
    "obj",
    [
        {},
        [],
        {"a": list(range(250)), "b": {"c": [{"x": i} for i in range(301)], "d": []}},
        {"n": 1, "s": "t\u00e9xt \u25b6", "none": None, "f": 0.1, "t": True},
        {7: "int keys are encoded whole"},
        [[1, 2]] * 101,
    ],
)
def test_sliced_json_is_the_same_text(obj: object) -> None:
    text, spent = asyncio.run(dumps_sliced(obj, slice_items=100))
    assert text == _dumps(obj)
    assert spent >= 0.0


def test_sliced_json_of_a_snapshot_is_the_same_text(ground: DemoGround) -> None:
    # 24 trains: every list of the snapshot is cut into several slices of 7
    snapshot = ground.snapshot(ground.now_s())
    assert len(snapshot["trains"]) > 3 * 7
    text, _ = asyncio.run(dumps_sliced(snapshot, slice_items=7))
    assert text == _dumps(snapshot)
    assert json.loads(text)["version"] == snapshot["version"]


def test_sliced_json_refuses_nan_as_the_page_would() -> None:
    with pytest.raises(ValueError):
        asyncio.run(dumps_sliced({"trains": [{"km": 1.0}] * 150 + [{"km": math.nan}]}))


@pytest.fixture
def client(ground: DemoGround) -> Iterator[TestClient]:
    app = create_app(ground, token=TOKEN, allowed_hosts=["testserver"])
    with TestClient(app) as c:
        yield c


def test_every_push_is_recorded_with_its_cost_and_size(client: TestClient) -> None:
    with client.websocket_connect("/ws") as ws:
        text = ws.receive_text()
    pushes = list(client.app.state.pushes)  # type: ignore[attr-defined]
    assert pushes and all(isinstance(p, Push) for p in pushes)
    first = pushes[0]
    assert first.size_bytes == len(text)
    assert first.build_s >= 0.0 and first.encode_s >= 0.0


def test_the_pages_first_fetch_is_the_shared_snapshot_the_pushes_send(
    client: TestClient,
) -> None:
    """``GET /api/snapshot`` goes through the shared snapshot (built and encoded a slice at
    a time, recorded as a push), not a whole snapshot built in one go in the ground's
    loop."""
    fetched = client.get("/api/snapshot")
    assert fetched.status_code == 200
    assert fetched.headers["content-type"].startswith("application/json")
    pushes = list(client.app.state.pushes)  # type: ignore[attr-defined]
    assert len(pushes) == 1 and pushes[0].size_bytes == len(fetched.text)
    with client.websocket_connect("/ws") as ws:
        pushed = ws.receive_text()
    assert json.loads(pushed)["version"] == fetched.json()["version"]
