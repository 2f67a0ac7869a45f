"""One result object per run: columnar time series, metrics and metadata.

Plots live in railpilot.report and take results; nothing here draws.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

#: Recorded channels, in the column order of the kernel's recorder, with units.
CHANNELS: tuple[tuple[str, str], ...] = (
    ("time_s", "time [s]"),
    ("position_m", "train head position [m]"),
    ("speed_mps", "speed [m/s]"),
    ("accel_mps2", "acceleration over the step from time_s to time_s + dt [m/s^2]"),
    ("ref_position_m", "reference position [m]"),
    ("ref_speed_mps", "reference speed [m/s]"),
    ("ref_accel_mps2", "reference acceleration [m/s^2]"),
    ("command_mps2", "controller command, acceleration [m/s^2]"),
    ("demand_n", "brake force demand [N]"),
    ("electric_n", "electric brake force [N]"),
    ("air_n", "air (shoe) brake force [N]; the whole brake force for a lag-delay brake"),
    ("odometer_m", "position the ATO believes (odometry) [m]"),
)

#: Metrics every run reports, with units and definitions (docs/metrics.md).
METRICS: dict[str, str] = {
    "stop_error_m": "stop position minus stop point [m]; + overshoot, - short",
    "stop_time_s": "time from the braking point to standstill [s] (nan if not stopped)",
    "max_speed_error_mps": "max |v - v_ref(t)| while moving [m/s]",
    "rms_speed_error_mps": "RMS of v - v_ref(t) while moving [m/s]",
    "speed_error_at_changeover_mps": "|v - v_ref(t)| when v first drops to the changeover speed",
    "max_decel_mps2": "max deceleration while moving [m/s^2]",
    "max_jerk_mps3": "max |d/dt (E + A) / m_eff| while moving [m/s^3]: jerk of the brake's "
    "deceleration (outside-force steps and the stopping instant excluded)",
    "max_position_error_m": "max |x - x_ref(t)| while moving [m]",
    "energy_electric_j": "energy taken by the electric brake (regenerated) [J]",
    "energy_friction_j": "energy dissipated by the shoes [J]",
    "odometry_error_at_stop_m": "odometer position minus true position at the end [m]",
    "slide_time_s": "time the wheels slid (adhesion exceeded) [s]",
    "energy_traction_j": "work done by traction at the wheel [J]",
    "energy_traction_against_air_j": "work traction did against the air brake at the wheel: "
    "the smaller of the two forces while both act, times the distance [J]",
    "max_speed_mps": "highest speed of the run [m/s]",
    "max_speed_kmh": "highest speed of the run [km/h]",
    "running_time_s": "time to the stop (nan if the train did not stop) [s]",
    "energy_traction_kwh": "traction energy drawn from the supply: wheel work / the traction "
    "chain's efficiency (1 for an actuator without one) [kWh]",
    "energy_regenerated_kwh": "electric braking energy returned to the supply: wheel work x "
    "the regeneration efficiency (1 for an actuator without one) [kWh]",
    "energy_traction_against_air_kwh": "of the traction energy drawn, what pulled against the "
    "air brake (energy_traction_against_air_j / the traction chain's efficiency) [kWh]",
}


@dataclass
class SimResult:
    """Time series (dict of equal-length NumPy arrays), metrics and metadata of one run."""

    series: dict[str, np.ndarray]
    metrics: dict[str, float]
    meta: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.series[name]

    def to_pandas(self) -> pd.DataFrame:
        """The time series as a DataFrame indexed by time."""
        import pandas as pd

        frame = pd.DataFrame(self.series)
        return frame.set_index("time_s")

    def to_csv(self, path: Path) -> Path:
        """Write the time series as CSV (header = channel names)."""
        self.to_pandas().to_csv(path)
        return path

    def to_parquet(self, path: Path) -> Path:
        """Write the time series as Parquet, with metrics and metadata in the schema."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pydict(self.series)
        info = {"metrics": self.metrics, "meta": self.meta}
        table = table.replace_schema_metadata({"railpilot": json.dumps(info, default=str)})
        pq.write_table(table, path)
        return path

    def summary(self) -> dict[str, float]:
        """Metrics as plain floats (JSON-ready; nan becomes None)."""
        return {
            k: (None if not np.isfinite(v) else float(v))  # type: ignore[misc]
            for k, v in self.metrics.items()
        }
