"""Pictures of the wrench-feasible workspace (``cdprctl workspace --plot DIR``), after CASPR's
workspace plots: slices through the feasible part of the grid coloured by the tension margin
(N), the boundary drawn on the cells' edges, infeasible cells grey, the points where the
cables come closer than the clearance crossed (issue 67: not interference-free), the
configured workspace box, the anchors' projections and the home pose marked; and the
feasible points in 3-D, those under the clearance in red."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

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
    fig = slices_figure(model, res, margin, k, title)
    a, b = [i for i in range(3) if i != k]
    path = d / f"slices_{AXES[a]}{AXES[b]}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def slice_picks(res: WorkspaceResult, margin: np.ndarray, k: int, home: np.ndarray) -> list[int]:
    """Up to 9 indices along axis ``k`` spread over the slices with a feasible point (one all
    grey says nothing), the slice through home among them when the grid holds one."""
    count = res.grid.n[k]
    some = [i for i in range(count) if np.any(np.take(margin, i, axis=2 - k) >= 0.0)]
    lo, hi = (some[0], some[-1]) if some else (0, count - 1)
    picks = np.unique(np.linspace(lo, hi, min(hi - lo + 1, 9)).round().astype(int)).tolist()
    axis = res.grid.axes()[k]
    at_home = [i for i in range(count) if on_slice(float(home[k]), axis, i)]
    if at_home and at_home[0] not in picks:  # the nearest pick gives way to it
        nearest = min(range(len(picks)), key=lambda j: abs(picks[j] - at_home[0]))
        picks[nearest] = at_home[0]
    return sorted(set(picks))


def on_slice(value: float, axis: np.ndarray, i: int) -> bool:
    """Whether ``value`` (m) lies in slice ``i`` of ``axis``: within half the spacing of its
    plane (a one-slice axis: within 1 mm)."""
    half = _half_step(axis) if len(axis) > 1 else 1e-3
    return abs(value - float(axis[i])) <= half + 1e-12


def slices_figure(model: RobotModel, res: WorkspaceResult, margin: np.ndarray, k: int,
                  title: str) -> Figure:  # fmt: skip
    """Slices normal to axis ``k`` (``slice_picks``), coloured by the margin (N); the home
    star only on the slice through home, the configured box only on the slices it spans."""
    picks = slice_picks(res, margin, k, np.asarray(model.home.position, dtype=float))
    cols = min(3, len(picks))
    rows = math.ceil(len(picks) / cols)
    feasible = margin[np.isfinite(margin) & (margin >= 0.0)]  # the colours are theirs
    top = float(feasible.max()) if feasible.size else 1.0
    fig, axs = plt.subplots(rows, cols, figsize=(4.2 * cols + 1.2, 3.6 * rows + 0.6), squeeze=False,
                            layout="constrained")  # fmt: skip
    im = None
    n = res.grid.n
    clear = res.clear.reshape(n[2], n[1], n[0])
    for ax, idx in zip(axs.ravel(), picks, strict=False):
        im = _draw_slice(ax, model, res, np.take(margin, idx, axis=2 - k), k, idx, top or 1.0)
        _cross_blocked(ax, res, np.take(clear, idx, axis=2 - k), k)
    for ax in axs.ravel()[len(picks):]:
        ax.axis("off")
    if im is not None:
        fig.colorbar(im, ax=axs.ravel().tolist(), label="tension margin (N)")
    home_k = model.home.position[k]
    fig.suptitle(
        f"{title}\nfeasible: coloured by margin, red: boundary, grey: infeasible, "
        f"×: cables under the {res.limit * 1e3:.3g} mm clearance,\n"  # one line was wider
        f"dashed: configured workspace (where the slice cuts it), ▲ anchors (projected), "  # than
        f"☆ home (on its slice only, {AXES[k]} = {home_k:.3g} m)",  # the figure: cut off
        fontsize=9,
    )
    return fig


def _draw_slice(ax: Any, model: RobotModel, res: WorkspaceResult, sl: np.ndarray, k: int,
                idx: int, top: float) -> Any:  # fmt: skip
    """Slice ``idx`` normal to axis ``k`` (``sl``: its margins, N) into ``ax``."""
    axes = res.grid.axes()
    a, b = [i for i in range(3) if i != k]
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
    if np.nanmax(img) >= 0.0 > np.nanmin(img) and res.grid.n[a] > 1 and res.grid.n[b] > 1:
        # the feasibility (1/0) at level 0.5: halfway between a feasible point and an
        # infeasible one, i.e. on the edge between their cells (the margin's own zero
        # crossing, interpolated, sat up to half a cell off the coloured cells)
        ax.contour(axes[a], axes[b], (img >= 0.0).astype(float), levels=[0.5],
                   colors="red", linewidths=1.2)  # fmt: skip
    ws = model.workspace
    half = _half_step(axes[k]) if len(axes[k]) > 1 else 1e-3
    if ws.position_min[k] - half <= axes[k][idx] <= ws.position_max[k] + half:
        ax.add_patch(plt.Rectangle((ws.position_min[a], ws.position_min[b]),
                                   ws.position_max[a] - ws.position_min[a],
                                   ws.position_max[b] - ws.position_min[b],
                                   fill=False, ls="--", color="black", lw=1))  # fmt: skip
    ax.plot(model.anchors[:, a], model.anchors[:, b], "k^", ms=5)
    home = model.home.position
    if on_slice(float(home[k]), axes[k], idx):
        ax.plot(home[a], home[b], marker="*", ms=12, mfc="none", mec="white", mew=1.5,
                gid="home")  # fmt: skip
        ax.plot(home[a], home[b], marker="*", ms=12, mfc="none", mec="black", mew=0.7,
                gid="home")  # fmt: skip
    ax.set_title(f"{AXES[k]} = {axes[k][idx]:.3g} m" + (" (home)" if on_slice(
        float(home[k]), axes[k], idx) else ""), fontsize=9)  # fmt: skip
    ax.set_xlabel(f"{AXES[a]} (m)")
    ax.set_ylabel(f"{AXES[b]} (m)")
    return im


def _cross_blocked(ax: Any, res: WorkspaceResult, clear: np.ndarray, k: int) -> None:
    """A cross on each point of the slice that is not interference-free (``clear``: the
    slice's verdicts, rows the higher of the two remaining axes)."""
    axes = res.grid.axes()
    a, b = [i for i in range(3) if i != k]
    rows, cols = np.nonzero(~clear.reshape(len(axes[b]), len(axes[a])))
    if len(rows):
        ax.scatter(axes[a][cols], axes[b][rows], marker="x", s=8, c="red", linewidths=0.6)


def _half_step(x: np.ndarray) -> float:
    return float(x[1] - x[0]) / 2.0 if len(x) > 1 else 0.5


def _scatter(d: Path, model: RobotModel, res: WorkspaceResult, title: str) -> Path:
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ok = res.usable
    p = res.points[ok]
    # a cloud of thousands of opaque points hides itself: small, translucent
    sc = ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=res.margin[ok], s=2, alpha=0.35,
                    cmap="viridis", depthshade=False)  # fmt: skip
    a = model.anchors
    ax.scatter(a[:, 0], a[:, 1], a[:, 2], marker="^", c="k", s=30)
    h = model.home.position
    ax.scatter([h[0]], [h[1]], [h[2]], marker="*", c="red", s=120, label="home")
    near = res.points[res.feasible & ~res.clear]
    if len(near):
        ax.scatter(near[:, 0], near[:, 1], near[:, 2], marker="x", c="red", s=4, alpha=0.5,
                   label=f"feasible, cables < {res.limit * 1e3:.3g} mm apart")  # fmt: skip
    ws = model.workspace
    lo, hi = np.asarray(ws.position_min), np.asarray(ws.position_max)
    for i in range(3):  # the configured box's 12 edges
        for u in (lo, hi):
            for v in (lo, hi):
                e0, e1 = lo.copy(), hi.copy()
                j, m = [x for x in range(3) if x != i]
                e0[j] = e1[j] = u[j]
                e0[m] = e1[m] = v[m]
                ax.plot(*zip(e0, e1, strict=True), color="k", lw=0.6, ls="--")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    fig.colorbar(sc, ax=ax, shrink=0.6, label="tension margin (N)")
    ax.set_title(f"{title}\n{res.feasible.sum()} of {len(ok)} points wrench-feasible, "
                 f"{ok.sum()} of them interference-free ({res.usable_volume:.3g} m³)",
                 fontsize=9)  # fmt: skip
    path = d / "feasible_3d.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
