"""The calibration procedures on the drives (``cdprctl calibrate``): the driver is configured by
the caller; these enable the drives, hold or move the platform, sample at rest, disable them
(brakes) and identify. They run at the driver's period on its clock and ``wait``, so the same
code runs in real time and in lock-step with the simulated robot.

* ``known_pose``: the platform stands at a known pose (a home fixture); held where it stands,
  the motor angles and tensions give each cable's offset directly.
* ``self_calibrate``: from an unknown pose near home, with the drives only. The drives hold
  their cables in position mode (CiA 402 CSP): m − r of them by position targets, the ``r``
  redundant ones by their tension (an admittance loop on the measured torque), so the platform
  moves through poses around its start without the cables fighting each other, held stiffly by
  six cables. Pulling cables in turn in torque mode was the alternative: the platform then
  rests where the commanded tensions balance gravity, on the cables' geometric stiffness alone
  (rowc 37 N/m, CAROCA 25 N/m at home: settling takes tens of seconds per sample and friction
  moves it); stepping through the null space moves nothing at all. At each pose, at rest:
  motor angles and tensions; then ``identify`` (docs/homing.md).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np

from cdprctl.calibration.calibration_record import CalibrationRecord, identities_of, stamped
from cdprctl.calibration.identify import (
    Identification,
    Identified,
    Samples,
    Weights,
    length_noise,
    model_test,
)
from cdprctl.calibration.progress import Progress, stopped
from cdprctl.calibration.session import CalibrationFailedError, Session, hold_tensions
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.core.rotation import rpy_to_matrix
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel
from cdprctl.tda.hold import equilibrium_tensions
from drivers.base import WinchDriver
from drivers.errors import DriverError


@dataclasses.dataclass(frozen=True)
class SelfOptions:
    travel: float = 0.05  # m: each translation from the start, ± along x, y, z
    tilt: float = 0.05  # rad: each rotation, ± about x, y, z
    move_time: float = 1.0  # s per move (cosine ramp)
    settle_time: float = 1.0  # s at rest before sampling
    sample_time: float = 0.3  # s averaged per sample
    force_bandwidth: float = 2.0  # Hz: the redundant cables' tension loop
    fit_drum_scales: bool = False
    weights: Weights | None = None  # None: from the drives' resolution (Weights.of)
    max_condition: float = 1.0e4  # refuse beyond: the samples do not decide the pose
    max_std: tuple[float, float] = (0.002, 0.004)  # m, rad: refuse a predicted σ beyond


def known_pose(
    model: RobotModel,
    driver: WinchDriver,
    pose: np.ndarray,
    log: Callable[[str], None] = print,
    hold_time: float = 1.0,
    sample_time: float = 0.5,
) -> CalibrationRecord:
    """The platform is at ``pose`` (x, y, z m, roll, pitch, yaw rad): held where it stands
    with the tensions that hold it there as feed-forward (position mode) or as torques
    (torque mode), sampled at rest, each cable's offset from its unstretched length there."""
    ses = Session(model, driver, log)
    kin = KinematicsData(model)
    R = rpy_to_matrix(*map(float, pose[3:]))
    inverse_kinematics(model, kin, pose[:3], R)
    hold = equilibrium_tensions(model, kin)
    lengths = kin.length.copy()
    ses.tension_goal[:] = hold
    try:
        ses.enable()
        log(f"holding at the known pose with {hold.min():.1f}..{hold.max():.1f} N")
        ses.run(hold_time)
        theta, tension, speed = ses.average(sample_time)
    finally:
        ses.close()
    law = compliance_of(model.cables)
    l0 = unstretched_lengths(law, lengths, tension)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    theta_zero = theta - (kin.length - l0) / ses.ratio
    return stamped(
        model,
        "known-pose",
        theta_zero=[float(x) for x in theta_zero],
        drum_scale=[1.0] * model.n_cables,
        pose=[float(x) for x in pose],
        identities=identities_of(driver, model.n_cables),
        notes={"tensions": [round(float(x), 2) for x in tension],
               "max_motor_speed_while_sampled": speed},
    )  # fmt: skip


def force_cables(model: RobotModel) -> list[int]:
    """The ``r`` cables held by their tension in ``self_calibrate``: those whose removal
    leaves the best-conditioned 6 × 6 wrench matrix at home (the six others fix the pose)."""
    r = model.n_cables - 6
    if r <= 0:
        return []
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    W = np.array(kin.W)
    best, chosen = -1.0, ()  # type: tuple[float, tuple[int, ...]]
    for combo in itertools.combinations(range(model.n_cables), r):
        keep = [i for i in range(model.n_cables) if i not in combo]
        s = np.linalg.svd(W[:, keep], compute_uv=False)
        if s[-1] / s[0] > best:
            best, chosen = s[-1] / s[0], combo
    return list(chosen)


