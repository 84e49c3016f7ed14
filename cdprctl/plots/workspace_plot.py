"""Pictures of the wrench-feasible workspace (``cdprctl workspace --plot DIR``), after CASPR's
workspace plots: slices of the grid coloured by the tension margin (N), the boundary
(margin = 0) drawn, infeasible points grey, the configured workspace box and the anchors'
projections marked; and the feasible points in 3-D."""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from cdprctl.model import RobotModel
from cdprctl.tda.workspace import WorkspaceResult

AXES = "xyz"


def plot_workspace(out_dir: str, model: RobotModel, res: WorkspaceResult, title: str) -> list[str]:
    """Writes ``slices_<a><b>.png`` (slices across the grid's longest-sampled third axis) and
    ``feasible_3d.png`` into ``out_dir``; returns their paths."""
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    g = res.grid
    n = g.n
    margin = res.margin.reshape(n[2], n[1], n[0])  # [z, y, x]
    paths = []
    # slices normal to z, and to the axis across which the frame is thinnest when z is flat
    normals = [2] if n[2] > 1 else []
    if n[1] > 1 and n[2] > 1:
        normals.append(1)
    if not normals:
        normals = [2]
    for k in normals:
        paths.append(str(_slices(d, model, res, margin, k, title)))
    paths.append(str(_scatter(d, model, res, title)))
    return paths


def _slices(d: Path, model: RobotModel, res: WorkspaceResult, margin: np.ndarray, k: int,
            title: str) -> Path:  # fmt: skip
    g = res.grid
    axes = g.axes()
    a, b = [i for i in range(3) if i != k]
    count = g.n[k]
    picks = np.unique(np.linspace(0, count - 1, min(count, 9)).round().astype(int))
    cols = min(3, len(picks))
    rows = math.ceil(len(picks) / cols)
    feasible = margin[np.isfinite(margin) & (margin >= 0.0)]  # the colours are theirs
    top = float(feasible.max()) if feasible.size else 1.0
    top = top or 1.0
    fig, axs = plt.subplots(rows, cols, figsize=(4.2 * cols + 1.2, 3.6 * rows + 0.6), squeeze=False,
                            layout="constrained")  # fmt: skip
    ws = model.workspace
    im = None
    for ax, idx in zip(axs.ravel(), picks, strict=False):
        sl = np.take(margin, idx, axis=2 - k)  # array order is [z, y, x]
        # after np.take the remaining array axes are in [z, y, x] order without k: rows = the
        # higher of (a, b), columns = the lower
        img = np.where(np.isfinite(sl), sl, np.nan)
        shown = np.ma.masked_where(~(img >= 0.0), img)
        # pixels centred on the grid points, so the boundary contour sits between them
        ha, hb = _half_step(axes[a]), _half_step(axes[b])
        extent = (axes[a][0] - ha, axes[a][-1] + ha, axes[b][0] - hb, axes[b][-1] + hb)
        grey = np.where(img >= 0, np.nan, 0.0)
        ax.imshow(grey, origin="lower", extent=extent, cmap="Greys", vmin=-1, vmax=1,
                  aspect="auto", interpolation="nearest")  # fmt: skip
        im = ax.imshow(shown, origin="lower", extent=extent, cmap="viridis", vmin=0.0,
                       vmax=top, aspect="auto", interpolation="nearest")  # fmt: skip
        if np.nanmax(img) >= 0.0 > np.nanmin(img) and g.n[a] > 1 and g.n[b] > 1:
            ax.contour(axes[a], axes[b], np.nan_to_num(img, nan=-1e9), levels=[0.0],
                       colors="red", linewidths=1.2)  # fmt: skip
        ax.add_patch(plt.Rectangle((ws.position_min[a], ws.position_min[b]),
                                   ws.position_max[a] - ws.position_min[a],
                                   ws.position_max[b] - ws.position_min[b],
                                   fill=False, ls="--", color="black", lw=1))  # fmt: skip
        ax.plot(model.anchors[:, a], model.anchors[:, b], "k^", ms=5)
        ax.set_title(f"{AXES[k]} = {axes[k][idx]:.3g} m", fontsize=9)
        ax.set_xlabel(f"{AXES[a]} (m)")
        ax.set_ylabel(f"{AXES[b]} (m)")
    for ax in axs.ravel()[len(picks):]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axs.ravel().tolist(), label="tension margin (N)")
    fig.suptitle(
        f"{title}\nfeasible: coloured by margin, red: boundary, grey: infeasible, "
        f"dashed: configured workspace, ▲ anchors",
        fontsize=9,
    )
    path = d / f"slices_{AXES[a]}{AXES[b]}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _half_step(x: np.ndarray) -> float:
    return float(x[1] - x[0]) / 2.0 if len(x) > 1 else 0.5


def _scatter(d: Path, model: RobotModel, res: WorkspaceResult, title: str) -> Path:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ok = res.feasible
    p = res.points[ok]
    sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=res.margin[ok], s=4, cmap="viridis")
    a = model.anchors
    ax.scatter(a[:, 0], a[:, 1], a[:, 2], marker="^", c="k", s=30)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    fig.colorbar(sc, ax=ax, shrink=0.6, label="tension margin (N)")
    ax.set_title(f"{title}\n{ok.sum()} of {len(ok)} points feasible, {res.volume:.3g} m³",
                 fontsize=9)  # fmt: skip
    path = d / "feasible_3d.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
