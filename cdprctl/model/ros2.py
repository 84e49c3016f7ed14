"""The ``[ros2]`` section: the robot as a ROS 2 node sees it, over DDS (``cdprctl run
--ros2``, docs/ros2.md). Publishing only: plain DDS has no authentication, and commands stay
on the secured Zenoh path."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Any

from cdprctl.model.reader import Number, TableReader, read_fields, read_section

ROS2_KEYS = ("enabled", "domain_id", "namespace", "rate")

# ROS 2's domains that map to valid RTPS ports (0-101 and 215-232; ROS 2's docs, "The ROS
# DOMAIN ID"): the range DDS itself accepts
DOMAIN_MAX = 232
# a ROS 2 name: tokens of letters, digits and underscores, not starting with a digit
_NAMESPACE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")


@dataclass(frozen=True)
class Ros2Config:
    enabled: bool = False
    domain_id: int | None = None  # None: ROS_DOMAIN_ID, else 0 (``domain``)
    namespace: str = ""  # "": cdpr/<robot name> (``topic_namespace``)
    rate: float = 50.0  # Hz of every topic but /tf_static

    def domain(self) -> int:
        """The DDS domain: the file's, else ``ROS_DOMAIN_ID`` as ROS 2 reads it, else 0.
        Raises ValueError for a ``ROS_DOMAIN_ID`` that is not a domain (``environment_problem``
        says so in words): ROS 2 refuses it too, and falling back to the shared domain 0
        would put the robot where nobody asked."""
        if self.domain_id is not None:
            return self.domain_id
        text = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if not text:
            return 0
        if not text.isdigit() or int(text) > DOMAIN_MAX:
            raise ValueError(f"ROS_DOMAIN_ID = {text!r} is not a ROS 2 domain (0-{DOMAIN_MAX}):"
                             " set it to one, unset it (domain 0), or give [ros2] domain_id")
        return int(text)

    def environment_problem(self) -> str | None:
        """Why the link cannot start from this environment (None: it can)."""
        try:
            self.domain()
        except ValueError as exc:
            return str(exc)
        return None

    def topic_namespace(self, robot: str) -> str:
        return self.namespace or f"cdpr/{ros_token(robot)}"


def localhost_only() -> bool:
    """Whether ROS 2's environment keeps DDS on this machine: ``ROS_LOCALHOST_ONLY=1``
    (Humble, Iron) or ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` (Jazzy on)."""
    return (os.environ.get("ROS_LOCALHOST_ONLY", "").strip() == "1"
            or os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
            == "LOCALHOST")  # fmt: skip


# what rmw_cyclonedds adds to Cyclone DDS's configuration for localhost only: the loopback
# interface alone (a node so set hears nothing from, and sends nothing to, another interface)
LOOPBACK_CONFIG = ("<CycloneDDS><Domain><General><Interfaces><NetworkInterface "
                   'address="127.0.0.1"/></Interfaces></General></Domain></CycloneDDS>')


def dds_config() -> str | None:
    """Cyclone DDS's configuration for the link: ``CYCLONEDDS_URI`` as the user set it (the
    interface, peers, ...), with the loopback interface added when ROS 2's environment says
    localhost only; None: Cyclone's defaults (``CYCLONEDDS_URI`` read by Cyclone itself)."""
    if not localhost_only():
        return None
    uri = os.environ.get("CYCLONEDDS_URI", "").strip()
    return ",".join(x for x in (uri, LOOPBACK_CONFIG) if x)


def ros_token(name: str) -> str:
    """``name`` as one token of a ROS 2 name (anything else than letters, digits and
    underscores becomes an underscore; a leading digit gets one in front)."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name)
    return f"_{out}" if out[:1].isdigit() or not out else out


def read_ros2(rd: TableReader, data: dict[str, Any]) -> Ros2Config | None:
    def read(t: dict[str, Any], vals: dict[str, Any]) -> None:
        enabled = t.get("enabled", False)
        if not isinstance(enabled, bool):
            rd.error("ros2.enabled", enabled, "", "must be true or false")
        vals["enabled"] = enabled is True
        domain = rd.number(t, "domain_id", "ros2", "", required=False, minimum=0,
                           maximum=DOMAIN_MAX, integer=True)  # fmt: skip
        if domain is not None:
            vals["domain_id"] = int(domain)
        ns = rd.string(t, "namespace", "ros2", required=False, default="")
        if ns:
            ns = ns.strip("/")
            if _NAMESPACE.fullmatch(ns):
                vals["namespace"] = ns
            else:
                rd.error("ros2.namespace", ns, "", "must be a ROS 2 name: tokens of "
                         "letters, digits and underscores separated by /, none starting with a "
                         "digit")  # fmt: skip
        rate = Number("rate", "Hz", positive=True, maximum=500.0)
        read_fields(rd, t, "ros2", (rate,), Ros2Config(), vals)

    return read_section(rd, data, "ros2", ROS2_KEYS, Ros2Config, read)
