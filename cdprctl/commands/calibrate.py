"""``cdprctl calibrate``: find where each encoder reads zero and keep it in the state directory
(docs/homing.md)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.calibrating import WHO, moves_held
from cdprctl.commands.common import command_parser, load_or_report, parse_pose
from cdprctl.commands.records import (
    EXIT_STATE_DIR,
    drives_closed,
    keep_record,
    procedure_start,
)
from cdprctl.commands.sim import add_bus_arguments


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
        "  cdprctl calibrate --config config/rowc.toml friction --sim --plant-errors 1\n"
        "\nexit codes: 0 calibrated (the record written), 1 refused or stopped (the reason in "
        "one line),\n2 a bad option, 4 the state directory cannot take the record. A simulated "
        "robot's record\n(drives on udp_multicast) goes to "
        "~/.local/state/cdprctl/simulated/<robot> (docs/homing.md).\nA self, geometry or "
        "friction run stopped by a fault keeps its samples: the same command with --resume\n"
        "goes on.",
    )  # fmt: skip
    _robot_and_bus(p)
    methods = p.add_subparsers(dest="method", required=True, metavar="METHOD")
    kp = _known_pose_parser(methods)
    sp = _self_parser(methods)
    gp = _geometry_parser(methods)
    fp = _friction_parser(methods)
    for method in (kp, sp, gp, fp):
        _robot_and_bus(method, default=argparse.SUPPRESS)
    for method in (sp, gp):
        method.add_argument(
            "--resume", action="store_true",
            help="go on from the samples of a run stopped midway (kept in the state "
            "directory), on the same robot file and options, the drives not reset since",
        )  # fmt: skip
    _geometry_options(gp)


def _known_pose_parser(methods: Any) -> Any:
    """``calibrate known-pose``: its options."""
    kp = methods.add_parser(
        "known-pose",
        help="the platform stands at a known pose (the home fixture by default)",
        description="Hold the platform where it stands, at a known pose, and record each "
        "cable's motor angle at its unstretched length there.",
    )
    kp.add_argument("--pose", metavar="X,Y,Z,ROLL,PITCH,YAW",
                    help="m, rad; default: the home pose")
    kp.add_argument("--json", action="store_true", help="print the result as JSON")
    return kp


def _self_parser(methods: Any) -> Any:
    """``calibrate self``: its options."""
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
    return sp


def _geometry_parser(methods: Any) -> Any:
    """``calibrate geometry``: its options."""
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
    return gp


def _geometry_options(gp: Any) -> None:
    """``calibrate geometry``'s own options (after the common ones, as its help lists them)."""
    gp.add_argument("--poses", type=int, default=None, help="poses to sample (25; 10..80)")
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


def _friction_parser(methods: Any) -> Any:
    """``calibrate friction``: its options (``calibrate_friction``'s)."""
    fp = methods.add_parser(
        "friction",
        help="each winch's friction (viscous, Coulomb, Stribeck) and pulley loss, from its "
        "drive's torque while the platform goes out and back at three speeds (about two "
        "minutes of motion)",
        description="Move the platform out and back along three lines from where it stands, "
        "every cable by position, at three speeds; fit each winch's friction with the statics "
        "and the internal tensions taken out; refused when the residuals are more than the "
        "torque's noise explains; written into the calibration record, which the next "
        "cdprctl run applies (docs/friction.md).",
    )
    from cdprctl.commands.calibrate_friction import add_arguments

    add_arguments(fp)
    return fp

def run(args: argparse.Namespace) -> int:
    """Calibrate the robot's encoders: the drives are configured, enabled, the platform held
    (known-pose) or moved near its start (self), the drives disabled (brakes on), and the
    record written atomically to the state directory, where ``cdprctl run`` reads it."""
    from cdprctl.calibration.partial_session import path_of, remove
    from cdprctl.calibration.procedure import SelfOptions, known_pose, self_calibrate
    from cdprctl.calibration.progress import CalibrationStoppedError, check_reference
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
        from cdprctl.commands.calibrate_geometry import run_geometry

        return run_geometry(args, model)
    if args.method == "friction":
        from cdprctl.commands.calibrate_friction import run_friction

        return run_friction(args, model)
    pose = _pose_or_checked(args, model)
    proc = procedure_start(WHO, model, args, False)
    if isinstance(proc, int):
        return proc
    log = proc.log
    opt = None if pose is not None else SelfOptions(
        travel=args.travel, tilt=args.tilt, fit_drum_scales=args.fit_drum_scales)  # fmt: skip
    resumed = _self_progress(args, model, opt, proc.state_dir, log)
    if isinstance(resumed, int):
        return resumed
    progress, identities = resumed
    driver = create_driver(model, period=model.control.period, bus_overrides=proc.overrides)
    ident = None
    with drives_closed(driver):
        try:
            state_dir = proc.configure(driver, f"{model.name}, {args.method}")
            if state_dir is None:
                return EXIT_STATE_DIR
            if progress is not None and (why := check_reference(
                    model, driver, progress, identities, path_of(state_dir, "self"), log, WHO)):
                print(f"{WHO}: error: cannot resume: {why}", file=sys.stderr)
                return 1
            with moves_held(model, False, log):
                if pose is not None:
                    record = known_pose(model, driver, pose, log)
                elif opt is not None:
                    record, ident = self_calibrate(model, driver, opt, log, progress)
        except CalibrationStoppedError as exc:
            _self_stopped(args, model, exc, opt, proc.state_dir, proc.simulated, driver,
                          proc.overrides)  # fmt: skip
            return 1
        except (DriverError, CalibrationFailedError) as exc:
            if isinstance(exc, CalibrationFailedError) and exc.record is not None:
                remove(proc.state_dir, "self")  # every sample taken, the identification refused
            print(f"cdprctl calibrate: failed: {exc}", file=sys.stderr)
            return 1
    if opt is not None and remove(state_dir, "self"):
        log(f"{WHO}: completed: the stopped run's samples ({path_of(state_dir, 'self')}) "
            "removed")  # fmt: skip
    record.simulated = proc.simulated
    return _report_homing(args, record, ident, state_dir, log)


