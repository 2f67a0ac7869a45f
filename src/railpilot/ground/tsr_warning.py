"""Before a TSR is sent: the trains that already run faster than its limit where it holds.

A dispatcher who sets a temporary speed restriction over a stretch where a train already
runs above the new limit puts that train in overspeed the moment the restriction reaches
it. The ground warns first: :func:`trains_over_limit` lists such trains from their last
running info, and a request that does not say it confirms is refused with the list
(:class:`TsrWarning`, raised by :func:`refuse_unconfirmed`); the dispatcher sends it again
confirmed. No I/O, no clock: the time of "now" and of each report is passed in [s, ground
clock].

Which trains
------------
Each train is judged where its last report puts it, whenever the TSR starts (the ground
does not forecast where a train will be later):

- **inside**: its span from tail to head (tail = head - length going ``UP``, head + length
  going ``DOWN``; both ends included, as the block occupancy counts them) meets the TSR's
  ``[start_m, end_m]``, and it runs faster than the limit;
- **ahead**: it runs towards the TSR faster than the limit and its head is no farther from
  the TSR's near end than it runs until it can be at the limit: what it ran since its
  report (``speed * age``) plus its braking distance from its speed down to the limit,
  ``(v^2 - v_limit^2) / (2 b)``, at the service braking rate ``b`` below;
- **position unknown**: its report is older than the validity of a report (the
  occupancy's: ground/occupancy.py), and it had not passed the TSR when it was last heard.
  Where it is now and how fast it runs the ground does not know; it is listed with its
  last report rather than left out.

A train whose direction is unknown is taken as running either way.

The service braking rate
------------------------
:data:`SERVICE_BRAKE_MPS2` = 0.1 m/s^2: the planning brake every train's onboard plans its
slowing for a restriction with (onboard/planner.py, ``DEFAULT_BRAKE_MPS2``). The ground
does not know each train's brake; a loaded heavy-haul train's full service is about
0.5 m/s^2 (docs/consist.md), but a train that meets the restriction closer than it plans
to brake for can no longer slow down the way it drives. The lower rate makes the braking
distance longer, so the list errs on the side of warning: a warning costs the dispatcher
a second click, a missed one an overspeed.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from railpilot.errors import ConfigError, is_finite_number
from railpilot.link.messages import RunningInfo, TravelDirection
from railpilot.onboard.planner import DEFAULT_BRAKE_MPS2
from railpilot.units import m_to_km_post, mps_to_kmh

from .operations import Operation, OperationError, SetTsr

__all__ = [
    "AHEAD",
    "INSIDE",
    "SERVICE_BRAKE_MPS2",
    "UNKNOWN",
    "LastReport",
    "OverLimit",
    "TsrWarning",
    "confirm_flag",
    "last_reports",
    "refuse_unconfirmed",
    "trains_over_limit",
]

#: The service braking rate a train is taken to slow down at [m/s^2] (module docstring).
SERVICE_BRAKE_MPS2 = DEFAULT_BRAKE_MPS2

#: Where a listed train is (:attr:`OverLimit.where`).
INSIDE = "inside"
AHEAD = "ahead"
UNKNOWN = "position unknown"
_ORDER = {INSIDE: 0, AHEAD: 1, UNKNOWN: 2}

UP = TravelDirection.UP
DOWN = TravelDirection.DOWN


@dataclass(frozen=True)
class LastReport:
    """What the ground last heard of one train: head km post [m], speed [m/s], length [m],
    direction and when the report came [s, ground clock]."""

    train_id: int
    head_m: float
    speed_mps: float
    length_m: float
    direction: TravelDirection
    reported_s: float

    def __post_init__(self) -> None:
        for name in ("head_m", "speed_mps", "length_m", "reported_s"):
            value = getattr(self, name)
            if not is_finite_number(value) or (name != "reported_s" and value < 0):
                raise ConfigError(f"report.{name}", value, "a finite number >= 0")

    def directions(self) -> tuple[TravelDirection, ...]:
        """The ways it may be running: its own, or both when unknown."""
        return (self.direction,) if self.direction in (UP, DOWN) else (UP, DOWN)

    def span_m(self, direction: TravelDirection) -> tuple[float, float]:
        """Tail to head as ``(low, high)`` km posts [m], running ``direction``."""
        tail = self.head_m - self.length_m if direction is UP else self.head_m + self.length_m
        return min(tail, self.head_m), max(tail, self.head_m)


@dataclass(frozen=True)
class OverLimit:
    """One train a TSR would catch above its limit.

    ``where``: :data:`INSIDE`, :data:`AHEAD` or :data:`UNKNOWN`; ``distance_m`` from its
    head to the TSR's near end (0 inside; for a train of unknown position, as last
    reported); ``excess_mps``: its (last) speed above the limit, 0 or less for a train of
    unknown position that last ran slower.
    """

    train_id: int
    where: str
    head_m: float
    speed_mps: float
    excess_mps: float
    distance_m: float
    age_s: float

    def view(self) -> dict[str, Any]:
        """JSON-ready, in the dispatcher's units (km posts in km, speeds in km/h), with the
        line of :meth:`text`."""
        return {**self._numbers(), "text": self.text()}

    def _numbers(self) -> dict[str, Any]:
        return {
            "train": self.train_id,
            "where": self.where,
            "km": round(m_to_km_post(self.head_m), 3),
            "speed_kmh": round(float(mps_to_kmh(self.speed_mps)), 1),
            "over_limit_kmh": round(float(mps_to_kmh(self.excess_mps)), 1),
            "distance_m": round(self.distance_m),
            "report_age_s": round(self.age_s, 1),
        }

    def text(self) -> str:
        """One line for a terminal or a message."""
        v = self._numbers()
        if self.where == UNKNOWN:
            return (
                f"train {self.train_id}: position unknown (no report for {v['report_age_s']:g} s;"
                f" last at km {v['km']:.3f}, {v['speed_kmh']:g} km/h)"
            )
        at = "inside" if self.where == INSIDE else f"{v['distance_m']} m short of it"
        return (
            f"train {self.train_id}: {at} at km {v['km']:.3f}, {v['speed_kmh']:g} km/h, "
            f"{v['over_limit_kmh']:g} km/h over the limit"
        )


def trains_over_limit(
    start_m: float,
    end_m: float,
    limit_mps: float,
    trains: Iterable[LastReport],
    now_s: float,
    *,
    validity_s: float,
    brake_mps2: float = SERVICE_BRAKE_MPS2,
) -> tuple[OverLimit, ...]:
    """The trains a TSR on ``[start_m, end_m]`` [m] at ``limit_mps`` [m/s] would catch above
    its limit at ``now_s`` [s] (module docstring): inside first, then ahead, then of unknown
    position, each by train id. ``validity_s`` [s]: how long a report stays valid;
    ``brake_mps2`` [m/s^2]: the service braking rate."""
    if not (is_finite_number(start_m) and is_finite_number(end_m) and start_m < end_m):
        raise ConfigError("tsr.end_m", end_m, f"a km post [m] above start_m = {start_m}")
    if not is_finite_number(limit_mps) or limit_mps <= 0:
        raise ConfigError("tsr.limit_mps", limit_mps, "a speed > 0 [m/s]")
    if not is_finite_number(validity_s) or validity_s <= 0:
        raise ConfigError("validity_s", validity_s, "a time > 0 [s]")
    if not is_finite_number(brake_mps2) or brake_mps2 <= 0:
        raise ConfigError("brake_mps2", brake_mps2, "a deceleration > 0 [m/s^2]")
    found = []
    for train in trains:
        age = max(0.0, now_s - train.reported_s)
        hit = _judge(train, start_m, end_m, limit_mps, age, validity_s, brake_mps2)
        if hit is not None:
            found.append(hit)
    return tuple(sorted(found, key=lambda o: (_ORDER[o.where], o.train_id)))


def _judge(
    train: LastReport,
    start_m: float,
    end_m: float,
    limit_mps: float,
    age_s: float,
    validity_s: float,
    brake_mps2: float,
) -> OverLimit | None:
    v = train.speed_mps
    ahead: float | None = None  # the least distance to the near end, running towards it
    for direction in train.directions():
        low, high = train.span_m(direction)
        if low <= end_m and start_m <= high:
            ahead = 0.0
            break
        if direction is UP and train.head_m < start_m:
            gap = start_m - train.head_m
        elif direction is DOWN and train.head_m > end_m:
            gap = train.head_m - end_m
        else:
            continue  # past it: running away from it
        ahead = gap if ahead is None else min(ahead, gap)
    if ahead is None:
        return None
    if age_s > validity_s:
        return OverLimit(train.train_id, UNKNOWN, train.head_m, v, v - limit_mps, ahead, age_s)
    if v <= limit_mps:
        return None
    reach = v * age_s + (v * v - limit_mps * limit_mps) / (2.0 * brake_mps2)
    if ahead == 0.0:
        return OverLimit(train.train_id, INSIDE, train.head_m, v, v - limit_mps, 0.0, age_s)
    if ahead <= reach:
        return OverLimit(train.train_id, AHEAD, train.head_m, v, v - limit_mps, ahead, age_s)
    return None


# ---------------------------------------------------------------------------- the gate


class TsrWarning(OperationError):
    """A TSR refused until confirmed: it would catch ``trains`` above its limit. As an
    :class:`OperationError` naming the field ``confirm``, whoever does not know of it still
    sends nothing and says why."""

    def __init__(self, limit_mps: float, trains: tuple[OverLimit, ...]) -> None:
        self.limit_mps = limit_mps
        self.trains = trains
        limit = f"{float(mps_to_kmh(limit_mps)):g} km/h"
        listed = "; ".join(t.text() for t in trains)
        super().__init__(
            {
                "confirm": f"not sent: {len(trains)} train(s) already above the new limit of "
                f"{limit} where it holds or too close to slow down ({listed}); expected "
                "confirm = true to send it anyway"
            }
        )

    def view(self) -> dict[str, Any]:
        """JSON-ready: the limit [km/h] and each train (:meth:`OverLimit.view`)."""
        return {
            "limit_kmh": round(float(mps_to_kmh(self.limit_mps)), 1),
            "trains": [t.view() for t in self.trains],
        }


def last_reports(reports: Iterable[tuple[int, RunningInfo, float, float]]) -> list[LastReport]:
    """The registry's reports (``TrainRegistry.reports()``: id, running info, length [m],
    when it came [s]) as :class:`LastReport`."""
    return [
        LastReport(
            train_id,
            float(info.position_m),
            float(info.speed_mps),
            float(length_m),
            info.direction,
            float(received_s),
        )
        for train_id, info, length_m, received_s in reports
    ]


def refuse_unconfirmed(
    operation: Operation,
    reports: Iterable[tuple[int, RunningInfo, float, float]],
    now_s: float,
    *,
    validity_s: float,
    confirm: bool,
) -> None:
    """Raise :class:`TsrWarning` for a :class:`SetTsr` that is not confirmed and would catch
    trains above its limit; any other operation, or a confirmed one, passes."""
    if confirm or not isinstance(operation, SetTsr):
        return
    caught = trains_over_limit(
        operation.start_m,
        operation.end_m,
        operation.limit_mps,
        last_reports(reports),
        now_s,
        validity_s=validity_s,
    )
    if caught:
        raise TsrWarning(operation.limit_mps, caught)


def confirm_flag(request: Mapping[str, Any], op: object) -> bool:
    """A request's ``confirm`` (absent: False); a value other than true or false, or one on
    an operation other than ``tsr_set``, is an :class:`OperationError` naming it."""
    if "confirm" not in request:
        return False
    value = request["confirm"]
    if op != "tsr_set":
        raise OperationError(
            {"confirm": f"{value!r} is not allowed: expected confirm only with tsr_set"}
        )
    if not isinstance(value, bool):
        raise OperationError({"confirm": f"{value!r} is not allowed: expected true or false"})
    return value
