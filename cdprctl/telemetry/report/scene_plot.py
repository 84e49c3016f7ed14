"""The live view's scene (``scene.py``) as matplotlib 3-D stills, for people without Foxglove
(``cdprctl report``): the frame's anchors and box, each cable from its exit point to its
attachment coloured by tension (the same colours), slack and over-limit cables labelled, the
platform as the box of its attachments, the jaws, the target frame's origin."""

from __future__ import annotations

from typing import Any

import numpy as np

from cdprctl.telemetry.foxglove.scene import (
    TENSION_STOPS,
    Scene,
    SceneBuilder,
    SceneLayout,
)


def _box_edges(centre: np.ndarray, size: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    h = 0.5 * size
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    pts = centre + corners * h
    edges = [(0, 1), (0, 2), (0, 4), (1, 3), (1, 5), (2, 3), (2, 6), (3, 7), (4, 5), (4, 6),
             (5, 7), (6, 7)]  # fmt: skip
    return [(pts[a], pts[b]) for a, b in edges]


def draw_scene(ax: Any, layout: SceneLayout, scene: Scene, title: str) -> None:
    a = layout.anchors
    ax.scatter(a[:, 0], a[:, 1], a[:, 2], marker="^", color="0.4", s=25)
    lo, hi = a.min(axis=0), a.max(axis=0)
    for p, q in _box_edges(0.5 * (lo + hi), hi - lo):
        ax.plot(*zip(p, q, strict=True), color="0.75", lw=0.8)
    for circle in scene.pulleys:
        ax.plot(circle[:, 0], circle[:, 1], circle[:, 2], color="0.3", lw=0.8)
    for i in range(len(scene.exits)):
        e, b = scene.exits[i], scene.attach[i]
        slack = scene.status[i] == "slack"
        ax.plot(*zip(e, b, strict=True), color=scene.colours[i][:3], lw=1.0 if slack else 2.2,
                ls="--" if slack else "-")  # fmt: skip
        if scene.status[i]:
            m = 0.5 * (e + b)
            ax.text(m[0], m[1], m[2], f"{layout.names[i]} {scene.status[i]}", fontsize=7,
                    color=scene.colours[i][:3])  # fmt: skip
    centre, size = scene.box
    R, p = scene.rotation, scene.position
    for u, v in _box_edges(centre, size):
        ax.plot(*zip(p + R @ u, p + R @ v, strict=True), color=(0.85, 0.55, 0.2), lw=1.2)
    if len(scene.jaws):
        j = scene.jaws
        ax.scatter(j[:, 0], j[:, 1], j[:, 2], color=(0.9, 0.2, 0.2), s=20)
    t = scene.target_position
    ax.scatter([t[0]], [t[1]], [t[2]], marker="x", color="k", s=30)
    span = hi - lo
    mid = 0.5 * (lo + hi)
    r = 0.5 * float(max(span.max(), 1e-3))
    ax.set_xlim(mid[0] - r, mid[0] + r)
    ax.set_ylim(mid[1] - r, mid[1] + r)
    ax.set_zlim(mid[2] - r, mid[2] + r)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)", fontsize=8)
    ax.set_ylabel("y (m)", fontsize=8)
    ax.set_zlabel("z (m)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(title, fontsize=9)


def scene_stills(path: str, layout: SceneLayout, states: list[tuple[str, dict[str, Any]]],
                 suptitle: str, trace: Any = None) -> None:  # fmt: skip
    """``states``: (title, state payload) of each still, drawn side by side into ``path``;
    ``trace`` ((n, 3) m, optional): the platform's path over the run, drawn in each still with
    the still's own position on it (a robot's moves are small beside its frame: without it
    the stills looked alike)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    builder = SceneBuilder(layout)
    n = len(states)
    cols = min(2, n)
    rows = (n + cols - 1) // cols
    fig = plt.figure(figsize=(6.0 * cols + 1.0, 5.2 * rows), layout="constrained")
    axes = []
    for k, (title, state) in enumerate(states):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        scene = builder.build(state)
        if scene is not None:  # a row without a pose stays an empty frame
            draw_scene(ax, layout, scene, title)
        if trace is not None and len(trace):
            ax.plot(trace[:, 0], trace[:, 1], trace[:, 2], color="C1", lw=1.2,
                    label="the platform's path")  # fmt: skip
            p = state["pose"]["position"]
            ax.scatter([p[0]], [p[1]], [p[2]], color="C1", s=40, edgecolor="k")
            ax.legend(loc="upper left", fontsize=7)
        axes.append(ax)
    cmap = LinearSegmentedColormap.from_list("tension", [(s, c) for s, c in TENSION_STOPS])
    sm = plt.cm.ScalarMappable(norm=Normalize(0.0, 1.0), cmap=cmap)
    bar = fig.colorbar(sm, ax=axes, shrink=0.6,
                       label="tension, from t_min (0) to t_max (1) of each cable")  # fmt: skip
    bar.ax.tick_params(labelsize=7)
    fig.suptitle(f"{suptitle}\nslack cables dashed (light grey), over the limit magenta; "
                 "platform: the box of its attachments; x: the target", fontsize=9)  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)
