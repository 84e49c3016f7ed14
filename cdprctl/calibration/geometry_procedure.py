"""``cdprctl calibrate geometry``: the platform moved through poses planned for the geometric
identification, sampled at rest, the geometry identified (:mod:`geometry`), the record and the
robot file of the robot as built (docs/homing.md, "Geometric calibration").

The poses: :mod:`geometry_plan`.

The moves: as in ``self`` (:mod:`procedure`), six cables hold lengths (the position loops of
the drives), the redundant ones their tension (a loop on the measured torque): straight lines
between the poses, their planned lengths and tensions interpolated every cycle, at ``speed``.
A tension nearing its limit stops a move where it is (the sample is taken there).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import numpy as np

from cdprctl.calibration.calibration_record import CalibrationRecord, stamped
from cdprctl.calibration.geometry import GeometryIdentification, GeometryResult, GeometrySamples
from cdprctl.calibration.geometry_moves import (
    RETREAT_SPEED,
    GoalOf,
    held_while,
    motor_goals,
    move,
    retreat_to,
)
from cdprctl.calibration.geometry_plan import (
    STOP_MARGIN,
    GeometryOptions,
    check_robot,
    identification_of,
    motion_time,
    plan,
    tension_bounds,
)
from cdprctl.calibration.identify import Identification, Samples, model_test
from cdprctl.calibration.procedure import (
    SelfOptions,
    hold_by_tension,
    sample_around_start,
    sample_poses,
    where_around_start,
)
from cdprctl.calibration.progress import Progress, stopped
from cdprctl.calibration.session import CalibrationFailedError, Session, hold_tensions
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel
from drivers.base import WinchDriver
from drivers.errors import DriverError
from drivers.vocabulary import Lifecycle


@dataclasses.dataclass
class GeometryCalibration:
    result: GeometryResult
    reference: tuple[int, int, int]
    samples: GeometrySamples
    motion_time: float  # s the platform moved
    accepted: bool
    reason: str
    residuals_over_noise: float  # RMS of the length closures over the encoders' σ
    equilibrium_over_noise: float  # RMS of the weighted equilibrium residuals (σ units)


def geometry_calibrate(model: RobotModel, driver: WinchDriver,
                       opt: GeometryOptions | None = None,
                       log: Callable[[str], None] = print,
                       poses: np.ndarray | None = None,
                       progress: Progress | None = None) -> GeometryCalibration:  # fmt: skip
    """From a start near home: the moves and samples (``poses`` from :func:`plan`, planned
    here when None), the identification, the test. Raises :class:`CalibrationFailedError`
    (drives disabled) when it cannot run, :class:`CalibrationStoppedError` with the samples
    taken when it stops midway (``progress``: those of a stopped run on the same encoder
    reference, to go on from); a refused identification comes back with ``accepted`` False
    and the reason."""
    opt = opt or GeometryOptions.of(model)
    check_robot(model)
    if poses is None:
        poses = plan(model, opt)
    poses = poses.copy()
    progress = progress if progress is not None else Progress()
    ident = identification_of(model)
    reference = (ident.reference[0], ident.reference[1], ident.reference[2])
    refs = ", ".join(model.cables[i].name for i in reference)
    log(f"geometric calibration: {len(poses) - 1} poses over {opt.fill:.0%} of the "
        f"workspace (about {motion_time(poses, opt):.0f} s of motion); the anchors of cables "
        f"{refs} taken as drawn (they fix the frame)")  # fmt: skip
    ses = Session(model, driver, log)
    ses.t_stop_low, ses.t_stop_high = tension_bounds(model, STOP_MARGIN)
    try:
        _visit(ses, poses, opt, progress)
    except (CalibrationFailedError, DriverError) as exc:
        raise stopped(exc, progress, ses, where_stopped(model, progress, len(poses))) from None
    finally:
        ses.close()
    samples = GeometrySamples(*progress.arrays())
    result = ident.solve(samples)
    reason, ratio, eq_ratio = verdict(ident, result, samples, opt)
    log(f"the residuals: lengths {ratio:.2f}x the encoders' σ, equilibrium {eq_ratio:.2f}x "
        "the torques' (each must pass a χ² test at 99.9 %)")  # fmt: skip
    return GeometryCalibration(result, reference, samples, progress.moved,
                               reason == "accepted", reason, ratio, eq_ratio)  # fmt: skip


def start_pose(model: RobotModel, near: Samples) -> np.ndarray:
    """The start's pose (m; rotation vector rad) identified from the samples around it on the
    file's geometry (module-level: ``held_while`` runs it in a process of its own)."""
    return Identification(model, False).solve(near).poses[0]


