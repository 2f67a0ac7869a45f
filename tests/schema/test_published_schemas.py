"""The JSON Schemas under schemas/ are the ones the code generates, `railpilot schema` prints
them, and every shipped file of a format is one its schema accepts."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path
from typing import Any

import pytest
from tests.link.helpers import KEY_FILE

from railpilot.cli import main
from railpilot.line.loader import SHIPPED_LINES
from railpilot.onboard.timetable import SHIPPED as TIMETABLES
from railpilot.schema.formats import FORMATS, json_schema, schema_text

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "schemas"
CONSISTS = ROOT / "src" / "railpilot" / "vehicle" / "data" / "consists"

#: every shipped file of each format
EXAMPLES = sorted((ROOT / "examples").glob("*.toml"))
SHIPPED: dict[str, list[Path]] = {
    "scenario": [
        p
        for p in EXAMPLES
        if tomllib.loads(p.read_text()).get("kind", "ep-braking") == "ep-braking"
        and "[[services]]" not in p.read_text()
    ],
    "consist": sorted(p for p in CONSISTS.glob("*.toml") if p.name != "library.toml"),
    "consist-library": [CONSISTS / "library.toml"],
    "line-run": sorted(
        p for p in (ROOT / "examples").glob("*.toml") if "[[services]]" in p.read_text()
    ),
    "eddy-brake": sorted(
        p for p in (ROOT / "examples").glob("*.toml") if 'kind = "eddy-brake"' in p.read_text()
    ),
    "line": [ROOT / "src" / "railpilot" / "line" / "data" / f for f in SHIPPED_LINES.values()],
    "timetable": [ROOT / "src" / "railpilot" / "line" / "data" / f for f in TIMETABLES.values()],
    "train-dynamics": sorted(
        p for p in (ROOT / "examples").glob("*.toml") if 'kind = "train-dynamics"' in p.read_text()
    ),
}


@pytest.mark.parametrize("name", list(FORMATS))
def test_the_committed_schema_is_the_generated_one(name: str) -> None:
    path = SCHEMAS / FORMATS[name].file_name
    assert path.read_text(encoding="utf-8") == schema_text(name), (
        f"{path} is out of date: run `railpilot schema --write schemas`"
    )


def test_schemas_holds_a_schema_for_each_format_and_nothing_else() -> None:
    assert sorted(p.name for p in SCHEMAS.iterdir()) == sorted(
        f.file_name for f in FORMATS.values()
    )


def test_the_write_option_writes_what_the_test_compares(tmp_path: Path) -> None:
    assert main(["schema", "--write", str(tmp_path)]) == 0
    for name, fmt in FORMATS.items():
        assert (tmp_path / fmt.file_name).read_text(encoding="utf-8") == schema_text(name)


def test_the_command_prints_one_format_s_schema_as_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", "consist"]) == 0
    assert json.loads(capsys.readouterr().out) == json_schema("consist")


def test_the_list_names_every_format(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", "--list"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == list(FORMATS)


def test_an_unknown_format_exits_2_naming_the_formats(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["schema", "timetables"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "FORMAT = 'timetables'" in captured.err and "consist" in captured.err


# --- the shipped files against the published schemas --------------------------------------


def _resolve(schema: dict[str, Any], root: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in schema:
        schema = root["$defs"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


def _faults(value: Any, schema: dict[str, Any], root: dict[str, Any], where: str) -> list[str]:
    """What the schema's keywords that these formats use (type, enum, const, bounds,
    required, properties, additionalProperties, items, oneOf) say is wrong with
    ``value``: a small reader of the published schema, independent of the models."""
    schema = _resolve(schema, root)
    if "oneOf" in schema and "discriminator" in schema:
        tag = schema["discriminator"]["propertyName"]
        ref = schema["discriminator"]["mapping"].get(value.get(tag))
        if ref is None:
            return [f"{where}.{tag}: {value.get(tag)!r} is no variant"]
        return _faults(value, {"$ref": ref}, root, where)
    if "oneOf" in schema:  # exactly one of the alternatives
        fits = [not _faults(value, option, root, where) for option in schema["oneOf"]]
        return [] if fits.count(True) == 1 else [f"{where}: fits {fits.count(True)} variants"]
    kind = schema.get("type")
    types = {"object": dict, "array": list, "string": str, "boolean": bool}
    if kind in ("number", "integer"):
        ok = isinstance(value, int if kind == "integer" else int | float)
        if not ok or isinstance(value, bool):
            return [f"{where}: {value!r} is no {kind}"]
        low, high = schema.get("minimum", -float("inf")), schema.get("maximum", float("inf"))
        if not low <= value <= high or value <= schema.get("exclusiveMinimum", -float("inf")):
            return [f"{where}: {value!r} is out of bounds"]
        return []
    if kind in types and not isinstance(value, types[kind]):
        return [f"{where}: {value!r} is no {kind}"]
    if "enum" in schema and value not in schema["enum"]:
        return [f"{where}: {value!r} is not in {schema['enum']}"]
    if "const" in schema and value != schema["const"]:
        return [f"{where}: {value!r} is not {schema['const']!r}"]
    faults = []
    if kind == "object":
        properties = schema.get("properties", {})
        faults += [f"{where}.{k}: required" for k in schema.get("required", []) if k not in value]
        for key, item in value.items():
            if key in properties:
                faults += _faults(item, properties[key], root, f"{where}.{key}")
            elif isinstance(schema.get("additionalProperties"), dict):
                faults += _faults(item, schema["additionalProperties"], root, f"{where}.{key}")
            elif schema.get("additionalProperties") is False:
                faults.append(f"{where}.{key}: not a key of the format")
    if kind == "array" and "items" in schema:
        for i, item in enumerate(value):
            faults += _faults(item, schema["items"], root, f"{where}[{i}]")
    return faults


CASES = [(name, path) for name, paths in SHIPPED.items() for path in paths]


@pytest.mark.parametrize(("name", "path"), CASES, ids=[f"{n}:{p.name}" for n, p in CASES])
def test_every_shipped_file_is_one_its_schema_accepts(name: str, path: Path) -> None:
    root = json_schema(name)
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    assert _faults(data, root, root, path.name) == []


def test_the_schema_reader_of_these_tests_does_find_faults() -> None:
    root = json_schema("consist")
    data = tomllib.loads((SHIPPED["consist"][0]).read_text(encoding="utf-8"))
    bad = {**data, "brake_pipe_kpa": -1.0, "colour": "red", "train": [{"count": 1}]}
    faults = _faults(bad, root, root, "f")
    assert any("brake_pipe_kpa" in f for f in faults)
    assert any("colour" in f for f in faults)
    assert any("train[0].type: required" in f for f in faults)
    root = json_schema("scenario")
    data = tomllib.loads(SHIPPED["scenario"][0].read_text(encoding="utf-8"))
    bad = {**data, "reference": {"shape": "constant"}, "brake": {"model": "disc"}}
    faults = _faults(bad, root, root, "f")
    assert "f.reference: fits 0 variants" in faults and "f.brake: fits 0 variants" in faults


def test_every_format_has_a_shipped_file() -> None:
    # no key file is shipped (keys are secrets): the link tests' own is checked below
    assert set(SHIPPED) | {"keys"} == set(FORMATS)
    assert all(SHIPPED.values())


def test_the_link_tests_key_file_is_one_its_schema_accepts() -> None:
    root = json_schema("keys")
    data = tomllib.loads(KEY_FILE)
    assert _faults(data, root, root, "keys") == []
    assert _faults({"train": [{"id": "1001", "keys": {}}]}, root, root, "keys") != []
