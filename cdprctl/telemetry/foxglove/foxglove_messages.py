"""Foxglove's typed messages of a scene (``scene.py``), built with the ``foxglove-sdk``
schemas: the live view (``foxglove_view.py``) and ``cdprctl record --mcap`` log the same.

Topics: ``/tf`` (``FrameTransforms``: base → platform from the estimated pose, base → target
from the trajectory's target), ``/scene`` (``SceneUpdate``: the frame's anchors and box, the
pulleys, each cable as a line from its exit point to its attachment coloured by its tension,
slack and over-limit cables labelled, the platform as the box of its attachments, the jaws),
``/signals`` (JSON: tensions, torques, tracking error — what Foxglove's plots read) and
``/log`` (``Log``: state changes, faults, events)."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np
from foxglove.messages import (
    Color,
    CubePrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Log,
    LogLevel,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from cdprctl.core.rotation import FloatArray
from cdprctl.telemetry.foxglove.scene import Scene, SceneLayout

BASE, PLATFORM, TARGET = "base", "platform", "target"
TOPICS = {"tf": "/tf", "scene": "/scene", "signals": "/signals", "log": "/log"}


def quaternion(R: FloatArray) -> Quaternion:
    x, y, z, w = quaternion_xyzw(R)
    return Quaternion(x=x, y=y, z=z, w=w)


def quaternion_xyzw(R: FloatArray) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    m = R
    tr = float(m[0, 0] + m[1, 1] + m[2, 2])
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        w, x = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        y, z = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2.0
        w, x = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2.0
        w, x = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2.0
        w, x = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        y, z = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return float(x), float(y), float(z), float(w)


def _stamp(ns: int) -> Timestamp:
    return Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def _pt(v: FloatArray) -> Point3:
    return Point3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _color(c: tuple[float, float, float, float]) -> Color:
    return Color(r=c[0], g=c[1], b=c[2], a=c[3])


def transforms(scene: Scene, ns: int) -> FrameTransforms:
    stamp = _stamp(ns)
    out = []
    for child, p, R in ((PLATFORM, scene.position, scene.rotation),
                        (TARGET, scene.target_position, scene.target_rotation)):  # fmt: skip
        out.append(FrameTransform(timestamp=stamp, parent_frame_id=BASE, child_frame_id=child,
                                  translation=Vector3(x=float(p[0]), y=float(p[1]),
                                                      z=float(p[2])),
                                  rotation=quaternion(R)))  # fmt: skip
    return FrameTransforms(transforms=out)


class SceneMessages:
    """Builds the ``SceneUpdate`` of a scene; the parts that never move are made once."""

    def __init__(self, layout: SceneLayout):
        self.layout = layout
        a = layout.anchors
        span = float(np.linalg.norm(a.max(axis=0) - a.min(axis=0))) or 1.0
        self.size = 0.01 * span  # m: anchors, jaws and line widths scale with the robot
        grey = Color(r=0.55, g=0.55, b=0.6, a=1.0)
        self.anchors = [SpherePrimitive(pose=Pose(position=Vector3(x=float(p[0]),
                                                                   y=float(p[1]),
                                                                   z=float(p[2]))),
                                        size=Vector3(x=self.size, y=self.size, z=self.size),
                                        color=grey) for p in a]  # fmt: skip
        lo, hi = a.min(axis=0), a.max(axis=0)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])  # fmt: skip
        edges = [(0, 1), (0, 2), (0, 4), (1, 3), (1, 5), (2, 3), (2, 6), (3, 7), (4, 5),
                 (4, 6), (5, 7), (6, 7)]  # fmt: skip
        pts = [_pt(corners[k]) for e in edges for k in e]
        self.frame_box = LinePrimitive(type=LinePrimitiveLineType.LineList, points=pts,
                                       thickness=0.3 * self.size, color=grey)  # fmt: skip

    def update(self, scene: Scene, ns: int) -> SceneUpdate:
        stamp = _stamp(ns)
        s = self.size
        cables = [
            LinePrimitive(type=LinePrimitiveLineType.LineList,
                          points=[_pt(scene.exits[i]), _pt(scene.attach[i])],
                          thickness=(0.25 if scene.status[i] == "slack" else 0.5) * s,
                          color=_color(scene.colours[i]))
            for i in range(len(scene.exits))
        ]  # fmt: skip
        labels = []  # the slack and over-limit cables, named at their middle
        for i in (i for i, status in enumerate(scene.status) if status):
            m = 0.5 * (scene.exits[i] + scene.attach[i])
            text = f"{self.layout.names[i]}: {scene.status[i]} ({scene.tensions[i]:.0f} N)"
            labels.append(TextPrimitive(
                pose=Pose(position=Vector3(x=float(m[0]), y=float(m[1]), z=float(m[2]))),
                billboard=True, font_size=2.0 * s, scale_invariant=False,
                color=_color(scene.colours[i]),
                text=text))  # fmt: skip
        pulleys = [LinePrimitive(type=LinePrimitiveLineType.LineStrip,
                                 points=[_pt(q) for q in circle], thickness=0.3 * s,
                                 color=Color(r=0.3, g=0.3, b=0.35, a=1.0))
                   for circle in scene.pulleys]  # fmt: skip
        centre, size = scene.box
        platform = CubePrimitive(pose=Pose(position=Vector3(x=float(centre[0]),
                                                            y=float(centre[1]),
                                                            z=float(centre[2])),
                                           orientation=Quaternion(x=0, y=0, z=0, w=1)),
                                 size=Vector3(x=float(size[0]), y=float(size[1]),
                                              z=float(size[2])),
                                 color=Color(r=0.85, g=0.55, b=0.2, a=0.6))  # fmt: skip
        jaws = [SpherePrimitive(pose=Pose(position=Vector3(x=float(j[0]), y=float(j[1]),
                                                           z=float(j[2]))),
                                size=Vector3(x=1.5 * s, y=1.5 * s, z=1.5 * s),
                                color=Color(r=0.9, g=0.2, b=0.2, a=1.0))
                for j in scene.jaws]  # fmt: skip
        near = []  # the closest pair: a line between its points, named; red under the clearance
        if scene.closest is not None:
            points, label, under = scene.closest
            red, amber = Color(r=0.9, g=0.1, b=0.1, a=1.0), Color(r=0.95, g=0.75, b=0.1, a=1.0)
            colour = red if under else amber
            m = 0.5 * (points[0] + points[1])
            near = [SceneEntity(timestamp=stamp, frame_id=BASE, id="clearance",
                                lines=[LinePrimitive(type=LinePrimitiveLineType.LineList,
                                                     points=[_pt(points[0]), _pt(points[1])],
                                                     thickness=0.5 * s, color=colour)],
                                texts=[TextPrimitive(
                                    pose=Pose(position=Vector3(x=float(m[0]), y=float(m[1]),
                                                               z=float(m[2]))),
                                    billboard=True, font_size=2.0 * s, scale_invariant=False,
                                    color=colour, text=label)])]  # fmt: skip
        return SceneUpdate(entities=[
            SceneEntity(timestamp=stamp, frame_id=BASE, id="frame", spheres=self.anchors,
                        lines=[self.frame_box, *pulleys]),
            SceneEntity(timestamp=stamp, frame_id=BASE, id="cables", lines=cables,
                        texts=labels),
            SceneEntity(timestamp=stamp, frame_id=PLATFORM, id="platform", frame_locked=True,
                        cubes=[platform]),
            SceneEntity(timestamp=stamp, frame_id=BASE, id="jaws", spheres=jaws),
            *near,
        ])  # fmt: skip


def signals(state: dict[str, Any]) -> dict[str, Any]:
    """The plain numbers Foxglove's plots read, from a state payload."""
    return {
        "time": state.get("time"),
        "state": state.get("state"),
        "tensions": state.get("tensions"),
        "torques": state.get("torques"),
        "tracking_error": state.get("tracking_error"),
        "path": state.get("path"),
        "clearance": (state.get("clearance") or {}).get("distance"),
    }


SIGNALS_SCHEMA = {
    "type": "object",
    "properties": {
        "time": {"type": "number"},
        "state": {"type": "string"},
        "tensions": {"type": "array", "items": {"type": ["number", "null"]}},
        "torques": {"type": "array", "items": {"type": ["number", "null"]}},
        "tracking_error": {"type": "array", "items": {"type": ["number", "null"]}},
        "clearance": {"type": ["number", "null"]},  # m, the cables' least distance
    },
}


def log_message(ns: int, kind: str, text: str) -> Log:
    """An event as a ``Log``: a fault is an error, a rejection a warning, the rest info."""
    level = {"fault": LogLevel.Error, "reject": LogLevel.Warning}.get(kind, LogLevel.Info)
    return Log(timestamp=_stamp(ns), level=level, message=text, name=f"cdprctl.{kind}")


def signals_bytes(state: dict[str, Any]) -> bytes:
    return json.dumps(signals(state), separators=(",", ":"), allow_nan=False).encode()
