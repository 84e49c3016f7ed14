"""A path file's waypoints planned as the loop will play them, and checked before any motion.

Each waypoint is a ruckig segment (``Trajectory.set_segment``) from wherever the last one
ended: a straight line in the 6 coordinates (phase synchronisation) at the row's speed —
per-coordinate velocity limits proportional to the segment's direction, so the path speed
(m/s) is the row's along the line, not per axis; the accelerations and jerks are the
configured ones per axis. Where the path blends, the speed is a per-axis limit on the
segments either side (so up to √3 times it along a diagonal). A blended waypoint is passed
at a velocity (the mean of the two segments' cruise velocities, each coordinate within both
segments' limits and zero where the path reverses it): ruckig then reaches it moving and the
corner is rounded, within the limits. A timed row sets the segment's minimum duration.

The check plays the plan offline through the same ``Trajectory`` at the loop's period and
tests every sample (``SoftLimits``, the inertial load included) at most ``CHECK_SPACING``
apart, and the cables' clearance between the samples too (``clearance.py``); the first
failing sample rejects the path, naming its waypoint, time, pose and rule (for the clearance:
the pair and the distance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cdprctl.core.rotation import FloatArray, rpy_to_matrix
from cdprctl.geometry.interference import distance_words
from cdprctl.model.robot import RobotModel
from cdprctl.motion.gcode import looks_like_metres
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_file import csv_without_units, parse_path
from cdprctl.motion.trajectory import (
    Trajectory,
    acceleration_limits,
    coordinates_pose,
    pose_coordinates,
    velocity_limits,
)
from cdprctl.motion.waypoints import Waypoint

CHECK_SPACING = 0.002  # m (or rad) between checked samples at most
# m (or rad): a plan made where the reference rested still holds from a reference this close
# (enabling resets the reference to the estimate: nanometres away, across processes ~2e-9 m)
START_TOLERANCE = 1e-5
MAX_DURATION = 3600.0  # s: a path file is a job, not a program that runs forever
FLOOR = 1e-3  # of a limit: ruckig needs every coordinate's limits positive


class PathRejectedError(ValueError):
    pass


@dataclass
class Segment:
    target: FloatArray  # (6,) trajectory coordinates (m, rotation vector rad)
    velocity: list[float]  # at the target (m/s, rad/s)
    max_velocity: list[float]
    max_acceleration: list[float]
    minimum_duration: float | None  # s
    dwell: float  # s held at the target
    where: str  # the file's line

    def __post_init__(self) -> None:
        # ruckig's binding takes a list of any length for its six coordinates (and reads past
        # a short one): a wrong length is refused here, when the plan is made, not in the loop
        for name in ("target", "velocity", "max_velocity", "max_acceleration"):
            n = len(getattr(self, name))
            if n != 6:
                raise ValueError(f"{self.where}: a segment's {name} has {n} coordinates, not 6")


@dataclass
class PathPlan:
    segments: list[Segment]
    duration: float  # s, planned, dwells included
    samples: int  # checked
    spacing: float  # m (or rad): the largest distance between two checked samples
    min_margin: float  # N: the smallest tension margin met
    min_margin_at: str
    name: str = ""
    start: FloatArray = field(default_factory=lambda: np.zeros(6))  # coordinates, at rest
    waypoints: list[Waypoint] = field(default_factory=list)
    durations: list[float | None] = field(default_factory=list)  # s, each segment's least
    # m: the cables' least distance met at the checked samples (inf: nothing to check), what
    # and where (the pair, the file's line, the time), and the limit ([interference] clearance)
    min_clearance: float = math.inf
    min_clearance_at: str = ""
    clearance_limit: float = 0.0

    def starts_at(self, x: FloatArray) -> bool:
        """Whether the plan holds from the trajectory coordinates ``x`` (``START_TOLERANCE``)."""
        return float(np.max(np.abs(np.asarray(x) - self.start))) <= START_TOLERANCE

    def summary(self) -> str:
        n = len(self.segments)
        return (f"{n} segment{'s' if n != 1 else ''}, {self.duration:.2f} s; checked at "
                f"{self.samples} samples ≤ {self.spacing * 1e3:.1f} mm apart, smallest tension "
                f"margin {self.min_margin:.1f} N ({self.min_margin_at})")  # fmt: skip

    def clearance_text(self) -> str:
        """The least clearance met, with its pair, line and time, and the limit."""
        if not math.isfinite(self.min_clearance):
            return "clearance: nothing to check (one cable, no body, no obstacle)"
        least = (f"{self.min_clearance * 1e3:.2f} mm" if self.min_clearance >= 0.0 else
                 distance_words(self.min_clearance))  # fmt: skip
        return (f"least clearance {least}: {self.min_clearance_at}; "
                f"limit {self.clearance_limit * 1e3:.2f} mm ([interference] clearance)")


def coordinates_of(model: RobotModel, pose: tuple[float, ...] | FloatArray) -> FloatArray:
    """Trajectory coordinates of ``x, y, z, roll, pitch, yaw`` (m, rad)."""
    return pose_coordinates(model, np.asarray(pose[:3], dtype=float), rpy_to_matrix(*pose[3:]))


def _blends(waypoints: list[Waypoint], durations: list[float | None], i: int) -> bool:
    """Whether the path passes waypoint ``i`` moving (not where it dwells, ends, or a timed
    segment begins or ends)."""
    w = waypoints[i]
    return (w.blend and w.dwell == 0.0 and i + 1 < len(waypoints)
            and durations[i] is None and durations[i + 1] is None)  # fmt: skip


def _limits(
    model: RobotModel, delta: FloatArray, speed: float | None, blended: bool
) -> tuple[FloatArray, FloatArray]:
    """Per-coordinate velocity and acceleration limits of a straight segment ``delta``: the
    velocity along the line is ``speed`` (m/s; None: the configured maximum). A segment that
    starts or ends moving (a blend) has the speed per axis instead: its velocity turns from
    one line's direction to the next on the way."""
    c = model.control
    v_lim, a_lim = velocity_limits(c), acceleration_limits(c)
    frac = 1.0 if speed is None else speed / c.max_velocity
    vmax = v_lim * FLOOR
    for part in (slice(0, 3), slice(3, 6)):
        d = delta[part]
        norm = float(np.linalg.norm(d))
        if norm > 1e-12:
            u = np.ones(len(d)) if blended else np.abs(d) / norm
            vmax[part] = np.maximum(vmax[part], v_lim[part] * frac * u)
    return vmax, a_lim


