"""Opening a Zenoh session from the ``[zenoh]`` section or from a tool's options."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any


def zenoh_config(
    mode: str = "peer",
    listen: Sequence[str] = (),
    connect: Sequence[str] = (),
    multicast_scouting: bool = True,
    config_file: str = "",
) -> Any:
    """A ``zenoh.Config``: the JSON5 file first (ACL, TLS, user/password), then our keys."""
    import zenoh

    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(bool(multicast_scouting)))
    return conf


def open_session(**kw: Any) -> Any:
    import zenoh

    return zenoh.open(zenoh_config(**kw))
