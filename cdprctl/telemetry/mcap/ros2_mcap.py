"""A recording's ROS 2 channels (``cdprctl record --mcap`` → ``DIR/ros2.mcap``): the messages the
live ROS 2 link publishes (``ros2_frames.py``), built from each recorded ``state`` payload, in
an MCAP file of the ``ros2`` profile — ``ros2msg`` schemas (``ros2_definitions.py``), ``cdr``
messages (the DDS wire's bytes, encapsulation header included), each channel's offered QoS as
rosbag2 writes it — so ``ros2 bag play`` and Foxglove's ROS 2 panels read it as a bag
recorded from the live topics. A file of its own: ``telemetry.mcap``'s JSON and protobuf
channels are not ROS 2 types, which a ROS 2 player could not publish."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

# rosbag2's offered_qos_profiles (rosbag2_transport qos.cpp's YAML; rmw's enum values:
# history KEEP_LAST 1, reliability RELIABLE 1, durability TRANSIENT_LOCAL 1 / VOLATILE 2,
# liveliness AUTOMATIC 1; a duration of 0 s 0 ns: the default, unbounded). As the live link
# offers them: keep last 10 and volatile, /tf_static keep last 1 and transient local.
_QOS = """- history: 1
  depth: {depth}
  reliability: 1
  durability: {durability}
  deadline:
    sec: 0
    nsec: 0
  lifespan:
    sec: 0
    nsec: 0
  liveliness: 1
  liveliness_lease_duration:
    sec: 0
    nsec: 0
  avoid_ros_namespace_conventions: false
"""


def offered_qos(key: str) -> str:
    """The offered QoS of topic ``key`` (``ros2_frames.topics``) as rosbag2's YAML."""
    latched = key == "tf_static"
    return _QOS.format(depth=1 if latched else 10, durability=1 if latched else 2)


def write_ros2_mcap(path: Path, records: list[tuple[int, str, bytes]],
                    status: dict[str, Any]) -> int:  # fmt: skip
    """Writes the ROS 2 messages of ``records``' ``state`` payloads ((receive time ns, key,
    JSON) as ``write_mcap`` takes them) to ``path``, stamped with their receive time, and
    ``/tf_static`` once, at the first. ``status``: the daemon's (its ``config``: the robot's
    name, layout and ROS 2 namespace). Returns the number of messages."""
    from mcap.writer import Writer

    from cdprctl.model.ros2 import ros_token
    from cdprctl.telemetry.foxglove.scene import SceneLayout
    from cdprctl.telemetry.mcap.ros2_definitions import ros_type, schema_text
    from cdprctl.telemetry.ros2 import ros2_messages as rm
    from cdprctl.telemetry.ros2.ros2_frames import Ros2Frames, snapshot_of_payload, topics, types

    config = status["config"]
    robot = str(config["robot"])
    layout = SceneLayout.from_dict(config["layout"])
    namespace = (config.get("ros2") or {}).get("namespace") or f"cdpr/{ros_token(robot)}"
    frames = Ros2Frames(layout, list(layout.names), layout.home_rotation, robot)
    names, kinds = topics(namespace), types()
    n = 0
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="cdprctl")
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}

        def add(key: str, msg: Any, ns: int) -> None:
            nonlocal n
            if key not in channels:
                kind = ros_type(kinds[key].__idl_typename__)
                if kind not in schemas:
                    text = schema_text(kind.replace("/msg/", "/"))
                    schemas[kind] = writer.register_schema(name=kind, encoding="ros2msg",
                                                           data=text.encode())  # fmt: skip
                channels[key] = writer.register_channel(
                    topic=names[key], message_encoding="cdr", schema_id=schemas[kind],
                    metadata={"offered_qos_profiles": offered_qos(key)},
                )  # fmt: skip
            writer.add_message(channel_id=channels[key], log_time=ns, publish_time=ns,
                               data=msg.serialize(), sequence=n)  # fmt: skip
            n += 1

        for ns, key, data in records:
            if key != "state":
                continue
            try:
                body = json.loads(data)
            except ValueError:
                continue
            s = snapshot_of_payload(body) if isinstance(body, dict) else None
            if s is None or s["tensions"].size != layout.n_cables:
                continue
            stamp = rm.Time(ns // 1_000_000_000, ns % 1_000_000_000)
            if "tf_static" not in channels:
                add("tf_static", frames.static(stamp), ns)
            for k, msg in frames.build(s, stamp).items():
                add(k, msg, ns)
        writer.finish()
    return n

