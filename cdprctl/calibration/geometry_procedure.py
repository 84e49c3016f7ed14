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
import math
from collections.abc import Callable

import numpy as np

from cdprctl.calibration.geometry import GeometryIdentification, GeometryResult, GeometrySamples
from cdprctl.calibration.geometry_plan import (
    STOP_MARGIN,
    GeometryOptions,
    check_robot,
    identification_of,
    motion_time,
    move_duration,
    plan,
    tension_bounds,
)
from cdprctl.calibration.identify import Identification, model_test
from cdprctl.calibration.procedure import SelfOptions, sample_around_start
from cdprctl.calibration.record import CalibrationRecord, geometry_hash, now_iso
from cdprctl.calibration.session import CalibrationFailedError, Session, hold_tensions
from cdprctl.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel
from cdprctl.numerics import compliance_of, unstretched_lengths
from drivers.base import WinchDriver


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
                       poses: np.ndarray | None = None) -> GeometryCalibration:  # fmt: skip
    """From a start near home: the moves and samples (``poses`` from :func:`plan`, planned
    here when None), the identification, the test. Raises :class:`CalibrationFailedError`
    (drives disabled) when it cannot run; a refused identification comes back with
    ``accepted`` False and the reason."""
    opt = opt or GeometryOptions.of(model)
    check_robot(model)
    if poses is None:
        poses = plan(model, opt)
    poses = poses.copy()
    ident = identification_of(model)
    reference = (ident.reference[0], ident.reference[1], ident.reference[2])
    refs = ", ".join(model.cables[i].name for i in reference)
    log(f"geometric calibration: {len(poses) - 1} poses over {opt.fill:.0%} of the "
        f"workspace (about {motion_time(poses, opt):.0f} s of motion); the anchors of cables "
        f"{refs} taken as drawn (they fix the frame)")  # fmt: skip
    ses = Session(model, driver, log)
    ses.t_stop_low, ses.t_stop_high = tension_bounds(model, STOP_MARGIN)
    moved = 0.0
    try:
        # the start, first: poses a metre away reached from home's lengths would miss by the
        # start's offset (rowc 10 cm from home: its cables 40 N above plan, the moves stopped)
        near = sample_around_start(ses, SelfOptions())
        start = _held_while(ses, lambda: Identification(model, False).solve(near).poses[0])
        poses[0] = start
        log(f"the start: [{start[0]:.4f}, {start[1]:.4f}, {start[2]:.4f}] m (from the "
            "samples around it, on the file's geometry)")  # fmt: skip
        kin = KinematicsData(model)
        hold_tensions(model, kin, start)
        l0_start = unstretched_lengths(compliance_of(model.cables), kin.length.copy(),
                                       near.tension[0])  # fmt: skip
        goal_of = motor_goals(model, near.theta[0], l0_start, ses.ratio)

        theta_all, tension_all = list(near.theta), list(near.tension)
        guess = list(near.guess - near.guess[0] + start)  # around the start found
        here = start
        for k in range(1, len(poses)):
            origin = here
            done, took = _move(ses, here, poses[k], goal_of, opt)
            moved += took
            here = here + done * (poses[k] - here)
            ses.run(opt.settle_time)
            th, t, speed = ses.average(opt.sample_time)
            theta_all.append(th)
            tension_all.append(t)
            guess.append(here)
            why = f" (stopped: {ses.stopped_by})" if done < 1.0 else ""
            log(f"  pose {k}/{len(poses) - 1}: {done:.0%} of the move{why}, tensions "
                f"{t.min():.1f}..{t.max():.1f} N, motors at most {speed:.2g} rad/s")  # fmt: skip
            if done < 1.0:  # a tension near its limit: back a way it came (it held there)
                why = ses.stopped_by
                to = retreat_to(here, origin)
                try:  # stopped only by the session's limits (a slack cable, an overload)
                    back = dataclasses.replace(opt, speed=RETREAT_SPEED * opt.speed)
                    _, took = _move(ses, here, to, goal_of, back, stop=False)
                except CalibrationFailedError as exc:
                    raise CalibrationFailedError(
                        f"the move to pose {k} stopped ({why}) and the way back did too: "
                        f"{exc}; the robot differs from its file more than the plan allows: "
                        "plan closer to home (--fill)") from None  # fmt: skip
                moved += took
                here = to
        _, took = _move(ses, here, start, goal_of, opt)
        moved += took
        ses.run(opt.settle_time)
    finally:
        ses.close()
    samples = GeometrySamples(np.array(theta_all), np.array(tension_all), np.array(guess))
    result = ident.solve(samples)
    reason, ratio, eq_ratio = verdict(ident, result, samples, opt)
    log(f"the residuals: lengths {ratio:.2f}x the encoders' σ, equilibrium {eq_ratio:.2f}x "
        "the torques' (each must pass a χ² test at 99.9 %)")  # fmt: skip
    return GeometryCalibration(result, reference, samples, moved, reason == "accepted",
                               reason, ratio, eq_ratio)  # fmt: skip


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


