"""`cdprctl record --mcap`: the file reads back with Foxglove's MCAP reader, one channel per
key, the payloads unchanged, and a JSON Schema that validates them."""

from __future__ import annotations

import json

from mcap.reader import make_reader

from cdprctl.telemetry.mcap.mcap_log import json_schema, write_mcap


def _check(schema: dict, value: object) -> bool:
    """A minimal JSON Schema check (type, properties, items): independent of the writer."""
    types = schema.get("type")
    if types is not None:
        allowed = types if isinstance(types, list) else [types]
        kinds = {
            "object": dict,
            "array": list,
            "string": str,
            "boolean": bool,
            "number": (int, float),
            "null": type(None),
        }
        if not any(
            isinstance(value, kinds[t]) and not (t == "number" and isinstance(value, bool))
            for t in allowed
        ):
            return False
    if isinstance(value, dict):
        props = schema.get("properties", {})
        return all(_check(props[k], v) for k, v in value.items() if k in props)
    if isinstance(value, list):
        return all(_check(schema.get("items", {}), v) for v in value)
    return True


def test_mcap_round_trip(tmp_path):
    states = [
        {
            "schema": "cdprctl/1",
            "time": 10.0 + 0.01 * i,
            "state": "enabled",
            "pose": {"position": [1.5, 0.35, 0.59 + 1e-3 * i], "rpy": [0.0, None, 0.0]},
            "tensions": [100.0 + i] * 8,
            "grippers": [],
        }
        for i in range(5)
    ]
    event = {"schema": "cdprctl/1", "time": 10.02, "kind": "event", "text": "state a -> b"}
    records = [(1_000 + i, "state", json.dumps(s).encode()) for i, s in enumerate(states)]
    records.insert(3, (1_002, "events", json.dumps(event).encode()))
    records.append((1_010, "timing", b"{not json"))  # skipped, never written
    path = tmp_path / "telemetry.mcap"
    assert write_mcap(path, "cdpr/rowc", records) == 6
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.topic for c in summary.channels.values()}
        assert topics == {"cdpr/rowc/state", "cdpr/rowc/events"}
        got = list(reader.iter_messages())
    expected = ["cdpr/rowc/state"] * 3 + ["cdpr/rowc/events"] + ["cdpr/rowc/state"] * 2
    assert [channel.topic for _, channel, _ in got] == expected
    for schema, channel, message in got:
        assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
        body = json.loads(message.data)
        assert _check(json.loads(schema.data), body)
        assert message.publish_time == round(body["time"] * 1e9)
    assert [m.log_time for _, _, m in got] == sorted(m.log_time for _, _, m in got)
    assert [json.loads(m.data) for _, c, m in got if c.topic.endswith("state")] == states


def test_schema_describes_nested_payloads():
    s = json_schema({"a": [1.0, 2.0], "b": {"c": "x", "d": True}, "e": None, "f": []})
    assert s["properties"]["a"] == {"type": "array", "items": {"type": ["number", "null"]}}
    assert s["properties"]["b"]["properties"]["d"] == {"type": "boolean"}
    assert s["properties"]["e"] == {"type": ["number", "null"]}
    assert not _check(s, {"a": ["text"]})