def sample_poses(model: RobotModel, opt: SelfOptions) -> np.ndarray:
    """K × 6: home, then ± ``travel`` along x, y, z and ± ``tilt`` about x, y, z, each kept
    inside the workspace box and its largest angle, and halved (up to three times) until the
    tensions holding it leave ``TENSION_MARGIN`` of the tension range below the upper limit
    and above the lower one: the start is only near home, the real tensions differ (nominal:
    the start is taken as home)."""
    ws = model.workspace
    home = np.asarray(model.home.position, float)
    kin = KinematicsData(model)
    span = model.tension_max - model.tension_min
    low = model.tension_min + TENSION_MARGIN[0] * span
    high = model.tension_max - TENSION_MARGIN[1] * span
    out = [np.r_[home, 0.0, 0.0, 0.0]]
    for j in range(6):
        for sign in (1.0, -1.0):
            x = np.zeros(6)
            if j < 3:
                x[j] = float(np.clip(home[j] + sign * opt.travel, ws.position_min[j],
                                     ws.position_max[j]) - home[j])  # fmt: skip
            else:
                x[j] = sign * min(opt.tilt, ws.max_angle)
            for _ in range(4):
                pose = x + out[0]
                t = hold_tensions(model, kin, pose)
                if np.all(t <= high) and np.all(t >= low):
                    break
                x *= 0.5
            else:
                continue
            if np.any(x):
                out.append(pose)
    return np.array(out)


# fractions of each cable's tension range kept free below and above the planned tensions
TENSION_MARGIN = (0.0, 0.3)


def sample_around_start(ses: Session, opt: SelfOptions,
                        progress: Progress | None = None) -> Samples:  # fmt: skip
    """``self``'s samples, on ``ses`` (not enabled yet; left enabled, back at the start): the
    start and the moves of ``sample_poses`` away from it, six cables by position and the
    redundant ones by tension (module docstring). Each sample goes to ``progress``; one that
    holds samples already (a resume) goes on from the first pose it lacks, enabled where the
    platform stopped: the moves are planned from sample 0, on the same encoder reference."""
    model, log = ses.model, ses.log
    progress = progress if progress is not None else Progress()
    kin = KinematicsData(model)
    poses = sample_poses(model, opt)
    guess = poses.copy()
    plan, lengths = [], []
    for x in guess:
        plan.append(hold_tensions(model, kin, x))  # leaves kin at x
        lengths.append(kin.length.copy())
    force = hold_by_tension(ses, opt)
    k_axial = ses.k.copy()
    names = ", ".join(model.cables[i].name for i in force)
    log(f"self-calibration: the start pose and {len(poses) - 1} moves away from it "
        f"(± {opt.travel:g} m, ± {opt.tilt:g} rad); "
        f"cables {names or '(none)'} held by tension, the others by position")  # fmt: skip
    first = progress.samples
    ses.tension_goal[:] = plan[max(0, min(first, len(poses)) - 1)]
    ses.enable()
    ses.run(1.5)  # the redundant cables to their tensions (at the start, or where it stopped)
    if first == 0:
        theta0, t0, _ = ses.average(opt.sample_time)
        progress.add(theta0, t0, guess[0])
        progress.start_targets = ses.base.copy()
    else:
        log(f"  resumed: {first} of {len(poses)} samples kept, from where the platform stopped")
    theta0, t0 = progress.theta[0], progress.tension[0]
    comp = 1.0 / k_axial  # m/N
    for k in range(max(1, first), len(poses)):
        # the position cables: unstretched length change from the nominal geometry and the
        # planned tensions; the force cables: their planned tension
        dl0 = (lengths[k] - lengths[0]) - (plan[k] - t0) * comp
        goal = theta0 - dl0 / ses.ratio
        done = ses.move(goal, plan[k], opt.move_time)
        # the guess: where the ramp stopped
        g = guess[k] if done >= 1.0 else guess[0] + done * (guess[k] - guess[0])
        ses.run(opt.settle_time)
        th, t, speed = ses.average(opt.sample_time)
        progress.add(th, t, g)
        log(f"  pose {k}/{len(poses) - 1}: {done:.0%} of the move, tensions "
            f"{t.min():.1f}..{t.max():.1f} N, motors at most {speed:.2g} rad/s")  # fmt: skip
    assert progress.start_targets is not None
    ses.move(progress.start_targets, plan[0], opt.move_time)
    ses.run(opt.settle_time)
    return Samples(*progress.arrays(len(poses)))


def hold_by_tension(ses: Session, opt: SelfOptions) -> list[int]:
    """``ses``'s redundant cables (``force_cables``) held by their tension, at
    ``opt.force_bandwidth``, the loops scaled by the cables' stiffness at home; those cables."""
    model = ses.model
    kin = KinematicsData(model)
    hold_tensions(model, kin, np.r_[model.home.position, 0.0, 0.0, 0.0])
    force = force_cables(model)
    ses.force[force] = True
    ses.k[:] = model.cable_stiffness(kin.length.copy())
    ses.gain = 1.0 - math.exp(-2.0 * math.pi * opt.force_bandwidth * ses.driver.period)
    return force


