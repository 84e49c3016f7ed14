"""``cdprctl report RUN``: PNG plots of a run recorded by ``cdprctl record``."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "report", "draw PNG plots of a recorded run", report, config=False)
    p.add_argument("run", metavar="RUN", help="a directory written by cdprctl record")


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def _column(head: list[str], rows: list[list[str]], name: str) -> np.ndarray:
    i = head.index(name)
    return np.array([float(r[i]) if r[i] not in ("", "None") else np.nan for r in rows])


def report(args: argparse.Namespace) -> int:
    """Reads RUN/state.csv, timing.csv, meta.json (from `cdprctl record`) and writes
    RUN/pose.png (pose and reference), tracking.png, tensions.png (with the limits, like the
    ARK 2020 paper's Fig. 5), torques.png, timing.png, with grippers grippers.png (travel,
    squeeze and state as sensed from the drives), and scene.png: the robot in 3-D (cables
    coloured by tension, platform, frame) at four instants, as the live Foxglove view draws
    it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = Path(args.run)
    if not (run / "state.csv").is_file():
        print(f"cdprctl report: {run}/state.csv is missing (record a run first)", file=sys.stderr)
        return 1
    head, rows = _read_csv(run / "state.csv")
    if not rows:
        print(f"cdprctl report: {run}/state.csv has no rows", file=sys.stderr)
        return 1
    meta: dict[str, Any] = {}
    if (run / "meta.json").is_file():
        meta = json.loads((run / "meta.json").read_text()).get("config", {})
    t = _column(head, rows, "time")
    t = t - t[0]
    cables = [h[2:] for h in head if h.startswith("t_")]
    written = []

    def save(fig: Any, name: str) -> None:
        fig.tight_layout()
        fig.savefig(run / name, dpi=110)
        plt.close(fig)
        written.append(name)

    # estimated, reference and true coincide to a fraction of a mm: a wide pale band under two
    # thin lines keeps all three visible where they overlap
    fig, axes = plt.subplots(3, 2, sharex=True, figsize=(11, 7))
    for ax, a in zip(axes[:, 0], "xyz", strict=True):
        ax.plot(t, _column(head, rows, a), color="C0", lw=4, alpha=0.35, label="estimated")
        ax.plot(t, _column(head, rows, f"ref_{a}"), color="k", lw=1, ls="--", label="reference")
        true = _column(head, rows, f"true_{a}")
        if np.any(np.isfinite(true)):
            ax.plot(t, true, color="C3", lw=1, ls=":", label="simulated (true)")
        ax.set_ylabel(f"{a} (m)")
        ax.legend(loc="best", fontsize=7)
    for ax, a, name in zip(axes[:, 1], ("rx", "ry", "rz"), ("x", "y", "z"), strict=True):
        ax.plot(t, _column(head, rows, f"err_{a}") * 1e3, color="C2", lw=1)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"orientation error\nabout {name} (mrad)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(f"{meta.get('robot', '')}: platform position and reference (left), orientation "
                 "error, estimate − reference, base frame (right)")  # fmt: skip
    save(fig, "pose.png")

    fig, ax = plt.subplots(figsize=(9, 4))
    err = np.sqrt(sum(_column(head, rows, f"err_{a}") ** 2 for a in "xyz")) * 1e3
    ax.plot(t, err)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("tracking error (mm)")
    ax.set_title(
        f"position tracking error: RMS {np.sqrt(np.nanmean(err**2)):.2f} mm, "
        f"max {np.nanmax(err):.2f} mm"
    )
    save(fig, "tracking.png")

    fig, ax = plt.subplots(figsize=(9, 5))
    _per_cable(ax, t, [_column(head, rows, f"t_{c}") for c in cables], "cable", cables)
    lo, hi = meta.get("tension_min"), meta.get("tension_max")
    if lo and hi:
        ax.axhline(min(lo), color="k", ls="--", lw=1, label="t_min")
        ax.axhline(max(hi), color="r", ls="--", lw=1, label="t_max")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("commanded tension (N)")
    ax.legend(loc="best", fontsize=8, ncol=2)
    ax.set_title("cable tensions (cables that pull alike overlap: told apart by line style)")
    save(fig, "tensions.png")

    fig, ax = plt.subplots(figsize=(9, 4))
    _per_cable(ax, t, [_column(head, rows, f"tau_{c}") for c in cables], "winch", cables)
    limits = meta.get("torque_limit")
    if limits:
        ax.axhline(max(limits), color="r", ls="--", lw=1, label="torque limit")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("motor torque (N·m)")
    ax.legend(loc="best", fontsize=8, ncol=2)
    ax.set_title("motor torques (winches that pull alike overlap: told apart by line style)")
    save(fig, "torques.png")

    grips = [h[len("grip_travel_") :] for h in head if h.startswith("grip_travel_")]
    if grips:
        fig, (ax1, ax2, ax3) = plt.subplots(3, 1, sharex=True, figsize=(9, 8))
        code = {"open": 0, "contact": 1, "squeezing": 2}
        for gname in grips:
            ax1.plot(t, _column(head, rows, f"grip_travel_{gname}") * 1e3, label=f"gripper {gname}")
            ax1.plot(t, _column(head, rows, f"grip_target_{gname}") * 1e3, "--", lw=1)
            ax2.plot(t, _column(head, rows, f"grip_force_{gname}"), label=f"gripper {gname}")
            i = head.index(f"grip_state_{gname}")
            ax3.step(t, [code.get(r[i], np.nan) for r in rows], where="post", label=gname)
        ax1.set_ylabel("travel δ (mm), target dashed")
        ax1.legend(fontsize=8)
        ax2.set_ylabel("estimated squeeze (N)")
        ax3.set_yticks([0, 1, 2], ["open", "contact", "squeezing"])
        ax3.set_xlabel("time (s)")
        fig.suptitle("grippers, sensed from the drives (Sensors 2019 §2.4)")
        save(fig, "grippers.png")

    if (run / "timing.csv").is_file():
        th, tr = _read_csv(run / "timing.csv")
        if tr:
            fig, (ax1, ax3, ax2) = plt.subplots(1, 3, figsize=(14, 4))
            tt = _column(th, tr, "time")
            for key in ("lateness_p50_us", "lateness_p99_us", "lateness_max_us"):
                ax1.plot(tt - tt[0], _column(th, tr, key), label=key.replace("_us", ""))
            ax1.set_yscale("symlog", linthresh=1.0)
            ax1.set_xlabel("time (s)")
            ax1.set_ylabel("wake lateness (µs), per report window")
            ax1.legend(fontsize=8)
            # "missed" counts from the daemon's start: each window's own is the difference
            total = np.nan_to_num(_column(th, tr, "missed"))
            per_window = np.diff(total, prepend=total[0])
            ax3.bar(tt - tt[0], per_window, width=0.8 * float(np.median(np.diff(tt)))
                    if len(tt) > 1 else 0.5, color="C3")  # fmt: skip
            ax3.set_xlabel("time (s)")
            ax3.set_ylabel("missed periods, per report window")
            ax3.set_title(f"{int(total[-1] - total[0])} missed in the recording", fontsize=9)
            ax2.hist(_column(th, tr, "compute_p50_us"), bins=20)
            ax2.set_xlabel("compute per cycle, median of each report (µs)")
            ax2.set_ylabel("reports")
            fig.suptitle("loop timing")
            save(fig, "timing.png")
    if meta.get("layout"):
        _stills(run, head, rows, t, meta)
        written.append("scene.png")
    print(f"cdprctl report: {', '.join(written)} in {run}")
    return 0


