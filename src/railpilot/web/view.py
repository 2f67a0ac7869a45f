"""The dashboard's snapshot, part by part, from the ground's own objects (no I/O, no clock).

Each function turns what ``ground/`` and ``line/`` already compute into the JSON-ready
dicts of :mod:`railpilot.web.source` (km posts in km, speeds in km/h, times in s), so
every source produces the same snapshot. Nothing here decides
anything the ground does not: the one rule of its own is the signal aspect the page shows
(:func:`signal_aspects`) and what counts as an alarm (:func:`train_alarms`).
"""

from __future__ import annotations

import bisect
import functools
import itertools
import math
from collections.abc import Iterable, Mapping
from typing import Any

from railpilot.ground.occupancy import Occupancy
from railpilot.ground.registry import TrainState
from railpilot.ground.targets import DeclaredRestriction, Target
from railpilot.ground.tsr_manager import LineTsr, LineTsrState
from railpilot.line.model import RailLine, direction_name
from railpilot.link.events import AppliedTsr
from railpilot.link.ground import DeliveryState, TsrState
from railpilot.link.messages import TargetReason, TravelDirection
from railpilot.onboard.mrsp import SpeedProfile, most_restrictive_profile
from railpilot.units import m_to_km_post, mps_to_kmh

#: Alarm kinds: the link to a train failed or its running info is stale; a train reported
#: a speed above its most restrictive speed profile.
ALARM_LINK = "link"
ALARM_OVERSPEED = "overspeed"


def km(position_m: float) -> float:
    """A km post [m] as km, to the metre."""
    return round(float(m_to_km_post(position_m)), 3)


def kmh(speed_mps: float) -> float:
    """A speed [m/s] as km/h, to 0.1 km/h."""
    return round(float(mps_to_kmh(speed_mps)), 1)


def direction(value: TravelDirection) -> str:
    """``"up"`` / ``"down"`` (``"unknown"`` for a train that has not said)."""
    if value in (TravelDirection.UP, TravelDirection.DOWN):
        return direction_name(value)
    return "unknown"


# ---------------------------------------------------------------------------- the line


def plan_path(
    stops_m: Iterable[float],
    departures_s: Iterable[float],
    arrivals_s: Iterable[float],
    from_s: float,
    to_s: float,
) -> list[list[float]]:
    """A train's plan on the time-distance graph: ``[[t, km], ...]`` through its departure
    from each station's stop and its arrival at the next (``departures_s[j]`` from
    ``stops_m[j]``, ``arrivals_s[j]`` at ``stops_m[j + 1]``, [s] and [m]), straight between
    them as a timetable graph draws it, a dwell level; cut to ``[from_s, to_s]`` [s] with
    the points at the cuts interpolated. Empty when the plan lies outside the window."""
    stops = list(stops_m)
    points: list[tuple[float, float]] = []
    for j, (leave, arrive) in enumerate(zip(departures_s, arrivals_s, strict=True)):
        points += [(float(leave), stops[j]), (float(arrive), stops[j + 1])]
    path: list[list[float]] = []
    for (ta, xa), (tb, xb) in itertools.pairwise(points):
        lo, hi = max(ta, from_s), min(tb, to_s)
        if lo > hi or tb < ta:
            continue
        for t in (lo, hi):
            share = (t - ta) / (tb - ta) if tb > ta else 0.0
            point = [round(t, 1), km(xa + (xb - xa) * share)]
            if not path or path[-1] != point:
                path.append(point)
    return path


def signal_aspects(
    line: RailLine, occupancy: Occupancy, restricted: Mapping[str, TargetReason]
) -> dict[str, str]:
    """Signal id -> ``"red"`` when the block section beyond it (the one it protects) is
    occupied or held by a declaration, else ``"green"``.

    The dashboard's two-aspect picture of the ground's fixed-block rule (ground/targets.py:
    a signal is red when its block is not free); the line's real signalling may show more.
    """
    held = set(occupancy.by_block) | set(restricted)
    aspects = {signal.id: "green" for signal in line.signals}
    for block in line.block_sections:
        if block.entry_signal is not None and block.id in held:
            aspects[block.entry_signal] = "red"
    return aspects


def line_view(line: RailLine, aspects: Mapping[str, str]) -> dict[str, Any]:
    """The line: stations and signals (each with the block it protects and its aspect)."""
    protects = {b.entry_signal: b.id for b in line.block_sections if b.entry_signal is not None}
    return {
        "name": line.name,
        "start_km": km(line.start_m),
        "end_km": km(line.end_m),
        # each station's centre, and its loop (where its stops are)
        "stations": [
            {
                "id": s.id,
                "name": s.name,
                "km": km(s.centre_m),
                "from_km": km(s.loop_start_m),
                "to_km": km(s.loop_end_m),
            }
            for s in line.stations
        ],
        "signals": [
            {
                "id": s.id,
                "km": km(s.position_m),
                "direction": direction(s.direction),
                "kind": s.kind,
                "block": protects.get(s.id),
                "aspect": aspects.get(s.id, "green"),
            }
            for s in line.signals
        ],
    }


