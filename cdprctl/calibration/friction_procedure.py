"""``cdprctl calibrate friction``: the platform moved out and back along one line at several
speeds by the drives alone, every cycle's motor speeds and torques recorded, each winch's
friction fitted (:mod:`friction`; docs/friction.md).

The line: from where the platform stands, the direction (of a few, in the workspace) along
which the cable that moves least still moves most, as far as ``travel`` or the soft limits
(``motion/limits.py``: the workspace box and the tension margin) and the geometric
calibration's tension bounds along a move (``geometry_plan.PATH_MARGIN``) allow. The moves are the
geometric calibration's (:func:`geometry_moves.move`, every cable by position, the torques'
feed-forward from the planned tensions): a tension nearing its limit stops a move where it is,
and the platform goes back the way it came, slower (:data:`geometry_moves.RETREAT_SPEED`).

Where along the line each sample is comes from the measured motor angles (projected on the
planned ones), not from the plan: the drives follow it a period or two behind, the lag has the
sign of the motion, and read from the plan it put the statics' slope × the lag into the
viscous term (a few percent on rowc).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from cdprctl.calibration.friction import (
    WinchFriction,
    fit_measured,
    fit_winches,
    null_projectors,
    refusal,
)
from cdprctl.calibration.friction_progress import FrictionProgress
from cdprctl.calibration.geometry_moves import RETREAT_SPEED, GoalOf, motor_goals, move
from cdprctl.calibration.geometry_plan import (
    PATH_MARGIN,
    STOP_MARGIN,
    GeometryOptions,
    line_is_held,
    tension_bounds,
    tension_noise,
)
from cdprctl.calibration.progress import stopped
from cdprctl.calibration.session import CalibrationFailedError, Session
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from drivers.base import WinchDriver
from drivers.errors import DriverError


@dataclasses.dataclass(frozen=True)
class FrictionOptions:
    travel: float = 0.4  # m: each line's length at most
    lines: int = 3  # lines from the start, each in another direction
    speeds: tuple[float, ...] = (0.03, 0.09, 0.18)  # m/s: each way's mean speed
    repeats: int = 1  # out and back this many times at each speed
    settle_time: float = 0.5  # s at rest before the noise is measured and between the moves
    noise_time: float = 1.0  # s of torques at rest: their noise sets the residual's limit


@dataclasses.dataclass
class FrictionCalibration:
    fits: list[WinchFriction]
    start: list[float]  # x, y, z (m), rotation vector (rad): where every line starts
    ends: list[list[float]]  # each line's far end
    motion_time: float  # s the platform moved
    accepted: bool
    reason: str


# candidate directions of the line (base frame): the axes and the diagonals
_DIRECTIONS = np.array(
    [d for d in (np.array(v, float) for v in [
        (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1),
        (0, 1, 1), (0, 1, -1), (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)])]
)  # fmt: skip


def choose_lines(model: RobotModel, start: np.ndarray, travel: float,
                 count: int) -> list[np.ndarray]:  # fmt: skip
    """The far ends (6: m, rotation vector) of ``count`` lines from ``start``: of the
    candidate directions, either way, within the soft limits, those whose least-moving cable
    moves most over the reachable travel (each winch needs speeds of both signs), each at
    least 45° from the others (in another direction the cables' speeds and the wrench
    matrix's null space differ: along one line alone, two combinations of the winches'
    viscous terms are lost with the internal tensions)."""
    limits = SoftLimits(model)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, start[:3], model.home.rotation)
    l0 = kin.length.copy()
    bounds = tension_bounds(model, PATH_MARGIN)
    scored = []
    for d in _DIRECTIONS:
        for sign in (1.0, -1.0):
            u = sign * d / np.linalg.norm(d)
            far, _ = limits.ray_end(start, np.r_[u, 0.0, 0.0, 0.0], travel)
            if not line_is_held(model, kin, start, far, bounds):
                continue  # a cable would near its limit (the geometric calibration's rule)
            inverse_kinematics(model, kin, far[:3], model.home.rotation)
            scored.append((float(np.min(np.abs(kin.length - l0))), u, far))
    scored.sort(key=lambda x: -x[0])
    chosen: list[tuple[float, np.ndarray, np.ndarray]] = []
    for least, u, far in scored:
        if least >= 0.02 and all(abs(float(u @ v)) < np.cos(np.pi / 4) for _, v, _ in chosen):
            chosen.append((least, u, far))
        if len(chosen) == count:
            return [far for _, _, far in chosen]
    raise CalibrationFailedError(
        f"only {len(chosen)} lines from [{start[0]:.3f}, {start[1]:.3f}, {start[2]:.3f}] m "
        f"within the soft limits move every cable by 20 mm ({count} wanted, in directions "
        "45° apart): start nearer the workspace's centre")  # fmt: skip


def _grid(model: RobotModel, goal_of: GoalOf, start: np.ndarray,
          end: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The planned motor angles (101, m; rad), wrench matrices (101, 6, m) and pulley wraps
    (101, m; rad) along the line from ``start`` to ``end``, evenly spaced."""
    kin = KinematicsData(model)
    grid, W, wrap = [], [], []
    for f in np.linspace(0.0, 1.0, 101):
        x = start + f * (end - start)
        grid.append(goal_of(x)[0])
        inverse_kinematics(model, kin, x[:3], model.home.rotation)
        W.append(np.array(kin.W))
        wrap.append(kin.wrap_angle.copy())
    return np.array(grid), np.array(W), np.array(wrap)


