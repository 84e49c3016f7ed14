"""ROS 2's standard messages as DDS types (Cyclone DDS's Python IDL), for the ROS 2 link
(docs/ros2.md): the wire a ROS 2 node expects — topic ``rt/<name>``, type
``<pkg>::msg::dds_::<Type>_``, plain CDR, every struct ``@final`` (an ``@appendable`` one is
a QoS/type mismatch to rmw_cyclonedds). Each type follows its ``.msg`` in ROS 2's
common_interfaces (builtin_interfaces, std_msgs, geometry_msgs, sensor_msgs, tf2_msgs,
diagnostic_msgs) field by field; ``tests/telemetry/ros2/test_ros2_messages.py`` checks the bytes
against the ``rosbags`` package's own CDR serializer for each.

Builders from SI values: a pose as position (m) and rotation matrix, the time as ``Time``."""

# No ``from __future__ import annotations`` here: Cyclone DDS reads the fields' annotations
# as types, and resolves a string one only by name in this module (``str`` is not there).
import math
from dataclasses import dataclass, field

import numpy as np
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.annotations import final
from cyclonedds.idl.types import float64, int32, sequence, uint8, uint32

from cdprctl.core.rotation import FloatArray


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@final
@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    data: str = ""


@final
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@final
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@final
@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@final
@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@final
@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@final
@dataclass
class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    force: Vector3 = field(default_factory=Vector3)
    torque: Vector3 = field(default_factory=Vector3)


@final
@dataclass
class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    header: Header = field(default_factory=Header)
    wrench: Wrench = field(default_factory=Wrench)


@final
@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@final
@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@final
@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@final
@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0  # OK 0, WARN 1, ERROR 2, STALE 3 (the .msg's constants)
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@final
@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


# DiagnosticStatus levels (diagnostic_msgs/msg/DiagnosticStatus.msg)
OK, WARN, ERROR, STALE = 0, 1, 2, 3


def ros_time(seconds: float) -> Time:
    """``Time`` of a time in seconds (since the epoch, or any origin), nanoseconds floored."""
    sec = math.floor(seconds)
    return Time(int(sec), min(999_999_999, int((seconds - sec) * 1e9)))


def quaternion(R: FloatArray) -> Quaternion:
    """The unit quaternion (x, y, z, w; w ≥ 0) of rotation matrix ``R`` (Shepperd's method:
    the largest of the four diagonal combinations, no cancellation near 180°)."""
    m = np.asarray(R, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    cands = (tr, m[0, 0], m[1, 1], m[2, 2])
    k = int(np.argmax(cands))
    if k == 0:
        w = 0.5 * math.sqrt(1.0 + tr)
        x, y, z = ((m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
                   (m[1, 0] - m[0, 1]) / (4 * w))  # fmt: skip
    elif k == 1:
        x = 0.5 * math.sqrt(1.0 + 2 * m[0, 0] - tr)
        w, y, z = ((m[2, 1] - m[1, 2]) / (4 * x), (m[0, 1] + m[1, 0]) / (4 * x),
                   (m[0, 2] + m[2, 0]) / (4 * x))  # fmt: skip
    elif k == 2:
        y = 0.5 * math.sqrt(1.0 + 2 * m[1, 1] - tr)
        w, x, z = ((m[0, 2] - m[2, 0]) / (4 * y), (m[0, 1] + m[1, 0]) / (4 * y),
                   (m[1, 2] + m[2, 1]) / (4 * y))  # fmt: skip
    else:
        z = 0.5 * math.sqrt(1.0 + 2 * m[2, 2] - tr)
        w, x, y = ((m[1, 0] - m[0, 1]) / (4 * z), (m[0, 2] + m[2, 0]) / (4 * z),
                   (m[1, 2] + m[2, 1]) / (4 * z))  # fmt: skip
    s = -1.0 if w < 0.0 else 1.0
    return Quaternion(s * x, s * y, s * z, s * w)


def transform(stamp: Time, parent: str, child: str, position: FloatArray,
              R: FloatArray) -> TransformStamped:  # fmt: skip
    """The transform ``parent`` → ``child``: ``child``'s origin at ``position`` (m) and its
    axes ``R`` in ``parent``'s frame."""
    p = [float(v) for v in position]
    return TransformStamped(Header(stamp, parent), child,
                            Transform(Vector3(*p), quaternion(R)))  # fmt: skip


def pose_stamped(stamp: Time, frame: str, position: FloatArray, R: FloatArray) -> PoseStamped:
    p = [float(v) for v in position]
    return PoseStamped(Header(stamp, frame), Pose(Point(*p), quaternion(R)))


def joint_state(stamp: Time, frame: str, names: list[str], lengths: FloatArray,
                rates: FloatArray, tensions: FloatArray) -> JointState:  # fmt: skip
    """The cables as joints: position the lengths (m), velocity their rates (m/s), effort
    the tensions (N)."""
    return JointState(Header(stamp, frame), list(names), [float(v) for v in lengths],
                      [float(v) for v in rates], [float(v) for v in tensions])  # fmt: skip


def wrench_stamped(stamp: Time, frame: str, wrench: FloatArray) -> WrenchStamped:
    """``wrench``: force (N) then moment (N·m)."""
    w = [float(v) for v in wrench]
    return WrenchStamped(Header(stamp, frame), Wrench(Vector3(*w[:3]), Vector3(*w[3:6])))
