"""A recording as MCAP, the log format Foxglove opens: one channel per telemetry key, the
payloads as they came (JSON, ``cdprctl/1``), each with a JSON Schema derived from its first
message so that Foxglove can list and plot the fields.

With the robot's layout (the daemon's status), the same typed channels as the live view
(``foxglove_messages.py``: ``/tf``, ``/scene`` at ``scene_rate``, ``/signals``, ``/log``) are
written beside them, so a recording replays in Foxglove as the same 3D scene.

The container (records, CRCs, chunk indexes, summary) is written by ``mcap``, Foxglove's own
library: a reader's expectations of the format are what it encodes; the typed messages and
their schemas are ``foxglove-sdk``'s.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def json_schema(sample: Any) -> dict[str, Any]:
    """A JSON Schema (draft 2020-12 subset) describing ``sample``'s structure: objects with
    their properties, arrays of their first item's type, numbers, strings, booleans; a
    value that was ``null`` in the sample may be a number too (NaN is sent as ``null``)."""
    if isinstance(sample, dict):
        return {
            "type": "object",
            "properties": {k: json_schema(v) for k, v in sample.items()},
        }
    if isinstance(sample, list):
        return {"type": "array", "items": json_schema(sample[0]) if sample else {}}
    if isinstance(sample, bool):
        return {"type": "boolean"}
    if isinstance(sample, (int, float)):
        return {"type": ["number", "null"]}
    if isinstance(sample, str):
        return {"type": "string"}
    return {"type": ["number", "null"]}


def write_mcap(
    path: Path,
    prefix: str,
    records: list[tuple[int, str, bytes]],
    layout: dict[str, Any] | None = None,
    scene_rate: float = 30.0,
) -> int:
    """Write ``records`` — (receive time in ns since the epoch, key under ``prefix``, JSON
    payload) in order of arrival — to ``path``; the publish time of a message is its
    payload's ``time`` when it has one. With ``layout`` (``SceneLayout.to_dict``) the typed
    channels too, the scene at most ``scene_rate`` Hz. Returns the number of messages."""
    from mcap.writer import Writer

    channels: dict[str, int] = {}
    typed = _Typed(layout, scene_rate) if layout else None
    n = 0
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="cdprctl")
        for log_time, key, data in records:
            try:
                body = json.loads(data)
            except ValueError:
                continue
            if key not in channels:
                schema = writer.register_schema(
                    name=f"cdprctl.{key}",
                    encoding="jsonschema",
                    data=json.dumps(json_schema(body)).encode(),
                )
                channels[key] = writer.register_channel(
                    topic=f"{prefix}/{key}", message_encoding="json", schema_id=schema
                )
            stamp = body.get("time") if isinstance(body, dict) else None
            publish = round(stamp * 1e9) if isinstance(stamp, (int, float)) else log_time
            writer.add_message(
                channel_id=channels[key],
                log_time=log_time,
                data=data,
                publish_time=publish,
                sequence=n,
            )
            n += 1
            if typed is not None and isinstance(body, dict):
                for topic, encoding, schema_, payload in typed.messages(key, body, log_time):
                    if topic not in channels:
                        sid = writer.register_schema(name=schema_.name, encoding=schema_.encoding,
                                                     data=bytes(schema_.data))  # fmt: skip
                        channels[topic] = writer.register_channel(
                            topic=topic, message_encoding=encoding, schema_id=sid
                        )
                    writer.add_message(channel_id=channels[topic], log_time=log_time,
                                       data=payload, publish_time=log_time, sequence=n)  # fmt: skip
                    n += 1
        writer.finish()
    return n


class _Typed:
    """The live view's typed messages of each recorded payload."""

    def __init__(self, layout: dict[str, Any], scene_rate: float):
        import foxglove
        from foxglove.messages import FrameTransforms, Log, SceneUpdate

        from cdprctl.telemetry.foxglove import foxglove_messages as fm
        from cdprctl.telemetry.foxglove.scene import SceneBuilder, SceneLayout

        self.fm = fm
        self.schemas = {"tf": FrameTransforms.get_schema(), "scene": SceneUpdate.get_schema(),
                        "log": Log.get_schema()}  # fmt: skip
        SIGNALS_SCHEMA, SceneMessages = fm.SIGNALS_SCHEMA, fm.SceneMessages

        lay = SceneLayout.from_dict(layout)
        self.builder, self.scene = SceneBuilder(lay), SceneMessages(lay)
        self.every = round(1e9 / scene_rate)
        self.next = 0
        self.signals_schema = foxglove.Schema(name="cdprctl.signals", encoding="jsonschema",
                                              data=json.dumps(SIGNALS_SCHEMA).encode())  # fmt: skip

    def messages(
        self, key: str, body: dict[str, Any], ns: int
    ) -> list[tuple[str, str, Any, bytes]]:
        """(topic, message encoding, schema, payload) of what ``body`` (a ``key`` payload
        received at ``ns``) becomes."""
        fm, schemas, topics = self.fm, self.schemas, self.fm.TOPICS
        if key == "events":
            msg = fm.log_message(ns, str(body.get("kind", "event")), str(body.get("text", "")))
            return [(topics["log"], "protobuf", schemas["log"], msg.encode())]
        if key != "state" or "pose" not in body:
            return []
        out = [(topics["signals"], "json", self.signals_schema, fm.signals_bytes(body))]
        sc = self.builder.build(body) if ns >= self.next else None
        if sc is not None:
            self.next = max(self.next + self.every, ns - self.every // 2)
            out.append((topics["tf"], "protobuf", schemas["tf"],
                        fm.transforms(sc, ns).encode()))  # fmt: skip
            out.append((topics["scene"], "protobuf", schemas["scene"],
                        self.scene.update(sc, ns).encode()))  # fmt: skip
        return out