def where_around_start(samples: int, total: int) -> str:
    """Where ``self``'s pattern of ``total`` samples stopped with ``samples`` taken, in the
    log's words ("pose k/K" is the sample after the move to pose k)."""
    if samples == 0:
        return "the start, before its sample"
    if samples < total:
        return f"pose {samples} of {total - 1} (around the start)"
    return "the way back to the start"


def self_options(opt: SelfOptions) -> dict[str, Any]:
    """What ``self``'s samples and identification follow, by name (a partial session's plan)."""
    return {k: v for k, v in dataclasses.asdict(opt).items() if k != "weights"}


def self_calibrate(
    model: RobotModel,
    driver: WinchDriver,
    opt: SelfOptions | None = None,
    log: Callable[[str], None] = print,
    progress: Progress | None = None,
) -> tuple[CalibrationRecord, Identified]:
    """From an unknown pose near home: the samples (module docstring), the identification,
    the record. Raises :class:`CalibrationFailedError` (drives disabled) when the drives are not in
    position mode, the platform cannot be held, or the data do not decide the pose; stopped
    midway, :class:`CalibrationStoppedError` with the samples taken (``progress``: those of a
    stopped run to go on from)."""
    opt = opt or SelfOptions()
    if not model.drives.holds_lengths:
        raise CalibrationFailedError(
            "self-calibration moves the platform with the drives' position loops: it needs "
            "[drives] mode = \"csp\" (this robot's drives are in torque mode); use known-pose"
        )
    if model.grippers:
        raise CalibrationFailedError("self-calibration of a robot with grippers is not supported")
    ses = Session(model, driver, log)
    progress = progress if progress is not None else Progress()
    try:
        samples = sample_around_start(ses, opt, progress)
    except (CalibrationFailedError, DriverError) as exc:
        at = where_around_start(progress.samples, len(sample_poses(model, opt)))
        raise stopped(exc, progress, ses, at) from None
    finally:
        ses.close()
    poses = samples.guess
    force = list(np.flatnonzero(ses.force))
    ident = Identification(model, opt.fit_drum_scales, opt.weights).solve(samples)
    worst = max(max(ident.std[:3]) / opt.max_std[0], max(ident.std[3:]) / opt.max_std[1])
    record = stamped(
        model,
        "self",
        theta_zero=[float(x) for x in ident.theta_zero],
        drum_scale=[float(x) for x in ident.drum_scale],
        pose=ident.pose,
        identities=identities_of(driver, model.n_cables),
        residual_rms=ident.residual_rms,
        condition=ident.condition,
        std=ident.std,
        samples=len(poses),
        sample_residuals=ident.sample_residuals,
        notes={"force_rms": ident.force_rms, "force_cables": [model.cables[i].name for i in force],
               "travel": opt.travel, "tilt": opt.tilt, "fit_drum_scales": opt.fit_drum_scales},
    )  # fmt: skip
    weights = opt.weights or Weights.of(model)
    if not ident.success and ident.residual_rms > 5 * weights.length:
        raise CalibrationFailedError(f"the identification did not converge: {ident.message}")
    noise = length_noise(model)
    fits, ratio = model_test(ident.length_residuals, noise)
    record.notes["length_noise"] = noise
    record.notes["residuals_over_noise"] = ratio
    if not fits:
        raise CalibrationFailedError.with_result(record, ident,
            f"the length residuals are {ratio:.1f}x what the encoders and the torque "
            f"resolution explain (RMS {ident.residual_rms * 1e6:.1f} µm against "
            f"{noise * 1e6:.1f} µm; χ² test at 99.9 %): the robot's geometry differs from the "
            "file (anchors, drums); its pose from this record would be off by more than it "
            "predicts. Identify them: `cdprctl calibrate --config F geometry --out "
            "F-built.toml` (docs/homing.md, \"Geometric calibration\"), or measure them"
        )
    if ident.condition > opt.max_condition or worst > 1.0:
        raise CalibrationFailedError.with_result(record, ident,
            f"ill-conditioned: condition {ident.condition:.3g} (limit {opt.max_condition:g}), "
            f"predicted σ {np.round(np.array(ident.std[:3]) * 1e3, 2).tolist()} mm, "
            f"{np.round(np.array(ident.std[3:]) * 1e3, 2).tolist()} mrad (limits "
            f"{opt.max_std[0] * 1e3:g} mm, {opt.max_std[1] * 1e3:g} mrad): move further "
            "(--travel, --tilt) or calibrate at a known pose"
        )
    return record, ident
