"""The driving advice for a whole section, as a list a driver can follow.

The onboard drives its plan ahead on its model of the train (``railpilot drive``: the
consist with its driver, or the point mass with its ATO) and turns what that driver did
into instructions at km posts: the locomotives' effort in steady stretches ("power 300
kN", "regenerate 400 kN", "coast"), each air-brake application with its reduction
("reduce 50 kPa"), each release with the speed it is made at, and the stop, with the
arrival expected at the drive's pace. No I/O.

A stretch is a run of the recorded samples in one mode (traction, regeneration or neither,
within ``COAST_BELOW_N`` of nothing); stretches shorter than ``SHORTEST_STRETCH_M`` are
merged into the one before (a driver does not act on every wobble of a speed law), and a
stretch's force is its mean, rounded to ``FORCE_STEP_N``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from railpilot.sim.result import SimResult

Action = Literal["power", "regenerate", "coast", "reduce", "release", "stop"]

#: an electric force below this is coasting [N]
COAST_BELOW_N = 20e3
#: the shortest stretch of one effort that is its own instruction [m]
SHORTEST_STRETCH_M = 300.0
#: forces are given to this step [N]
FORCE_STEP_N = 50e3


@dataclass(frozen=True)
class Instruction:
    """One instruction: ``action`` from km post ``km`` on; ``value`` the force [kN] (power,
    regenerate), the reduction [kPa] (reduce, None where the run did not record its
    depth) or the speed [km/h] (release); ``time_s`` when the drive reached it [s from
    the departure]."""

    km: float
    action: Action
    value: float | None
    time_s: float

    @property
    def text(self) -> str:
        where = f"at km {self.km:.1f}"
        if self.action == "power":
            return f"power {self.value:.0f} kN from km {self.km:.1f}"
        if self.action == "regenerate":
            return f"regenerate {self.value:.0f} kN from km {self.km:.1f}"
        if self.action == "coast":
            return f"coast from km {self.km:.1f}"
        if self.action == "reduce":
            depth = "" if self.value is None else f" {self.value:.0f} kPa"
            return f"reduce{depth} {where}"
        if self.action == "release":
            return f"release {where} (about {self.value:.0f} km/h)"
        return f"stop {where}, {self.time_s:.0f} s after the departure"

    def as_dict(self) -> dict[str, Any]:
        return {
            "km": round(self.km, 3),
            "action": self.action,
            "value": None if self.value is None else round(self.value, 1),
            "time_s": round(self.time_s, 1),
            "text": self.text,
        }


def _mode(electric_n: float) -> Action:
    """``electric_n``: the locomotives' force in the brake's sign [N] (regeneration
    positive, traction negative)."""
    if electric_n <= -COAST_BELOW_N:
        return "power"
    if electric_n >= COAST_BELOW_N:
        return "regenerate"
    return "coast"


def _stretches(x: np.ndarray, modes: list[Action]) -> list[tuple[int, int]]:
    """``[start, end)`` sample ranges of one mode each, the short ones merged into the
    stretch before them (the first one kept whatever its length)."""
    runs: list[tuple[int, int]] = []
    start = 0
    for i in range(1, len(modes) + 1):
        if i == len(modes) or modes[i] != modes[start]:
            runs.append((start, i))
            start = i
    merged: list[tuple[int, int]] = []
    for a, b in runs:
        short = x[b - 1] - x[a] < SHORTEST_STRETCH_M
        if merged and (short or modes[a] == modes[merged[-1][0]]):
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    return merged


def advice_along(result: SimResult, km_post_m: Any) -> list[Instruction]:
    """The instructions of a drive (its ``result``: the head's series, the locomotives'
    force ``electric_n`` in the brake's sign, and on the consist ``meta["brake_events"]``)
    in the order the train meets them; ``km_post_m`` maps the distance from the departure
    [m] to the km post [m]."""
    x = np.asarray(result["position_m"], dtype=float)
    t = np.asarray(result["time_s"], dtype=float)
    if x.size == 0:
        return []
    electric = np.asarray(result["electric_n"], dtype=float)
    modes = [_mode(f) for f in electric]
    km = np.asarray(km_post_m(x), dtype=float) / 1000.0
    out: list[Instruction] = []
    for a, b in _stretches(x, modes):
        mode = modes[a]
        mean_n = abs(float(np.mean(electric[a:b])))
        force: float | None = round(mean_n / FORCE_STEP_N) * FORCE_STEP_N / 1e3
        if mode == "coast" or force == 0.0:
            mode, force = "coast", None  # a stretch whose wobbles average out
        if out and out[-1].action == mode and out[-1].value == force:
            continue
        out.append(Instruction(float(km[a]), mode, force, float(t[a])))
    speed = np.asarray(result["speed_mps"], dtype=float)
    for event in result.meta.get("brake_events", ()):
        at = int(np.clip(np.searchsorted(t, event["time_s"]), 0, t.size - 1))
        event_km = float(km_post_m(np.array([event["head_m"]]))[0]) / 1000.0
        if event["kind"] == "application":
            out.append(Instruction(event_km, "reduce", event["reduction_kpa"], event["time_s"]))
        elif event["kind"] == "release":
            kmh = float(speed[at]) * 3.6
            out.append(Instruction(event_km, "release", kmh, event["time_s"]))
    # at rest at the stop: where the run ended, when it came to rest
    arrival_s = float(result.metrics.get("running_time_s", np.nan))
    out.append(
        Instruction(
            float(km[-1]), "stop", None, arrival_s if arrival_s == arrival_s else float(t[-1])
        )
    )
    return sorted(out, key=lambda i: i.time_s)
