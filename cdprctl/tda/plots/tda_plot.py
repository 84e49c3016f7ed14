"""Pictures of one tension distribution (``cdprctl tda --plot``).

* Polygon methods: the feasible polygon in λ coordinates (Picard et al. 2020, eq. (6)) coloured
  by the displacement along the chosen direction under δw (their Fig. 4), with the barycenter,
  the stiffness-oriented corner, the minimum-energy point and the chosen solution.
* Energy method with one free dimension: the total energy and each cable's energy along the
  feasible segment (Sensors 2019, Fig. 9-10), with the energy bounds (eq. (17)-(18)).
"""

from __future__ import annotations

from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Polygon as PolygonPatch

from cdprctl.model import RobotModel
from cdprctl.tda import TDAMethod
from cdprctl.tda.energy import cable_energies
from cdprctl.tda.polygon import area_centroid, feasible_polygon, min_quadratic
from cdprctl.tda.sotda import SotdaModel, grid_candidates


def plot_tda(path: str, model: RobotModel, ctx: dict[str, Any]) -> None:
    out, options = ctx["out"], ctx["options"]
    if options.method is TDAMethod.ENERGY and out.free_directions.shape[1] == 1:
        _energy_line(path, model, ctx)
    elif model.redundancy == 2:
        _polygon(path, model, ctx)
    else:
        _bars(path, model, ctx)


def _polygon(path: str, model: RobotModel, ctx: dict[str, Any]) -> None:
    out, kin, k, N, t0 = ctx["out"], ctx["kin"], ctx["k"], ctx["N"], ctx["t0"]
    direction = ctx["direction"]
    lo, hi = model.tension_min, model.tension_max
    poly = feasible_polygon(N, t0, lo, hi)
    fig, ax = plt.subplots(figsize=(7.5, 6.0), dpi=120)
    if not poly:
        ax.text(0.5, 0.5, "wrench infeasible: empty polygon", ha="center", transform=ax.transAxes)
        fig.savefig(path)
        plt.close(fig)
        return
    P = np.array(poly)
    w_ext = -(ctx["wrench"] + model.gravity_wrench(kin.rotation))
    dw = w_ext if np.linalg.norm(w_ext[:3] @ direction) > 1e-9 else np.r_[direction, 0, 0, 0]
    sm = SotdaModel(kin, k, t0, N)
    pts = grid_candidates(poly, 160)[: -len(poly)]
    dp = sm.displacements(pts, dw)[:, :3] @ direction * 1e3
    sc = ax.scatter(pts[:, 0], pts[:, 1], c=dp, s=6, cmap="viridis", marker="s", linewidths=0)
    cb = fig.colorbar(sc, ax=ax)
    cb.set_label(
        f"δp along {(np.round(direction, 3) + 0.0).tolist()} (mm) under δw = "
        f"{(np.round(dw[:3], 1) + 0.0).tolist()} N"
    )
    ax.add_patch(PolygonPatch(P, closed=True, fill=False, ec="black", lw=1.5))
    ax.plot(P[:, 0], P[:, 1], "ko", ms=4, label="vertices")
    _, (bx, by) = area_centroid(poly)
    ax.plot(bx, by, "w^", ms=10, mec="k", label="barycenter")
    vd = sm.displacements(P, dw)[:, :3] @ direction
    so = P[int(np.argmin(np.abs(vd)))]
    ax.plot(so[0], so[1], "r*", ms=14, mec="k", label="SOTDA corner (ν = 1)")
    inv_k = 1.0 / k
    H = (N.T * inv_k) @ N
    g = (N.T * inv_k) @ t0
    ex, ey = min_quadratic(poly, H[0, 0], H[0, 1], H[1, 1], g[0], g[1])
    ax.plot(ex, ey, "cs", ms=9, mec="k", label="minimum energy")
    ax.plot(
        out.lam[0],
        out.lam[1],
        "mo",
        ms=11,
        mfc="none",
        mew=2,
        label=f"solution ({ctx['options'].method.value})",
    )
    ax.set_xlabel("λ1 (N)")
    ax.set_ylabel("λ2 (N)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(
        f"{model.name}: feasible polygon, {ctx['options'].method.value} [{out.status.name}]"
    )
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _energy_line(path: str, model: RobotModel, ctx: dict[str, Any]) -> None:
    out, k = ctx["out"], ctx["k"]
    ends = out.segment_ends
    s = np.linspace(0.0, 1.0, 400)
    T = ends[0][None, :] + s[:, None] * (ends[1] - ends[0])[None, :]  # (400, m)
    U = cable_energies(T, k[None, :])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7.5, 7.5), dpi=120, sharex=True)
    a1.plot(s, U.sum(axis=1), "b-", lw=2)
    span = ends[1] - ends[0]
    j = int(np.argmax(np.abs(span)))
    s_sol = float((out.tensions[j] - ends[0][j]) / span[j]) if abs(span[j]) > 0 else 0.0
    a1.plot(
        s_sol, out.energy_total, "ro", ms=8, label=f"minimum total energy {out.energy_total:.2f} J"
    )
    a1.set_ylabel("total elastic energy U (J)")
    a1.legend()
    a1.grid(alpha=0.3)
    imposed = {imp.cable for imp in ctx["options"].impositions}
    names = [c.name for c in model.cables]
    for i in range(model.n_cables):
        style = "--" if i in imposed else "-"
        a2.plot(
            s, U[:, i], style, label=f"cable {names[i]}" + (" (imposed)" if i in imposed else "")
        )
    u_lo = cable_energies(model.tension_min, k)
    u_hi = cable_energies(model.tension_max, k)
    a2.axhline(float(u_lo.min()), color="k", lw=0.8, ls=":")
    a2.axhline(float(u_hi.max()), color="k", lw=0.8, ls=":", label="energy bounds (eq. 17-18)")
    a2.set_yscale("log")
    a2.set_xlabel("position along the feasible segment (0 and 1: a cable at a bound)")
    a2.set_ylabel("cable energy U_i (J)")
    a2.legend(fontsize=7, ncol=3)
    a2.grid(alpha=0.3, which="both")
    units = {"energy": "J", "tension": "N", "deformation": "m"}
    imp_txt = ", ".join(
        f"cable {names[i.cable]} {i.quantity.value} = {i.value:g} {units[i.quantity.value]}"
        for i in ctx["options"].impositions
    )
    fig.suptitle(f"{model.name}: energy along the constrained line ({imp_txt})")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _bars(path: str, model: RobotModel, ctx: dict[str, Any]) -> None:
    out = ctx["out"]
    fig, ax = plt.subplots(figsize=(7.5, 4.5), dpi=120)
    x = np.arange(model.n_cables)
    ax.bar(x, out.tensions, color="tab:blue", label="tension")
    ax.plot(x, model.tension_min, "k_", ms=20, label="limits")
    ax.plot(x, model.tension_max, "k_", ms=20)
    ax.set_xticks(x, [c.name for c in model.cables])
    ax.set_ylabel("tension (N)")
    ax.set_title(f"{model.name}: {ctx['options'].method.value} [{out.status.name}]")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
