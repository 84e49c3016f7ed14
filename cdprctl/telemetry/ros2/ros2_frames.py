"""What the robot is to ROS 2 (docs/ros2.md): the topics, the TF frames, and the messages of
one state — from the loop's snapshot (the live link, ``ros2_view.py``) or from a recorded
``state`` payload (``cdprctl record --mcap``'s ROS 2 channels, ``ros2_mcap.py``), so a
recording replays as the live topics were."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cdprctl.control.states import State
from cdprctl.geometry.kinematics import CableLayout
from cdprctl.model.ros2 import ros_token
from cdprctl.telemetry.snapshot import FAULT_KINDS, STATES

# diagnostic_msgs/DiagnosticStatus levels of the states that are not OK: a fault (and the stop
# that leads to it) an ERROR; the e-stop a WARN — the safety chain is open, nothing is broken
LEVELS = {State.FAULT.value: 2, State.STOPPING.value: 2, State.ESTOP.value: 1}
# s between /diagnostics messages while nothing changes (diagnostic_updater's 1 Hz); a change
# of state or fault is sent at once
DIAGNOSTICS_PERIOD = 1.0


def frames(robot: str) -> dict[str, str]:
    """The TF frames' names: ``<robot>_base``, ``_platform`` (the estimate), ``_target``."""
    r = ros_token(robot)
    return {"base": f"{r}_base", "platform": f"{r}_platform", "target": f"{r}_target"}


def topics(namespace: str) -> dict[str, str]:
    """Each message's ROS 2 topic (the DDS topic is ``rt`` + it); ``namespace`` without its
    leading ``/`` (``Ros2Config.topic_namespace``)."""
    ns = "/" + namespace
    return {"tf": "/tf", "tf_static": "/tf_static", "joint_states": f"{ns}/joint_states",
            "pose": f"{ns}/pose", "wrench_estimate": f"{ns}/wrench_estimate",
            "state": f"{ns}/state", "diagnostics": "/diagnostics"}  # fmt: skip


def types() -> dict[str, Any]:
    """Each topic's message type (``ros2_messages``)."""
    from cdprctl.telemetry.ros2 import ros2_messages as rm

    return {"tf": rm.TFMessage, "tf_static": rm.TFMessage, "joint_states": rm.JointState,
            "pose": rm.PoseStamped, "wrench_estimate": rm.WrenchStamped, "state": rm.String,
            "diagnostics": rm.DiagnosticArray}  # fmt: skip


def _numbers(values: Any, n: int) -> np.ndarray:
    """A payload's list (``null`` for NaN) as floats; NaN where it is absent."""
    if not isinstance(values, list):
        return np.full(n, math.nan)
    out = np.array([math.nan if v is None else v for v in values[:n]], dtype=float)
    return np.pad(out, (0, n - out.size), constant_values=math.nan)


def snapshot_of_payload(body: dict[str, Any]) -> dict[str, np.ndarray] | None:
    """A ``state`` payload (``schema.state_payload``) as the snapshot's entries the messages
    use; None while it holds no pose (``null`` before the first estimate)."""
    pose = body.get("pose") or {}
    position = _numbers(pose.get("position"), 3)
    if not np.all(np.isfinite(position)):
        return None
    twist = body.get("twist") or {}
    tensions = body.get("tensions") or []
    state = body.get("state")
    kind = body.get("fault_kind")
    return {
        "position": position,
        "rpy": np.nan_to_num(_numbers(pose.get("rpy"), 3)),
        "target": np.nan_to_num(_numbers(body.get("target"), 6)),
        "velocity": np.nan_to_num(_numbers(twist.get("velocity"), 3)),
        "omega": np.nan_to_num(_numbers(twist.get("omega"), 3)),
        "tensions": _numbers(tensions, len(tensions)),
        "external_wrench": _numbers(body.get("external_wrench_estimate"), 6),
        "state": np.array([STATES.index(state) if state in STATES else math.nan]),
        "fault_kind": np.array([FAULT_KINDS.index(kind) if kind in FAULT_KINDS else math.nan]),
    }