def plan_path(
    model: RobotModel,
    waypoints: list[Waypoint],
    start: FloatArray,
    period: float,
    limits: SoftLimits | None = None,
    name: str = "",
    durations: list[float | None] | None = None,
) -> PathPlan:
    """The plan of ``waypoints`` from the trajectory coordinates ``start`` (at rest), checked;
    raises PathRejectedError with the first problem. ``durations`` (s, per segment, None: as fast
    as the limits allow) replaces the rows' times (a resumed path keeps its rows' pace)."""
    c = model.control
    if not waypoints:  # a file has one at least (path_file); a resume past the last has none
        raise PathRejectedError("the path has no waypoint left to go to")
    lim = limits or SoftLimits(model)
    start = np.asarray(start, dtype=float)
    targets = [coordinates_of(model, w.pose) for w in waypoints]
    near = lim.near_of(start, targets[-1])  # from under the clearance: no closer (but home)
    for k, (w, x) in enumerate(zip(waypoints, targets, strict=True)):  # the waypoints first
        margin, ok = lim.check(x[None], near=near)
        if not ok[0]:
            pose = (np.round(w.pose, 4) + 0.0).tolist()
            raise PathRejectedError(f"{w.where} (the end of segment {k + 1}): waypoint {pose}: "
                                    f"{lim.why(x, float(margin[0]), near=near)}")  # fmt: skip
        if w.speed is not None and w.speed > c.max_velocity * (1 + 1e-9):
            raise PathRejectedError(f"{w.where}: speed {w.speed:g} m/s exceeds the configured "
                               f"[control] max_velocity = {c.max_velocity:g} m/s")  # fmt: skip
    deltas = np.diff(np.vstack([start, *targets]), axis=0)
    if durations is None:
        durations = []
        prev_time = 0.0
        for w in waypoints:
            durations.append(None if w.time is None else w.time - prev_time)
            if w.time is not None:
                prev_time = w.time + w.dwell
    blended = [_blends(waypoints, durations, i) for i in range(len(waypoints))]
    bounds = [
        _limits(model, d, w.speed, blended[i] or (i > 0 and blended[i - 1]))
        for i, (d, w) in enumerate(zip(deltas, waypoints, strict=True))
    ]
    segments = []
    for i, w in enumerate(waypoints):
        vmax, amax = bounds[i]
        vel = np.zeros(6)
        if blended[i]:
            vel = _blend_velocity(deltas[i], deltas[i + 1], bounds[i], bounds[i + 1])
        segments.append(Segment(targets[i], vel.tolist(), vmax.tolist(), amax.tolist(),
                                durations[i], w.dwell, w.where))  # fmt: skip
    return _play_and_check(model, segments, waypoints, durations, start, period, lim, name)


def plan_text(
    model: RobotModel,
    text: str,
    start: FloatArray,
    period: float,
    limits: SoftLimits | None = None,
    name: str = "",
    units: str = "m",
) -> PathPlan:
    """A path file's content planned and checked from the trajectory coordinates ``start``
    (at rest; the axes a file leaves out keep its values); ``units``: a CSV's lengths without
    a row of units (``path_file.parse_path``); G-code arcs within the robot's ``[paths]
    arc_tolerance``. Raises PathFileError or PathRejectedError."""
    start = np.asarray(start, dtype=float)
    waypoints = parse_path(text, coordinates_pose(model, start), units,
                           model.paths.arc_tolerance)  # fmt: skip
    return plan_path(model, waypoints, start, period, limits, name)


