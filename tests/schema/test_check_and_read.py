"""The schema layer's two halves: a file read (TOML or JSON, a syntax error naming its line)
and a parsed file checked, the first fault named as the file writes it, with its value and
what is allowed."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Annotated, Any, Literal

import pytest
from pydantic import Field

from railpilot.errors import MISSING, ConfigError, ScenarioError
from railpilot.scenario.consist_file import (
    ConsistError,
    consist_preset,
    consist_to_mapping,
    load_consist,
    write_consist,
)
from railpilot.scenario.consist_scenario import consist_scenario_from_mapping
from railpilot.schema.fields import FileTable, FloatHeld, ScenarioWords, Unit, WhenMissing
from railpilot.schema.reading import read_document
from railpilot.schema.validate import check


class Leaf(FileTable):
    width_mm: Annotated[float, Field(gt=0.0, le=10.0), Unit("mm")]
    count: Annotated[int, Field(ge=1, le=5)] = 1


class Cat(FileTable):
    kind: Literal["cat"]
    lives: Annotated[int, FloatHeld()] = 9


class Dog(FileTable):
    kind: Literal["dog"]
    bark: bool = True


class Tree(FileTable):
    name: Annotated[str, Field(min_length=1), WhenMissing("the tree's name (the key is required)")]
    leaves: list[Leaf] = Field(default_factory=list)
    pets: dict[str, Annotated[Cat | Dog, Field(discriminator="kind")]] = Field(default_factory=dict)


class ScenarioLeaf(Leaf):
    WORDS = ScenarioWords


class ScenarioTree(Tree):
    """Each table words its own errors: these the scenario files' way."""

    WORDS = ScenarioWords
    leaves: list[ScenarioLeaf] = Field(default_factory=list)


def _fault(model: type[FileTable], data: Any) -> ConfigError:
    with pytest.raises(ConfigError) as info:
        check(model, data, ConfigError)
    return info.value


GOOD: dict[str, Any] = {
    "name": "oak",
    "leaves": [{"width_mm": 2.0}, {"width_mm": 3.0, "count": 2}],
    "pets": {"tom": {"kind": "cat"}, "rex": {"kind": "dog", "bark": False}},
}


def test_a_good_table_reads_into_the_model_with_its_defaults_and_what_was_given() -> None:
    tree = check(Tree, GOOD, ConfigError)
    assert [leaf.count for leaf in tree.leaves] == [1, 2]
    assert not tree.leaves[0].given("count") and tree.leaves[1].given("count")
    assert isinstance(tree.pets["tom"], Cat) and tree.pets["tom"].lives == 9


@pytest.mark.parametrize(
    ("change", "field", "value", "allowed"),
    [
        (
            ("leaves", 1, "width_mm", 0),
            "leaves[1].width_mm",
            0,
            "a finite number > 0 and <= 10 [mm]",
        ),
        (("leaves", 0, "width_mm", True), "leaves[0].width_mm", True, "a finite number > 0"),
        (("leaves", 0, "width_mm", float("nan")), "leaves[0].width_mm", None, "a finite number"),
        (("leaves", 1, "count", 6), "leaves[1].count", 6, "a whole number from 1 to 5"),
        (("pets", "tom", "lives", 10**400), "pets.tom.lives", 10**400, "a float can hold"),
        (("pets", "rex", "bark", "yes"), "pets.rex.bark", "yes", "true or false"),
        (("pets", "rex", "kind", "fish"), "pets.rex.kind", "fish", "one of cat, dog"),
        (("name", ""), "name", "", "a non-empty string"),
    ],
)
def test_the_first_fault_names_the_key_as_the_file_writes_it(
    change: tuple[Any, ...], field: str, value: Any, allowed: str
) -> None:
    data = json.loads(json.dumps(GOOD))
    table = data
    for key in change[:-2]:
        table = table[key]
    table[change[-2]] = change[-1]
    fault = _fault(Tree, data)
    assert fault.field == field
    if value is not None:
        assert fault.value == value
    assert allowed in fault.allowed


def test_an_unknown_key_is_refused_listing_the_table_s_keys() -> None:
    fault = _fault(Tree, {**GOOD, "leaves": [{"width_mm": 1.0, "colour": "green"}]})
    assert fault.field == "leaves[0].colour" and fault.value == "green"
    assert fault.allowed == "a known key instead of 'colour' (allowed here: width_mm, count)"


def test_a_missing_key_says_what_it_must_be() -> None:
    fault = _fault(Tree, {"leaves": []})
    assert (fault.field, fault.value) == ("name", MISSING)
    assert fault.allowed == "the tree's name (the key is required)"
    fault = _fault(Tree, {"name": "oak", "leaves": [{}]})
    assert fault.allowed == "a finite number > 0 and <= 10 [mm] (the key is required)"


def test_a_file_that_is_no_table_is_named_as_the_file() -> None:
    assert _fault(Tree, [1, 2]).field == "<file>"


