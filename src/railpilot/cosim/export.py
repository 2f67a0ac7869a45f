"""A line run as tables a researcher opens in their own tools (``railpilot line simulate
--out DIR`` writes them; docs/line-run.md "Files").

:func:`trace_table` and :func:`section_table` give a :class:`~railpilot.cosim.line_run.LineResult`
as pandas tables, :func:`events_document` its events as one JSON-ready object. Times are
seconds since the run's start, as in the KPIs (a ground's answer inside an event, e.g. a
TSR's validity, is as the ground gave it, on its clock); positions are km posts [km] and
speeds km/h, as the line's files and the dashboard give them.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from railpilot.units import KMH_PER_MPS, m_to_km_post

from .kpis import KPIS

if TYPE_CHECKING:
    import pandas as pd

    from .line_run import LineResult

#: trace.csv: the trackside's sample of every train, every second
TRACE_COLUMNS = ("driver", "train", "number", "t_s", "km", "speed_kmh")
#: sections.csv: one row per station pair a train ran (driver.py ``SectionRun``)
SECTION_COLUMNS = (
    "driver",
    "train",
    "number",
    "kind",
    "from_station",
    "to_station",
    "planned_departure_s",
    "departure_s",
    "planned_arrival_s",
    "arrival_s",
    "planned_running_time_s",
    "target_running_time_s",
    "running_time_s",
    "conformity_pct",
    "energy_traction_kwh",
    "energy_regenerated_kwh",
    "energy_traction_against_air_kwh",
    "stops_at_red",
    "replans",
)


def _driver(result: LineResult) -> str:
    return "advised" if result.advised else "baseline"


def trace_table(result: LineResult) -> pd.DataFrame:
    """Every train's samples (``LineResult.trace``): time [s since the run's start], head
    km post [km], speed [km/h], in order of train and time."""
    import pandas as pd

    numbers = {i: d.service.number for i, d in result.drivers.items()}
    parts = []
    for train_id, rows in sorted(result.trace.items()):
        n = len(rows)
        parts.append(
            pd.DataFrame(
                {
                    "driver": [_driver(result)] * n,
                    "train": np.full(n, train_id),
                    "number": [numbers.get(train_id, "")] * n,
                    "t_s": rows[:, 0],
                    "km": m_to_km_post(rows[:, 1]),
                    "speed_kmh": rows[:, 2] * KMH_PER_MPS,
                }
            )
        )
    if not parts:
        return pd.DataFrame({c: [] for c in TRACE_COLUMNS})
    return pd.concat(parts, ignore_index=True)[list(TRACE_COLUMNS)]


def section_table(result: LineResult) -> pd.DataFrame:
    """One row per station pair each train ran: the plan, what happened, and the
    conformity ``(actual - planned) / planned * 100`` the KPIs average (empty for a section
    the run ended in)."""
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for train_id, driver in sorted(result.drivers.items()):
        for s in driver.sections:
            planned, actual = s.planned_running_time_s, s.running_time_s
            rows.append(
                {
                    "driver": _driver(result),
                    "train": train_id,
                    "number": driver.service.number,
                    "kind": driver.service.kind,
                    "from_station": s.from_station,
                    "to_station": s.to_station,
                    "planned_departure_s": s.planned_departure_s,
                    "departure_s": s.departure_s,
                    "planned_arrival_s": s.planned_arrival_s,
                    "arrival_s": s.arrival_s,
                    "planned_running_time_s": planned,
                    "target_running_time_s": s.target_running_time_s,
                    "running_time_s": actual,
                    "conformity_pct": (actual - planned) / planned * 100.0
                    if math.isfinite(actual)
                    else math.nan,
                    "energy_traction_kwh": s.energy_traction_kwh,
                    "energy_regenerated_kwh": s.energy_regenerated_kwh,
                    "energy_traction_against_air_kwh": s.energy_traction_against_air_kwh,
                    "stops_at_red": s.stops_at_red,
                    "replans": s.replans,
                }
            )
    return pd.DataFrame(rows, columns=list(SECTION_COLUMNS))


def events_document(result: LineResult) -> dict[str, Any]:
    """What happened on the line besides the trains' motion: the scenario's events as
    played, the ground's restarts and re-timings, and everything the trackside saw that a
    KPI counts (cosim/kpis.py ``Kpi.records``: every TSR violation, signal passed at red
    and overspeed, each with its time and train)."""
    return {
        "scenario": result.scenario.name,
        "seed": result.seed,
        "driver": _driver(result),
        "events": result.events_on_run_clock(),
        "ground_restarts": result.restarts,
        "retiming": result.retimings(),
        **{
            key: [asdict(seen) for seen in of_run(result)]
            for key, of_run in (k.records for k in KPIS if k.records is not None)
        },
    }
