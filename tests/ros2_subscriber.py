"""An independent ROS 2 subscriber for tests/telemetry/ros2/test_ros2.py: its own DDS types, written
from ROS 2's message definitions (common_interfaces: sensor_msgs/JointState.msg,
tf2_msgs/TFMessage.msg, geometry_msgs/{PoseStamped,TransformStamped,...}.msg), not from cdprctl's
code, on its own participant in its own process. Counts what arrives on each topic for ``seconds``
and prints one JSON line: counts, the last pose and transforms, the joint names and efforts.

    python tests/ros2_subscriber.py DOMAIN NAMESPACE SECONDS
"""

import json
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import float64, int32, sequence, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@final
@dataclass
class Stamp(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@final
@dataclass
class Hdr(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Stamp
    frame_id: str


@final
@dataclass
class Vec(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@final
@dataclass
class Pt(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@final
@dataclass
class Quat(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@final
@dataclass
class Pse(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Pt
    orientation: Quat


@final
@dataclass
class PseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Hdr
    pose: Pse


@final
@dataclass
class Tf(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vec
    rotation: Quat


@final
@dataclass
class TfStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Hdr
    child_frame_id: str
    transform: Tf


@final
@dataclass
class TfMsg(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TfStamped]


@final
@dataclass
class Joints(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Hdr
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


@final
@dataclass
class Text(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str


def main() -> None:
    domain, ns, seconds = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
    dp = DomainParticipant(domain)
    qos = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(10))
    latched = Qos(Policy.Reliability.Reliable(duration(milliseconds=100)),
                  Policy.History.KeepLast(1), Policy.Durability.TransientLocal)
    readers = {
        "joint_states": DataReader(dp, Topic(dp, f"rt/{ns}/joint_states", Joints), qos=qos),
        "pose": DataReader(dp, Topic(dp, f"rt/{ns}/pose", PseStamped), qos=qos),
        "state": DataReader(dp, Topic(dp, f"rt/{ns}/state", Text), qos=qos),
        "tf": DataReader(dp, Topic(dp, "rt/tf", TfMsg), qos=qos),
        "tf_static": DataReader(dp, Topic(dp, "rt/tf_static", TfMsg), qos=latched),
    }
    counts = {k: 0 for k in readers}
    last: dict = {}
    first_at: dict = {}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for k, r in readers.items():
            for s in r.take(N=100):
                if not isinstance(s, IdlStruct):
                    continue  # an InvalidSample: the writer gone (disposed, unregistered)
                counts[k] += 1
                first_at.setdefault(k, time.monotonic())
                last[k] = s
        time.sleep(0.005)
    out = {"counts": counts, "seconds": seconds,
           "since_first": {k: end - v for k, v in first_at.items()}}
    if "pose" in last:
        p = last["pose"].pose
        out["pose"] = [p.position.x, p.position.y, p.position.z, p.orientation.x,
                       p.orientation.y, p.orientation.z, p.orientation.w]
        out["pose_frame"] = last["pose"].header.frame_id
    if "tf" in last:
        out["tf"] = {t.child_frame_id: [t.header.frame_id, t.transform.translation.x,
                                        t.transform.translation.y, t.transform.translation.z]
                     for t in last["tf"].transforms}
    if "tf_static" in last:
        out["anchors"] = {t.child_frame_id: [t.transform.translation.x, t.transform.translation.y,
                                             t.transform.translation.z]
                          for t in last["tf_static"].transforms}
    if "joint_states" in last:
        j = last["joint_states"]
        out["joints"] = {"name": list(j.name), "position": list(j.position),
                         "effort": list(j.effort)}
    if "state" in last:
        out["state"] = last["state"].data
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
