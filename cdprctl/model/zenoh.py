"""The ``[zenoh]`` section: where telemetry goes and whether commands are taken."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdprctl.model.reader import Flag, Number, TableReader, read_fields, read_section

ZENOH_KEYS = (
    "enabled",
    "prefix",
    "mode",
    "listen",
    "connect",
    "multicast_scouting",
    "state_rate",
    "timing_rate",
    "commands",
    "allow_unauthenticated_commands",
    "config_file",
)
_KEY_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")  # no wildcards, no $, no empty chunks


@dataclass(frozen=True)
class ZenohConfig:
    enabled: bool = False  # start the gateway with the daemon (`cdprctl run --zenoh` also does)
    prefix: str = ""  # key expression prefix; "" means cdpr/<robot name>
    mode: str = "peer"  # peer | client | router
    listen: tuple[str, ...] = ()  # Zenoh endpoints, e.g. "tcp/0.0.0.0:7447"
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = True
    state_rate: float = 100.0  # Hz, decimated from the loop
    timing_rate: float = 1.0  # Hz
    commands: bool = False  # commands are refused unless this is true
    # commands without authentication and a default-deny ACL (a bench on an isolated
    # network): the daemon then warns at start, in status and in every state payload
    allow_unauthenticated_commands: bool = False
    config_file: str = ""  # a Zenoh JSON5 file (ACL, TLS, user/password); relative to the TOML

    def key_prefix(self, robot: str) -> str:
        return self.prefix or f"cdpr/{robot}"


ENDPOINT_PROTOCOLS = ("tcp", "udp", "tls", "quic")
ZENOH_FLAGS = tuple(Flag(key) for key in ("enabled", "multicast_scouting", "commands",
                                          "allow_unauthenticated_commands"))  # fmt: skip
ZENOH_RATES = (Number("state_rate", "Hz", positive=True, maximum=1000.0),
               Number("timing_rate", "Hz", positive=True, maximum=100.0))  # fmt: skip


def read_zenoh(rd: TableReader, data: dict[str, Any], robot: str) -> ZenohConfig | None:
    def read(t: dict[str, Any], vals: dict[str, Any]) -> None:
        d = ZenohConfig()
        read_fields(rd, t, "zenoh", ZENOH_FLAGS, d, vals)
        prefix = rd.string(t, "prefix", "zenoh", required=False, default="")
        if prefix:
            if not all(_KEY_CHUNK.match(c) for c in prefix.split("/")):
                rd.error(
                    "zenoh.prefix",
                    prefix,
                    "",
                    "must be a Zenoh key of non-empty chunks of letters, digits, _ . - (no "
                    "wildcards)",
                )
            else:
                vals["prefix"] = prefix
        elif not all(_KEY_CHUNK.match(c) for c in robot.split("/")):
            rd.error("name", robot, "", "cannot be a Zenoh key chunk: set zenoh.prefix")
        mode = rd.string(t, "mode", "zenoh", required=False, default="peer")
        if mode is not None and mode not in ("peer", "client", "router"):
            rd.error("zenoh.mode", mode, "", "must be peer, client or router")
        elif mode:
            vals["mode"] = mode
        for key in ("listen", "connect"):
            eps = t.get(key, [])
            if not isinstance(eps, list) or not all(
                isinstance(e, str) and "/" in e and e.split("/", 1)[0] in ENDPOINT_PROTOCOLS
                for e in eps
            ):
                rd.error(
                    f"zenoh.{key}",
                    eps,
                    "",
                    'must be a list of Zenoh endpoints such as "tcp/192.168.1.10:7447" '
                    "(tcp, udp, tls or quic)",
                )
            else:
                vals[key] = tuple(eps)
        read_fields(rd, t, "zenoh", ZENOH_RATES, d, vals)
        cf = rd.string(t, "config_file", "zenoh", required=False, default="")
        if cf:
            path = Path(cf) if Path(cf).is_absolute() else Path(rd.file).parent / cf
            if not path.is_file():
                rd.error("zenoh.config_file", cf, "", f"must name an existing file ({path} is not)")
            else:
                vals["config_file"] = str(path)

    return read_section(rd, data, "zenoh", ZENOH_KEYS, ZenohConfig, read)
