"""``cdprctl report RUN``: PNG plots of a run recorded by ``cdprctl record``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cdprctl.commands.common import command_parser


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "report", "draw PNG plots of a recorded run", report, config=False)
    p.add_argument("run", metavar="RUN", help="a directory written by cdprctl record")


def report(args: argparse.Namespace) -> int:
    """Reads RUN/state.csv, timing.csv, events.csv, meta.json (from `cdprctl record`) and
    writes RUN/pose.png (pose and reference), tracking.png (the position error while the
    robot tracks: the drives-off spans shaded, not counted), tensions.png (with the limits,
    like the ARK 2020 paper's Fig. 5), torques.png, timing.png, with grippers grippers.png
    (travel, squeeze and state as sensed from the drives): each time plot marks the run's
    events (state changes, faults, rejected commands). And scene.png: the robot in 3-D
    (cables coloured by tension, platform, frame) at the start, the end and the two poses of
    the run farthest apart, as the live Foxglove view draws it."""
    import matplotlib.pyplot as plt

    from cdprctl.telemetry.report import report_plots as rp
    from cdprctl.telemetry.report.recording import load_recording

    run = Path(args.run)
    rec = load_recording(run)
    if isinstance(rec, str):
        print(f"cdprctl report: {rec}", file=sys.stderr)
        return 1
    written = []
    figures = (("pose.png", rp.pose_figure), ("tracking.png", rp.tracking_figure),
               ("tensions.png", rp.tensions_figure), ("torques.png", rp.torques_figure),
               ("grippers.png", rp.grippers_figure), ("timing.png", rp.timing_figure))  # fmt: skip
    for name, draw in figures:
        fig = draw(rec)
        if fig is not None:
            fig.savefig(run / name, dpi=110)
            plt.close(fig)
            written.append(name)
    if rp.scene_figure(rec, str(run / "scene.png")):
        written.append("scene.png")
    print(f"cdprctl report: {', '.join(written)} in {run}")
    return 0