def restriction_view(
    ident: int, restriction: DeclaredRestriction, line: RailLine
) -> dict[str, Any]:
    """A declared restriction as the page lists it: its id, reason (the operation's name
    for it), the block or km span it holds at red and on which track."""
    blocks = restriction.blocks(line)
    if restriction.block_id is not None:
        start_m, end_m = blocks[0].start_m, blocks[0].end_m
        track = direction(blocks[0].direction)
    else:
        assert restriction.start_m is not None and restriction.end_m is not None
        start_m, end_m = restriction.start_m, restriction.end_m
        track = "both" if restriction.direction is None else direction(restriction.direction)
    return {
        "id": ident,
        "reason": restriction.reason.name.lower(),
        "block": restriction.block_id,
        "start_km": km(start_m),
        "end_km": km(end_m),
        "track": track,
        "blocks": [b.id for b in blocks],
    }


def blocks_view(
    line: RailLine, occupancy: Occupancy, restricted: Mapping[str, TargetReason]
) -> list[dict[str, Any]]:
    """The block sections that are not free, in line order: occupied (by which trains) or
    restricted (by a declaration, which wins, as in ground/targets.py)."""
    out = []
    for block in sorted(line.block_sections, key=lambda b: (b.start_m, b.direction)):
        trains = occupancy.occupants(block.id)
        reason = restricted.get(block.id)
        if reason is None and not trains:
            continue
        out.append(
            {
                "id": block.id,
                "direction": direction(block.direction),
                "start_km": km(block.start_m),
                "end_km": km(block.end_m),
                "state": "restricted" if reason is not None else "occupied",
                "trains": list(trains),
                "reason": None if reason is None else reason.name,
            }
        )
    return out


# ---------------------------------------------------------------------------- the trains


def static_profile(line: RailLine, category: str, travel: TravelDirection) -> SpeedProfile:
    """The line's static limit for ``category`` going ``travel`` as an MRSP input."""
    return SpeedProfile(*line.static_limit(category, travel))


def mrsp_at(
    static: SpeedProfile,
    applied: Iterable[AppliedTsr],
    travel: TravelDirection,
    head_m: float,
    now_s: float,
) -> float:
    """The train's most restrictive speed [m/s] at its head ``head_m`` [m] at ``now_s``.

    The onboard's own MRSP (onboard/mrsp.py, :func:`most_restrictive_profile`) over the
    static limit and the TSRs the train has confirmed (``applied``, each extended by the
    train's length), read at one point; target points are left out (the page shows them
    apart).

    Notes
    -----
    Read at one point the MRSP is the lowest of: the static limit there (the stricter side
    exactly at an edge, 0 outside the line: :meth:`SpeedProfile.at`) and the limit of
    every TSR in force (:func:`tsr_in_force`) whose closed zone holds the point. This is
    that, without building the whole profile: the snapshot asks it of every train, and
    building 1,000 profiles took ~0.25 s of the ground's event loop per snapshot
    (docs/scaling.md). :func:`mrsp_at_full` is the reference it is tested against. (The
    full profile also refuses two different TSRs under one session; the server's records
    hold one per session.)
    """
    if travel not in (TravelDirection.UP, TravelDirection.DOWN) or not math.isfinite(head_m):
        # what the full profile refuses (UNKNOWN, NaN), refused the same way
        return mrsp_at_full(static, applied, travel, head_m, now_s)
    speed = _static_at(static, head_m)
    for tsr in applied:
        if (
            tsr.valid_from_s <= now_s < tsr.valid_until_s
            and tsr.zone_start_m <= head_m <= tsr.zone_end_m
        ):
            speed = min(speed, tsr.limit_mps)
    return speed


def mrsp_at_full(
    static: SpeedProfile,
    applied: Iterable[AppliedTsr],
    travel: TravelDirection,
    head_m: float,
    now_s: float,
) -> float:
    """:func:`mrsp_at` by building the whole MRSP (slow; the reference for the tests)."""
    profile = most_restrictive_profile(static, applied, (), direction=travel, now_s=now_s)
    return float(profile.at(head_m)[()])


@functools.lru_cache(maxsize=32)
def _steps(static: SpeedProfile) -> tuple[list[float], list[float]]:
    """A profile's edges and speeds as Python lists (a point lookup without numpy)."""
    return static.edges_m.tolist(), static.speeds_mps.tolist()


