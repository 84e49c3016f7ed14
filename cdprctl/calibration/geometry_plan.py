"""The poses of the geometric calibration (``cdprctl calibrate geometry``), planned before the
drives are configured: candidates over the workspace (a grid of positions through ``fill`` of
the box, each level and tilted about x, y and z), kept where the nominal model holds them
with a wide tension margin (the real geometry differs from the file: its tensions do too);
chosen one by one (D-optimal) for the information they add on the geometry. Each sample's
rows depend on the geometry, the start pose and its own pose only, so its own pose is
eliminated per sample (a Schur complement) and the information on (geometry, start) is a sum
over samples: the greedy choice costs a determinant per candidate, not a least-squares
problem. Then a short tour through them, and the motion budget."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from cdprctl.calibration.geometry import GeometryIdentification, GeometrySamples
from cdprctl.calibration.identify import Weights, length_noise, quantization_std
from cdprctl.calibration.session import CalibrationFailedError, hold_tensions
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.model.calibration import reference_anchors
from cdprctl.model.robot import RobotModel


@dataclasses.dataclass(frozen=True)
class GeometryOptions:
    poses: int = 25  # samples, the start included
    fill: float = 0.8  # fraction of the workspace box the poses span (about its centre)
    tilt: float = 0.8  # fraction of the workspace's max_angle the tilted poses take
    speed: float = 0.1  # m/s (and rad/s): the moves' mean speed
    settle_time: float = 1.0  # s at rest before sampling
    sample_time: float = 0.3  # s averaged per sample
    force_bandwidth: float = 2.0  # Hz: the redundant cables' tension loop
    max_motion: float = 300.0  # s: refuse a plan whose moves take longer
    max_anchor_std: float = 0.005  # m: refuse a predicted σ beyond, per anchor (3-D)
    max_scale_std: float = 0.001  # refuse a drum's predicted σ beyond (fraction)

    @classmethod
    def of(cls, model: RobotModel, **given: float | int | None) -> GeometryOptions:
        """The options for ``model``: ``given`` (None: not given), else the robot file's
        ``[calibration] geometry_fill``/``geometry_speed``, else the defaults above."""
        c = model.calibration
        chosen = {k: v for k, v in (("fill", c.geometry_fill), ("speed", c.geometry_speed))
                  if v is not None}  # fmt: skip
        chosen.update({k: v for k, v in given.items() if v is not None})
        return cls(**chosen)  # type: ignore[arg-type]


# What each cable's tension may be at a candidate (CANDIDATE_MARGIN), along a move
# (PATH_MARGIN) and before a move stops short (STOP_MARGIN): below, a fraction of the way from
# the cable's lower limit up to its tension at home (a fraction of the whole range would not
# do: CoGiRo holds its home at 7 % of a 100-5000 N range, and no pose passed); above, a
# fraction of the range kept free. Each wider than the next: the poses are far from the start,
# and a robot whose anchors are 20 mm off holds them with other tensions (rowc: 25 N more than
# planned at 0.3; lock-step); a straight move between two held poses can pass where a cable
# goes slack (rowc's way back from a pose stopped below 29 N; lock-step).
CANDIDATE_MARGIN = (0.35, 0.4)


PATH_MARGIN = (0.25, 0.3)


STOP_MARGIN = (0.18, 0.15)


def move_duration(distance: float, opt: GeometryOptions) -> float:
    """s: a move of ``distance`` (m and rad, the pose's 6-vector norm) at ``opt.speed`` mean
    (a cosine time law), at least 1 s."""
    return max(1.0, distance / opt.speed)


def tension_noise(model: RobotModel) -> float:
    """N: the σ of a tension read at rest: one torque count, quantized (/√12). (With the
    motor's Coulomb friction added, uniform /√3, rowc's anchors came out 4.8 mm off where
    without it 2.4 mm, lock-step: at rest the position loops hold, friction barely acts.)"""
    return quantization_std(Weights.of(model).tension)


PATH_STEP = 0.05  # m (and rad) between the checked points of a move


Bounds = tuple[np.ndarray, np.ndarray]  # N per cable: (lower, upper)


def tension_bounds(model: RobotModel, margin: tuple[float, float]) -> Bounds:
    """N per cable: (lower, upper) bounds of ``margin`` (the MARGINs above)."""
    home = hold_tensions(model, KinematicsData(model), np.r_[model.home.position, np.zeros(3)])
    span = model.tension_max - model.tension_min
    low = model.tension_min + margin[0] * np.maximum(home - model.tension_min, 0.0)
    return low, model.tension_max - margin[1] * span


def line_is_held(model: RobotModel, kin: KinematicsData, a: np.ndarray, b: np.ndarray,
                 bounds: Bounds) -> bool:  # fmt: skip
    """Whether the nominal model holds every point of the straight move from ``a`` to ``b``
    (every ``PATH_STEP``) within ``bounds`` (``tension_bounds(model, PATH_MARGIN)``)."""
    low, high = bounds
    n = max(2, math.ceil(float(np.linalg.norm(b - a)) / PATH_STEP) + 1)
    for f in np.linspace(0.0, 1.0, n):
        t = hold_tensions(model, kin, a + f * (b - a))
        if np.any(t < low) or np.any(t > high):
            return False
    return True


def candidate_poses(model: RobotModel, opt: GeometryOptions,
                    start: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """N × 6: the grid's poses the nominal model holds within ``CANDIDATE_MARGIN`` (and, with
    ``start``, along the straight move from it: the way back is always there)."""
    ws = model.workspace
    lo, hi = np.asarray(ws.position_min, float), np.asarray(ws.position_max, float)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo) * opt.fill
    tilt = opt.tilt * ws.max_angle
    turns = [np.zeros(3)] + [s * a * np.eye(3)[j] for j in range(3) for s in (1.0, -1.0)
                             for a in (0.5 * tilt, tilt)]  # fmt: skip
    low, high = tension_bounds(model, CANDIDATE_MARGIN)
    path = tension_bounds(model, PATH_MARGIN)
    kin = KinematicsData(model)
    out = []
    for f in itertools.product((-1.0, -0.5, 0.0, 0.5, 1.0), repeat=3):
        p = centre + np.array(f) * half
        for r in turns:
            x = np.r_[p, r]
            t = hold_tensions(model, kin, x)
            if np.all(t >= low) and np.all(t <= high) and (
                    start is None or line_is_held(model, kin, start, x, path)):  # fmt: skip
                out.append(x)
    return np.array(out)


def _nominal_samples(model: RobotModel, poses: np.ndarray) -> GeometrySamples:
    """What the drives would read at ``poses`` were the robot its file (for planning)."""
    kin = KinematicsData(model)
    law = compliance_of(model.cables)
    ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
    theta, tension = [], []
    for x in poses:
        t = hold_tensions(model, kin, x)
        l0 = unstretched_lengths(law, kin.length.copy(), t)
        theta.append(-l0 / ratio)
        tension.append(t)
    return GeometrySamples(np.array(theta), np.array(tension), poses.copy())


def plan_poses(model: RobotModel, ident: GeometryIdentification, opt: GeometryOptions,
               start: np.ndarray) -> np.ndarray:  # fmt: skip
    """K × 6: ``start``, then greedily the candidate adding the most information on the
    geometry (D-optimal, the poses eliminated: module docstring)."""
    cands = candidate_poses(model, opt, start)
    if len(cands) == 0:
        raise CalibrationFailedError("no pose of the workspace is held with margin: check "
                                     "[workspace] and the tension limits")  # fmt: skip
    g, m = ident.n_geo, ident.m
    infos = []
    z_geo = np.r_[ident.anchors0[ident.free].ravel(), np.ones(m)]
    for x in cands:
        s = _nominal_samples(model, np.array([start, x]))
        J = ident.jacobian(np.r_[z_geo, s.guess.ravel()], s)
        rows = J[6:]  # sample 1: its length closures and its equilibrium
        A, B = rows[:, : g + 6], rows[:, g + 6 :]
        BtB = B.T @ B
        infos.append(A.T @ A - A.T @ B @ np.linalg.solve(BtB, B.T @ A))
    s0 = _nominal_samples(model, np.array([start]))
    J0 = ident.jacobian(np.r_[z_geo, s0.guess.ravel()], s0)
    total = J0.T @ J0  # the start's equilibrium
    chosen: list[int] = []
    scale = np.sqrt(np.maximum(np.diag(total + sum(infos)), 1e-300))

    def score(info: np.ndarray) -> float:
        M = info / np.outer(scale, scale)
        Mgg, Mg0, M00 = M[:g, :g], M[:g, g:], M[g:, g:]
        S = Mgg - Mg0 @ np.linalg.pinv(M00) @ Mg0.T
        sign, logdet = np.linalg.slogdet(S + 1e-12 * np.eye(g))
        return logdet if sign > 0 else -math.inf

    for _ in range(min(opt.poses - 1, len(cands))):
        best, pick = -math.inf, -1
        for j, info in enumerate(infos):
            if j in chosen:
                continue
            v = score(total + info)
            if v > best:
                best, pick = v, j
        chosen.append(pick)
        total = total + infos[pick]
    return np.vstack([start, _tour(model, start, cands[chosen])])


def _tour(model: RobotModel, start: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """The poses in a short order from ``start`` (nearest neighbour among the moves the
    nominal model holds all along; when none is, through the start: every candidate's way
    from and to it is held)."""
    kin = KinematicsData(model)
    path = tension_bounds(model, PATH_MARGIN)
    left = list(range(len(poses)))
    out, here = [], start
    while left:
        near = sorted(left, key=lambda i: float(np.linalg.norm(poses[i] - here)))
        j = next((i for i in near[:8] if line_is_held(model, kin, here, poses[i], path)),
                 None)
        if j is None:
            out.append(start)  # sampled again on the way: a check of the start's drift
            j = near[0]
        left.remove(j)
        out.append(poses[j])
        here = poses[j]
    return np.array(out)


def motion_time(poses: np.ndarray, opt: GeometryOptions) -> float:
    """s: the moves (there and back) and the samples at rest."""
    legs = np.r_[np.linalg.norm(np.diff(poses, axis=0), axis=1),
                 np.linalg.norm(poses[-1] - poses[0])]  # fmt: skip
    moves = float(sum(move_duration(d, opt) for d in legs))
    return moves + len(poses) * (opt.settle_time + opt.sample_time)


def check_robot(model: RobotModel) -> None:
    """What the geometric calibration needs of a robot (:class:`CalibrationFailedError`)."""
    if not model.drives.holds_lengths:
        raise CalibrationFailedError(
            "the geometric calibration moves the platform with the drives' position loops: "
            "it needs [drives] mode = \"csp\" (this robot's drives are in torque mode)"
        )
    if model.grippers:
        raise CalibrationFailedError("the geometric calibration of a robot with grippers is "
                                     "not supported")  # fmt: skip
    if any(c.pulley is not None for c in model.cables):
        raise CalibrationFailedError("the geometric calibration identifies exit points: "
                                     "cables with [cables.pulley] are not supported")  # fmt: skip


def identification_of(model: RobotModel) -> GeometryIdentification:
    reference = reference_anchors(model.calibration, model.anchors)
    return GeometryIdentification(model, list(reference), length_noise(model),
                                  tension_noise(model))  # fmt: skip


def plan(model: RobotModel, opt: GeometryOptions) -> np.ndarray:
    """The poses (K × 6, the first home: the start replaces it), checked against the motion
    budget. Before the drives are configured: seconds of computing with a configured bus
    idle left the drives' velocity readings at 10³ rad/s and a following-error fault at the
    first move (across processes), and the poses hardly depend on where near home the
    platform starts."""
    check_robot(model)
    home = np.r_[model.home.position, 0.0, 0.0, 0.0]
    poses = plan_poses(model, identification_of(model), opt, home)
    planned = motion_time(poses, opt)
    if planned > opt.max_motion:
        raise CalibrationFailedError(
            f"the plan's {len(poses)} poses take {planned:.0f} s of motion, more than "
            f"{opt.max_motion:g} s: fewer poses (--poses) or faster moves (--speed)"
        )
    return poses
