"""Logs every viewer decodes (issue 11, item 1): one JSON-schema `type` per field (Foxglove's
JSON-schema support refuses a topic whose schema has a type union), absent values omitted rather
than null, and a Foxglove layout that names only topics and fields the logs have."""

from __future__ import annotations

import json
import re
from pathlib import Path

import jsonschema
import pytest

from runlog import vmain, read_log, write_show

ROOT = Path(__file__).resolve().parent.parent
LOG_SCHEMAS = sorted((ROOT / "schemas").glob("log.*.schema.json")) + [ROOT / "schemas" / "foxglove.Log.schema.json"]


def fields(schema: dict, path: str = ""):
    """Every (path, sub-schema) that describes a value, properties and array items included."""
    yield path or "/", schema
    for name, sub in schema.get("properties", {}).items():
        yield from fields(sub, f"{path}.{name}")
    if isinstance(schema.get("items"), dict):
        yield from fields(schema["items"], f"{path}[]")


@pytest.mark.parametrize("path", LOG_SCHEMAS, ids=lambda p: p.name)
def test_every_log_schema_field_has_one_type(path):
    schema = json.loads(path.read_text())
    for where, sub in fields(schema):
        kind = sub.get("type")
        if kind is None:  # foxglove.Log's level: Foxglove's own enum, which it knows
            assert path.name == "foxglove.Log.schema.json", where
            continue
        assert isinstance(kind, str), f"{path.name} {where}: a type union {kind} (Foxglove refuses it)"
        if kind == "array":
            assert isinstance(sub.get("items", {}).get("type"), str), f"{path.name} {where}: untyped items"


SHOW = """
    version: 1
    name: viewers
    motions:
      home: {number: 0, duration: 0.05}
    on_abort: home
    steps:
      - play: 3
        label: first
        at: 0.05
      - wait: done
      - wait: 0.05
      - play: 4
"""


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    directory = tmp_path_factory.mktemp("viewers")
    path = directory / "run.mcap"
    show = write_show(directory, SHOW)
    assert vmain(["run", str(show), "--log", str(path), "--port", "sim://?drop=7&motion_s=0.1",
                 "--timeout", "0.05", "-q"]) == 0
    return read_log(path)


def test_logged_messages_match_their_schemas_and_hold_no_null(log):
    schemas = {path.name: json.loads(path.read_text()) for path in LOG_SCHEMAS}
    by_topic = {"/rcb4/tx": "log.tx.schema.json", "/rcb4/rx": "log.rx.schema.json",
                "/choreo/step": "log.step.schema.json", "/choreo/log": "foxglove.Log.schema.json",
                "/choreo/clock": "log.clock.schema.json"}
    seen = set()
    for topic, messages in log.messages.items():
        for message in messages:
            message = {k: v for k, v in message.items() if not k.startswith("_")}
            jsonschema.validate(message, schemas[by_topic[topic]])
            assert None not in message.values(), (topic, message)
            seen.update(f"{topic}.{key}" for key in message)
    # the optional fields do appear where they have a value
    assert {"/rcb4/tx.step", "/rcb4/tx.label", "/rcb4/tx.motion", "/rcb4/rx.executing",
            "/rcb4/rx.error", "/choreo/step.cue", "/choreo/step.outcome"} <= seen


def test_the_foxglove_layout_names_only_what_logs_have():
    layout = json.loads((ROOT / "foxglove" / "choreo-layout.json").read_text())
    panels = layout["configById"]
    schemas = {"/rcb4/tx": "log.tx", "/rcb4/rx": "log.rx", "/choreo/step": "log.step"}

    def field_exists(topic: str, field: str) -> bool:
        schema = json.loads((ROOT / "schemas" / f"{schemas[topic]}.schema.json").read_text())
        return field in schema["properties"] and schema["properties"][field]["type"] in ("number", "integer")

    plotted = [p["value"] for panel, config in panels.items() if panel.startswith("Plot!") for p in config["paths"]]
    assert plotted
    for value in plotted:
        topic, field = re.fullmatch(r"(/[a-z0-9/]+)(?:\{[^}]*\})?\.(\w+)", value).groups()
        assert field_exists(topic, field), value
    assert any(config.get("topicPath") == "/rcb4/tx" for config in panels.values())
    assert any(panel.startswith("RosOut!") for panel in panels)

    def leaves(node):
        if isinstance(node, str):
            yield node
        else:
            yield from leaves(node["first"])
            yield from leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


def test_the_logs_format_is_spelled_in_one_module():
    """Topic names and message decoding live in choreo/log/format.py: a reader elsewhere that
    spelled a topic or parsed a message's JSON itself would drift from what the recorder writes."""
    import re

    package = Path(__file__).resolve().parent.parent / "choreo"
    spelled = re.compile(r"""["'](/rcb4/|/choreo/)|json\.loads\(|(?<![.\w])decode\(""")
    offenders = [f"{path.relative_to(package)}:{number}"
                 for path in package.rglob("*.py") if path.relative_to(package).as_posix() != "log/format.py"
                 for number, line in enumerate(path.read_text().splitlines(), 1)
                 if spelled.search(line) and "show/" not in str(path.relative_to(package))]
    assert offenders == []


def test_a_merged_log_of_two_hosts_decodes_on_every_topic(tmp_path):
    """`choreo log merge` (issue 25): every channel carries its JSON schema and every message on
    it validates against that schema as stored in the file (what Foxglove decodes with), no null."""
    from mcap.reader import make_reader

    from hostlogs import merged_hosts

    merged = merged_hosts(tmp_path).merged
    topics = set()
    with open(merged, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "jsonschema" and channel.message_encoding == "json"
            decoded = json.loads(message.data)
            jsonschema.validate(decoded, json.loads(schema.data))
            assert None not in decoded.values(), (channel.topic, decoded)
            topics.add(channel.topic)
    assert {"/rcb4/lead/tx", "/rcb4/follow/rx", "/choreo/follow/step", "/choreo/stageleft/clock",
            "/choreo/stageright/clock"} <= topics
