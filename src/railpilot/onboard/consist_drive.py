"""The onboard's drive of a station pair on the consist model.

The plan is the onboard's (its planner works on the point-mass train the consist derives,
vehicle/consist.py); the train that follows it is the consist: every vehicle a mass,
couplings with slack and draft gears, the freight air brake along the train, the remote
units by radio (sim/consist_run.py). The driver follows the planned curve with traction
and regeneration, uses the air brake in cycles where regeneration cannot hold it, and
stops with the air brake at the section's end. :class:`ConsistDrive` offers what the
drive's event loop (onboard/drive.py) needs of a run: advance to a time, where the train
is, a new plan from here, the result.
"""

from __future__ import annotations

import math

import numpy as np

from railpilot.brakes.freight_air import FreightAirBrake
from railpilot.sim.consist_run import (
    C_ENDED,
    C_REDUCTION,
    C_STOPPING,
    M_STEPS,
    M_STOP_T,
    ConsistDriver,
    ConsistRunSettings,
    ConsistScenario,
    ConsistStepper,
    DriverCommand,
)
from railpilot.sim.drive_profile import PlannedProfile
from railpilot.sim.result import SimResult
from railpilot.vehicle.consist import Consist
from railpilot.vehicle.line import Line

#: the consist metrics a drive's summary reports beside the point-mass ones
CONSIST_METRICS = (
    "max_coupler_tension_kn",
    "max_coupler_compression_kn",
    "coupler_force_limit_kn",
    "coupler_force_limit_exceeded_s",
    "air_brake_applications",
    "air_brake_releases",
    "min_recharge_margin_s",
)


#: the energy metrics a drive's summary reads, by the names both models give them
ENERGY_METRICS = (
    "energy_traction_kwh",
    "energy_regenerated_kwh",
    "energy_traction_against_air_kwh",
    "max_speed_kmh",
)


def _number(value: float | int | None) -> float:
    """A metric as a float (nan where the run has none)."""
    return math.nan if value is None else float(value)