class Ros2Frames:
    """The messages of one state (``build``), with the kinematics they need allocated once:
    the cables' lengths (m) at the estimated pose by inverse kinematics, their rates (m/s) as
    ``−Wᵀ`` the estimated twist. ``layout``: the robot's cables (a ``RobotModel`` or the
    ``SceneLayout`` of the daemon's status), ``names`` theirs, ``home_rotation`` the
    platform's at home (the target's orientation is about it)."""

    def __init__(self, layout: CableLayout, names: list[str], home_rotation: np.ndarray,
                 robot: str):  # fmt: skip
        from cdprctl.geometry.kinematics import KinematicsData

        self.layout = layout
        self.kin = KinematicsData(layout)
        self.names = list(names)
        self.home_rotation = np.asarray(home_rotation, dtype=float)
        self.robot = robot
        self.frames = frames(robot)
        self.twist = np.zeros(6)
        self._said = ""  # the last /diagnostics' text
        self._next_diagnostics = -math.inf  # s, the stamps' clock

    def static(self, stamp: Any) -> Any:
        """``/tf_static``: each anchor's frame (``<robot>_anchor_<i>``, 1-based, the base's
        axes) in the base frame."""
        from cdprctl.telemetry.ros2 import ros2_messages as rm

        r = ros_token(self.robot)
        return rm.TFMessage([rm.transform(stamp, self.frames["base"], f"{r}_anchor_{i + 1}",
                                          a, np.eye(3))
                             for i, a in enumerate(self.layout.anchors)])  # fmt: skip

    def build(self, s: dict[str, np.ndarray], stamp: Any) -> dict[str, Any]:
        """The messages of snapshot ``s`` (or ``snapshot_of_payload``) stamped ``stamp``, by
        topic key; ``diagnostics`` only when due (``DIAGNOSTICS_PERIOD``, or a change). The
        wrench estimate (N, N·m at the platform's point, base axes) is given in the
        platform's frame, as ROS reads a WrenchStamped: about its frame's origin, in its axes."""
        from cdprctl.core.rotation import rpy_to_matrix
        from cdprctl.geometry.kinematics import inverse_kinematics
        from cdprctl.motion.trajectory import coordinates_rotation
        from cdprctl.telemetry.ros2 import ros2_messages as rm

        f = self.frames
        p = s["position"]
        R = rpy_to_matrix(*map(float, s["rpy"]))
        target = s["target"]
        R_t = coordinates_rotation(self.home_rotation, target[3:6])
        inverse_kinematics(self.layout, self.kin, p, R)
        self.twist[:3], self.twist[3:] = s["velocity"], s["omega"]
        rates = -(self.kin.W.T @ self.twist)
        i = float(s["state"][0])
        state = STATES[int(i)] if np.isfinite(i) and 0 <= i < len(STATES) else "unknown"
        k = float(s["fault_kind"][0])
        fault = FAULT_KINDS[int(k)] if np.isfinite(k) and 0 <= k < len(FAULT_KINDS) else ""
        level = LEVELS.get(state, rm.OK)
        text = f"{state}: {fault}" if fault else state
        wrench = np.asarray(s["external_wrench"], dtype=float)
        local = np.concatenate([R.T @ wrench[:3], R.T @ wrench[3:6]])
        out = {
            "tf": rm.TFMessage([rm.transform(stamp, f["base"], f["platform"], p, R),
                                rm.transform(stamp, f["base"], f["target"], target[:3], R_t)]),
            "joint_states": rm.joint_state(stamp, f["base"], self.names, self.kin.length, rates,
                                           s["tensions"]),
            "pose": rm.pose_stamped(stamp, f["base"], p, R),
            "wrench_estimate": rm.wrench_stamped(stamp, f["platform"], local),
            "state": rm.String(text),
        }
        t = stamp.sec + 1e-9 * stamp.nanosec
        if text != self._said or t >= self._next_diagnostics:
            self._said, self._next_diagnostics = text, t + DIAGNOSTICS_PERIOD
            out["diagnostics"] = rm.DiagnosticArray(rm.Header(stamp, ""), [rm.DiagnosticStatus(
                level, f"cdprctl: {self.robot}", text, self.robot,
                [rm.KeyValue("state", state), rm.KeyValue("fault_kind", fault)])])  # fmt: skip
        return out
