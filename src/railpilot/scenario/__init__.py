"""Scenario files (TOML) -> validated, typed configuration.

The only place that reads files for the simulation. Bad input raises
:class:`~railpilot.errors.ScenarioError` naming the key, the value and what is
allowed, before anything runs.
"""

from railpilot.scenario.loader import load_scenario, scenario_from_mapping
from railpilot.scenario.model import ATOModel, ControllerSpec, Scenario, SimSettings

__all__ = [
    "ATOModel",
    "ControllerSpec",
    "Scenario",
    "SimSettings",
    "load_scenario",
    "scenario_from_mapping",
]