def where_stopped(model: RobotModel, progress: Progress, n_poses: int) -> str:
    """Where a calibration of ``n_poses`` (the start included) stopped, in words."""
    if progress.near is None:
        n = len(sample_poses(model, SelfOptions()))
        return where_around_start(progress.samples, n).replace("the way back to", "back at")
    k = progress.samples - progress.near + 1
    return f"pose {k} of {n_poses - 1}" if k < n_poses else "the way back to the start"


def _visit(ses: Session, poses: np.ndarray, opt: GeometryOptions, progress: Progress) -> None:
    """The start's samples (``self``'s pattern) and its estimate, then the poses from the
    first one ``progress`` lacks, each sampled at rest, and back to the start. Resumed past the
    start's samples: enabled where the platform stopped (``progress.here``), the moves planned
    from the same samples as before (the same encoder reference)."""
    model, log = ses.model, ses.log
    if progress.near is None:
        near = sample_around_start(ses, SelfOptions(), progress)
        progress.near = progress.samples
        start = held_while(ses, functools.partial(start_pose, model, near))
    else:  # identified again, the drives off: the same samples, the same start
        near = Samples(*progress.arrays(progress.near))
        start = start_pose(model, near)
    poses[0] = start
    log(f"the start: [{start[0]:.4f}, {start[1]:.4f}, {start[2]:.4f}] m (from the "
        "samples around it, on the file's geometry)")  # fmt: skip
    kin = KinematicsData(model)
    hold_tensions(model, kin, start)
    l0_start = unstretched_lengths(compliance_of(model.cables), kin.length.copy(),
                                   near.tension[0])  # fmt: skip
    goal_of = motor_goals(model, near.theta[0], l0_start, ses.ratio)
    if progress.here is None:
        progress.here = start.copy()
    here = progress.here
    if ses.driver.lifecycle is not Lifecycle.ACTIVE:
        hold_by_tension(ses, SelfOptions())
        ses.tension_goal[:] = goal_of(here)[1]
        ses.enable()
        ses.run(1.5)  # the redundant cables to their tensions where the platform stopped
        log(f"  resumed at [{here[0]:.4f}, {here[1]:.4f}, {here[2]:.4f}] m: {progress.samples}"
            f" samples kept ({progress.near} around the start)")  # fmt: skip
    for k in range(progress.samples - progress.near + 1, len(poses)):
        _visit_pose(ses, k, poses, goal_of, opt, progress)
    _, took = move(ses, here, start, goal_of, opt, track=here)
    progress.moved += took
    ses.run(opt.settle_time)


def _visit_pose(ses: Session, k: int, poses: np.ndarray, goal_of: GoalOf,
                opt: GeometryOptions, progress: Progress) -> None:  # fmt: skip
    """The move to pose ``k`` from ``progress.here``, its sample at rest; a move stopped short
    by a tension near its limit is sampled where it stopped, then backs off the way it came."""
    assert progress.here is not None
    here, origin = progress.here, progress.here.copy()
    done, took = move(ses, origin, poses[k], goal_of, opt, track=here)
    progress.moved += took
    here[:] = origin + done * (poses[k] - origin)
    ses.run(opt.settle_time)
    th, t, speed = ses.average(opt.sample_time)
    progress.add(th, t, here)
    why = f" (stopped: {ses.stopped_by})" if done < 1.0 else ""
    ses.log(f"  pose {k}/{len(poses) - 1}: {done:.0%} of the move{why}, tensions "
            f"{t.min():.1f}..{t.max():.1f} N, motors at most {speed:.2g} rad/s")  # fmt: skip
    if done >= 1.0:
        return
    why = ses.stopped_by  # a tension near its limit: back a way it came (it held there)
    to = retreat_to(here, origin)
    try:  # stopped only by the session's limits (a slack cable, an overload)
        back = dataclasses.replace(opt, speed=RETREAT_SPEED * opt.speed)
        _, took = move(ses, here, to, goal_of, back, stop=False, track=here)
    except CalibrationFailedError as exc:
        raise CalibrationFailedError(
            f"the move to pose {k} stopped ({why}) and the way back did too: "
            f"{exc}; the robot differs from its file more than the plan allows: "
            "plan closer to home (--fill)") from None  # fmt: skip
    progress.moved += took
    here[:] = to


