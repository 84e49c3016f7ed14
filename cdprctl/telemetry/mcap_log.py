"""A recording as MCAP, the log format Foxglove opens: one channel per telemetry key, the
payloads as they came (JSON, ``cdprctl/1``), each with a JSON Schema derived from its first
message so that Foxglove can list and plot the fields.

The container (records, CRCs, chunk indexes, summary) is written by ``mcap``, Foxglove's own
library: a reader's expectations of the format are what it encodes.
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


def write_mcap(path: Path, prefix: str, records: list[tuple[int, str, bytes]]) -> int:
    """Write ``records`` — (receive time in ns since the epoch, key under ``prefix``, JSON
    payload) in order of arrival — to ``path``; the publish time of a message is its
    payload's ``time`` when it has one. Returns the number of messages written."""
    from mcap.writer import Writer

    channels: dict[str, int] = {}
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
            writer.add_message(
                channel_id=channels[key],
                log_time=log_time,
                data=data,
                publish_time=round(stamp * 1e9) if isinstance(stamp, (int, float)) else log_time,
                sequence=n,
            )
            n += 1
        writer.finish()
    return n
