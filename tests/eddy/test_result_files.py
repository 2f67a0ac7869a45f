"""Issue 9 item 8: the eddy-brake loop's result writes the stopping simulator's files,
and ``load_scenario`` reads the eddy-brake examples too."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
from numpy.testing import assert_allclose

from railpilot.eddy.scenario import EddyScenario
from railpilot.scenario import load_scenario
from railpilot.scenario.model import Scenario

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def test_load_scenario_reads_both_kinds() -> None:
    assert isinstance(load_scenario(EXAMPLES / "eddy_case1.toml"), EddyScenario)
    assert isinstance(load_scenario(EXAMPLES / "paper002_qsmc_stop.toml"), Scenario)


def test_an_eddy_result_writes_csv_and_parquet_like_a_braking_result(tmp_path: Path) -> None:
    scenario = load_scenario(EXAMPLES / "eddy_case1.toml")
    assert isinstance(scenario, EddyScenario)
    short = dataclasses.replace(scenario, duration_s=0.2)
    result, _ = short.run("pid", record_every=10)
    csv = pd.read_csv(result.to_csv(tmp_path / "run.csv"), index_col=0)
    assert_allclose(csv["torque_nm"].to_numpy(), result.torque_nm)
    assert_allclose(csv.index.to_numpy(), result.time_s)
    table = pq.read_table(result.to_parquet(tmp_path / "run.parquet"))
    assert_allclose(table.column("speed_mps").to_numpy(), result.speed_mps)
    assert b"railpilot" in table.schema.metadata
