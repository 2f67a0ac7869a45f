"""The human-driver baseline of a line run: how a heavy-haul driver without advice drives
a section (docs/line-run.md, "The human-driver baseline").

The minimum-time baseline drives to the limits (the planner's fastest run). A person
drives differently, by rules of thumb learnt on the road and in the train-handling
manuals, and this module writes those rules down as a speed profile over the section,
which the same simulation core tracks as it tracks every other (cosim/driver.py: the
point mass and its precise-stop ATO, the same brake, the same line):

* **a speed margin**: the driver holds a few km/h under the permitted speed, not on it
  (``margin_kmh``);
* **coasting habits**: power is shut off a fixed distance before every braking point,
  for a lower limit ahead or the station stop (``coast_before_brake_m``), and the train
  coasts until the braking curve meets it (powering again only if it would fall below
  the lower limit ahead, or half its speed: ``COAST_ABOVE_SHARE``; not on a rise:
  ``COAST_MAX_RISE_N_PER_KN``);
* **braking cycles on a descent**: where the regenerative brake alone cannot hold the
  train at its speed, the driver lets it run up to a fixed *apply* speed (the limit less
  the margin), applies the air brake, brakes down to a fixed *release* speed, releases in
  full, expects the train to hold about that speed while the brake releases along it (its
  release delay and time constant), and lets it run up again, the regenerative brake
  taking what the descent gives beyond a moderate run-up, no traction in between
  (``cycle_release_below_kmh``, ``cycle_min_release_kmh``, ``cycle_decel_mps2``,
  ``cycle_run_up_mps2``); under a limit too low for a cycle above the least release
  speed, a steady application holds it;
* **braking for a lower limit or a stop** as the planner's curves brake (the planning
  brake, regeneration first; a target stop at least the planner's net deceleration), so
  the two baselines differ by the habits above and not by a different brake;
* **reaction time**: the driver acts on a changed limit or aspect (a TSR received, a red
  signal appearing in the cab or clearing) ``reaction_s`` after it changed. The driver
  knows the road, so the static limits and the gradients are in the profile from the start.

What it is not: there is no driver error, no fatigue and no spread between drivers; one
set of parameters is one (careful) driver. The air brake's recharge between cycles is
not modelled (the point mass has no brake pipe to recharge). The profile is the human's;
the hands that follow it are the point mass's ATO, which tracks a cycle's application
and release with its air brake and its traction together where a person would not pull
against the brake: the run's ``energy_traction_against_air_kwh`` shows what that costs
(docs/line-run.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from railpilot.checks import check_number
from railpilot.errors import ConfigError
from railpilot.onboard.planner import DrivingTrain, SectionGrid, SpeedPlan, braking_envelope
from railpilot.units import kmh_to_mps
from railpilot.vehicle.traction import regen_force_max, traction_force_max


@dataclass(frozen=True)
class HumanDriving:
    """One human driver's habits (module docstring; sources in docs/line-run.md, "The
    human-driver baseline").

    Attributes
    ----------
    margin_kmh
        How far under the permitted speed the driver holds the train [km/h]. 8 km/h:
        the common rule of thumb of freight drivers, "5 mph under the limit" (assumption
        from practice, not a published measurement).
    reaction_s
        Delay between a change of what the driver is told (TSR, cab-signal aspect) and
        the driver acting on it [s]. 3 s: the middle of the 2-4 s a brief perception and
        decision takes (assumption).
    coast_before_brake_m
        Power is shut off this far before every braking point for a lower limit or a
        stop [m]; the train coasts from there until the braking curve meets it. 2,000 m
        (assumption: a loaded train coasting at 70 km/h loses a few km/h in 2 km on the
        level, the visible "roll in" of a heavy train).
    cycle_release_below_kmh
        On a descent the regenerative brake cannot hold, the air brake applied at the
        apply speed (the limit less the margin) is released this much lower [km/h].
        25 km/h (assumption, from cyclic braking of long freight trains: a release at
        speed leaves time for the brake to release along the train).
    cycle_min_release_kmh
        ... but never below this speed [km/h]: a freight train's brake is released
        while the train is still fast enough for it to release in full before the train
        runs slowly (train-handling manuals, e.g. release above about 10 mph); 40 km/h
        (assumption for a 10,000 t train, whose brake takes about a minute to release).
    cycle_decel_mps2
        The net deceleration of a cycle's application [m/s^2]: a light service
        reduction, what the train slows at with it and the regenerative brake against
        the descent. 0.05 m/s^2 (assumption).
    cycle_run_up_mps2
        After a release the train runs up to the apply speed at this rate [m/s^2], the
        regenerative brake taking what the descent gives beyond it (or all it can, if
        the descent gives more). 0.03 m/s^2 (assumption: about 1 km/h every 9 s).
    """

    margin_kmh: float = 8.0
    reaction_s: float = 3.0
    coast_before_brake_m: float = 2_000.0
    cycle_release_below_kmh: float = 25.0
    cycle_min_release_kmh: float = 40.0
    cycle_decel_mps2: float = 0.05
    cycle_run_up_mps2: float = 0.03

    def __post_init__(self) -> None:
        for name, low, high in (
            ("margin_kmh", 0.0, 50.0),
            ("reaction_s", 0.0, 30.0),
            ("coast_before_brake_m", 0.0, 20_000.0),
            ("cycle_release_below_kmh", 1.0, 80.0),
            ("cycle_min_release_kmh", 0.0, 120.0),
        ):
            allowed = f"a number in [{low:g}, {high:g}]"
            check_number(
                name,
                getattr(self, name),
                minimum=low,
                maximum=high,
                allowed=allowed,
                error=ConfigError,
            )
        for name in ("cycle_decel_mps2", "cycle_run_up_mps2"):
            check_number(
                name,
                getattr(self, name),
                positive=True,
                maximum=0.5,
                allowed="an acceleration in (0, 0.5] m/s^2",
                error=ConfigError,
            )


#: in a coasting zone the driver coasts while the train keeps above this share of the
#: speed it would hold (and above the lower limit it brakes for), and powers below it: a
#: train just departed, or slowed by a rise, is not left to crawl to the braking point
COAST_ABOVE_SHARE = 0.5

#: ... and only where the line rises less than this [N/kN, per mille]: no driver shuts off
#: power early on a rise, where the train would slow long before its braking point
COAST_MAX_RISE_N_PER_KN = 1.0

#: the human driver of every line run's human baseline
DEFAULT_HUMAN = HumanDriving()


def human_curve(
    train: DrivingTrain,
    sec: SectionGrid,
    human: HumanDriving,
    *,
    planned_margin_mps: float,
    stop_net_mps2: float = 0.0,
    release_s: float = 0.0,
) -> SpeedPlan:
    """The speed profile [m/s] the human driver runs ``sec`` with (module docstring).

    ``sec`` is the planner's section: its ceiling the limits less ``planned_margin_mps``
    [m/s] (the scenario's margin); the human's margin replaces it where it is larger.
    ``stop_net_mps2``: the least net deceleration of the stop at the end, as the
    onboard's plan brakes it (onboard/drive.py ``StationRoute.stop_net_mps2``).
    ``release_s``: how long the train's air brake takes to release along it [s] (its
    release delay and time constant): after a cycle's release the driver expects the
    train to hold its speed that long before it runs up again.
    The plan's energy figures are NaN: what the run draws is what the simulation core
    measures following it.
    """
    ceiling = _human_ceiling(sec.ceiling_mps, kmh_to_mps(human.margin_kmh) - planned_margin_mps)
    envelope = braking_envelope(train, sec, ceiling, stop_net_mps2)
    coast = _coast_zone(sec, ceiling, envelope, human.coast_before_brake_m)
    speed = _forward(train, sec, ceiling, envelope, coast, human, release_s)
    mean = 0.5 * (speed[1:] + speed[:-1])
    moving = mean > 0.0
    time_s = float(np.sum(sec.dx_m / mean[moving]))
    return SpeedPlan(
        sec.s_m,
        speed,
        time_s,
        math.nan,
        math.nan,
        None,
        None,
        None,
        True,
        strategy="human",
    )


def _human_ceiling(ceiling: np.ndarray, extra_mps: float) -> np.ndarray:
    """The planner's ceiling less the human's extra margin (never below half of it, as
    the planner's own margin), its first point (the speed it starts at) and its last (the
    stop) kept."""
    out = ceiling.copy()
    if extra_mps > 0.0:
        inner = ceiling[1:-1]
        out[1:-1] = np.maximum(inner - extra_mps, 0.5 * inner)
    return out


def _coast_zone(
    sec: SectionGrid, ceiling: np.ndarray, envelope: np.ndarray, before_m: float
) -> np.ndarray:
    """Where the driver has shut off power, from ``before_m`` [m] before every point at
    which a braking curve leaves the ceiling (a lower limit or the stop ahead) to where
    that curve ends, and the least speed [m/s] it coasts down to there (NaN: not in a
    zone): the lower limit it brakes for (no coasting below it, on a rise), and never
    below ``COAST_ABOVE_SHARE`` of the ceiling."""
    at_ceiling = envelope >= ceiling
    onsets = np.flatnonzero(at_ceiling[:-1] & ~at_ceiling[1:])
    floor = np.full(envelope.size, np.nan)
    cells = round(before_m / sec.dx_m)
    for i in onsets:
        back = np.flatnonzero(at_ceiling[i + 1 :])
        end = i + 1 + int(back[0]) if back.size else envelope.size - 1
        target = envelope[end]
        # from the shut-off to where the braking ends: it coasts until the curve meets it
        zone = slice(max(i - cells, 0), end + 1)
        floor[zone] = np.fmax(floor[zone], np.maximum(target, COAST_ABOVE_SHARE * ceiling[zone]))
    return floor


def _forward(
    train: DrivingTrain,
    sec: SectionGrid,
    ceiling: np.ndarray,
    envelope: np.ndarray,
    coast: np.ndarray,
    human: HumanDriving,
    release_s: float,
) -> np.ndarray:
    """The driver's speed step by step: traction up to the ceiling (none in a coasting
    zone, none on a descent between a cycle's release and the next application), the
    regenerative brake holding it on a descent, and the air brake in cycles where that is
    not enough; bounded by the braking envelope."""
    loco = train.locomotive
    m_eff = train.train.effective_mass_kg
    dx = sec.dx_m
    drop = kmh_to_mps(human.cycle_release_below_kmh)
    floor = kmh_to_mps(human.cycle_min_release_kmh)
    cycle = human.cycle_decel_mps2
    n = envelope.size
    v = np.empty(n)
    v[0] = envelope[0]
    braking = False  # a cycle's air brake is applied
    cycling = False  # on a descent where the driver brakes in cycles (regeneration on)
    release = 0.0
    held_to_m = -math.inf  # after a release the speed is held to here [m]
    for i in range(n - 1):
        speed = v[i]
        cruise = ceiling[i + 1]
        a_coast = train.coast_decel_mps2(speed, 0.5 * (sec.line_w[i] + sec.line_w[i + 1]))
        coasting = math.sqrt(max(speed * speed - 2.0 * dx * a_coast, 0.0))
        regen = regen_force_max(
            speed, loco.regen.max_force_n, loco.regen.max_power_w, loco.regen.fade_below_mps
        )
        sq = speed * speed - 2.0 * dx * (a_coast + regen / m_eff)
        regenerating = math.sqrt(max(sq, 0.0))
        if braking:
            nxt = max(math.sqrt(max(speed * speed - 2.0 * dx * cycle, 0.0)), release)
            if nxt <= release:
                # released; the brake takes ``release_s`` to release along the train,
                # and the train holds about its speed meanwhile
                braking = False
                held_to_m = sec.s_m[i + 1] + nxt * release_s
        elif coasting >= cruise:
            release = max(cruise - drop, floor)
            if regenerating > cruise and release < cruise:
                # the regenerative brake cannot hold the apply speed: apply the air brake
                # and brake down to the release speed
                braking = cycling = True
                nxt = min(cruise, math.sqrt(max(speed * speed - 2.0 * dx * cycle, 0.0)))
            else:
                # regeneration holds it; or, under a limit too low to release above the
                # least release speed (a TSR on the descent), a steady application does
                nxt = min(coasting, max(cruise, regenerating))
        elif cycling and a_coast < 0.0 and sec.s_m[i + 1] <= held_to_m:
            nxt = min(speed, cruise)  # the brake releasing
        elif cycling and a_coast < 0.0 and regenerating >= speed:
            # released on the descent: no traction; the train runs up to the apply speed
            # at the run-up rate, the regenerative brake taking the rest of the descent
            run_up = max(min(-a_coast, human.cycle_run_up_mps2), -a_coast - regen / m_eff)
            nxt = math.sqrt(max(speed * speed + 2.0 * dx * run_up, 0.0))
        else:
            cycling = False
            rise = 0.5 * (sec.line_w[i] + sec.line_w[i + 1]) > COAST_MAX_RISE_N_PER_KN
            # False outside a zone (NaN), and at rest (a zone just ahead of a stand)
            if coasting >= coast[i] and coasting > 0.0 and not rise:
                nxt = coasting
            else:
                # power on: not in a coasting zone, or too slow to coast on (just
                # departed, or slowed by a rise to the lower limit it coasts towards)
                trac = traction_force_max(
                    speed,
                    loco.traction.max_force_n,
                    loco.traction.max_power_w,
                    loco.traction.speed_limit_mps,
                )
                sq = speed * speed + 2.0 * dx * (trac / m_eff - a_coast)
                nxt = min(cruise, math.sqrt(max(sq, 0.0)))
        if nxt >= envelope[i + 1]:
            nxt = envelope[i + 1]
            braking = False  # the braking curve governs
        v[i + 1] = nxt
    return v