def _stills(run: Path, head: list[str], rows: list[list[str]], t: np.ndarray,
            meta: dict[str, Any]) -> None:  # fmt: skip
    """scene.png: the robot in 3-D at four instants spread over the run (the live view's
    scene, docs/foxglove.md)."""
    from cdprctl.telemetry.scene import SceneLayout
    from cdprctl.telemetry.scene_plot import scene_stills

    layout = SceneLayout.from_dict(meta["layout"])
    grips = [h[len("grip_travel_") :] for h in head if h.startswith("grip_travel_")]
    state_col = head.index("state")
    xyz = np.column_stack([_column(head, rows, a) for a in "xyz"])
    # the start, the farthest from it, the farthest from both, the end: instants that differ
    far = int(np.nanargmax(np.linalg.norm(xyz - xyz[0], axis=1))) if len(xyz) > 1 else 0
    both = np.minimum(np.linalg.norm(xyz - xyz[0], axis=1), np.linalg.norm(xyz - xyz[far], axis=1))
    third = int(np.nanargmax(both)) if np.any(np.isfinite(both)) else 0
    picks = sorted({0, far, third, len(rows) - 1})

    def value(r: list[str], name: str) -> float:
        x = r[head.index(name)]
        return float(x) if x not in ("", "None") else float("nan")

    states = []
    for i in picks:
        r = rows[i]
        state = {
            "pose": {"position": [value(r, a) for a in "xyz"],
                     "rpy": [value(r, a) for a in ("roll", "pitch", "yaw")]},
            "target": [value(r, f"ref_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")],
            "tensions": [value(r, f"t_{c}") for c in layout.names],
            "grippers": [{"travel": value(r, f"grip_travel_{g}")} for g in grips],
        }  # fmt: skip
        states.append((f"t = {t[i]:.1f} s, {r[state_col]}", state))
    scene_stills(str(run / "scene.png"), layout, states,
                 f"{meta.get('robot', '')}: the robot at the start, the end and the run's two "
                 "farthest points", trace=xyz)  # fmt: skip


def _per_cable(ax: Any, t: Any, series: list[Any], what: str, names: list[str]) -> None:
    """One line per cable: a symmetric robot's cables pull alike, so lines lie on lines —
    each cable its colour and one of four styles, wide under narrow, so every one shows."""
    styles = ("-", "--", ":", "-.")
    for k, (y, c) in enumerate(zip(series, names, strict=True)):
        ax.plot(t, y, ls=styles[k % 4], lw=2.6 - 0.5 * (k % 4), color=f"C{k % 10}",
                label=f"{what} {c}", zorder=2 + k % 4)  # fmt: skip
