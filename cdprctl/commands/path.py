"""``cdprctl path check``: a path file planned and checked offline, as the daemon would."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser, load_or_report, os_error_text


def add_parser(sub: Any) -> None:
    p = sub.add_parser("path", help="path files: check one offline (plan, limits, tensions)")
    actions = p.add_subparsers(dest="path_action", metavar="ACTION", required=True)
    c = command_parser(actions, "check", "plan and check a path file without a robot", check)
    c.add_argument("file", metavar="FILE", help="the path (CSV or G-code, docs/operating.md)")
    c.add_argument("--from", dest="start", default="", metavar="X,Y,Z[,ROLL,PITCH,YAW]",
                   help="where the path starts (m, rad; default: the robot's home pose)")
    c.add_argument("--units", choices=("m", "mm", "in"), default="m",
                   help="a CSV's lengths (speeds per s) when it has no row of units")
    c.add_argument("--rate", type=float, default=None,
                   help="Hz, the loop's rate the plan is played at (default: [control] rate)")


def check(args: argparse.Namespace) -> int:
    """The path as `cdprctl run --path` and the gateway plan it, from the robot's home pose
    (or --from), at rest: every waypoint and the trajectory between them against the soft
    limits and the tension margins, without a robot. Prints the plan (segments, duration,
    the closest approach to the limits); exit 0 when it holds, 2 when it is refused (why, on
    one line)."""
    from cdprctl.motion.limits import SoftLimits
    from cdprctl.motion.path_plan import (
        PathRejectedError,
        coordinates_of,
        plan_text,
        units_hint,
    )
    from cdprctl.motion.waypoints import PathFileError

    model = load_or_report(args.config)
    if model is None:
        return 1
    try:
        text = Path(args.file).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        print(f"cdprctl path check: error: {args.file}: {os_error_text(exc)}", file=sys.stderr)
        return 2
    home = [*model.home.position, *model.home.rpy]
    try:
        given = [float(v) for v in args.start.split(",")] if args.start else home
    except ValueError:
        given = []
    if len(given) not in (3, 6) or not np.all(np.isfinite(given)):
        print(f"cdprctl path check: error: --from = {args.start!r}: give x,y,z (m) or "
              "x,y,z,roll,pitch,yaw (m, rad)", file=sys.stderr)  # fmt: skip
        return 2
    pose = np.array(given + home[len(given):], dtype=float)
    limits, start = SoftLimits(model), coordinates_of(model, pose)
    if args.start and (outside := limits.outside(start)):
        print(f"cdprctl path check: error: --from = {args.start!r}: {outside} ([workspace] of "
              f"{model.source_file}): no robot stands there to start a path", file=sys.stderr)
        return 2
    period = 1.0 / (args.rate or model.control.rate)
    try:
        plan = plan_text(model, text, start, period, limits, args.file, args.units)
    except (PathFileError, PathRejectedError) as exc:
        print(f"cdprctl path check: {args.file} rejected: {exc}"
              f"{units_hint(text, args.units, str(exc))}", file=sys.stderr)  # fmt: skip
        return 2
    at = ", ".join(f"{v:.4g}" for v in pose[:3])
    print(f"{args.file} on {model.name}, from [{at}] m: {plan.summary()}")
    for k, s in enumerate(plan.segments, 1):
        to = ", ".join(f"{v:.4f}" for v in s.target[:3])
        extra = f", dwell {s.dwell:g} s" if s.dwell else ""
        timed = f", in {s.minimum_duration:.2f} s" if s.minimum_duration is not None else ""
        print(f"  {k:3d}  {s.where:>9}  to [{to}] m{timed}{extra}")
    print(f"  {plan.clearance_text()}")
    n = len(plan.segments)
    print(f"ok: the path holds ({n} segment{'s' if n != 1 else ''}, {plan.duration:.2f} s)")
    return 0