def _static_at(static: SpeedProfile, x: float) -> float:
    """:meth:`SpeedProfile.at` at one finite point: the piece's speed, the lower side at an
    edge, 0 outside and at the two ends."""
    edges, speeds = _steps(static)
    if not edges[0] < x < edges[-1]:
        return 0.0
    i = bisect.bisect_right(edges, x) - 1  # x in [edges[i], edges[i+1]), 0 <= i < n
    if x == edges[i]:  # an inner edge: the stricter side
        return min(speeds[i - 1], speeds[i])
    return speeds[i]


def train_alarms(state: TrainState, mrsp_mps: float | None) -> list[str]:
    """The alarms of one train: ``link`` when the link is down or failed or its running info
    is stale (older than the registry's validity); ``overspeed`` when its reported speed is
    above ``mrsp_mps`` [m/s]."""
    alarms = []
    if state.registered and (not state.health.connected or not state.info_valid):
        alarms.append(ALARM_LINK)
    info = state.running_info
    if info is not None and mrsp_mps is not None and info.speed_mps > mrsp_mps:
        alarms.append(ALARM_OVERSPEED)
    return alarms


def target_view(
    target: Target | None, target_id: int | None, delivery: DeliveryState | None
) -> dict[str, Any] | None:
    """A train's current target point (the red signal it must stop before), or None."""
    if target is None:
        return None
    return {
        "id": target_id,
        "km": km(target.position_m),
        "reason": target.reason.name,
        "signal": target.signal_id,
        "block": target.block_id,
        "state": None if delivery is None else delivery.name,
    }


def train_view(
    state: TrainState,
    *,
    mrsp_mps: float | None,
    deviation_s: float | None,
    target: dict[str, Any] | None,
    category: str | None = None,
) -> dict[str, Any]:
    """One train from the registry's :class:`TrainState` (km, km/h, link health, alarms).

    ``deviation_s`` [s] (+ late) is the registry's unless the source knows better;
    ``category`` is the train's speed-limit category where the source knows it.
    """
    info = state.running_info
    health = state.health
    return {
        "id": state.train_id,
        "number": state.train_number or (info.train_number if info else str(state.train_id)),
        "category": category,
        "registered": state.registered,
        "length_km": None if state.length_m is None else km(state.length_m),
        "km": None if info is None else km(info.position_m),
        "speed_kmh": None if info is None else kmh(info.speed_mps),
        "direction": "unknown" if info is None else direction(info.direction),
        "valid": state.info_valid,
        "info_age_s": None if state.info_age_s is None else round(state.info_age_s, 1),
        "mrsp_kmh": None if mrsp_mps is None or not math.isfinite(mrsp_mps) else kmh(mrsp_mps),
        "deviation_s": None if deviation_s is None else round(deviation_s),
        "link": {
            "connected": health.connected,
            "timeouts": health.timeouts,
            "failures": health.failures,
            "rejections": dict(health.rejections),
        },
        "target": target,
        "alarms": train_alarms(state, mrsp_mps),
    }


def alarms_view(trains: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Every alarm of every train (from :func:`train_view`), links first."""
    out = []
    for kind in (ALARM_LINK, ALARM_OVERSPEED):
        for train in trains:
            if kind not in train["alarms"]:
                continue
            if kind == ALARM_LINK:
                age = train["info_age_s"]
                text = (
                    "link failed"
                    if train["link"]["failures"] and not train["link"]["connected"]
                    else "link down"
                    if not train["link"]["connected"]
                    else "running info stale"
                )
                if age is not None:
                    text += f": last report {age:.0f} s ago at km {train['km']:.3f}"
            else:
                text = (
                    f"at {train['speed_kmh']:.1f} km/h, above its MRSP of "
                    f"{train['mrsp_kmh']:.1f} km/h at km {train['km']:.3f}"
                )
            out.append(
                {"kind": kind, "train": train["id"], "number": train["number"], "text": text}
            )
    return out


# ---------------------------------------------------------------------------- TSRs


def tsr_view(
    tsr: LineTsr,
    state: LineTsrState,
    deliveries: Mapping[int, TsrState],
    numbers: Mapping[int, str],
) -> dict[str, Any]:
    """A line TSR with its delivery state on each train it went to (by train id)."""
    return {
        "session": tsr.session,
        "start_km": km(tsr.start_m),
        "end_km": km(tsr.end_m),
        "limit_kmh": kmh(tsr.limit_mps),
        "valid_from_s": tsr.valid_from_s,
        "valid_until_s": tsr.valid_until_s,
        "reason": tsr.reason,
        "set_by": tsr.set_by,
        "state": state.name,
        "deliveries": [
            {"train": t, "number": numbers.get(t, str(t)), "state": deliveries[t].name}
            for t in sorted(deliveries)
        ],
    }