def verdict(ident: GeometryIdentification, result: GeometryResult, samples: GeometrySamples,
            opt: GeometryOptions) -> tuple[str, float, float]:  # fmt: skip
    """Whether the identified geometry is accepted ("accepted", else why not), and the RMS
    of the length closures and of the equilibrium residuals over their noise. Each set must
    pass its χ² test: the lengths against the encoders' resolution, the equilibrium against
    the torques'. A platform heavier than its file bends the fit: rowc 5 % heavier (lock-step,
    seed 2), anchors 10 mm off whose length closures pass (0.46x) and whose equilibrium does
    not (1.79x; the right mass: 0.45 mm, 0.06x and 0.07x)."""
    length_res, equilibrium_res = _residuals(ident, result, samples)
    fits, ratio = model_test(length_res, ident.sigma_l)
    balances, eq_ratio = model_test(equilibrium_res, 1.0)  # weighted: in units of σ
    noise = ident.sigma_l
    worst_anchor = float(np.max(np.linalg.norm(result.std_anchors, axis=1)))
    worst_scale = float(np.max(result.std_drum_scale))
    reason = "accepted"
    if ident.at_bound(result):
        reason = (f"an anchor or a drum ended at its bound ({ident.ANCHOR_BOUND * 1e3:g} mm, "
                  f"{ident.SCALE_BOUND:.0%} from the file): the data do not decide it, or the "
                  "robot is not this file's")  # fmt: skip
    elif not result.success and ratio > 5.0:
        reason = f"the identification did not converge: {result.message}"
    elif not fits:
        reason = (f"the length residuals are {ratio:.1f}x what the encoders and the torque "
                  f"resolution explain (RMS {result.residual_rms * 1e6:.1f} µm against "
                  f"{noise * 1e6:.1f} µm; χ² test at 99.9 %): the robot differs from the file "
                  "in more than its anchors and drums (its attachments, a pulley, a cable "
                  "that slips, a wrong cable law)")  # fmt: skip
    elif not balances:
        reason = (f"the equilibrium residuals are {eq_ratio:.1f}x what the torque resolution "
                  f"explains (forces RMS {result.force_rms:.2f} N; χ² test at 99.9 %): the "
                  "platform's mass or centre of mass differs from the file, or a cable's "
                  "tension is not what its drive's torque says (friction, a pulley)")  # fmt: skip
    elif worst_anchor > opt.max_anchor_std or worst_scale > opt.max_scale_std:
        reason = (f"ill-conditioned: predicted σ up to {worst_anchor * 1e3:.2f} mm per anchor "
                  f"(limit {opt.max_anchor_std * 1e3:g} mm) and {worst_scale * 100:.3f} % per "
                  f"drum (limit {opt.max_scale_std * 100:g} %), condition "
                  f"{result.condition:.3g}: more poses (--poses) or other reference "
                  "anchors")  # fmt: skip
    return reason, ratio, eq_ratio


def _residuals(ident: GeometryIdentification, result: GeometryResult,
               s: GeometrySamples) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """At the solution: the length closures (m, samples 1..K-1) and the equilibrium
    residuals, weighted (units of their σ, every sample): ``residuals``' rows are sample 0's
    six equilibrium rows, then per sample its m lengths and six equilibrium rows."""
    K, m = s.theta.shape
    z = np.r_[result.anchors[ident.free].ravel(), result.drum_scale, result.poses.ravel()]
    r = ident.residuals(z, s)
    lengths = [r[6 + (k - 1) * (m + 6) : 6 + (k - 1) * (m + 6) + m] for k in range(1, K)]
    balance = [r[:6], *(r[6 + (k - 1) * (m + 6) + m : 6 + k * (m + 6)] for k in range(1, K))]
    return (np.concatenate(lengths) * ident.sigma_l if lengths else np.zeros(0),
            np.concatenate(balance))  # fmt: skip


def geometry_record(built: RobotModel, cal: GeometryCalibration,
                    identities: list[dict[str, int] | None]) -> CalibrationRecord:  # fmt: skip
    """The calibration record of ``built`` (the robot file as identified): its encoders'
    zeros, its drums as they are (scale 1), the start pose."""
    r = cal.result
    return stamped(
        built,
        "geometry",
        theta_zero=[float(x) for x in r.theta_zero],
        drum_scale=[1.0] * built.n_cables,
        pose=r.pose,
        identities=identities,
        residual_rms=r.residual_rms,
        condition=r.condition,
        std=r.std_pose,
        samples=len(r.poses),
        notes={"residuals_over_noise": cal.residuals_over_noise,
               "equilibrium_over_noise": cal.equilibrium_over_noise, "force_rms": r.force_rms,
               "motion_time": cal.motion_time,
               "reference_anchors": [built.cables[i].name for i in cal.reference]},
    )  # fmt: skip
