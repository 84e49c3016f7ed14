"""A recording's ROS 2 channels (``cdprctl record --mcap`` → ``ros2.mcap``,
cdprctl/telemetry/mcap/ros2_mcap.py) read back by two readers that are not ours:
``mcap-ros2-support`` decodes every message from the file's own ``ros2msg`` schema text, and
``rosbags`` from its own definitions of the type the schema names. The message definitions are
checked against rosbags' field by field; the cables' lengths against the straight-line distance
anchor → attachment (rowc has no pulleys)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from cdprctl.daemon.report import config_summary
from cdprctl.robot_file import load_robot
from cdprctl.telemetry.mcap.ros2_definitions import MSG, SEPARATOR, schema_text
from cdprctl.telemetry.mcap.ros2_mcap import write_ros2_mcap

CONFIG = Path(__file__).resolve().parents[3] / "config"
STORE = get_typestore(Stores.ROS2_HUMBLE)


@pytest.mark.parametrize("name", sorted(MSG))
def test_each_definition_is_ros2s_field_by_field(name):
    """Our .msg text parsed by rosbags' own parser gives the fields and constants of rosbags'
    built-in definition of the type (ROS 2 Humble's common_interfaces)."""
    pkg, t = name.split("/")
    full = f"{pkg}/msg/{t}"
    ours = get_types_from_msg(MSG[name], full)[full]
    assert ours == STORE.fielddefs[full]


@pytest.mark.parametrize("name", sorted(MSG))
def test_a_schema_holds_each_type_it_uses_once(name):
    text = schema_text(name)
    parts = text.split(SEPARATOR + "\n")
    assert parts[0] == MSG[name]
    used = [p.split("\n", 1)[0].removeprefix("MSG: ") for p in parts[1:]]
    assert len(used) == len(set(used))
    for u, p in zip(used, parts[1:], strict=True):
        assert p == f"MSG: {u}\n{MSG[u]}"
    # every complex field type resolves within the schema (what rosbag2 and Foxglove need)
    for part in [MSG[name]] + [MSG[u] for u in used]:
        for line in part.splitlines():
            kind = line.split()[0].split("[")[0]
            if "/" in kind:
                assert kind in used


def offered(text: str) -> dict[str, int]:
    """The scalars of a one-profile rosbag2 QoS list (``- history: 1`` then ``  depth: 10``,
    nested durations left out): a reader of what rosbag2 reads, not our writer's template."""
    lines = text.splitlines()
    assert lines[0].startswith("- ") and not any(x.startswith("- ") for x in lines[1:])
    out = {}
    for line in [lines[0][2:]] + [x[2:] for x in lines[1:] if x[:2] == "  " and x[2] != " "]:
        key, _, value = line.partition(":")
        if value.strip():
            out[key] = int(value) if value.strip().isdigit() else value.strip()
    assert {"history", "depth", "reliability", "durability", "liveliness"} <= set(out)
    return out


T0 = 1_764_900_000_000_000_000  # ns since the epoch


def recording(model, n: int = 50) -> list[tuple[int, str, bytes]]:
    """``n`` state payloads 20 ms apart, the platform moving and turning, with an event and a
    timing payload between (not ROS 2 messages) and a last one in FAULT."""
    records = []
    for k in range(n):
        state = {"schema": "cdprctl/1", "time": 5.0 + 0.02 * k,
                 "state": "fault" if k == n - 1 else "moving",
                 "fault_kind": "cable tension" if k == n - 1 else "",
                 "pose": {"position": [1.5 + 0.002 * k, 0.35, 0.59 - 0.001 * k],
                          "rpy": [0.01, -0.02 + 0.0005 * k, 0.03]},
                 "twist": {"velocity": [0.1, 0.0, -0.05], "omega": [0.0, 0.025, 0.0]},
                 "target": [1.6, 0.35, 0.55, 0.0, 0.0, 0.0],
                 "external_wrench_estimate": [30.0, 0.0, -1.5, 0.1, None, -0.3],
                 "cables": [c.name for c in model.cables],
                 "tensions": [100.0 + k + i for i in range(model.n_cables)]}  # fmt: skip
        records.append((T0 + k * 20_000_000, "state", json.dumps(state).encode()))
    records.insert(3, (T0 + 1, "events", b'{"kind": "event", "text": "x"}'))
    records.insert(5, (T0 + 2, "timing", b'{"time": 5.0}'))
    records.insert(7, (T0 + 3, "state", b"{not json"))
    return records


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    model = load_robot(CONFIG / "rowc.toml")
    records = recording(model)
    path = tmp_path_factory.mktemp("ros2") / "ros2.mcap"
    n = write_ros2_mcap(path, records, {"config": config_summary(model, True)})
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        summary = reader.get_summary()
        decoded = [(c.topic, s.name, m, d) for s, c, m, d in reader.iter_decoded_messages()]
    return model, records, n, header, summary, decoded


def test_the_file_is_of_the_ros2_profile_with_each_topic_typed_and_its_qos(bag):
    _, _, n, header, summary, decoded = bag
    # /tf_static once; /diagnostics at the first state, and the last's fault (1 Hz else)
    assert header.profile == "ros2" and n == len(decoded) == 1 + 5 * 50 + 2
    channels = {c.topic: c for c in summary.channels.values()}
    types = {c.topic: summary.schemas[c.schema_id].name for c in channels.values()}
    assert types == {
        "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage",
        "/cdpr/rowc/joint_states": "sensor_msgs/msg/JointState",
        "/cdpr/rowc/pose": "geometry_msgs/msg/PoseStamped",
        "/cdpr/rowc/wrench_estimate": "geometry_msgs/msg/WrenchStamped",
        "/cdpr/rowc/state": "std_msgs/msg/String",
        "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    }  # fmt: skip
    for topic, c in channels.items():
        assert c.message_encoding == "cdr"
        assert summary.schemas[c.schema_id].encoding == "ros2msg"
        qos = offered(c.metadata["offered_qos_profiles"])
        latched = topic == "/tf_static"
        assert (qos["reliability"], qos["history"]) == (1, 1)  # RELIABLE, KEEP_LAST
        assert (qos["depth"], qos["durability"]) == ((1, 1) if latched else (10, 2))


def test_every_message_decodes_from_its_schema_and_as_rosbags_types_it(bag):
    """mcap-ros2-support decodes by the schema text in the file; rosbags by its own
    definition of the type the schema names: the two agree on every field read here."""
    *_, decoded = bag
    for topic, name, m, d in decoded:
        theirs = STORE.deserialize_cdr(m.data, name)
        if name == "sensor_msgs/msg/JointState":
            assert list(theirs.name) == list(d.name)
            assert np.array_equal(theirs.position, d.position)
            assert np.array_equal(theirs.effort, d.effort)
        elif name == "geometry_msgs/msg/PoseStamped":
            assert theirs.pose.position.x == d.pose.position.x
            assert theirs.header.stamp.sec == d.header.stamp.sec
        elif name == "std_msgs/msg/String":
            assert theirs.data == d.data
        assert m.log_time == m.publish_time, topic


def test_the_messages_are_the_recorded_states(bag):
    """Each state's pose within 0.1 mm (its payload's), the stamp its receive time, the
    cables by name with the tensions recorded and the straight-line lengths, the rates
    −Wᵀ·twist by a finite difference of those lengths, the target and the anchors in TF, the
    last state's fault an ERROR in /diagnostics."""
    model, records, *_, decoded = bag
    states = [(ns, json.loads(d)) for ns, k, d in records if k == "state" and d[:2] == b"{\""]
    by_topic: dict[str, list] = {}
    for topic, _, m, d in decoded:
        by_topic.setdefault(topic, []).append((m, d))
    assert [m.log_time for m, _ in by_topic["/cdpr/rowc/pose"]] == [ns for ns, _ in states]
    names = [c.name for c in model.cables]
    for (ns, s), (_, pose), (_, js), (_, tf) in zip(
        states, by_topic["/cdpr/rowc/pose"], by_topic["/cdpr/rowc/joint_states"],
        by_topic["/tf"], strict=True,
    ):  # fmt: skip
        p = np.array(s["pose"]["position"])
        R = Rotation.from_euler("xyz", s["pose"]["rpy"]).as_matrix()  # roll, pitch, yaw (fixed)
        got = pose.pose.position
        assert np.allclose([got.x, got.y, got.z], p, atol=1e-4)
        assert (pose.header.stamp.sec, pose.header.stamp.nanosec) == divmod(ns, 10**9)
        assert pose.header.frame_id == "rowc_base"
        q = pose.pose.orientation
        assert np.allclose(Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix(), R, atol=1e-9)
        assert list(js.name) == names and np.allclose(js.effort, s["tensions"])
        ref = [np.linalg.norm(model.anchors[i] - (p + R @ model.attachments[i]))
               for i in range(model.n_cables)]  # fmt: skip
        assert np.allclose(js.position, ref, atol=1e-9)
        # the rates: a finite difference of the lengths along the recorded twist
        h = 1e-6
        v, w = np.array(s["twist"]["velocity"]), np.array(s["twist"]["omega"])
        R2 = Rotation.from_rotvec(w * h).as_matrix() @ R
        ahead = [np.linalg.norm(model.anchors[i] - (p + v * h + R2 @ model.attachments[i]))
                 for i in range(model.n_cables)]  # fmt: skip
        assert np.allclose(js.velocity, (np.array(ahead) - ref) / h, atol=1e-5)
        platform, target = tf.transforms
        assert (platform.child_frame_id, target.child_frame_id) == ("rowc_platform", "rowc_target")
        assert math.isclose(target.transform.translation.x, 1.6)
    (_, static), = by_topic["/tf_static"]
    assert [t.child_frame_id for t in static.transforms] == [f"rowc_anchor_{i + 1}"
                                                             for i in range(model.n_cables)]
    a = static.transforms[2].transform.translation
    assert np.allclose([a.x, a.y, a.z], model.anchors[2])
    # the wrench in the platform's frame: its axes (Rᵀ of the base's), about its origin
    (ns, s), (_, ws) = states[0], by_topic["/cdpr/rowc/wrench_estimate"][0]
    R = Rotation.from_euler("xyz", s["pose"]["rpy"]).as_matrix()
    w = ws.wrench
    assert ws.header.frame_id == "rowc_platform"
    assert np.allclose([w.force.x, w.force.y, w.force.z], R.T @ [30.0, 0.0, -1.5])
    assert all(math.isnan(v) for v in (w.torque.x, w.torque.y, w.torque.z))  # one is unknown
    assert [d.data for _, d in by_topic["/cdpr/rowc/state"]][-2:] == [
        "moving", "fault: cable tension"]
    (status,) = by_topic["/diagnostics"][-1][1].status
    assert status.level == 2 and status.message == "fault: cable tension"
    assert by_topic["/diagnostics"][0][1].status[0].level == 0
    assert [m.log_time for m, _ in by_topic["/diagnostics"]] == [states[0][0], states[-1][0]]