def units_hint(text: str, units: str, why: str) -> str:
    """A hint for a file rejected outside the workspace whose units may not be what it was
    read in: a CSV read in metres (its numbers may be mm), G-code without G20/G21 read in mm
    (its numbers may be metres)."""
    if "outside the workspace box" not in why:
        return ""
    if units == "m" and csv_without_units(text):
        return (" (a file in millimetres? add a row of units under the header, such as "
                "'mm, mm, mm', or give --units mm)")
    if looks_like_metres(text):
        return (" (a file in metres? G-code's lengths are mm unless G20 says inches: write "
                "them in mm, with G21)")
    return ""


def _blend_velocity(d_in: FloatArray, d_out: FloatArray, b_in: tuple, b_out: tuple) -> FloatArray:
    """The velocity to pass a waypoint at: the mean of both segments' cruise velocities,
    within both segments' limits, zero on a coordinate that reverses, and no more than what
    accelerates over half of the shorter neighbour (so ruckig need not overshoot)."""
    cruise = []
    for d, (vmax, _) in ((d_in, b_in), (d_out, b_out)):
        t = float(np.max(np.abs(d) / vmax))  # s at cruise speed
        cruise.append(d / t if t > 0 else np.zeros(6))
    v = 0.5 * (cruise[0] + cruise[1])
    v[np.sign(d_in) * np.sign(d_out) <= 0] = 0.0
    cap = np.minimum(b_in[0], b_out[0])
    reach = np.sqrt(np.minimum(b_in[1], b_out[1]) * np.minimum(np.abs(d_in), np.abs(d_out)))
    return np.clip(v, -np.minimum(cap, reach), np.minimum(cap, reach))


def _play_and_check(
    model: RobotModel,
    segments: list[Segment],
    waypoints: list[Waypoint],
    durations: list[float | None],
    start: FloatArray,
    period: float,
    lim: SoftLimits,
    name: str,
) -> PathPlan:
    tr = Trajectory(model, period)
    tr.reset(start)
    c = model.control
    fastest = max(c.max_velocity, c.max_angular_velocity)
    every = max(1, int(CHECK_SPACING / (fastest * period)))
    pos, acc, seg_of, times = [start.copy()], [np.zeros(6)], [0], [0.0]
    t = 0.0
    max_steps = int(MAX_DURATION / period)
    steps = 0
    for k, s in enumerate(segments):
        tr.set_segment(s.target, s.velocity, s.max_velocity, s.max_acceleration,
                       s.minimum_duration)  # fmt: skip
        t_start = t
        while not tr.finished:
            tr.update(period)
            t += period
            steps += 1
            if steps % every == 0 or tr.finished:
                pos.append(tr.position.copy())
                acc.append(tr.acceleration.copy())
                seg_of.append(k)
                times.append(t)
            if steps > max_steps:
                raise PathRejectedError(f"{s.where}: the path lasts longer than {MAX_DURATION:g} s")
        if tr.result.name not in ("Working", "Finished"):
            raise PathRejectedError(f"{s.where}: no trajectory to this waypoint ({tr.result.name})")
        if s.minimum_duration is not None:
            took = t - t_start
            if took > s.minimum_duration + 2 * period:
                raise PathRejectedError(
                    f"{s.where}: its time cannot be met: the segment needs "
                    f"{took:.3f} s at the velocity and acceleration limits, "
                    f"{s.minimum_duration:.3f} s were given"
                )
        t += s.dwell
    P = np.array(pos)
    margin, ok, floor = lim.along(P, np.array(acc))
    if not ok.all():
        i = int(np.argmin(ok))
        k = seg_of[i]
        pose = np.round(P[i, :3], 4).tolist()
        why = lim.why(P[i], float(margin[i]), floor, lim.nearest_at[i], lim.near)
        raise PathRejectedError(
            f"{segments[k].where} (segment {k + 1}): at t = {times[i]:.2f} s, position {pose} m: "
            f"{why}"
        )
    steps_apart = np.linalg.norm(np.diff(P[:, :3], axis=0), axis=1)  # a segment: 2 samples at least
    j, jc = int(np.argmin(margin)), int(np.argmin(lim.nearest))
    near_at, least = "", float(lim.nearest[jc])
    if lim.clearance.active:  # the distance as measured, the pair (and its start's floor)
        least, pair = lim.clearance.closest_at(lim.nearest_at[jc])
        near_at = f"{pair} ({segments[seg_of[jc]].where}, t = {times[jc]:.2f} s)"
        g = lim.clearance.interference
        if lim.near is not None and g.slack[g.best[0]] == 0.0:  # another pair than the start's
            near_at += f"; the start under the clearance: {lim.clearance.started}"
    return PathPlan(
        segments=segments,
        duration=t,
        samples=len(P),
        spacing=float(np.max(steps_apart)),
        min_margin=float(margin[j]),
        min_margin_at=f"{segments[seg_of[j]].where}, t = {times[j]:.2f} s",
        name=name,
        start=start.copy(),
        waypoints=list(waypoints),
        durations=list(durations),
        min_clearance=least,
        min_clearance_at=near_at,
        clearance_limit=lim.clearance.limit,
    )