class ConsistDrive:
    """A consist following the onboard's plan, stepped by the drive's event loop; its
    driver stops at ``stop_net_mps2`` [m/s^2] net of the line (the plan's station stop:
    onboard/drive.py ``station_stop_net``)."""

    def __init__(
        self,
        consist: Consist,
        vehicle_line: Line,
        profile: PlannedProfile,
        stop_m: float,
        dt_s: float,
        duration_s: float,
        stop_net_mps2: float,
        record_every_s: float = 1.0,
    ) -> None:
        air = FreightAirBrake(charged_kpa=consist.brake_pipe_kpa)
        driver = ConsistDriver(
            commands=(DriverCommand(at_s=0.0, follow=True),),
            stop_net_mps2=stop_net_mps2,
            profile_m=tuple(profile.x_m.tolist()),
            profile_mps=tuple(profile.v_mps.tolist()),
            stop_m=stop_m,
        )
        self.stop_m = stop_m
        scenario = ConsistScenario(
            "drive",
            consist,
            vehicle_line,
            driver,
            air,
            sim=ConsistRunSettings(dt_s=dt_s, duration_s=duration_s, record_every_s=record_every_s),
        )
        self.stepper = ConsistStepper(scenario)

    @property
    def time_s(self) -> float:
        return self.stepper.time_s

    @property
    def step(self) -> int:
        return int(self.stepper.metrics[M_STEPS])

    @property
    def n_steps(self) -> int:
        return self.stepper.n_steps

    @property
    def stop_time_s(self) -> float:
        """When the train came to its stand [s] (nan while it has not)."""
        return float(self.stepper.metrics[M_STOP_T])

    @property
    def position_m(self) -> float:
        return self.stepper.position_m

    @property
    def speed_mps(self) -> float:
        """The lead's speed [m/s]; a few mm/s backwards as the couplers settle at a stand
        read as 0 (the planner plans forwards)."""
        return max(self.stepper.speed_mps, 0.0)

    @property
    def at_rest(self) -> bool:
        return bool(self.stepper.metrics[C_ENDED] > 0.5)

    def advance_to(self, time_s: float) -> None:
        self.stepper.advance_to(time_s)

    def run_to_end(self) -> None:
        self.stepper.run_to_end()

    def follow(self, profile: PlannedProfile, stop_m: float) -> None:
        """A new plan from here: follow ``profile`` to a stop at ``stop_m`` [m]."""
        self.stop_m = stop_m
        self.stepper.replace_profile(profile.x_m, profile.v_mps, stop_m)

    def hold(self) -> None:
        """Stand where it is (nothing ahead may be entered): the stop's application here."""
        here = self.position_m
        self.stop_m = here
        self.stepper.replace_profile(np.array([here - 1.0, here]), np.zeros(2), here)
        self.stepper.metrics[C_STOPPING] = 1.0

    def restart(self) -> None:
        """Go on from a stand (a target point cleared): release and follow the plan."""
        self.stepper.metrics[C_REDUCTION] = 0.0
        self.stepper.metrics[C_STOPPING] = 0.0
        self.stepper.metrics[C_ENDED] = 0.0

    def result(self) -> SimResult:
        """The run as the drive's summary reads it: the head's series, the point-mass
        run's metric names, and the consist's own (:data:`CONSIST_METRICS`).

        Beside the head's series, the coupler-force envelope of each recorded sample
        (``max_coupler_tension_n``, ``max_coupler_compression_n``: the largest tension and
        the largest compression along the train [N], both >= 0), and in
        ``meta["brake_events"]`` the driver's brake applications and releases, each
        ``{time_s, kind, head_m, reduction_kpa}`` (``head_m`` travelled from the departure;
        ``reduction_kpa``: an application's deepest reduction before its release, None for
        a release, an emergency or an application shorter than a recorded sample)."""
        run = self.stepper.result()
        m = run.metrics
        ended = self.stepper.metrics[C_ENDED] > 0.5
        metrics: dict[str, float] = {
            "running_time_s": _number(m["running_time_s"]) if ended else math.nan,
            "stop_error_m": _number(m["final_position_m"]) - self.stop_m if ended else math.nan,
            **{key: _number(m[key]) for key in ENERGY_METRICS + CONSIST_METRICS},
        }
        series = {
            "time_s": run.series["time_s"],
            "position_m": run.series["position_m"],
            "speed_mps": run.series["speed_mps"],
            "traction_n": run.series["traction_n"],
            "electric_n": run.series["regeneration_n"] - run.series["traction_n"],
            "air_n": run.series["air_brake_n"],
        }
        coupler = run.fields["coupler_force_n"]  # + tension; one column a coupling
        no_couplers = np.zeros(coupler.shape[0])
        series["max_coupler_tension_n"] = (
            np.maximum(coupler.max(axis=1), 0.0) if coupler.shape[1] else no_couplers
        )
        series["max_coupler_compression_n"] = (
            np.maximum(-coupler.min(axis=1), 0.0) if coupler.shape[1] else no_couplers
        )
        # the lead's equalising reservoir as the driver set it: charged less the reduction
        reduction_kpa = self.stepper.scenario.consist.brake_pipe_kpa - run.series["lead_er_kpa"]
        times = list(run.events["time_s"])
        brake_events = []
        for i, (time_s, kind, head_m) in enumerate(
            zip(times, run.events["kind"], run.events["head_m"], strict=True)
        ):
            depth = None
            if kind == "application":
                # applied until the next event (the brake's state changes at each)
                end_s = times[i + 1] if i + 1 < len(times) else math.inf
                held = (run.series["time_s"] >= time_s) & (run.series["time_s"] < end_s)
                depth = float(reduction_kpa[held].max()) if held.any() else None
            brake_events.append(
                {"time_s": time_s, "kind": kind, "head_m": head_m, "reduction_kpa": depth}
            )
        meta = {"model": "consist", "consist": run.meta["consist"], "brake_events": brake_events}
        return SimResult(series, metrics, meta)