# of the moves' speed, a retreat's: it starts where a cable is near its lower stop, and at full
# speed the way back let one go slack (CoGiRo at 0.2 m/s: 4 of 10 seeds stopped so, every one
# on its way back from pose 11; at 0.4 of it, seed 3 went through, anchors within 0.11 mm)
RETREAT_SPEED = 0.4
# m (and rad, the pose's 6-vector): how far a retreat goes back the way it came, the whole
# way when shorter. The tension that stopped the move fell over its last stretch; going back
# the whole way made CoGiRo's seed 20 retreat 0.9 m twice (415 s of motion, 5 minutes allowed)
RETREAT_DISTANCE = 0.1



def retreat_to(here: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Where a stopped move backs off to: ``RETREAT_DISTANCE`` back towards ``origin`` (the
    pose it came from, which held), or ``origin`` when that is nearer."""
    way = float(np.linalg.norm(origin - here))
    return here + min(1.0, RETREAT_DISTANCE / max(way, 1e-12)) * (origin - here)


# s the platform is held after the start is identified in lock-step (below)
HOLD_AFTER_IDENTIFYING = 1.0


def _held_while(ses: Session, compute: Callable[[], np.ndarray]) -> np.ndarray:
    """``compute()`` in a thread while the session holds the platform, cycle by cycle: the
    drives want their SYNC and targets every period (an idle bus left their velocity readings
    at 10³ rad/s and a following-error fault at the next move, across processes).

    On a simulated clock (lock-step: the driver's ``clock`` is not the wall's) nothing waits
    for it: ``compute()`` runs here, then the platform is held ``HOLD_AFTER_IDENTIFYING``.
    Held for as long as the thread took (5-8 s of wall time here: 900-1100 blocks of 0.05 s),
    the same seed gave other samples from run to run and under load."""
    import time

    if ses.driver.clock is not time.monotonic:
        out = compute()
        ses.run(HOLD_AFTER_IDENTIFYING)
        return out
    import threading

    results: list[np.ndarray] = []
    failed: list[BaseException] = []

    def work() -> None:
        import contextlib
        import os

        # at the normal scheduler: a SCHED_FIFO copy of the holder starved it (0x8130)
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        try:
            results.append(compute())
        except BaseException as exc:  # re-raised in the caller's thread
            failed.append(exc)

    worker = threading.Thread(target=work, name="cdprctl-identify", daemon=True)
    worker.start()
    while worker.is_alive():
        ses.run(0.05)
    if failed:
        raise failed[0]
    return results[0]


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


GoalOf = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # pose -> (rad, N) per cable


def motor_goals(model: RobotModel, theta_ref: np.ndarray, l0_ref: np.ndarray,
                ratio: np.ndarray) -> GoalOf:  # fmt: skip
    """``goal_of(x)``: the motor angles (rad) that give pose ``x``'s unstretched lengths under
    its planned tensions, from motor angles ``theta_ref`` where the unstretched lengths are
    ``l0_ref`` (m; ``ratio``: m of cable per motor rad), and those tensions (N). The cable law
    whole: over a metre of travel rowc's compliance changes by half, 1.3 mm of stretch, 40 N
    on its stiff cables."""
    kin = KinematicsData(model)
    law = compliance_of(model.cables)

    def goal_of(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = hold_tensions(model, kin, x)
        return theta_ref - (unstretched_lengths(law, kin.length, t) - l0_ref) / ratio, t

    return goal_of


def _move(ses: Session, a: np.ndarray, b: np.ndarray,
          goal_of: GoalOf,
          opt: GeometryOptions, stop: bool = True) -> tuple[float, float]:  # fmt: skip
    """From pose ``a`` to ``b`` in a straight line (a cosine time law at ``opt.speed``): the
    planned motor angles and tensions every 1 cm (or 0.01 rad), interpolated per cycle.
    Returns the fraction done (a tension near its limit stops it, unless ``stop`` is False:
    a retreat along a way it came, where only the session's hard limits stop it) and the
    seconds taken (a stopped move ends where it stopped: holding the rest of its time would
    only add to the motion's)."""
    dist = float(np.linalg.norm(b - a))
    n = max(2, math.ceil(dist / 0.01) + 1)
    fr = np.linspace(0.0, 1.0, n)
    m = ses.model.n_cables
    G, T = np.zeros((n, m)), np.zeros((n, m))
    ready = [0]  # waypoints computed: as the ramp needs them, a few per cycle at most (all at
    # once, a metre's 100 took 20-35 ms without a SYNC, a third of the drives' comm_timeout)
    base0, tension0 = ses.base.copy(), ses.tension_goal.copy()

    def waypoint(j: int) -> None:
        while ready[0] <= j:
            k = ready[0]
            G[k], T[k] = goal_of(a + fr[k] * (b - a))
            if k == 0:
                offset_g, offset_t = base0 - G[0], tension0 - T[0]
                G_off[:], T_off[:] = offset_g, offset_t
            # from where the drives are (a stopped move, the real start): that offset fades
            # out along the move, as ``Session.move``'s ramp does
            G[k] += (1.0 - fr[k]) * G_off
            T[k] += (1.0 - fr[k]) * T_off
            ready[0] += 1

    G_off, T_off = np.zeros(m), np.zeros(m)
    waypoint(0)
    duration = move_duration(dist, opt)
    reached = [0.0]  # the fraction of the way
    ses.begin_move()

    def step(f: float) -> bool:
        if stop and ses.move_stops():  # the targets stay where they are; the run ends
            ses.pace = 0.0
            return True
        s = 0.5 - 0.5 * math.cos(math.pi * f)
        reached[0] = s
        ses.pace = math.sin(math.pi * f)
        x = s * (n - 1)
        i = min(int(x), n - 2)
        u = x - i
        waypoint(i + 1)
        ses.base[:] = G[i] + u * (G[i + 1] - G[i])
        ses.tension_goal[:] = T[i] + u * (T[i + 1] - T[i])
        return False

    took = ses.run(duration, step)
    ses.pace = 0.0
    return reached[0], took


def geometry_record(built: RobotModel, cal: GeometryCalibration,
                    identities: list[dict[str, int] | None]) -> CalibrationRecord:  # fmt: skip
    """The calibration record of ``built`` (the robot file as identified): its encoders'
    zeros, its drums as they are (scale 1), the start pose."""
    r = cal.result
    return CalibrationRecord(
        robot=built.name,
        method="geometry",
        time=now_iso(),
        geometry_hash=geometry_hash(built),
        encoders=built.drives.encoders,
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
