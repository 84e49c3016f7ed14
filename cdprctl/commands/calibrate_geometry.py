"""``cdprctl calibrate geometry``: the poses planned (or, with ``--resume``, those of a stopped
run read back), the drives configured, the platform moved through the poses and sampled, the
geometry identified; the robot file as built and its record written with ``--out``. A stop
midway keeps its samples in the state directory (docs/homing.md)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.commands.calibrating import WHO, moves_held
from cdprctl.commands.common import load_or_report
from cdprctl.commands.records import EXIT_STATE_DIR, drives_closed, keep_record, records_dir
from cdprctl.commands.resume import (
    keep,
    load_to_resume,
    new_partial,
    replaced_warning,
    resume_command,
    state_dir_or_warn,
    stopped_line,
)
from cdprctl.commands.sim import bus_overrides, refuse_in_process_bus
from drivers.simulated import simulated_robot

KIND = "geometry"
# the options a stopped run's plan followed, and where each is set
WHERE = {"poses": "--poses", "fill": "--fill or [calibration] geometry_fill",
         "speed": "--speed or [calibration] geometry_speed"}  # fmt: skip


def _bad_option(args: argparse.Namespace, model: Any) -> int:
    """2 after one line naming a refused option, else 0."""
    from cdprctl.model.calibration import FILL_RANGE, SPEED_RANGE

    for name, value, (lo, hi) in (("poses", args.poses, (10, 80)),
                                  ("fill", args.fill, FILL_RANGE),
                                  ("speed", args.speed, SPEED_RANGE)):  # fmt: skip
        if value is not None and not lo <= value <= hi:
            print(f"{WHO}: error: --{name} = {value}: must be in [{lo}, {hi}]", file=sys.stderr)
            return 2
    out = Path(args.out) if args.out else None
    if out is not None and out.resolve() == Path(model.source_file).resolve():
        print(f"{WHO}: error: --out is the robot file itself: write the robot as built to "
              "another file (it names this one as its base)", file=sys.stderr)  # fmt: skip
        return 2
    if out is not None and not out.resolve().parent.is_dir():
        # checked before the drives move: found after two minutes of motion, the run is lost
        print(f"{WHO}: error: --out {out}: the directory {out.resolve().parent} does not "
              "exist: create it first", file=sys.stderr)  # fmt: skip
        return 2
    return 0


def _state_dir(args: argparse.Namespace, model: Any, simulated: bool,
               log: Callable[[str], None]) -> tuple[Path | None, bool]:  # fmt: skip
    """(the state directory, whether the run may go on): needed with --out (the record) and
    --resume (the samples); otherwise a stop without one only keeps nothing."""
    if args.out or args.resume:
        path = records_dir(WHO, model.name, args.state_dir, simulated)
        return path, path is not None
    return state_dir_or_warn(WHO, model.name, args.state_dir, simulated, log), True


def _plan_or_resume(args: argparse.Namespace, model: Any, opt: Any, state_dir: Path | None,
                    log: Callable[[str], None]) -> Any:  # fmt: skip
    """(poses, progress, the drives' identities then) — planned, or a stopped run's read
    back with ``--resume``; else the exit code after one line."""
    from cdprctl.calibration.calibration_record import geometry_hash
    from cdprctl.calibration.geometry_plan import plan
    from cdprctl.calibration.progress import Progress
    from cdprctl.calibration.session import CalibrationFailedError

    if args.resume:
        assert state_dir is not None
        partial = load_to_resume(WHO, state_dir, KIND, model.name, geometry_hash(model),
                                 asdict(opt), WHERE)  # fmt: skip
        if partial is None:
            return 2
        progress = Progress.from_data(partial.data, partial.started)
        log(f"{WHO}: {model.name}, geometry: resuming the run stopped at "
            f"{partial.stopped_at} ({kept_words(progress)} kept)")  # fmt: skip
        return np.array(partial.data["plan"], float), progress, partial.identities
    replaced_warning(state_dir, KIND, log, WHO)
    try:
        log(f"{WHO}: {model.name}, geometry: planning the poses")
        poses = plan(model, opt)
    except CalibrationFailedError as exc:
        print(f"{WHO}: failed: {exc}", file=sys.stderr)
        return 1
    return poses, Progress(), []


def kept_words(progress: Any) -> str:
    """What a geometric calibration's samples are, in words."""
    if progress.near is None:
        return f"{progress.samples} of the start's samples"
    return f"{progress.samples - progress.near} poses and the start's {progress.near} samples"


def run_geometry(args: argparse.Namespace, model: Any) -> int:
    """``calibrate geometry``: exit 0 accepted (with --out: the file and its record written),
    1 refused or stopped (the reason in one line), 2 bad options."""
    from cdprctl.calibration.geometry_plan import GeometryOptions
    from cdprctl.calibration.geometry_procedure import geometry_calibrate
    from cdprctl.calibration.partial_session import path_of, remove
    from cdprctl.calibration.progress import CalibrationStoppedError, check_reference
    from cdprctl.calibration.session import CalibrationFailedError
    from drivers import create_driver
    from drivers.errors import DriverError

    if code := _bad_option(args, model):
        return code
    overrides = bus_overrides(args)
    if refuse_in_process_bus(WHO, model, overrides, False):
        return 2
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    simulated = simulated_robot(model, overrides)
    state_dir, go_on = _state_dir(args, model, simulated, log)
    if not go_on:
        return EXIT_STATE_DIR
    opt = GeometryOptions.of(model, poses=args.poses, fill=args.fill, speed=args.speed)
    started = _plan_or_resume(args, model, opt, state_dir, log)
    if isinstance(started, int):
        return started
    poses, progress, identities = started
    driver = create_driver(model, period=model.control.period, bus_overrides=overrides)
    with drives_closed(driver):
        try:
            log(f"{WHO}: {model.name}, geometry: configuring the drives")
            driver.configure()
            if not simulated and simulated_robot(model, overrides, driver):
                simulated = True  # simulated drives behind a kernel CAN interface (HIL)
                if args.resume and not args.state_dir:
                    print(f"{WHO}: error: cannot resume: the drives are simulated ones (0x1018), "
                          "whose sessions are kept apart: give --state-dir DIR, the directory "
                          "of the stopped run", file=sys.stderr)  # fmt: skip
                    return 2
                state_dir, go_on = _state_dir(args, model, simulated, log)
                if not go_on:
                    return EXIT_STATE_DIR
            if simulated and state_dir is not None:
                log(f"{WHO}: a simulated robot: its record and samples go to {state_dir}")
            kept_in = path_of(state_dir, KIND) if state_dir is not None else None
            if args.resume and (why := check_reference(model, driver, progress, identities,
                                                        kept_in, log, WHO)):  # fmt: skip
                print(f"{WHO}: error: cannot resume: {why}", file=sys.stderr)
                return 1
            with moves_held(model, not args.no_realtime, log):
                cal = geometry_calibrate(model, driver, opt, log, poses, progress)
        except CalibrationStoppedError as exc:
            _stopped(args, model, exc, opt, poses, state_dir, simulated, driver, overrides)
            return 1
        except (DriverError, CalibrationFailedError) as exc:
            print(f"{WHO}: failed: {exc}", file=sys.stderr)
            return 1
    if remove(state_dir, KIND):
        log(f"{WHO}: completed: the stopped run's samples ({kept_in}) removed")
    return _report(args, model, cal, state_dir, simulated, driver, log)


def _stopped(args: argparse.Namespace, model: Any, exc: Any, opt: Any, poses: np.ndarray,
             state_dir: Path | None, simulated: bool, driver: Any,
             overrides: dict[str, Any]) -> None:  # fmt: skip
    """A run stopped midway: its samples and plan kept, one line."""
    p = exc.progress
    partial = new_partial(KIND, model, asdict(opt), str(exc), exc.at, p.samples,
                          {**p.to_data(), "plan": poses.tolist()}, p.started, simulated,
                          list(getattr(driver, "identities", [])))  # fmt: skip
    kept = keep(WHO, state_dir, partial, kept_words(p))
    tail = "geometry" + (f" --out {args.out}" if args.out else "") + (
        " --no-realtime" if args.no_realtime else "")  # fmt: skip
    resume = resume_command("cdprctl calibrate", args, overrides, tail)
    print(stopped_line(WHO, exc.at, str(exc), kept, exc.cause, resume,
                       kept.startswith(kept_words(p) + " kept")), file=sys.stderr)  # fmt: skip


def _report(args: argparse.Namespace, model: Any, cal: Any, state_dir: Path | None,
            simulated: bool, driver: Any, log: Callable[[str], None]) -> int:  # fmt: skip
    """The result: with --out (accepted) the robot file and its record; JSON or lines."""
    from cdprctl.calibration.calibration_record import now_iso, save
    from cdprctl.calibration.geometry_file import calibrated_robot_text
    from cdprctl.calibration.geometry_procedure import geometry_record

    out = Path(args.out) if args.out else None
    r = cal.result
    drawn = model.anchors
    radius = np.array([c.winch.drum_radius for c in model.cables]) * r.drum_scale
    result = _result(model, cal, radius)
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
        if not keep_record(WHO, save, record, state_dir, result):
            return EXIT_STATE_DIR
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


def _result(model: Any, cal: Any, radius: np.ndarray) -> dict[str, Any]:
    """What ``--json`` prints (docs/homing.md)."""
    r, drawn = cal.result, model.anchors
    return {
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