def _pose_or_checked(args: argparse.Namespace, model: Any) -> np.ndarray | None:
    """known-pose: the pose (``--pose``, else home); self: None, its options checked
    (SystemExit naming a refused one)."""
    if args.method == "known-pose":
        if args.pose:
            return parse_pose(args.pose, "--pose", model)
        return np.r_[model.home.position, model.home.rpy]
    for name in ("travel", "tilt"):
        value = getattr(args, name)
        if not 0.0 < value <= 0.3:
            raise SystemExit(f"--{name} = {value}: must be in (0, 0.3] (m or rad)")
    return None


def _report_homing(args: argparse.Namespace, record: Any, ident: Any, state_dir: Path,
                   log: Callable[[str], None]) -> int:  # fmt: skip
    """``known-pose``'s or ``self``'s record written, the result said (JSON or lines)."""
    from cdprctl.calibration.calibration_record import save

    result = {
        "pose": record.pose,
        "residual_rms": record.residual_rms,
        "condition": record.condition,
        "method": record.method,
        "std": record.std,
        "sample_residuals": record.sample_residuals,
        "drum_scale": record.drum_scale,
    }
    if not keep_record(WHO, save, record, state_dir, result):
        return EXIT_STATE_DIR
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
        log(f"record: {result['record']}")
    return 0


def _self_progress(args: argparse.Namespace, model: Any, opt: Any, state_dir: Path,
                   log: Callable[[str], None]) -> Any:  # fmt: skip
    """(progress, the drives' identities then) of a stopped ``self`` with ``--resume``,
    (None, []) otherwise; the exit code after one line when it cannot resume."""
    from cdprctl.calibration.calibration_record import geometry_hash
    from cdprctl.calibration.procedure import self_options
    from cdprctl.calibration.progress import Progress
    from cdprctl.commands.resume import load_to_resume, replaced_warning

    if opt is None:
        return None, []
    if not args.resume:
        replaced_warning(state_dir, "self", log, WHO)
        return None, []
    where = {"travel": "--travel", "tilt": "--tilt", "fit_drum_scales": "--fit-drum-scales"}
    partial = load_to_resume(WHO, state_dir, "self", model.name, geometry_hash(model),
                             self_options(opt), where)  # fmt: skip
    if partial is None:
        return 2
    log(f"{WHO}: {model.name}, self: resuming the run stopped at {partial.stopped_at} "
        f"({partial.kept} samples kept)")  # fmt: skip
    return Progress.from_data(partial.data, partial.started), partial.identities


def _self_stopped(args: argparse.Namespace, model: Any, exc: Any, opt: Any,
                  state_dir: Path | None,
                  simulated: bool, driver: Any, overrides: dict[str, Any]) -> None:  # fmt: skip
    """``self`` stopped midway: its samples kept, one line."""
    from cdprctl.calibration.procedure import self_options
    from cdprctl.commands.resume import keep, new_partial, resume_command, stopped_line

    p = exc.progress
    partial = new_partial("self", model, self_options(opt), str(exc), exc.at, p.samples,
                          p.to_data(), p.started, simulated,
                          list(getattr(driver, "identities", [])))  # fmt: skip
    words = f"{p.samples} samples"
    kept = keep(WHO, state_dir, partial, words)
    tail = (f"self --travel {args.travel:g} --tilt {args.tilt:g}"
            + (" --fit-drum-scales" if args.fit_drum_scales else ""))  # fmt: skip
    resume = resume_command("cdprctl calibrate", args, overrides, tail)
    print(stopped_line(WHO, exc.at, str(exc), kept, exc.cause, resume,
                       kept.startswith(words + " kept")), file=sys.stderr)  # fmt: skip
