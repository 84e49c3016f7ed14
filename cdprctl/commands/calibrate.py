"""``cdprctl calibrate``: find where each encoder reads zero and keep it in the state directory
(docs/homing.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser, load_or_report, parse_pose
from cdprctl.commands.sim import add_bus_arguments, bus_overrides


def add_parser(sub: Any) -> None:
    p = command_parser(
        sub, "calibrate", "find the encoders' zero (homing): known-pose or self", run
    )
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="where the record goes (default /var/lib/cdprctl/<robot>)",
    )
    add_bus_arguments(p)
    methods = p.add_subparsers(dest="method", required=True, metavar="METHOD")
    kp = methods.add_parser(
        "known-pose",
        help="the platform stands at a known pose (the home fixture by default)",
        description="Hold the platform where it stands, at a known pose, and record each "
        "cable's motor angle at its unstretched length there.",
    )
    kp.add_argument("--pose", help="x,y,z,roll,pitch,yaw (m, rad); default: the home pose")
    kp.add_argument("--json", action="store_true", help="print the result as JSON")
    sp = methods.add_parser(
        "self",
        help="from an unknown pose near home, with the drives only",
        description="Move the platform through poses around its start (six cables by "
        "position, the redundant ones by tension), sample motor angles and tensions at rest, "
        "identify the start pose by least squares; refused when the data do not decide it.",
    )
    sp.add_argument("--json", action="store_true", help="print the result as JSON")
    sp.add_argument("--travel", type=float, default=0.05, help="m of each translation (0.05)")
    sp.add_argument("--tilt", type=float, default=0.05, help="rad of each rotation (0.05)")
    sp.add_argument(
        "--fit-drum-scales", action="store_true", help="identify each drum's pay-out scale too"
    )


def run(args: argparse.Namespace) -> int:
    """Calibrate the robot's encoders: the drives are configured, enabled, the platform held
    (known-pose) or moved near its start (self), the drives disabled (brakes on), and the
    record written atomically to the state directory, where ``cdprctl run`` reads it."""
    from cdprctl.calibration.procedure import (
        CalibrationFailedError,
        SelfOptions,
        known_pose,
        self_calibrate,
    )
    from cdprctl.calibration.record import default_state_dir, save
    from drivers import create_driver
    from drivers.errors import DriverError

    model = load_or_report(args.config)
    if model is None:
        return 1
    state_dir = Path(args.state_dir) if args.state_dir else default_state_dir(model.name)
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    pose = None
    if args.method == "known-pose":
        pose = (
            parse_pose(args.pose, "--pose")
            if args.pose
            else np.r_[model.home.position, model.home.rpy]
        )
    else:
        for name in ("travel", "tilt"):
            value = getattr(args, name)
            if not 0.0 < value <= 0.3:
                raise SystemExit(f"--{name} = {value}: must be in (0, 0.3] (m or rad)")
    driver = create_driver(model, period=model.control.period, bus_overrides=bus_overrides(args))
    ident = None
    try:
        log(f"cdprctl calibrate: {model.name}, {args.method}: configuring the drives")
        driver.configure()
        if pose is not None:
            record = known_pose(model, driver, pose, log)
        else:
            opt = SelfOptions(
                travel=args.travel, tilt=args.tilt, fit_drum_scales=args.fit_drum_scales
            )
            record, ident = self_calibrate(model, driver, opt, log)
    except (DriverError, CalibrationFailedError) as exc:
        print(f"cdprctl calibrate: failed: {exc}", file=sys.stderr)
        return 1
    finally:
        driver.shutdown()
    path = save(record, state_dir)
    result = {
        "pose": record.pose,
        "residual_rms": record.residual_rms,
        "condition": record.condition,
        "method": record.method,
        "std": record.std,
        "sample_residuals": record.sample_residuals,
        "drum_scale": record.drum_scale,
        "record": str(path),
    }
    if args.json:
        print(json.dumps(result))
    else:
        p = record.pose
        log(f"pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m, rpy [{p[3]:.4f}, {p[4]:.4f}, "
            f"{p[5]:.4f}] rad")  # fmt: skip
        if ident is not None:
            std = np.array(ident.std) * 1e3
            log(f"residual {ident.residual_rms * 1e6:.1f} µm RMS over {record.samples} "
                f"samples, condition {ident.condition:.3g}, predicted σ "
                f"{np.round(std[:3], 2).tolist()} mm, "
                f"{np.round(std[3:], 2).tolist()} mrad")  # fmt: skip
        log(f"record: {path}")
    return 0
