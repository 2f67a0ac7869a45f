"""Small consists for the tests: a draft gear, a wagon, a lead locomotive, a train."""

from __future__ import annotations

from railpilot.vehicle.consist import Consist, Vehicle
from railpilot.vehicle.coupler import DraftGear
from railpilot.vehicle.traction import hxd1_locomotive

#: a draft gear's fields (an MT-2-like pair)
GEAR_FIELDS: dict[str, object] = {
    "name": "G",
    "slack_m": 0.01,
    "travel_m": 0.166,
    "preload_n": 1e5,
    "force_at_travel_n": 2.27e6,
    "unloading_ratio": 0.2,
    "stop_stiffness_n_per_m": 1e8,
    "damping_n_s_per_m": 1e5,
}
GEAR = DraftGear(**GEAR_FIELDS)  # type: ignore[arg-type]

#: a loaded wagon's fields
WAGON_FIELDS: dict[str, object] = {
    "name": "W-1",
    "kind": "wagon",
    "mass_kg": 100e3,
    "rotating_mass_factor": 0.02,
    "length_m": 12.0,
    "davis_a0": 0.92,
    "davis_a1": 0.0048,
    "davis_a2": 0.000125,
    "service_brake_force_n": 50e3,
    "distributor": "direct-release",
    "draft_gear": GEAR,
}


def wagon(name: str = "W-1", **changes: object) -> Vehicle:
    return Vehicle(**(WAGON_FIELDS | {"name": name} | changes))  # type: ignore[arg-type]


def lead(name: str = "L-1", **changes: object) -> Vehicle:
    loco = hxd1_locomotive()
    fields: dict[str, object] = {
        "name": name,
        "kind": "locomotive",
        "mass_kg": loco.mass_kg,
        "rotating_mass_factor": 0.065,
        "length_m": loco.length_m,
        "davis_a0": 2.25,
        "davis_a1": 0.019,
        "davis_a2": 0.00032,
        "service_brake_force_n": 0.0,
        "distributor": "none",
        "draft_gear": GEAR,
        "locomotive": loco,
    }
    return Vehicle(**(fields | changes))  # type: ignore[arg-type]


def train_of(n_wagons: int, **wagon_changes: object) -> Consist:
    wagons = tuple(wagon(f"W-{k}", **wagon_changes) for k in range(1, n_wagons + 1))
    return Consist("t", (lead(), *wagons))
