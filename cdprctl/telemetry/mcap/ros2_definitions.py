"""ROS 2's message definitions (``.msg``) of the messages the ROS 2 link publishes, as an MCAP
``ros2msg`` schema holds them: the type's own text, then each type it uses after a line of 80
``=`` and ``MSG: <pkg>/<Type>`` (rosbag2's message-definition format, which Foxglove and
``ros2 bag`` read). The texts are those of ROS 2's common_interfaces (Humble and later) with
the comments left out; ``tests/telemetry/mcap/test_ros2_mcap.py`` checks them against the
``rosbags`` package's definitions field by field."""

from __future__ import annotations

# <pkg>/<Type> → its .msg (a type of the same package is named without it, as the files do)
MSG = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/String": "string data\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"),
    "geometry_msgs/Wrench": "Vector3 force\nVector3 torque\n",
    "geometry_msgs/WrenchStamped": "std_msgs/Header header\nWrench wrench\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "sensor_msgs/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n"),
    "diagnostic_msgs/KeyValue": "string key\nstring value\n",
    "diagnostic_msgs/DiagnosticStatus": (
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\n"
        "string message\nstring hardware_id\nKeyValue[] values\n"),
    "diagnostic_msgs/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status\n",
}  # fmt: skip

PRIMITIVES = frozenset(("bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
                        "uint16", "int32", "uint32", "int64", "uint64", "string", "wstring"))
SEPARATOR = "=" * 80


def used_types(name: str) -> list[str]:
    """The complex types ``name``'s fields use, as ``<pkg>/<Type>``, in order of first use."""
    pkg = name.split("/")[0]
    out = []
    for line in MSG[name].splitlines():
        kind = line.split()[0].split("[")[0]
        if kind in PRIMITIVES or "=" in line:
            continue
        full = kind if "/" in kind else f"{pkg}/{kind}"
        if full not in out:
            out.append(full)
    return out


def schema_text(name: str) -> str:
    """The ``ros2msg`` schema of ``name`` (``<pkg>/<Type>``): its .msg and every type it uses,
    depth first, each once."""
    seen: list[str] = []

    def visit(t: str) -> None:
        for u in used_types(t):
            if u not in seen:
                seen.append(u)
                visit(u)

    visit(name)
    parts = [MSG[name]] + [f"{SEPARATOR}\nMSG: {t}\n{MSG[t]}" for t in seen]
    return "".join(parts)


def ros_type(idl_typename: str) -> str:
    """``pkg::msg::dds_::Type_`` (the DDS type) → ``pkg/msg/Type`` (the MCAP schema's name)."""
    pkg, _, _, t = idl_typename.split("::")
    return f"{pkg}/msg/{t.removesuffix('_')}"
