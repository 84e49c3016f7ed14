"""The robot as a scene, from one ``state`` payload (``schema.state_payload``): where each cable
leaves the frame and meets the platform, its tension's colour, the platform's box, the
pulleys and the jaws — in the base frame, numbers only. The live Foxglove view, the typed
channels of ``cdprctl record --mcap`` (``foxglove_messages.py``) and the report's stills
(``cdprctl report``) draw this one scene.

A client that has no config file rebuilds the layout from the daemon's status
(``SceneLayout.to_dict``/``from_dict``, under ``config.layout``)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.core.rotation import FloatArray, rpy_to_matrix
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import coordinates_rotation

SLACK_FRACTION = 0.005  # of the tension range below t_min: a cable drawn as slack


@dataclass(frozen=True)
class SceneLayout:
    """The geometry a scene needs (SI, base frame but ``attachments``: platform frame)."""

    names: tuple[str, ...]
    anchors: FloatArray  # (m, 3)
    attachments: FloatArray  # (m, 3) platform frame
    pulley_radius: FloatArray  # (m,), 0 without a pulley
    pulley_axis: FloatArray  # (m, 3)
    tension_min: FloatArray  # (m,) N
    tension_max: FloatArray  # (m,) N
    home_rotation: FloatArray  # (3, 3): the trajectory's rotation vectors are from it
    jaws: tuple[tuple[int, tuple[float, ...], tuple[float, ...]], ...] = ()  # (cable, L1, k̂)

    @property
    def n_cables(self) -> int:
        return len(self.names)

    @staticmethod
    def from_model(model: RobotModel) -> SceneLayout:
        return SceneLayout(
            names=tuple(c.name for c in model.cables),
            anchors=np.array(model.anchors, dtype=float),
            attachments=np.array(model.attachments, dtype=float),
            pulley_radius=np.array(model.pulley_radius, dtype=float),
            pulley_axis=np.array(model.pulley_axis, dtype=float),
            tension_min=np.array(model.tension_min, dtype=float),
            tension_max=np.array(model.tension_max, dtype=float),
            home_rotation=np.array(model.home.rotation, dtype=float),
            jaws=tuple((g.cable, tuple(map(float, g.jaw_offset)), tuple(map(float, g.guide_axis)))
                       for g in model.grippers),
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": list(self.names),
            "anchors": self.anchors.tolist(),
            "attachments": self.attachments.tolist(),
            "pulley_radius": self.pulley_radius.tolist(),
            "pulley_axis": self.pulley_axis.tolist(),
            "tension_min": self.tension_min.tolist(),
            "tension_max": self.tension_max.tolist(),
            "home_rotation": self.home_rotation.tolist(),
            "jaws": [[c, list(L1), list(k)] for c, L1, k in self.jaws],
        }

    @staticmethod
    def from_dict(d: dict[str, Any]) -> SceneLayout:
        return SceneLayout(
            names=tuple(d["names"]),
            anchors=np.array(d["anchors"], dtype=float).reshape(-1, 3),
            attachments=np.array(d["attachments"], dtype=float).reshape(-1, 3),
            pulley_radius=np.array(d["pulley_radius"], dtype=float),
            pulley_axis=np.array(d["pulley_axis"], dtype=float).reshape(-1, 3),
            tension_min=np.array(d["tension_min"], dtype=float),
            tension_max=np.array(d["tension_max"], dtype=float),
            home_rotation=np.array(d["home_rotation"], dtype=float).reshape(3, 3),
            jaws=tuple((int(c), tuple(L1), tuple(k)) for c, L1, k in d.get("jaws", [])),
        )


# (fraction of the tension range, RGB): blue at t_min, green, yellow, red at t_max
TENSION_STOPS = ((0.0, (0.1, 0.3, 1.0)), (0.33, (0.0, 0.8, 0.2)), (0.66, (1.0, 0.85, 0.0)),
                 (1.0, (1.0, 0.1, 0.0)))  # fmt: skip
SLACK_RGBA = (0.75, 0.75, 0.75, 1.0)
OVER_RGBA = (1.0, 0.0, 1.0, 1.0)


def tension_rgba(t: float, lo: float, hi: float) -> tuple[float, float, float, float]:
    """The colour of a cable at tension ``t`` (N) between its limits (``TENSION_STOPS``);
    slack (below ``lo`` by more than ``SLACK_FRACTION`` of the range) light grey; beyond
    ``hi`` magenta; unknown (NaN) black."""
    if not math.isfinite(t):
        return (0.0, 0.0, 0.0, 1.0)
    status = cable_status(t, lo, hi)
    if status:
        return SLACK_RGBA if status == "slack" else OVER_RGBA
    s = min(1.0, max(0.0, (t - lo) / max(hi - lo, 1e-9)))
    for (s0, c0), (s1, c1) in itertools.pairwise(TENSION_STOPS):
        if s <= s1:
            f = (s - s0) / (s1 - s0)
            r, g, b = (a + f * (b - a) for a, b in zip(c0, c1, strict=True))
            return (r, g, b, 1.0)
    return (*TENSION_STOPS[-1][1], 1.0)


def cable_status(t: float, lo: float, hi: float) -> str:
    """"slack", "over limit" or "" (the rule of ``tension_rgba``)."""
    span = max(hi - lo, 1e-9)
    if math.isfinite(t) and t < lo - SLACK_FRACTION * span:
        return "slack"
    if math.isfinite(t) and t > hi:
        return "over limit"
    return ""


@dataclass
class Scene:
    """One instant of the robot, base frame (m)."""

    position: FloatArray  # (3,) P, estimated
    rotation: FloatArray  # (3, 3) platform → base
    target_position: FloatArray  # (3,)
    target_rotation: FloatArray  # (3, 3)
    exits: FloatArray  # (m, 3) where each cable leaves the frame (the pulley's tangent point)
    attach: FloatArray  # (m, 3) where it meets the platform
    tensions: FloatArray  # (m,) N
    colours: list[tuple[float, float, float, float]]
    status: list[str]  # per cable: "", "slack", "over limit"
    pulleys: list[FloatArray]  # (k, 3) circles of the pulleys' wheels
    box: tuple[FloatArray, FloatArray]  # platform frame: the attachments' box (centre, size)
    jaws: FloatArray  # (g, 3) base frame
    # the cables' least distance (``schema.clearance_payload``): the closest points (2, 3),
    # the label ("cables 1 and 2: 25.7 mm") and whether it is under the clearance; None: none
    closest: tuple[FloatArray, str, bool] | None = None


class SceneBuilder:
    def __init__(self, layout: SceneLayout):
        self.layout = layout
        self.kin = KinematicsData(layout)
        a = layout.attachments
        lo, hi = a.min(axis=0), a.max(axis=0)
        size = np.maximum(hi - lo, 0.01)  # a flat platform still shows as a slab
        self.box = (0.5 * (lo + hi), size)

    def build(self, state: dict[str, Any]) -> Scene | None:
        """The scene of a ``state`` payload (``pose``, ``target``, ``tensions``, ``grippers``);
        None while the pose is unknown (``null`` before the first estimate)."""
        lay = self.layout
        p = np.array([math.nan if x is None else x for x in state["pose"]["position"]], float)
        if not np.all(np.isfinite(p)):
            return None
        rpy = [x if x is not None else 0.0 for x in state["pose"]["rpy"]]
        R = rpy_to_matrix(*rpy)
        target = np.array([x if x is not None else 0.0 for x in state["target"]], dtype=float)
        Rt = coordinates_rotation(lay.home_rotation, target[3:])
        inverse_kinematics(lay, self.kin, p, R)
        exits = np.array(self.kin.exit_points)
        attach = self.kin.rb + p
        t = np.array([x if x is not None else math.nan for x in state["tensions"]], dtype=float)
        lo, hi = lay.tension_min, lay.tension_max
        pulleys = []
        for i in np.flatnonzero(lay.pulley_radius > 0.0):
            z = lay.pulley_axis[i]
            d = exits[i] - lay.anchors[i]
            e = d - float(d @ z) * z
            n = float(np.linalg.norm(e))
            if n < 1e-12:
                continue
            e /= n
            r = float(lay.pulley_radius[i])
            centre = lay.anchors[i] + r * e
            th = np.linspace(0.0, 2.0 * math.pi, 25)
            pulleys.append(centre + r * (np.cos(th)[:, None] * e + np.sin(th)[:, None] * z))
        jaws = np.zeros((len(lay.jaws), 3))
        grip = state.get("grippers") or []
        for j, (cable, L1, k) in enumerate(lay.jaws):
            travel = grip[j].get("travel") if j < len(grip) else None
            local = lay.attachments[cable] + np.array(L1) + float(travel or 0.0) * np.array(k)
            jaws[j] = p + R @ local
        return Scene(
            position=p, rotation=R, target_position=target[:3], target_rotation=Rt,
            exits=exits, attach=attach, tensions=t,
            colours=[tension_rgba(float(t[i]), float(lo[i]), float(hi[i])) for i in range(len(t))],
            status=[cable_status(float(t[i]), float(lo[i]), float(hi[i])) for i in range(len(t))],
            pulleys=pulleys, box=self.box, jaws=jaws, closest=closest_pair(state),
        )  # fmt: skip


def closest_pair(state: dict[str, Any]) -> tuple[FloatArray, str, bool] | None:
    """The closest pair of a state payload's ``clearance``: its points, label, and whether
    it is under the clearance."""
    c = state.get("clearance")
    if not c or c["distance"] is None or None in c["points"][0] + c["points"][1]:
        return None
    points = np.array(c["points"], dtype=float)
    a, b = c["between"]
    what = {"cable": f"cables {a} and {b}", "platform": f"the platform's {a} and {b}"}.get(
        c["kind"], f"cable {a} and {b}")
    under = c["limit"] is not None and c["distance"] < c["limit"]
    return points, f"{what}: {c['distance'] * 1e3:.1f} mm", under
