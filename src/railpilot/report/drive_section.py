"""The report's section of heavy-haul drives on the consist model: for each section
driven, its figure of brake cycles, forces and coupler forces
(:func:`railpilot.report.drive_plots.section_figure`) and a row of what the run did."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from railpilot.onboard.drive import DriveOutcome
from railpilot.report.section import Reproduction, Table

#: the report's anchor for the section, and the folder of its figures under the report's
DRIVE_CYCLES = "drive-cycles"


@dataclass(frozen=True)
class DrivenSection:
    """One section the report shows: the train's name, the drive, the running time it was
    given [s], and the command that drives it again (``railpilot drive ...``)."""

    train: str
    outcome: DriveOutcome
    running_time_s: float
    command: str


def drive_cycles_section(driven: list[DrivenSection], out_dir: Path) -> Reproduction:
    """Write each drive's figure to ``out_dir/drive-cycles/`` and return the section."""
    from railpilot.report.drive_plots import section_figure
    from railpilot.report.figure import save_figure

    folder = out_dir / DRIVE_CYCLES
    folder.mkdir(parents=True, exist_ok=True)
    rows: list[list[Any]] = []
    figures: list[Path] = []
    for d in driven:
        o, m = d.outcome, d.outcome.result.metrics
        name = f"{d.train}_{o.from_station}-{o.to_station}_cycles.png"
        figures.append(save_figure(section_figure(o), folder / name))
        rows.append(
            [
                d.train,
                f"{o.from_station} -> {o.to_station}",
                d.running_time_s,
                m["running_time_s"],
                int(m["air_brake_applications"]),
                int(m["air_brake_releases"]),
                m["min_recharge_margin_s"],  # nan where no release was followed by an application
                m["energy_traction_kwh"],
                m["energy_traction_against_air_kwh"],
                m["max_coupler_tension_kn"],
                m["max_coupler_compression_kn"],
            ]
        )
    limit_kn = float(driven[0].outcome.result.metrics["coupler_force_limit_kn"]) if driven else 0.0
    table = Table(
        "Each section driven on the consist model",
        [
            "train",
            "section",
            "running time given [s]",
            "driven [s]",
            "applications",
            "releases",
            "least recharge margin [s]",
            "traction [kWh]",
            "of it against the air brake [kWh]",
            "largest tension [kN]",
            "largest compression [kN]",
        ],
        rows,
        note=f"Coupler-force limit {limit_kn:,.0f} kN. A negative recharge margin: an "
        "application before the train had recharged from the release before it.",
    )
    return Reproduction(
        DRIVE_CYCLES,
        "Heavy-haul drives on the consist model: brake cycles, forces, coupler forces",
        {},
        [table],
        figures,
        [
            "Each figure shows, over the km post: the speed against the MRSP and the plan, "
            "each air-brake application (its reduction) and release where the head was; "
            "the locomotives' traction and regeneration and the air brake's force; the "
            "largest tension and compression along the train at each second against the "
            "limit."
        ],
        rerun=tuple(dict.fromkeys(d.command for d in driven)),
    )
