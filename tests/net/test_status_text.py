"""``railpilot ground status`` as text (net/status_text.py): one line for the ground, one per
train with its deliveries under it, then the dispatch core's TSRs, restrictions and targets."""

from __future__ import annotations

from typing import Any

from railpilot.net.status_text import status_lines

NOW_S = 1_700_000_000.0


def status(**dispatch: Any) -> dict[str, Any]:
    return {
        "ground_id": 3,
        "host": "127.0.0.1",
        "port": 7400,
        "connections": 1,
        "registered": 1,
        "trains": [
            {
                "train_id": 1001,
                "train_number": "K1",
                "connected": True,
                "state": "OPEN",
                "registered": True,
                "running_info": {
                    "position_km": 12.5,
                    "speed_kmh": 60.0,
                    "direction": "up",
                    "age_s": 0.5,
                    "valid": False,
                },
                "tsrs": {"7": "acknowledged"},
                "target_points": {},
                "dispatch_commands": {"2": "pending"},
            },
            {
                "train_id": 1002,
                "train_number": None,
                "connected": False,
                "state": "CLOSED",
                "registered": False,
                "running_info": None,
                "tsrs": {},
                "target_points": {"4": "sent"},
                "dispatch_commands": {},
            },
        ],
        "dispatch": dispatch,
    }


def tsr(session: int, valid_until_s: float) -> dict[str, Any]:
    return {
        "session": session,
        "state": "active",
        "start_km": 10.0,
        "end_km": 11.25,
        "limit_kmh": 45.0,
        "valid_until_s": valid_until_s,
        "reason": "track work",
        "set_by": "ops",
        "trains": [1001],
    }


def test_the_ground_and_each_train_with_its_deliveries() -> None:
    lines = status_lines(status(), NOW_S)
    assert lines[0] == "ground 3 on 127.0.0.1:7400: 1 connections, 1 registered trains"
    assert lines[1].startswith("  train 1001 K1: connected (OPEN), registered, km 12.500 ")
    assert lines[1].endswith("(0.5 s ago, INVALID)")
    assert lines[2:4] == ["    TSR 7: acknowledged", "    dispatch command 2: pending"]
    assert lines[4] == "  train 1002 : not connected, not registered, no running info"
    assert lines[5] == "    target point 4: sent"
    assert len(lines) == 6


def test_a_tsr_shows_the_minutes_left_from_now_or_that_it_expired() -> None:
    dispatch = {"tsrs": [tsr(1, NOW_S + 30 * 60.0), tsr(2, NOW_S - 1.0)]}
    lines = status_lines(status(**dispatch), NOW_S)[6:]
    assert "30 min left" in lines[0] and lines[0].startswith("TSR 1: active, km 10.000-11.250")
    assert "expired" in lines[1] and "min left" not in lines[1]


def test_restrictions_and_only_the_targets_that_have_a_place() -> None:
    dispatch = {
        "restrictions": [
            {"id": "r1", "reason": "section_fault", "block": "down-040"},
            {
                "id": "r2",
                "reason": "lost_switch",
                "block": None,
                "start_km": 5.0,
                "end_km": 6.0,
                "track": "up",
            },
        ],
        "targets": {
            "1001": {"target_id": 9, "km": 40.0, "signal": "S40", "reason": "occupied"},
            "1002": {"target_id": 1, "km": None, "signal": None, "reason": "clear"},
        },
    }
    lines = status_lines(status(**dispatch), NOW_S)[6:]
    assert lines == [
        "restriction r1: section_fault on down-040",
        "restriction r2: lost_switch on km 5.000-6.000 (up)",
        "target point 9 for train 1001: km 40.000 signal S40 (occupied)",
    ]