#: s: the span of the motion's polynomial fit (Savitzky-Golay, cubic) around each sample
MOTION_WINDOW = 0.04


def motion_of(theta: np.ndarray, t: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's motor speeds (rad/s) and accelerations (rad/s²) from the motor angles
    ``theta`` (rows sampled every ``period`` s at times ``t``, in runs without a gap): a cubic
    fit over ``MOTION_WINDOW`` s centred on the sample, at the torque's instant. The drives'
    own speed (``velocity_source = "derived"``) is the mean over the last period, half a
    period before the torque it is paired with, and one encoder count per period noisy."""
    from scipy.signal import savgol_filter

    n = max(5, round(MOTION_WINDOW / period) | 1)
    w, a = np.zeros_like(theta), np.zeros_like(theta)
    # a run resumed in another process: its clock restarted (or went on, far later)
    step = np.diff(t)
    cuts = np.flatnonzero((step > 1.5 * period) | (step <= 0.0)) + 1
    for k in np.split(np.arange(len(t)), cuts):
        if len(k) >= n:
            w[k] = savgol_filter(theta[k], n, 3, deriv=1, delta=period, axis=0)
            a[k] = savgol_filter(theta[k], n, 3, deriv=2, delta=period, axis=0)
    return w, a


def _where(theta: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The fraction of the line (0..1) each row of ``theta`` (motor angles) is at: projected
    on the planned angles ``grid`` (n points along the line, evenly spaced)."""
    n = len(grid)
    d = np.linalg.norm(theta[:, None, :] - grid[None, :, :], axis=2)
    j = np.clip(np.argmin(d, axis=1), 0, n - 2)
    a, b = grid[j], grid[j + 1]
    u = np.einsum("ij,ij->i", theta - a, b - a) / np.einsum("ij,ij->i", b - a, b - a)
    return np.clip((j + np.clip(u, -1.0, 2.0)) / (n - 1), 0.0, 1.0)


def friction_calibrate(model: RobotModel, driver: WinchDriver, theta_zero: np.ndarray,
                       here: np.ndarray, opt: FrictionOptions | None = None,
                       log: Callable[[str], None] = print,
                       kept: FrictionProgress | None = None) -> FrictionCalibration:  # fmt: skip
    """From the platform at rest at ``here`` (6: m, rotation vector from home) with the
    encoders' zeros ``theta_zero`` (rad, the calibration record's): the moves, the samples,
    the fits; ``kept``: a stopped run's (``--resume``: its lines, from its start, which the
    platform goes back to first; its round trips not made again). Raises
    :class:`CalibrationStoppedError` (drives disabled, what was measured in it) when a move
    stops and the platform went back, the way back stops too, or the drives fault; a fit
    refused comes back with ``accepted`` False and the reason."""
    opt = opt or FrictionOptions()
    start = kept.start if kept is not None else here
    ends = kept.ends if kept is not None else choose_lines(model, start, opt.travel, opt.lines)
    ses = Session(model, driver, log)
    ses.t_stop_low, ses.t_stop_high = tension_bounds(model, STOP_MARGIN)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    goal_of = motor_goals(model, theta_zero, kin.length.copy(), ses.ratio)
    grids = [_grid(model, goal_of, start, end) for end in ends]
    plan = [(j, v) for j in range(len(ends)) for v in opt.speeds for _ in range(opt.repeats)]
    log(f"friction calibration: out and back along {len(ends)} lines of up to "
        f"{opt.travel:g} m from [{start[0]:.3f}, {start[1]:.3f}, {start[2]:.3f}] m, "
        f"{opt.repeats}x at each of {', '.join(f'{v:g}' for v in opt.speeds)} m/s")  # fmt: skip
    # per cycle: line, time, motor angles, speeds, torques, the cells' tensions (NaN: none)
    rows: list[np.ndarray] = []
    on = [0]

    def sample(_: float) -> None:
        st = ses.states
        rows.append(np.r_[on[0], driver.clock(), st.position, st.velocity, st.torque,
                          st.tension])  # fmt: skip

    progress = kept
    at = "the start (the torques' noise at rest)" if kept is None else "the way to the start"
    try:
        ses.tension_goal[:] = goal_of(here)[1]
        ses.enable()
        ses.run(opt.settle_time)
        if progress is None:
            progress = FrictionProgress(start.copy(), ends, _noise_at_rest(ses, opt), [])
        else:
            log(f"  resumed: {progress.done} of {len(plan)} round trips kept "
                f"({progress.samples} samples)")  # fmt: skip
            _to_start(ses, model, here, start, goal_of, min(opt.speeds), opt.settle_time)
        for k in range(progress.done, len(plan)):
            j, v = plan[k]
            at = f"round trip {k + 1} of {len(plan)} (line {j + 1}, {v:g} m/s)"
            on[0] = j
            g = dataclasses.replace(GeometryOptions.of(model), speed=v)
            took = 0.0
            for a, b in ((start, ends[j]), (ends[j], start)):
                took += _leg(ses, a, b, goal_of, g, sample, start)
                ses.run(opt.settle_time)
            progress.trips.append(np.array(rows))
            rows.clear()
            progress.done, progress.moved = k + 1, progress.moved + took
            if k + 1 == len(plan) or plan[k + 1][0] != j:
                log(f"  line {j + 1}/{len(ends)} to [{ends[j][0]:.3f}, {ends[j][1]:.3f}, "
                    f"{ends[j][2]:.3f}] m done")  # fmt: skip
    except (DriverError, CalibrationFailedError) as exc:
        raise stopped(exc, progress, ses, at) from None
    finally:
        ses.close()
    return _fitted(model, driver, ses, progress, grids)


def _noise_at_rest(ses: Session, opt: FrictionOptions) -> np.ndarray:
    """The torques' standard deviation (N·m per winch) over ``opt.noise_time`` at rest."""
    rest: list[np.ndarray] = []

    def at_rest(_: float) -> None:
        rest.append(ses.states.torque.copy())

    ses.run(opt.noise_time, at_rest)
    return np.std(np.array(rest), axis=0)


def _to_start(ses: Session, model: RobotModel, here: np.ndarray, start: np.ndarray,
              goal_of: GoalOf, speed: float, settle: float) -> None:  # fmt: skip
    """A resumed run's platform from where it stands (``here``) back to its lines' start at
    ``speed`` (m/s), where the model holds the way there (else refused: the platform was
    moved since the stop), a tension nearing its limit stopping it (the way is new: the
    nominal model's word on it is not the robot's); then ``settle`` s at rest."""
    far = float(np.linalg.norm(here[:3] - start[:3]))
    if far < 1e-3:
        return
    if not line_is_held(model, KinematicsData(model), here, start,
                        tension_bounds(model, PATH_MARGIN)):  # fmt: skip
        raise CalibrationFailedError(
            f"the platform stands {far * 1e3:.0f} mm from the stopped run's start "
            f"[{start[0]:.3f}, {start[1]:.3f}, {start[2]:.3f}] m and the way there nears a "
            "tension limit: bring it nearer, or start over without --resume")  # fmt: skip
    g = dataclasses.replace(GeometryOptions.of(model), speed=speed)
    done, _ = move(ses, here, start, goal_of, g)
    if done < 1.0:
        raise CalibrationFailedError(
            f"the way back to the stopped run's start stopped at {done:.0%} "
            f"({ses.stopped_by}): bring the platform nearer to [{start[0]:.3f}, "
            f"{start[1]:.3f}, {start[2]:.3f}] m, or start over without --resume")  # fmt: skip
    ses.run(settle)


def _fitted(model: RobotModel, driver: WinchDriver, ses: Session, progress: FrictionProgress,
            grids: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> FrictionCalibration:
    """Each winch's friction fitted on every sample of ``progress``."""
    m, noise = model.n_cables, progress.noise
    data = progress.rows
    line, t, theta = data[:, 0].astype(int), data[:, 1], data[:, 2 : 2 + m]
    tau, cell = data[:, 2 + 2 * m : 2 + 3 * m], data[:, 2 + 3 * m :]
    s = np.zeros(len(t))
    Q, wrap = np.empty((len(t), m, m)), np.empty((len(t), m))
    for j, (grid, W, wraps) in enumerate(grids):
        k = line == j
        s[k] = _where(theta[k], grid)
        at = np.rint(s[k] * (len(grid) - 1)).astype(int)
        Q[k], wrap[k] = null_projectors(W, ses.ratio)[at], wraps[at]
    w, acc = motion_of(theta, t, driver.period)
    # the residual's limit: the noise at rest and one torque count (tension_noise: N, √12)
    count = tension_noise(model) * np.sqrt(12.0) * ses.ratio
    limit = np.hypot(noise, count)
    cells = measured_winches(cell)
    # the projection where any cable has no cell (all winches' equations together)
    projected = fit_winches(s, line, Q, w, acc, tau, limit, wrap) if len(cells) < m else []
    fits = [_measured(s, line, w, acc, tau, ses.ratio[i] * cell[:, i], t, driver.period,
                      limit, wrap, i)
            if i in cells else projected[i] for i in range(m)]  # fmt: skip
    why = refusal([c.name for c in model.cables], fits)
    return FrictionCalibration(fits, progress.start.tolist(),
                               [e.tolist() for e in progress.ends], progress.moved, not why,
                               why or "accepted")  # fmt: skip


#: a cable's cell heard at this fraction of the samples at least: its winch fitted on it
CELL_HEARD = 0.9


def measured_winches(cell: np.ndarray) -> list[int]:
    """The winches whose cable's load cell (``cell``: N, (n, m), NaN: none, or not heard) gave
    a tension at ``CELL_HEARD`` of the samples or more."""
    return [int(i) for i in np.flatnonzero(np.mean(np.isfinite(cell), axis=0) >= CELL_HEARD)]


def _measured(s: np.ndarray, line: np.ndarray, w: np.ndarray, acc: np.ndarray, tau: np.ndarray,
              load: np.ndarray, t: np.ndarray, period: float, limit: np.ndarray,
              wrap: np.ndarray, i: int) -> WinchFriction:  # fmt: skip
    """Winch ``i`` fitted on its cell (``load``: r × its tension, N·m, at the times ``t``,
    s), on the samples it was heard at; its rate by the motion's fit (``motion_of``) over
    the load with a lost frame's gap filled in."""
    k = np.isfinite(load)
    filled = np.interp(np.arange(len(load)), np.flatnonzero(k), load[k])
    rate = motion_of(filled[:, None], t, period)[0][:, 0]
    return fit_measured(s[k], line[k], w[k, i], acc[k, i], tau[k, i], load[k], rate[k],
                        float(limit[i]), wrap[k, i])  # fmt: skip


def _leg(ses: Session, a: np.ndarray, b: np.ndarray, goal_of: GoalOf, opt: GeometryOptions,
         sample: Callable[[float], None], origin: np.ndarray) -> float:  # fmt: skip
    """One way from ``a`` to ``b``, sampled every cycle; a move stopped by a tension near its
    limit goes back to ``origin`` (the start, which held) slower, then stops the calibration.
    Returns the seconds moved."""
    here = a.copy()
    done, took = move(ses, a, b, goal_of, opt, track=here, each=sample)
    if done >= 1.0:
        return took
    why = ses.stopped_by
    back = dataclasses.replace(opt, speed=RETREAT_SPEED * opt.speed)
    try:
        move(ses, here, origin, goal_of, back, stop=False, track=here)
    except CalibrationFailedError as exc:
        raise CalibrationFailedError(f"a move stopped ({why}) and the way back did too: "
                                     f"{exc}") from None  # fmt: skip
    raise CalibrationFailedError(
        f"a move stopped at {done:.0%} of its way ({why}); the platform went back to the start:"
        " a shorter line (--travel) or a start nearer the workspace's centre")  # fmt: skip
