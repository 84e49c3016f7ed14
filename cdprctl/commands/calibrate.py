"""``cdprctl calibrate``: find where each encoder reads zero and keep it in the state directory
(docs/homing.md)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser, load_or_report, parse_pose
from cdprctl.commands.records import EXIT_STATE_DIR, records_dir, save_or_keep
from cdprctl.commands.sim import add_bus_arguments, bus_overrides, refuse_in_process_bus
from drivers.simulated import simulated_robot


def _robot_and_bus(p: argparse.ArgumentParser, **default: Any) -> None:
    """The options of every method, before or after its name (``default``: on a method,
    ``SUPPRESS``, so one given before it is kept)."""
    p.add_argument("--config", help="robot description (TOML)", **default)
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="where the record goes (default /var/lib/cdprctl/<robot>)",
        **default,
    )
    add_bus_arguments(p, **default)


@contextlib.contextmanager
def moves_held(model: Any, realtime: bool, log: Callable[[str], None]) -> Iterator[None]:
    """A procedure's cycles as the daemon's loop runs its own: the garbage collector frozen
    (a full collection of what the start-up built held a cycle ~80 ms on this VM: the drives
    extrapolated, then a step in their targets) and, with ``realtime``, SCHED_FIFO on the
    loop's CPU (a late cycle is a tension spike on stiff cables: rowc's moves stopped short,
    a following error). Given back after."""
    from cdprctl import realtime as rt

    try:
        for w in rt.lock_memory_and_freeze_gc(False, model.control.freeze_gc):
            log(f"cdprctl calibrate: warning: {w}")
        if realtime:
            for w in rt.schedule_realtime(model.control.sched_priority, model.control.cpu):
                log(f"cdprctl calibrate: warning: {w}")
        yield
    finally:
        if realtime:
            rt.leave_realtime()
        rt.restore_gc()


WHO = "cdprctl calibrate"


def _simulated_after_configure(model: Any, overrides: dict[str, Any], driver: Any,
                               args: argparse.Namespace, simulated: bool,
                               state_dir: Path | None,
                               log: Callable[[str], None]) -> tuple[bool, Path | None]:  # fmt: skip
    """(simulated, the record's directory) once the drives have said who they are: simulated
    drives behind a kernel CAN interface (HIL) write where a simulated robot's records go
    (None: refused, said)."""
    if not simulated and simulated_robot(model, overrides, driver):
        simulated = True
        state_dir = records_dir(WHO, model.name, args.state_dir, simulated)
    if simulated and state_dir is not None:
        log(f"{WHO}: a simulated robot: the record goes to {state_dir}")
    return simulated, state_dir


def add_parser(sub: Any) -> None:
    p = command_parser(
        sub, "calibrate", "homing (known-pose, self) or geometric calibration (geometry)", run,
        config=False,
        epilog="examples:\n"
        "  cdprctl calibrate --config ROBOT.toml --can-interface socketcan --can-channel can0 "
        "known-pose\n"
        "  cdprctl calibrate --config config/caroca.toml --can-interface udp_multicast "
        "--can-channel 239.74.163.9 self --json\n"
        "  cdprctl calibrate --config config/rowc.toml --can-interface udp_multicast "
        "--can-channel 239.74.163.9 geometry --out built.toml\n"
        "\nexit codes: 0 calibrated (the record written), 1 refused or stopped (the reason in "
        "one line),\n2 a bad option, 4 the state directory cannot take the record. A simulated "
        "robot's record\n(drives on udp_multicast) goes to "
        "~/.local/state/cdprctl/simulated/<robot> (docs/homing.md).",
    )  # fmt: skip
    _robot_and_bus(p)
    methods = p.add_subparsers(dest="method", required=True, metavar="METHOD")
    kp = methods.add_parser(
        "known-pose",
        help="the platform stands at a known pose (the home fixture by default)",
        description="Hold the platform where it stands, at a known pose, and record each "
        "cable's motor angle at its unstretched length there.",
    )
    kp.add_argument("--pose", metavar="X,Y,Z,ROLL,PITCH,YAW",
                    help="m, rad; default: the home pose")
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
    gp = methods.add_parser(
        "geometry",
        help="the anchors, drums and encoders' zeros, from a start near home (a few minutes "
        "of motion over the workspace)",
        description="Estimate the start (as self), move the platform through poses planned "
        "for the identification (six cables by position, the redundant ones by tension), "
        "sample at rest, identify every anchor but the reference ones, each drum's radius "
        "and the encoders' zeros; refused when the residuals are more than the drives' "
        "resolution explains or the data do not decide them (docs/homing.md).",
    )
    for method in (kp, sp, gp):
        _robot_and_bus(method, default=argparse.SUPPRESS)
    gp.add_argument("--poses", type=int, default=25, help="poses to sample (25; 10..80)")
    gp.add_argument("--fill", type=float, default=None,
                    help="fraction of the workspace box the poses span (the robot file's "
                         "[calibration] geometry_fill, else 0.8)")  # fmt: skip
    gp.add_argument("--speed", type=float, default=None,
                    help="m/s of the moves (the robot file's [calibration] geometry_speed, "
                         "else 0.1)")  # fmt: skip
    gp.add_argument("--json", action="store_true", help="print the result as JSON")
    gp.add_argument("--no-realtime", action="store_true",
                    help="do not ask for SCHED_FIFO and CPU pinning while it moves")
    gp.add_argument("--out", metavar="FILE",
                    help="write the robot file as identified to FILE, and the calibration "
                    "record for it to the state directory (then: cdprctl run --config "
                    "FILE)")  # fmt: skip


def run(args: argparse.Namespace) -> int:
    """Calibrate the robot's encoders: the drives are configured, enabled, the platform held
    (known-pose) or moved near its start (self), the drives disabled (brakes on), and the
    record written atomically to the state directory, where ``cdprctl run`` reads it."""
    from cdprctl.calibration.procedure import SelfOptions, known_pose, self_calibrate
    from cdprctl.calibration.record import save
    from cdprctl.calibration.session import CalibrationFailedError
    from drivers import create_driver
    from drivers.errors import DriverError

    if not args.config:
        print(f"cdprctl calibrate: error: --config FILE is required (the robot: cdprctl "
              f"calibrate --config FILE {args.method} ...)", file=sys.stderr)  # fmt: skip
        return 2
    model = load_or_report(args.config)
    if model is None:
        return 1
    if args.method == "geometry":
        return run_geometry(args, model)
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    pose = None
    if args.method == "known-pose":
        pose = (
            parse_pose(args.pose, "--pose", model)
            if args.pose
            else np.r_[model.home.position, model.home.rpy]
        )
    else:
        for name in ("travel", "tilt"):
            value = getattr(args, name)
            if not 0.0 < value <= 0.3:
                raise SystemExit(f"--{name} = {value}: must be in (0, 0.3] (m or rad)")
    overrides = bus_overrides(args)
    if refuse_in_process_bus(WHO, model, overrides, False):
        return 2
    simulated = simulated_robot(model, overrides)
    state_dir = records_dir(WHO, model.name, args.state_dir, simulated)
    if state_dir is None:
        return EXIT_STATE_DIR
    driver = create_driver(model, period=model.control.period, bus_overrides=overrides)
    ident = None
    try:
        log(f"cdprctl calibrate: {model.name}, {args.method}: configuring the drives")
        driver.configure()
        simulated, state_dir = _simulated_after_configure(model, overrides, driver, args,
                                                          simulated, state_dir, log)  # fmt: skip
        if state_dir is None:
            return EXIT_STATE_DIR
        with moves_held(model, False, log):
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
    record.simulated = simulated
    result = {
        "pose": record.pose,
        "residual_rms": record.residual_rms,
        "condition": record.condition,
        "method": record.method,
        "std": record.std,
        "sample_residuals": record.sample_residuals,
        "drum_scale": record.drum_scale,
    }
    path = save_or_keep(WHO, save, record, state_dir, {**result, "record": asdict(record)})
    if path is None:
        return EXIT_STATE_DIR
    result["record"] = str(path)
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


def run_geometry(args: argparse.Namespace, model: Any) -> int:
    """``calibrate geometry``: exit 0 accepted (with --out: the file and its record written),
    1 refused or stopped (the reason in one line), 2 bad options."""
    from cdprctl.calibration.geometry_file import calibrated_robot_text
    from cdprctl.calibration.geometry_plan import GeometryOptions, plan
    from cdprctl.calibration.geometry_procedure import geometry_calibrate, geometry_record
    from cdprctl.calibration.record import now_iso, save
    from cdprctl.calibration.session import CalibrationFailedError
    from cdprctl.model.calibration import FILL_RANGE, SPEED_RANGE
    from drivers import create_driver
    from drivers.errors import DriverError

    for name, value, (lo, hi) in (("poses", args.poses, (10, 80)),
                                  ("fill", args.fill, FILL_RANGE),
                                  ("speed", args.speed, SPEED_RANGE)):  # fmt: skip
        if value is not None and not lo <= value <= hi:
            print(f"cdprctl calibrate: error: --{name} = {value}: must be in [{lo}, {hi}]",
                  file=sys.stderr)  # fmt: skip
            return 2
    out = Path(args.out) if args.out else None
    if out is not None and out.resolve() == Path(model.source_file).resolve():
        print("cdprctl calibrate: error: --out is the robot file itself: write the robot as "
              "built to another file (it names this one as its base)", file=sys.stderr)  # fmt: skip
        return 2
    if out is not None and not out.resolve().parent.is_dir():
        # checked before the drives move: found after two minutes of motion, the run is lost
        print(f"cdprctl calibrate: error: --out {out}: the directory {out.resolve().parent} "
              "does not exist: create it first", file=sys.stderr)  # fmt: skip
        return 2
    overrides = bus_overrides(args)
    if refuse_in_process_bus(WHO, model, overrides, False):
        return 2
    simulated = simulated_robot(model, overrides)
    state_dir = records_dir(WHO, model.name, args.state_dir, simulated) if out else None
    if out is not None and state_dir is None:
        return EXIT_STATE_DIR
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    opt = GeometryOptions.of(model, poses=args.poses, fill=args.fill, speed=args.speed)
    try:
        log(f"cdprctl calibrate: {model.name}, geometry: planning the poses")
        poses = plan(model, opt)
    except CalibrationFailedError as exc:
        print(f"cdprctl calibrate: failed: {exc}", file=sys.stderr)
        return 1
    driver = create_driver(model, period=model.control.period, bus_overrides=overrides)
    try:
        log(f"cdprctl calibrate: {model.name}, geometry: configuring the drives")
        driver.configure()
        if out is not None:
            found = _simulated_after_configure(model, overrides, driver, args, simulated,
                                               state_dir, log)  # fmt: skip
            simulated, state_dir = found
            if state_dir is None:
                return EXIT_STATE_DIR
        with moves_held(model, not args.no_realtime, log):
            cal = geometry_calibrate(model, driver, opt, log, poses)
    except (DriverError, CalibrationFailedError) as exc:
        print(f"cdprctl calibrate: failed: {exc}", file=sys.stderr)
        return 1
    finally:
        driver.shutdown()
    r = cal.result
    drawn = model.anchors
    radius = np.array([c.winch.drum_radius for c in model.cables]) * r.drum_scale
    result: dict[str, Any] = {
        "accepted": cal.accepted,
        "reason": cal.reason,
        "reference_anchors": [model.cables[i].name for i in cal.reference],
        "anchors": np.round(r.anchors, 6).tolist(),
        "anchor_moved": np.round(np.linalg.norm(r.anchors - drawn, axis=1), 6).tolist(),
        "drum_scale": np.round(r.drum_scale, 7).tolist(),
        "drum_radius": np.round(radius, 8).tolist(),
        "theta_zero": np.round(r.theta_zero, 6).tolist(),
        "pose": r.pose,
        "residual_rms": r.residual_rms,
        "residuals_over_noise": cal.residuals_over_noise,
        "equilibrium_over_noise": cal.equilibrium_over_noise,
        "force_rms": r.force_rms,
        "std": {"anchors": np.round(np.linalg.norm(r.std_anchors, axis=1), 6).tolist(),
                "drum_scale": np.round(r.std_drum_scale, 7).tolist(),
                "pose": r.std_pose},
        "condition": r.condition,
        "poses": len(r.poses),
        "motion_time": cal.motion_time,
    }
    if cal.accepted and out is not None:
        how = (f"{now_iso()}: {len(r.poses)} poses, {cal.motion_time:.0f} s of motion, "
               f"residuals {cal.residuals_over_noise:.2f}x the drives' resolution, anchors "
               f"of cables {', '.join(result['reference_anchors'])} as drawn")  # fmt: skip
        out.write_text(calibrated_robot_text(model, r.anchors, radius, how), encoding="utf-8")
        built = load_or_report(str(out), "cdprctl calibrate")
        if built is None:
            return 1
        record = geometry_record(built, cal, list(getattr(driver, "identities",
                                                          [None] * model.n_cables)))  # fmt: skip
        record.simulated = simulated
        result["robot_file"] = str(out)
        assert state_dir is not None  # checked before the motion, with --out
        path = save_or_keep(WHO, save, record, state_dir, {**result, "record": asdict(record)})
        if path is None:
            return EXIT_STATE_DIR
        result["record"] = str(path)
    if args.json:
        print(json.dumps(result))
    else:
        moved = np.linalg.norm(r.anchors - drawn, axis=1) * 1e3
        sig = np.linalg.norm(r.std_anchors, axis=1) * 1e3
        for i, c in enumerate(model.cables):
            a = r.anchors[i]
            ref = "  (reference: as drawn)" if i in cal.reference else (
                f"  {moved[i]:.2f} mm from the drawing, σ {sig[i]:.2f} mm")  # fmt: skip
            log(f"cable {c.name}: anchor [{a[0]:.4f}, {a[1]:.4f}, {a[2]:.4f}] m, drum "
                f"x{r.drum_scale[i]:.5f}{ref}")  # fmt: skip
        log(f"residual {r.residual_rms * 1e6:.1f} µm RMS ({cal.residuals_over_noise:.2f}x the "
            f"drives' resolution), condition {r.condition:.3g}, {len(r.poses)} poses, "
            f"{cal.motion_time:.0f} s of motion")  # fmt: skip
        log(("accepted" if cal.accepted else "refused: ") + ("" if cal.accepted else
                                                              cal.reason))  # fmt: skip
        if "robot_file" in result:
            log(f"robot file: {result['robot_file']}; record: {result['record']} — run it "
                f"with `cdprctl run --config {result['robot_file']}`")  # fmt: skip
        elif cal.accepted:
            log("(nothing written: give --out FILE for the robot file and its record)")
    return 0 if cal.accepted else 1
