"""The smallest line run the KPI tests use: one loaded train from station 1 to 2 in half an
hour, a lossy radio (10 %)."""

TINY = {
    "name": "tiny",
    "line": "heavy-haul",
    "seed": 5,
    "duration_h": 0.5,
    "channel": {"loss": 0.1},
    "services": [
        {"kind": "loaded", "from": 1, "to": 2, "first_departure_min": 1.0, "first_id": 101}
    ],
}