def test_the_scenario_files_words() -> None:
    fault = _fault(ScenarioTree, {"name": "oak", "leaves": [{"width_mm": -1.0}], "x": 1})
    assert fault.allowed == "a number > 0 and <= 10"  # the first fault, in the file's order
    fault = _fault(ScenarioTree, {"name": "oak", "x": 1})
    assert fault.allowed == "a known key instead of 'x' (known here: leaves, name, pets)"


# --- reading --------------------------------------------------------------------------------


def test_a_consist_file_in_json_reads_as_its_toml_twin(tmp_path: Path) -> None:
    preset = consist_preset("heavy-haul-20kt-dp")
    toml_file = tmp_path / "train.toml"
    write_consist(preset, toml_file)
    json_file = tmp_path / "train.json"
    document = {"$schema": "../schemas/consist.schema.json", **consist_to_mapping(preset)}
    json_file.write_text(json.dumps(document), encoding="utf-8")
    assert load_consist(json_file) == load_consist(toml_file)


def test_a_syntax_error_names_the_file_line_and_column(tmp_path: Path) -> None:
    broken = tmp_path / "train.json"
    broken.write_text('{"name": "x",\n "train": [}', encoding="utf-8")
    with pytest.raises(ConsistError, match=r"valid JSON \(.* at line 2, column 12\)") as info:
        load_consist(broken)
    assert str(info.value).startswith(f"{broken}: ")
    broken = tmp_path / "train.toml"
    broken.write_text('name = "x"\n\ntrain = [1,,]\n', encoding="utf-8")
    with pytest.raises(ConsistError, match=r"valid TOML \(.*at line 3, column"):
        load_consist(broken)


def test_a_file_that_cannot_be_read_names_the_option(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="existing scenario file") as info:
        read_document(tmp_path / "none.json", "SCENARIO", "scenario file", ScenarioError)
    assert info.value.field == "SCENARIO"


# --- the train-dynamics scenario over the layer ---------------------------------------------

DYNAMICS: dict[str, Any] = {
    "name": "short",
    "kind": "train-dynamics",
    "consist": "heavy-haul-10kt",
    "line": {"gradients": [{"start_km": 0.0, "end_km": 5.0, "permille": -4.0}]},
    "air": {"application_time_s": 20.0},
    "sim": {"duration_s": 60.0, "lump": 5},
    "driver": {"commands": [{"at_s": 0.0, "effort": 0.0}, {"at_s": 2.0, "release": True}]},
}


def _dynamics_fault(**changes: Any) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        consist_scenario_from_mapping({**DYNAMICS, **changes})
    return info.value


def test_a_train_dynamics_file_reads_its_keys_and_leaves_the_rest_to_the_defaults() -> None:
    scenario = consist_scenario_from_mapping(DYNAMICS)
    assert scenario.air.application_time_s == 20.0
    assert scenario.sim.lump == 5 and scenario.sim.duration_s == 60.0
    assert scenario.driver.commands[1].reduction_kpa == 0.0  # release: a zero reduction
    assert scenario.line.gradients[0].end_m == 5000.0


def test_a_train_dynamics_file_s_errors_name_the_key() -> None:
    bad = {"commands": [{"at_s": -1.0}]}
    assert _dynamics_fault(driver=bad).field == "driver.commands[0].at_s"
    assert _dynamics_fault(sim={"lump": 10**400}).allowed.startswith("an integer a float")
    assert _dynamics_fault(air={"charged_kpa": 500.0}).field == "air.charged_kpa"
    twice = {"commands": [{"at_s": 1.0, "release": True, "reduction_kpa": 60.0}]}
    assert _dynamics_fault(driver=twice).field == "driver.commands[0].release"
    fault = _dynamics_fault(line={"curves": [{"start_km": 0.0, "end_km": 1.0}]})
    assert (fault.field, fault.allowed) == (
        "line.curves[0].radius_m",
        "a number (the key is required)",
    )
    assert _dynamics_fault(consist="my_train.csv").field == "consist"


# --- every reader over the layer takes JSON as well as TOML ----------------------------------

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.mark.parametrize(
    ("example", "reader"),
    [
        ("paper000_montecarlo.toml", "scenario"),
        ("heavy_haul_run.toml", "scenario"),
        ("line_live_short.toml", "line-run"),
    ],
)
def test_an_example_written_as_json_reads_as_the_toml_file(
    example: str, reader: str, tmp_path: Path
) -> None:
    from railpilot.cosim.scenario import load_line_scenario as load_line_run
    from railpilot.scenario.loader import load_scenario_and_spec

    load = load_scenario_and_spec if reader == "scenario" else load_line_run
    source = EXAMPLES / example
    twin = tmp_path / f"{source.stem}.json"
    data = tomllib.loads(source.read_text(encoding="utf-8"))
    twin.write_text(json.dumps({"$schema": "schemas/x.json", **data}), encoding="utf-8")
    assert repr(load(twin)) == repr(load(source))
