"""The show schema for editors (issue 11, item 5): defaults and examples that are valid values,
and `choreo schema` pointing at the installed schema."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema

from choreo.cli import main

ROOT = Path(__file__).resolve().parent.parent
SCHEMA = json.loads((ROOT / "schemas" / "show.schema.json").read_text())


def described(node, path=""):
    if isinstance(node, dict):
        if "default" in node or "examples" in node:
            yield path, node
        for key, value in node.items():
            if key in ("properties", "$defs"):
                for name, sub in value.items():
                    yield from described(sub, f"{path}/{name}")
            elif key in ("items", "additionalProperties"):
                yield from described(value, f"{path}/{key}")


def test_every_default_and_example_is_a_value_the_schema_accepts():
    found = list(described(SCHEMA))
    assert len(found) >= 12
    for _path, node in found:
        sub = {**node, "$defs": SCHEMA["$defs"]}
        for value in ([node["default"]] if "default" in node else []) + node.get("examples", []):
            jsonschema.validate(value, sub)


def test_fields_an_editor_fills_in_have_defaults_that_are_not_zero():
    step = SCHEMA["$defs"]["step"]["properties"]
    assert step["timeout"]["default"] == 60 and step["repeat"]["default"] >= 1
    assert SCHEMA["$defs"]["robot"]["properties"]["timeout"]["default"] == 0.2


def test_choreo_schema_prints_the_installed_schema(capsys):
    assert main(["schema"]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path.is_absolute() and json.loads(path.read_text()) == SCHEMA
    assert main(["schema", "--modeline"]) == 0
    line = capsys.readouterr().out.strip()
    assert line == f"# yaml-language-server: $schema={path.as_uri()}"
