"""``cdprctl workspace``: the wrench-feasible and the interference-free workspace on a grid
(``cdprctl.tda.workspace``, ``cdprctl.geometry.interference``)."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser, load_or_report
from cdprctl.core.angles import user_angles

DESCRIPTION = """\
For every point of a grid, whether the cables can hold the platform there, at the given
orientation, against its weight plus the given external wrench, within their tension limits —
and the tension margin: how far (N) the best tension distribution stays from the nearest limit
(negative: by how much the least-violating one exceeds a limit). Redundancy 2: an exact 2-D
linear programme per point (compiled); otherwise scipy's linprog (HiGHS) per point. And
whether it is interference-free: every pair of cables, each cable and the platform's body,
each cable and the cell's obstacles, the body and the obstacles at least [interference]
clearance apart (the least distance and its pair per point). Each point that fails says
why: the tension, the clearance or both.
--json prints {"points": [[x, y, z], ...], "feasible": [...], "margin": [N, ...],
"clearance": [m, ...], "clear": [...], "usable": [...], "why": [...], "pair": [index into
"pairs"], "volume": m³, "volume_usable": m³, ...} with x varying fastest, then y, then z."""

EPILOG = """\
examples:
  cdprctl workspace --config config/rowc.toml --wrench 0,30,0,0,0,0 --plot out/ws_rowc
  cdprctl workspace --config config/seed000.toml --grid 0:14:40,0:8:40,0:3:40 --json
  cdprctl workspace --config config/cogiro.toml --rpy 0,0,10deg   # --rpy: rad, or deg suffix"""


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "workspace", "the wrench-feasible and interference-free workspace "
                       "on a grid (JSON, slice plots)", run, description=DESCRIPTION,
                       epilog=EPILOG)  # fmt: skip
    p.add_argument("--rpy", metavar="ROLL,PITCH,YAW",
                   help="orientation in RADIANS (default: the home one), e.g. 0,0,0.2; a value "
                   "ending in deg is in degrees, e.g. 0,0,10deg; a bare value beyond pi is "
                   "refused (degrees meant as radians)")  # fmt: skip
    p.add_argument(
        "--wrench",
        default="0,0,0,0,0,0",
        metavar="FX,FY,FZ,MX,MY,MZ",
        help="external wrench fx,fy,fz,mx,my,mz (N, N·m at the platform's reference point, "
        "base frame), added to the weight (default 0)",
    )
    p.add_argument(
        "--grid",
        help="x0:x1:nx,y0:y1:ny,z0:z1:nz (m, counts); default: the box of the anchors and "
        "the configured workspace, 20 points per axis",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", metavar="DIR", help="write slice plots (PNG) into DIR")


def _floats(text: str, n: int, what: str, unit: str) -> np.ndarray | None:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.array([])
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        print(f"cdprctl workspace: error: {what} = {text!r} must be {n} finite numbers "
              f"({unit})", file=sys.stderr)  # fmt: skip
        return None
    return v


def _angles(text: str) -> np.ndarray | str:
    """``--rpy``: three angles (rad), or why they are refused (``core.angles``' rule)."""
    got = user_angles(text.split(","))
    return got if isinstance(got, str) else np.array(got)


def _beyond_max_angle(model: Any, rpy: np.ndarray) -> str:
    """Why the orientation ``rpy`` (rad) is beyond the robot's ``[workspace] max_angle`` from
    its home orientation (the limit every target keeps), or ""."""
    from cdprctl.core.rotation import log_so3, rpy_to_matrix

    angle = float(np.linalg.norm(log_so3(rpy_to_matrix(*rpy) @ model.home.rotation.T)))
    limit = model.workspace.max_angle
    if angle <= limit + 1e-9:
        return ""
    return (f"{angle:.4f} rad ({np.degrees(angle):.2f}°) from the home orientation, beyond "
            f"[workspace] max_angle = {limit:g} rad ({np.degrees(limit):.2f}°) of {model.name} "
            "(no target may turn that far): give one within it")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from cdprctl.core.rotation import rpy_to_matrix
    from cdprctl.tda.workspace import Grid, wrench_feasible_workspace

    model = load_or_report(args.config)
    if model is None:
        return 1
    rpy = np.array(model.home.rpy, dtype=float)
    if args.rpy is not None:
        given = _angles(args.rpy)
        if isinstance(given, str):
            print(f"cdprctl workspace: error: --rpy = {args.rpy!r}: {given}", file=sys.stderr)
            return 2
        rpy = given
        why = _beyond_max_angle(model, rpy)
        if why:
            print(f"cdprctl workspace: error: --rpy = {args.rpy!r}: {why}", file=sys.stderr)
            return 2
    wrench = _floats(args.wrench, 6, "--wrench", "N, N·m")
    if wrench is None:
        return 2
    try:
        grid = Grid.parse(args.grid) if args.grid else Grid.around(model)
    except ValueError as exc:
        print(f"cdprctl workspace: error: {exc}", file=sys.stderr)
        return 2
    res = wrench_feasible_workspace(model, grid, rpy_to_matrix(*rpy), wrench)
    feasible = res.feasible
    n_ok = int(feasible.sum())
    if args.plot:
        from cdprctl.tda.plots.workspace_plot import plot_workspace

        title = (f"{model.name}: rpy {np.round(rpy, 3).tolist()} rad, external wrench "
                 f"{np.round(wrench, 2).tolist()} N, N·m")  # fmt: skip
        for path in plot_workspace(args.plot, model, res, title):
            print(f"wrote {path}", file=sys.stderr if args.json else sys.stdout)
    if args.json:
        margin = [round(float(x), 4) if np.isfinite(x) else None for x in res.margin]
        clearance = [round(float(x), 6) if np.isfinite(x) else None for x in res.clearance]
        json.dump(
            {
                "robot": model.name,
                "rpy": rpy.tolist(),
                "wrench": wrench.tolist(),
                "grid": {"lo": grid.lo, "hi": grid.hi, "n": grid.n, "order": "x fastest"},
                "points": np.round(res.points, 6).tolist(),
                "feasible": feasible.tolist(),
                "margin": margin,
                "clearance": clearance,
                "clearance_limit": res.limit,
                "clear": res.clear.tolist(),
                "usable": res.usable.tolist(),
                "why": why_each(res),
                "pair": res.pair.tolist(),
                "pairs": res.pairs,
                "volume": res.volume,
                "volume_usable": res.usable_volume,
                "method": res.method,
                "seconds": res.seconds,
                "clearance_seconds": res.clearance_seconds,
            },
            sys.stdout,
        )
        print()
        return 0
    unit = grid.measure_unit  # a planar grid's is an area, a line's a length
    size = (f" ({res.volume:.4g} {unit} at {grid.cell_volume():.3g} {unit} per point)"
            if unit else "")  # fmt: skip
    print(f"{model.name}: {n_ok} of {len(feasible)} points wrench-feasible{size}; "
          f"{res.method} in {res.seconds:.2f} s")  # fmt: skip
    if n_ok:
        p = res.points[feasible]
        print(f"  feasible x {p[:, 0].min():.3f}..{p[:, 0].max():.3f} m, "
              f"y {p[:, 1].min():.3f}..{p[:, 1].max():.3f} m, "
              f"z {p[:, 2].min():.3f}..{p[:, 2].max():.3f} m; "
              f"largest margin {res.margin.max():.1f} N")  # fmt: skip
    print(clearance_summary(res, unit))
    return 0


def why_each(res: Any) -> list[str]:
    """Why each point fails: "", "tension", "clearance" or "tension, clearance"."""
    words = ("", "tension", "clearance", "tension, clearance")
    code = (~res.feasible).astype(int) + 2 * (~res.clear).astype(int)
    return [words[c] for c in code]


def clearance_summary(res: Any, unit: str = "m³") -> str:
    """The interference-free points, both (their volume in ``unit``: "" says none), and why
    the others fail (the pairs that bound the clearance most often)."""
    n, clear, usable = len(res.margin), res.clear, res.usable
    if not len(res.clearance):
        return "  interference: nothing to check (one cable, no body, no obstacle)"
    tension_only = int(np.count_nonzero(~res.feasible & clear))
    clearance_only = int(np.count_nonzero(res.feasible & ~clear))
    both = int(np.count_nonzero(~res.feasible & ~clear))
    size = f" ({res.usable_volume:.4g} {unit})" if unit else ""
    text = (f"  interference-free (cables, body, cell ≥ {res.limit * 1e3:.2f} mm apart): "
            f"{int(clear.sum())} of {n} points, in {res.clearance_seconds:.2f} s; both: "
            f"{int(usable.sum())}{size}; failing: {tension_only} on "
            f"the tension only, {clearance_only} on the clearance only, {both} on both"
            )  # fmt: skip
    blocked = res.pair[~clear & np.isfinite(res.clearance)]
    if len(blocked):
        ids, counts = np.unique(blocked, return_counts=True)
        top = np.argsort(-counts, kind="stable")[:3]
        text += "\n  closest under the clearance: " + ", ".join(
            f"{res.pairs[int(ids[j])]} ({int(counts[j])} points)" for j in top)
    return text
