"""The Foxglove layout config/foxglove/rig_layout.json (docs/foxglove.md), checked without Foxglove.

The test does not open the layout in Foxglove (docs/foxglove.md says why). What it checks instead: the file
follows the layout format that Foxglove's and Lichtblick's "Import layout from file" read (``configById``,
``globalVariables``, ``userNodes``, ``playbackConfig``, a mosaic tree in ``layout``; the panel configs of
Lichtblick 1.10's ``Plot``, ``CallService``, ``RawMessages`` and ``Parameters`` panels), as a JSON schema
written here and applied by a small validator; every panel of the tree has a config and every config is
placed; and every message path names a rig topic and a field of that topic's message definition (the
installed ``.msg`` files), and the service panel a rig service with a request of its request type.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from rimd_sim.io.msgdefs import message_definition, service_definitions

LAYOUT = "config/foxglove/rig_layout.json"
TOPICS = {"/rig/cart/displacement": "rimd_msgs/msg/SampleBlock", "/rig/rimd/displacement": "rimd_msgs/msg/SampleBlock",
          "/rig/rimd/acceleration": "rimd_msgs/msg/SampleBlock", "/rig/impact/force": "rimd_msgs/msg/SampleBlock",
          "/rig/impact/events": "rimd_msgs/msg/ImpactEvent", "/rig/motor/state": "rimd_msgs/msg/MotorState",
          "/rig/faults": "rimd_msgs/msg/FaultEvent"}

_PATH = {"type": "object", "required": ["value", "enabled", "timestampMethod"],
         "properties": {"value": {"type": "string"}, "enabled": {"type": "boolean"},
                        "timestampMethod": {"enum": ["receiveTime", "headerStamp"]}, "label": {"type": "string"}}}
#: The layout format, as a JSON schema (draft 7 subset: type, required, properties, enum, items,
#: additionalProperties, oneOf).
SCHEMA = {
    "type": "object",
    "required": ["configById", "globalVariables", "userNodes", "playbackConfig", "layout"],
    "properties": {
        "configById": {"type": "object"},
        "globalVariables": {"type": "object"},
        "userNodes": {"type": "object"},
        "playbackConfig": {"type": "object", "required": ["speed"], "properties": {"speed": {"type": "number"}}},
        "layout": {"$ref": "#/definitions/mosaic"},
    },
    "definitions": {"mosaic": {"oneOf": [
        {"type": "string"},
        {"type": "object", "required": ["direction", "first", "second"],
         "properties": {"direction": {"enum": ["row", "column"]}, "first": {"$ref": "#/definitions/mosaic"},
                        "second": {"$ref": "#/definitions/mosaic"}, "splitPercentage": {"type": "number"}}},
    ]}},
}
PANELS = {
    "Plot": {"type": "object", "required": ["paths", "showLegend", "legendDisplay", "showPlotValuesInLegend",
                                            "showXAxisLabels", "showYAxisLabels", "isSynced", "xAxisVal",
                                            "sidebarDimension"],
             "properties": {"paths": {"type": "array", "items": _PATH},
                            "xAxisVal": {"enum": ["timestamp", "index", "custom", "currentCustom"]},
                            "legendDisplay": {"enum": ["floating", "top", "left", "none"]}}},
    "CallService": {"type": "object", "required": ["serviceName", "requestPayload"],
                    "properties": {"serviceName": {"type": "string"}, "requestPayload": {"type": "string"},
                                   "layout": {"enum": ["vertical", "horizontal"]}}},
    "RawMessages": {"type": "object", "required": ["topicPath", "diffTopicPath", "diffMethod", "diffEnabled",
                                                   "showFullMessageForDiff"],
                    "properties": {"topicPath": {"type": "string"}, "diffMethod": {"enum": ["custom",
                                                                                           "previous message"]}}},
    "Parameters": {"type": "object"},
}
_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "number": (int, float)}


def validate(instance, schema, root=None, where="$") -> list[str]:
    """The places where ``instance`` breaks ``schema`` (the subset of JSON schema used above)."""
    root = root or schema
    if "$ref" in schema:
        schema = root["definitions"][schema["$ref"].rsplit("/", 1)[-1]]
    if "oneOf" in schema:
        ok = [s for s in schema["oneOf"] if not validate(instance, s, root, where)]
        return [] if len(ok) == 1 else [f"{where}: matches {len(ok)} of the oneOf alternatives"]
    errors = []
    expected = _TYPES.get(schema.get("type"))
    if expected is not None and (not isinstance(instance, expected) or isinstance(instance, bool) != (
            schema["type"] == "boolean")):
        return [f"{where}: not a {schema['type']}"]
    if "enum" in schema and instance not in schema["enum"]:
        errors.append(f"{where}: {instance!r} not one of {schema['enum']}")
    if isinstance(instance, dict):
        errors += [f"{where}: '{key}' missing" for key in schema.get("required", []) if key not in instance]
        for key, sub in schema.get("properties", {}).items():
            if key in instance:
                errors += validate(instance[key], sub, root, f"{where}.{key}")
    if isinstance(instance, list) and "items" in schema:
        for i, item in enumerate(instance):
            errors += validate(item, schema["items"], root, f"{where}[{i}]")
    return errors


def _leaves(node) -> list[str]:
    return [node] if isinstance(node, str) else _leaves(node["first"]) + _leaves(node["second"])


def _fields(type_name: str) -> dict[str, str]:
    """Field name -> type of a message (its own .msg text, before the dependencies)."""
    text = message_definition(type_name).text.split("=" * 80)[0]
    fields = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line and "=" not in line:
            kind, name = line.split()[:2]
            fields[name] = kind
    return fields


@pytest.fixture(scope="module")
def layout(repo_root) -> dict:
    return json.loads((Path(repo_root) / LAYOUT).read_text(encoding="utf-8"))


def test_the_layout_follows_the_layout_format(layout):
    assert validate(layout, SCHEMA) == []
    placed = _leaves(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"]), "every panel placed once, every placed panel configured"
    for panel_id, config in layout["configById"].items():
        kind = panel_id.split("!", 1)[0]
        assert kind in PANELS, panel_id
        assert validate(config, PANELS[kind], where=panel_id) == []
    kinds = [panel_id.split("!", 1)[0] for panel_id in placed]
    assert kinds.count("Plot") == 6 and {"CallService", "RawMessages", "Parameters"} <= set(kinds)


def test_every_message_path_names_a_rig_topic_and_a_field_of_its_message(layout):
    paths = [p["value"] for c in layout["configById"].values() for p in c.get("paths", [])]
    paths += [c["topicPath"] for c in layout["configById"].values() if "topicPath" in c]
    plotted = set()
    for path in paths:
        match = re.fullmatch(r"(/[\w/]+?)(?:\.(\w+)(\[\d+\])?)?", path)
        assert match, path
        topic, field, index = match.groups()
        assert topic in TOPICS, path
        plotted.add(topic)
        if field is not None:
            kind = _fields(TOPICS[topic]).get(field)
            assert kind is not None, f"{path}: {TOPICS[topic]} has no field {field}"
            assert kind.endswith("[]") == (index is not None), f"{path}: an array is indexed, a number is not"
            assert kind.removesuffix("[]") in ("float64", "uint64"), f"{path}: not a number to plot"
    # The four channels, the impact events' peak force, the motor state, the faults (docs/foxglove.md, The layout).
    assert plotted == set(TOPICS)
    assert "/rig/impact/events.peak_force" in paths


def test_the_service_panel_calls_set_motor_frequency_with_a_request_of_its_type(layout):
    (config,) = [c for k, c in layout["configById"].items() if k.startswith("CallService!")]
    assert config["serviceName"] == "/rig/set_motor_frequency"
    request, _ = service_definitions("rimd_msgs/srv/SetMotorFrequency")
    fields = {line.split()[1] for line in request.text.split("=" * 80)[0].splitlines()
              if line.strip() and not line.lstrip().startswith("#")}
    payload = json.loads(config["requestPayload"])
    assert set(payload) <= fields and "frequency_hz" in payload
