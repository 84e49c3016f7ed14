"""The ROS 2 messages (cdprctl/telemetry/ros2/ros2_messages.py) against independent references: the
CDR bytes of each type against the ``rosbags`` package's serializer (its own definitions of
ROS 2's messages, not ours), the type names ROS 2's DDS naming gives, and the quaternion
against scipy's."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore
from scipy.spatial.transform import Rotation

from cdprctl.telemetry.ros2 import ros2_messages as rm

STORE = get_typestore(Stores.ROS2_HUMBLE)


def ros_name(msg) -> str:
    """``pkg::msg::dds_::Type_`` → ``pkg/msg/Type``."""
    pkg, _, _, t = type(msg).__idl_typename__.split("::")
    return f"{pkg}/msg/{t.removesuffix('_')}"


def to_rosbags(msg):
    """The same message as rosbags' own class (field by field, sequences of numbers as
    numpy arrays as rosbags takes them)."""
    cls = STORE.types[ros_name(msg)]
    kw = {}
    for f in dataclasses.fields(msg):
        v = getattr(msg, f.name)
        if dataclasses.is_dataclass(v):
            v = to_rosbags(v)
        elif isinstance(v, list) and v and dataclasses.is_dataclass(v[0]):
            v = [to_rosbags(x) for x in v]
        elif isinstance(v, list) and (not v or isinstance(v[0], float)):
            v = np.array(v, dtype=np.float64)
        kw[f.name] = v
    return cls(**kw)


R0 = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
STAMP = rm.Time(1_764_900_000, 123_456_789)
SAMPLES = [
    rm.Time(5, 7),
    rm.Header(STAMP, "rowc_base"),
    rm.String("ENABLED"),
    rm.pose_stamped(STAMP, "rowc_base", [1.5, 0.3, 0.6], R0),
    rm.transform(STAMP, "rowc_base", "rowc_platform", [1.5, 0.3, 0.6], R0),
    rm.TFMessage([rm.transform(STAMP, "rowc_base", f"a{i}", [i, 0.0, 2.0], np.eye(3))
                  for i in range(3)]),
    rm.TFMessage([]),
    rm.joint_state(STAMP, "rowc_base", ["cable 1", "cable 2"], [1.2, 2.5], [0.01, -0.02],
                   [120.5, 88.25]),
    rm.joint_state(STAMP, "", [], [], [], []),
    rm.wrench_stamped(STAMP, "rowc_platform", [30.0, 0.0, -1.5, 0.1, 0.2, -0.3]),
    rm.DiagnosticArray(rm.Header(STAMP, ""), [rm.DiagnosticStatus(
        rm.ERROR, "cdprctl: rowc", "FAULT: cable 3 slipped", "rowc",
        [rm.KeyValue("state", "FAULT"), rm.KeyValue("fault_kind", "CABLE_TENSION")])]),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_each_message_is_the_cdr_ros2_writes(msg):
    ours = msg.serialize()
    theirs = bytes(STORE.serialize_cdr(to_rosbags(msg), ros_name(msg)))
    assert ours == theirs
    back = type(msg).deserialize(theirs)
    assert back == msg


def test_the_types_follow_ros2s_dds_naming_and_are_final():
    for msg in SAMPLES:
        name = type(msg).__idl_typename__
        _, kind, dds, t = name.split("::")
        assert kind == "msg" and dds == "dds_" and t.endswith("_"), name
        assert type(msg).__idl_annotations__["extensibility"] == "final"  # as declared


@pytest.mark.parametrize("seed", range(20))
def test_the_quaternion_is_scipys(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng).as_matrix()
    if seed == 0:  # near 180° about x: the trace's branch would cancel
        R = Rotation.from_rotvec([np.pi - 1e-9, 0.0, 0.0]).as_matrix()
    q = rm.quaternion(R)
    ref = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    ref = ref if ref[3] >= 0 else -ref
    assert np.allclose([q.x, q.y, q.z, q.w], ref, atol=1e-9)


def test_a_time_in_seconds_is_seconds_and_nanoseconds():
    t = rm.ros_time(1_764_900_000.25)
    assert (t.sec, t.nanosec) == (1_764_900_000, 250_000_000)
    assert rm.ros_time(3.0) == rm.Time(3, 0)
