"""Controller parameters in a scenario file: wrong shapes are refused by key, never crash."""

from __future__ import annotations

import pytest

from railpilot.errors import ScenarioError
from railpilot.scenario import scenario_from_mapping


@pytest.mark.parametrize(
    ("controller", "params", "key", "allowed"),
    [
        ("pid", {"kp": "x"}, "controller.pid.kp", "a number"),
        ("smarc", {"c": "x"}, "controller.smarc.c", "a number"),
        ("smarc", {"gamma": [1]}, "controller.smarc.gamma", "a list of 2"),  # used to crash
        ("smarc", {"theta_bounds": [[1, 2], [3]]}, "controller.smarc.theta_bounds", "a list"),
        ("smarc", {"output_limits": [1]}, "controller.smarc.output_limits", "a list of 2"),
        ("qsmc", {"c": [1, 2]}, "controller.qsmc.c", "a number"),
        ("qsmc", {"keep_q": 1}, "controller.qsmc.keep_q", "true or false"),
        ("smarc", {"c": -1}, "controller.smarc.c", ">= 0"),
        ("qsmc", {"eps": -1}, "controller.qsmc.eps", "> 0"),
        ("pid", {"anti_windup": "x"}, "controller.pid.anti_windup", "'clamp' or 'backcalc'"),
    ],
)
def test_bad_controller_value_names_the_key(
    controller: str, params: dict[str, object], key: str, allowed: str
) -> None:
    with pytest.raises(ScenarioError) as info:
        scenario_from_mapping({"name": "t", "controller": {controller: params}})
    assert info.value.field == key
    assert allowed in info.value.allowed


def test_good_controller_values_load() -> None:
    scenario = scenario_from_mapping(
        {"name": "t", "controller": {"name": "pid", "pid": {"kp": 2, "output_limits": [-1, 0.5]}}}
    )
    assert scenario.controller.params["pid"]["kp"] == 2
