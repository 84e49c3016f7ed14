"""``cdprctl calibrate friction``: each winch's friction identified from its drive's torque
while the platform goes out and back along three lines at three speeds, written into the
calibration record, which the next ``cdprctl run`` applies (docs/friction.md). ``--sim``: on the
simulated robot in this process (lock-step), each winch's friction drawn off the file's
(``--plant-errors SEED``), the result printed, no record written."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

import numpy as np

from cdprctl.commands.calibrating import WHO, moves_held
from cdprctl.commands.records import EXIT_STATE_DIR, bus_and_records, records_dir
from cdprctl.commands.resume import state_dir_or_warn


def add_arguments(fp: Any) -> None:
    """The options of ``calibrate friction``."""
    fp.add_argument("--sim", action="store_true",
                    help="on the simulated robot, in this process (lock-step): the result "
                    "printed, no record written")  # fmt: skip
    fp.add_argument("--plant-errors", type=int, metavar="SEED", default=None,
                    help="with --sim: each winch's viscous and Coulomb friction 30-50 %% off "
                    "the file's, up or down (seeded), a Stribeck term half the Coulomb "
                    "one")  # fmt: skip
    fp.add_argument("--pulley-friction", type=float, default=None, metavar="MU",
                    help="with --sim: every pulley's μ in the simulated robot")  # fmt: skip
    fp.add_argument("--travel", type=float, default=None,
                    help="m of each line at most (default 0.4: FrictionOptions)")
    fp.add_argument("--json", action="store_true", help="print the result as JSON")
    fp.add_argument("--no-realtime", action="store_true",
                    help="do not ask for SCHED_FIFO and CPU pinning while it moves")
    fp.add_argument("--resume", action="store_true",
                    help="go on from a run stopped midway (its round trips kept in the state "
                    "directory), with the robot file and options it was started with")


KIND = "friction"
# what a stopped run's samples were measured with, and where each is set
WHERE = {"travel": "--travel", "period": "[control] rate", "plant_errors": "--plant-errors",
         "pulley_friction": "--pulley-friction",
         "encoder_zeros": "the calibration record's (a homing since the stop)"}  # fmt: skip


def plan_of(args: argparse.Namespace, model: Any, opt: Any,
            theta_zero: np.ndarray) -> dict[str, Any]:  # fmt: skip
    """What the samples follow: the moves' options, the control period (s) they were taken
    at (the fit's speeds come from it), the encoders' zeros and, with --sim, the simulated
    robot's friction."""
    plan = {**dataclasses.asdict(opt), "period": model.control.period,
            "encoder_zeros": [float(x) for x in theta_zero]}  # fmt: skip
    plan["speeds"] = list(plan["speeds"])
    if args.sim:
        plan.update(plant_errors=args.plant_errors, pulley_friction=args.pulley_friction)
    return plan


def run_friction(args: argparse.Namespace, model: Any) -> int:
    """Exit 0 accepted (the record updated, unless --sim), 1 refused or stopped (the reason in
    one line), 2 bad options or a resume refused, 4 the state directory cannot take the
    record (with --resume: cannot be read)."""
    from cdprctl.calibration.friction_procedure import FrictionOptions, friction_calibrate
    from cdprctl.calibration.partial_session import path_of, remove
    from cdprctl.calibration.progress import CalibrationStoppedError
    from cdprctl.calibration.session import CalibrationFailedError
    from drivers.errors import DriverError

    if args.travel is not None and not 0.05 <= args.travel <= 2.0:
        print(f"{WHO}: error: --travel = {args.travel} m: must be in [0.05, 2]", file=sys.stderr)
        return 2
    if not args.sim and (args.plant_errors is not None or args.pulley_friction is not None):
        print(f"{WHO}: error: --plant-errors and --pulley-friction are the simulated robot's: "
              "give --sim", file=sys.stderr)  # fmt: skip
        return 2
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    opt = FrictionOptions() if args.travel is None else FrictionOptions(travel=args.travel)
    sim, driver, record, state_dir, overrides = None, None, None, None, {}
    try:
        if args.sim:  # no record: a directory it cannot write keeps no stop, said
            state_dir = (records_dir(WHO, model.name, args.state_dir, True) if args.resume
                         else state_dir_or_warn(WHO, model.name, args.state_dir, True, log))
            if state_dir is None and args.resume:
                return EXIT_STATE_DIR
            sim = _lockstep(args, model)
            driver = sim.driver
            driver.configure()
            theta_zero = np.zeros(model.n_cables)
            here = np.r_[model.home.position, 0.0, 0.0, 0.0]
        else:
            got = _on_the_robot(args, model, log)
            if isinstance(got, int):
                return got
            driver, record, state_dir, overrides, theta_zero, here = got
        kept = _kept(args, model, driver, state_dir, plan_of(args, model, opt, theta_zero), log)
        if isinstance(kept, int):
            return kept
        with moves_held(model, not (args.no_realtime or args.sim), log):
            cal = friction_calibrate(model, driver, theta_zero, here, opt, log, kept)
    except CalibrationStoppedError as exc:
        simulated = args.sim or bool(record is not None and record.simulated)
        _stopped(args, model, exc, state_dir, simulated, driver, overrides,
                 plan_of(args, model, opt, theta_zero))  # fmt: skip
        return 1
    except (DriverError, CalibrationFailedError) as exc:
        print(f"{WHO}: failed: {exc}", file=sys.stderr)
        return 1
    finally:
        if sim is not None:
            sim.close()
        elif driver is not None:
            driver.shutdown()
    if state_dir is not None and remove(state_dir, KIND):
        log(f"{WHO}: completed: the stopped run's samples ({path_of(state_dir, KIND)}) removed")
    return _report(args, model, cal, record, state_dir, sim, log)


def _kept(args: argparse.Namespace, model: Any, driver: Any, state_dir: Any,
          plan: dict[str, Any], log: Any) -> Any:  # fmt: skip
    """A stopped run's progress with ``--resume`` (None without), checked against this robot
    file, these options and these drives; else the exit code after one line."""
    from cdprctl.calibration.calibration_record import geometry_hash
    from cdprctl.calibration.friction_progress import FrictionProgress
    from cdprctl.calibration.partial_session import path_of
    from cdprctl.calibration.progress import check_reference
    from cdprctl.commands.resume import load_to_resume, replaced_warning

    if not args.resume:
        replaced_warning(state_dir, KIND, log, WHO)
        return None
    partial = load_to_resume(WHO, state_dir, KIND, model.name, geometry_hash(model), plan,
                             WHERE)  # fmt: skip
    if partial is None:
        return 2
    try:
        progress = FrictionProgress.from_data(partial.data, partial.started)
    except (KeyError, TypeError, ValueError) as exc:  # binascii.Error is a ValueError
        print(f"{WHO}: error: cannot resume: {path_of(state_dir, KIND)} holds no friction "
              f"calibration's samples ({type(exc).__name__}: {exc}): start over without "
              "--resume", file=sys.stderr)  # fmt: skip
        return 2
    log(f"{WHO}: {model.name}, friction: resuming the run stopped at {partial.stopped_at} "
        f"({progress.done} round trips, {progress.samples} samples kept)")  # fmt: skip
    if args.sim:  # a new simulated robot at home each run, its zeros there: the same reference
        return progress
    if why := check_reference(model, driver, progress, partial.identities,
                              path_of(state_dir, KIND), log, WHO):  # fmt: skip
        print(f"{WHO}: error: cannot resume: {why}", file=sys.stderr)
        return 1
    return progress


def _stopped(args: argparse.Namespace, model: Any, exc: Any, state_dir: Any, simulated: bool,
             driver: Any, overrides: dict[str, Any], plan: dict[str, Any]) -> None:  # fmt: skip
    """A run stopped midway: the round trips made kept, one line."""
    from cdprctl.commands.resume import keep, new_partial, resume_command, stopped_line

    p = exc.progress
    done = p.done if p is not None else 0
    data = p.to_data() if p is not None else {}
    partial = new_partial(KIND, model, plan, str(exc), exc.at, done, data,
                          p.started if p is not None else 0.0, simulated,
                          list(getattr(driver, "identities", [])))  # fmt: skip
    words = f"{done} round trips ({p.samples if p is not None else 0} samples)"
    kept = keep(WHO, state_dir, partial, words)
    resume = resume_command(WHO, args, overrides, _options_again(args))
    print(stopped_line(WHO, exc.at, str(exc), kept, exc.cause, resume,
                       kept.startswith(words + " kept")), file=sys.stderr)  # fmt: skip


def _options_again(args: argparse.Namespace) -> str:
    """``friction`` and the options of this run that its resume must be given again."""
    given = [("--sim", args.sim),
             (f"--plant-errors {args.plant_errors}", args.plant_errors is not None),
             (f"--pulley-friction {args.pulley_friction}", args.pulley_friction is not None),
             (f"--travel {args.travel}", args.travel is not None),
             ("--no-realtime", args.no_realtime)]  # fmt: skip
    return " ".join(["friction", *(text for text, on in given if on)])


def _lockstep(args: argparse.Namespace, model: Any) -> Any:
    """The simulated robot at home, its winches' friction as ``--plant-errors`` draws it."""
    from sim_backend.network import LockStep
    from sim_backend.plant import CdprPlant
    from sim_backend.plant_errors import PlantErrors

    truth = model
    if args.plant_errors is not None or args.pulley_friction is not None:
        drawn = (0.3, 0.5) if args.plant_errors is not None else (0.0, 0.0)
        truth = PlantErrors(args.plant_errors or 0, 0.0, 0.0, friction=drawn,
                            stribeck=0.5 if args.plant_errors is not None else 0.0,
                            pulley=args.pulley_friction).apply(model)[0]  # fmt: skip
    plant = CdprPlant(truth)
    plant.set_pose(model.home.position, model.home.rotation, None)
    ls = LockStep(model, plant=plant)
    ls.truth = truth  # type: ignore[attr-defined]  # the report compares with it
    return ls


def _on_the_robot(args: argparse.Namespace, model: Any, log: Any) -> Any:
    """(driver, record, state directory, bus overrides, the encoders' zeros, where the
    platform stands) on the robot over its buses, the drives configured and checked against
    the record; an exit code after one line when it cannot go on."""
    from cdprctl.calibration.calibration_record import CalibrationError
    from cdprctl.calibration.startup_checks import (
        check_drives,
        how_to_calibrate,
        load_record,
        offsets,
    )
    from drivers import create_driver

    where = bus_and_records(WHO, model, args, False)
    if isinstance(where, int):
        return where
    overrides, simulated, state_dir = where
    try:
        record = load_record(model, state_dir, simulated)
    except CalibrationError as exc:
        print(f"{WHO}: error: {exc}: the encoders' zeros are needed to move the platform; "
              f"{how_to_calibrate(model, state_dir)}", file=sys.stderr)  # fmt: skip
        return 1
    driver = create_driver(model, period=model.control.period, bus_overrides=overrides)
    log(f"{WHO}: {model.name}, friction: configuring the drives")
    driver.configure()
    try:
        check_drives(model, record, driver)
    except CalibrationError as exc:
        driver.shutdown()
        print(f"{WHO}: error: {exc}", file=sys.stderr)
        return 1
    theta_zero, scale = offsets(record)
    return (driver, record, state_dir, overrides, theta_zero,
            _start_pose(model, driver, theta_zero, scale))


def _start_pose(model: Any, driver: Any, theta_zero: np.ndarray,
                scale: np.ndarray) -> np.ndarray:  # fmt: skip
    """Where the platform stands (6: m, the home orientation taken): the estimator's forward
    kinematics on the encoders and the tensions at rest."""
    from cdprctl.control.cycle.estimator import Estimator

    states = driver.read(driver.clock())
    e = Estimator(model)
    e.apply_calibration(theta_zero, scale)
    r = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
    for k in range(60):
        e.update(0.01 * k, states.position.copy(), states.torque / r)
    return np.r_[e.position, 0.0, 0.0, 0.0]


def _winch_line(r: dict[str, Any]) -> str:
    """One winch's line of the text report: its terms ± 1 σ, what it was fitted on, the
    residual against its limit, the simulated robot's terms labelled "plant:" (--sim)."""
    sd = r["std"]
    on = "its load cell" if r["fitted_on"] == "load cell" else "the torques"
    line = (f"  winch {r['cable']} (fitted on {on}): viscous {r['viscous']:.4g} ± {sd[0]:.2g} "
            f"N·m·s/rad, Coulomb {r['coulomb']:.4g} ± {sd[1]:.2g} N·m, Stribeck "
            f"{r['stribeck']:.3g} ± {sd[2]:.2g} N·m, inertia {r['inertia']:.3g} kg·m², "
            f"residual {r['residual_rms']:.2g} N·m (refused beyond {r['residual_limit']:.2g})")
    if "plant" in r:
        p = r["plant"]
        line += (f" [plant: viscous {p['viscous']:.4g}, Coulomb {p['coulomb']:.4g}, "
                 f"Stribeck {p['stribeck']:.3g}]")  # fmt: skip
    mu = (f"; pulley μ {r['pulley']:.3g} ± {r['pulley_std']:.2g}"
          if r["pulley"] is not None else f"; pulley: {r['pulley_note']}")  # fmt: skip
    return line + mu + (f" ({r['clipped']})" if r["clipped"] else "")


def _report(args: argparse.Namespace, model: Any, cal: Any, record: Any, state_dir: Any,
            sim: Any, log: Any) -> int:  # fmt: skip
    """Each winch's terms and σ (with --sim, the simulated robot's beside them); the record
    updated when accepted on a robot."""
    from cdprctl.calibration.calibration_record import save
    from cdprctl.calibration.friction import RESIDUAL_FACTOR
    from cdprctl.calibration.friction_record import clipped_note, friction_entry, stored_terms

    truth = getattr(sim, "truth", None)
    rows = []
    for i, (c, f) in enumerate(zip(model.cables, cal.fits, strict=True)):
        viscous, coulomb, stribeck = stored_terms(f)  # as the record keeps them
        row = {"cable": c.name, "viscous": viscous, "coulomb": coulomb,
               "stribeck": stribeck, "clipped": clipped_note(f), "inertia": f.inertia,
               "std": list(f.std),
               "pulley": f.pulley, "pulley_std": f.pulley_std, "pulley_note": f.pulley_note,
               "residual_rms": f.residual_rms, "residual_limit": f.residual_limit,
               "fitted_on": f.source}  # fmt: skip
        if truth is not None:
            w = truth.cables[i].winch
            row["plant"] = {"viscous": w.viscous_friction, "coulomb": w.coulomb_friction,
                            "stribeck": w.stribeck_friction,
                            "pulley": w.pulley_friction}  # fmt: skip
        rows.append(row)
    written = None
    if cal.accepted and record is not None and state_dir is not None:
        record.friction = friction_entry(model, cal.fits, cal.motion_time, record.simulated)
        written = str(save(record, state_dir))
    if args.json:
        print(json.dumps({"accepted": cal.accepted, "reason": cal.reason, "winches": rows,
                          "motion_time": cal.motion_time, "record": written},
                         indent=1))  # fmt: skip
    else:
        log(f"{WHO}: each term ± 1 σ of the fit (the samples' noise only: a bias is not in it, "
            "docs/friction.md); residual: the RMS of what the law leaves, against its limit "
            f"({RESIDUAL_FACTOR:g}x the torque's noise at rest), beyond which the fit is "
            "refused")  # fmt: skip
        for r in rows:
            log(_winch_line(r))
        tail = (f"; the record updated: {written} (the next cdprctl run applies it)" if written
                else " (--sim: no record written)" if sim is not None else "")  # fmt: skip
        log(f"{WHO}: friction {'accepted' if cal.accepted else 'refused: ' + cal.reason}{tail}")
    return 0 if cal.accepted else 1
