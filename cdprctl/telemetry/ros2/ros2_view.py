"""The robot as ROS 2 sees it: a process beside the loop's (like the Zenoh gateway and the
Foxglove view) that reads the loop's shared snapshot at ``[ros2] rate`` and publishes ROS 2's
standard messages over DDS (``ros2_messages.py``; docs/ros2.md). A plain DDS participant that
follows ROS 2's naming is a ROS 2 publisher to every node on the domain. It takes no commands
(plain DDS has no authentication). The daemon's side is ``Ros2Link``."""

from __future__ import annotations

import time
from typing import Any

from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.helper import NewStates, SnapshotLink, paced
from cdprctl.telemetry.ros2.ros2_frames import Ros2Frames, topics, types
from cdprctl.telemetry.snapshot import SharedSnapshot


def ros2_main(model: RobotModel, snapshot_name: str, stop: Any, ready: Any) -> None:
    from cyclonedds.core import Policy, Qos
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.topic import Topic
    from cyclonedds.util import duration

    from cdprctl.core.realtime import loop_cpu, yield_to_the_loop
    from cdprctl.telemetry.ros2 import ros2_messages as rm

    yield_to_the_loop(loop_cpu(model.control.cpu))  # best effort, as the gateway's
    snap = SharedSnapshot(model.n_cables, snapshot_name, g=len(model.grippers))
    from cdprctl.model.ros2 import dds_config

    domain_id, config = model.ros2.domain(), dds_config()
    domain = Domain(domain_id, config) if config is not None else None  # kept while it runs
    dp = DomainParticipant(domain_id)
    # ROS 2's defaults: reliable, keep last 10, volatile; /tf_static transient local, keep 1
    # per publisher (tf2's static broadcaster: a late subscriber gets the anchors)
    default = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                  Policy.History.KeepLast(10), Policy.Durability.Volatile)  # fmt: skip
    latched = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                  Policy.History.KeepLast(1), Policy.Durability.TransientLocal)  # fmt: skip
    kinds = types()
    writers: dict[str, Any] = {
        key: DataWriter(dp, Topic(dp, "rt" + name, kinds[key]),
                        qos=latched if key == "tf_static" else default)
        for key, name in topics(model.ros2.topic_namespace(model.name)).items()
    }  # fmt: skip
    frames_of = Ros2Frames(model, [c.name for c in model.cables], model.home.rotation,
                           model.name)  # fmt: skip
    writers["tf_static"].write(frames_of.static(rm.ros_time(time.time())))

    def publish(s: Any) -> None:
        for key, msg in frames_of.build(s, rm.ros_time(time.time())).items():
            writers[key].write(msg)

    new_states = NewStates(snap, "cdprctl-ros2", publish)
    ready.set()
    try:
        for _ in paced(stop, 1.0 / model.ros2.rate):
            new_states()
    finally:
        snap.close()
        del dp, domain  # the participant before its domain


class Ros2Link(SnapshotLink):
    """The daemon's side: starts the ROS 2 process, writes its snapshot. Used by the daemon's
    I/O thread only — never by the loop."""

    def __init__(self, model: RobotModel):
        super().__init__(model, 1.0 / model.ros2.rate)
        self.start_helper("cdprctl-ros2", "the ROS 2 link", ros2_main, model,
                          self.snapshot.name, self.stop, self.ready)  # fmt: skip

    def announcement(self) -> list[tuple[str, bool]]:
        from cdprctl.model.ros2 import localhost_only

        t = topics(self.model.ros2.topic_namespace(self.model.name))
        where = " (this machine only: ROS 2's localhost setting)" if localhost_only() else ""
        return [(f"ros2: domain {self.model.ros2.domain()}{where}, {t['joint_states']}, "
                 f"{t['pose']}, "
                 f"{t['wrench_estimate']}, {t['state']}, /tf, /tf_static, /diagnostics at "
                 f"{self.model.ros2.rate:g} Hz (publishing only: docs/ros2.md)",
                 False)]  # fmt: skip

    def event(self, t: float, text: str, kind: str = "event") -> None:
        return  # the state and diagnostics topics carry the state; no log topic yet

    def take_commands(self) -> list[Any]:
        """ROS 2 takes no commands (docs/ros2.md: plain DDS has no authentication)."""
        return []
