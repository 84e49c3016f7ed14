"""The cables' clearance over a robot's documented workspace by brute force, apart from the
project's kernel (``cdprctl/geometry/interference.py``; issue 67): numpy, every cable sampled
every 0.1 mm, and where a cable or the body meets a box, scipy's qhull for how deep (signed: the
least translation that parts them, from the hull of the two shapes' Minkowski difference, as
the kernel reports it by its separating axes).

* **A cable** is the segment from its attachment ``p + R b_i`` to its exit point (the anchor;
  with a swivel pulley, the tangent point as ``cdprctl/geometry/kinematics.py`` computes it: the one
  value read from the project).
* **Cable against cable**: the points of cable ``i``, every ``step`` (0.1 mm), each projected
  onto cable ``j``'s segment (clamped): the least such distance is the pair's, at most
  ``step / 2`` above the exact one. Pairs that share an anchor or an attachment by design
  (within 1 µm) touch there at every pose and are skipped.
* **Cable against the platform's body** (``[[platform.body.boxes]]``): the points of the cable
  from ``attachment_exclusion`` along it from its attachment on, each measured to every box
  (the point in the box's frame, its excess over the half extents).
* **Cable against the cell** (``[[cell.obstacles]]``): the whole cable, to each box and
  half-space.
* **The platform's body against the cell**: each box of the body against each obstacle box,
  the 12 edges of each sampled against the other, solid (two boxes' least distance is had at
  a corner or on an edge of one of them; boxes that overlap have an edge in the other: 0);
  against a half-space, the least of the body box's 8 corners' signed distances (negative in
  it).
* **The grid**: the ``[workspace]`` box every ``--step`` (m, per axis), at the home orientation
  and turned from it about the 26 axes of a cube's faces, edges and corners by each angle of
  ``--angles`` (fractions of ``max_angle``), plus ``--random`` rotations (axis uniform, angle
  uniform up to ``max_angle``, seeded).

    .venv/bin/python tools/clearance_check.py config/rowc.toml [--step 0.1 0.035 0.1]
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model import RobotModel
from cdprctl.model.interference import Box
from cdprctl.robot_file import load_robot

STEP = 1e-4  # m: the cables' sampling
COARSE = 0.01  # m: the first pass that brackets each least
SHARED = 1e-6  # m: anchors or attachments this close are one point by design


def rotation(axis_angle: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, written here (not ``cdprctl.core.rotation``)."""
    theta = float(np.linalg.norm(axis_angle))
    if theta == 0.0:
        return np.eye(3)
    k = axis_angle / theta
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(theta) * K + (1.0 - math.cos(theta)) * K @ K


def sampled(
    a: np.ndarray, b: np.ndarray, dist: Callable[[np.ndarray], np.ndarray], step: float = STEP
) -> float:
    """m: the least of ``dist`` over the points of the segment ``a``-``b`` every ``step``.
    The distance from a point moving along a segment to a convex set is convex along it, so
    the best point of a 1 cm sampling brackets the minimum: only that bracket is sampled every
    ``step`` (the same least as sampling the whole segment every ``step``)."""
    length = float(np.linalg.norm(b - a))
    coarse = np.linspace(0.0, 1.0, max(2, math.ceil(length / COARSE) + 1))
    k = int(np.argmin(dist(a + coarse[:, None] * (b - a))))
    lo, hi = coarse[max(k - 1, 0)], coarse[min(k + 1, len(coarse) - 1)]
    fine = np.linspace(lo, hi, max(2, math.ceil((hi - lo) * length / step) + 1))
    return float(dist(a + fine[:, None] * (b - a)).min())


def to_segment(a: np.ndarray, b: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """Each point's distance (m) to the segment ``a``-``b``: its projection, clamped."""
    d = b - a
    dd = max(float(d @ d), 1e-300)
    return lambda P: np.sqrt(((P - a - np.clip((P - a) @ d / dd, 0.0, 1.0)[:, None] * d) ** 2)
                             .sum(axis=1))  # fmt: skip


def edges(centre: np.ndarray, R: np.ndarray, half: np.ndarray) -> list[tuple]:
    """The 12 edges of a box (centre, axes ``R``, ``half`` extents; m) as segment ends."""
    corners = {c: centre + R @ (np.array(c) * half) for c in itertools.product((-1, 1), repeat=3)}
    return [(corners[a], corners[b]) for a, b in itertools.combinations(corners, 2)
            if sum(x != y for x, y in zip(a, b, strict=True)) == 1]  # fmt: skip


def box_to_box(one: tuple, other: tuple, step: float) -> float:
    """m: two boxes' least distance (each ``(centre, R, half)``), their edges sampled."""
    d = min(sampled(a, b, to_box(*target), step)
            for source, target in ((one, other), (other, one))
            for a, b in edges(*source))  # fmt: skip
    return signed(d, corners(*one), corners(*other))


def corners(centre: np.ndarray, R: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The eight corners (8, 3) of a box (centre, axes ``R``, ``half`` extents; m)."""
    return np.array([centre + R @ (np.array(c) * half) for c in itertools.product((-1, 1),
                                                                                  repeat=3)])


def signed(d: float, A: np.ndarray, B: np.ndarray) -> float:
    """``d`` (m) where two convex shapes (their vertices ``A``, ``B``) are apart; where they
    meet (``d`` under 1 nm), minus how deep: the origin's distance to the nearest facet of the
    hull of ``A − B`` (0 touching)."""
    if d > 1e-9:
        return d
    from scipy.spatial import ConvexHull

    b = ConvexHull(np.array([a - x for a in A for x in B])).equations[:, 3]
    return float(np.max(b)) if np.all(b < 0.0) else 0.0


def to_box(
    centre: np.ndarray, R: np.ndarray, half: np.ndarray
) -> Callable[[np.ndarray], np.ndarray]:
    """Each point's distance (m) to the box: in the box's frame, its excess over ``half``."""
    return lambda P: np.sqrt((np.maximum(np.abs((P - centre) @ R) - half, 0.0) ** 2).sum(axis=1))


@dataclass
class Least:
    """The least distance of one kind over the poses seen, with what and where."""

    distance: float = math.inf  # m
    what: str = ""
    where: str = ""  # the pose
    below: int = 0  # poses under the clearance

    def see(self, d: float, what: str, where: str, clear: float) -> None:
        self.below += d < clear
        if d < self.distance:
            self.distance, self.what, self.where = d, what, where


@dataclass
class Clearance:
    """A robot's brute-force clearance at poses, by kind (cables, body, cell)."""

    model: RobotModel
    step: float = STEP
    least: dict[str, Least] = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = self.model
        self.kin = KinematicsData(m)
        self.names = [c.name for c in m.cables]
        A, b = np.asarray(m.anchors), np.asarray(m.attachments)
        self.pairs = [(i, j) for i, j in itertools.combinations(range(m.n_cables), 2)
                      if np.linalg.norm(A[i] - A[j]) >= SHARED
                      and np.linalg.norm(b[i] - b[j]) >= SHARED]  # fmt: skip
        self.least = {k: Least() for k in ("cables", "body", "cell", "platform")}

    def at(self, p: np.ndarray, R: np.ndarray, turn: str = "") -> dict[str, tuple[float, str]]:
        """Every kind's least distance (m) and what, at the pose ``p`` (m), ``R`` (``turn``:
        how ``R`` was chosen, for the report)."""
        m, cfg = self.model, self.model.interference
        inverse_kinematics(m, self.kin, p, R)
        B = p + np.asarray(m.attachments) @ R.T
        E = np.array(self.kin.exit_points, dtype=float)
        out = {k: (math.inf, "") for k in self.least}
        for i, j in self.pairs:
            d = sampled(B[i], E[i], to_segment(B[j], E[j]), self.step)
            if d < out["cables"][0]:
                a, b = self.names[i], self.names[j]  # names that say "cable" already
                said = a.startswith("cable") and b.startswith("cable")
                out["cables"] = (d, f"{a} and {b}" if said else f"cables {a} and {b}")
        for i in range(m.n_cables):
            length = float(np.linalg.norm(E[i] - B[i]))
            start = B[i] + (E[i] - B[i]) * (cfg.attachment_exclusion / length)
            for box in cfg.body if length > cfg.attachment_exclusion else ():
                shape = (p + R @ box.centre, R @ box.rotation, box.half_extents)
                d = signed(sampled(start, E[i], to_box(*shape), self.step),
                           np.array([start, E[i]]), corners(*shape))  # fmt: skip
                if d < out["body"][0]:
                    out["body"] = (d, f"cable {self.names[i]} and the platform's {box.name}")
            for ob in cfg.obstacles:
                if isinstance(ob, Box):
                    dist = to_box(ob.centre, ob.rotation, ob.half_extents)
                else:
                    dist = lambda P, ob=ob: np.maximum((P - ob.point) @ ob.normal, 0.0)  # noqa: E731
                d = sampled(B[i], E[i], dist, self.step)
                if isinstance(ob, Box):
                    d = signed(d, np.array([B[i], E[i]]),
                               corners(ob.centre, ob.rotation, ob.half_extents))  # fmt: skip
                if d < out["cell"][0]:
                    out["cell"] = (d, f"cable {self.names[i]} and {ob.name}")
        for part, ob in itertools.product(cfg.body, cfg.obstacles):
            body = (p + R @ part.centre, R @ part.rotation, part.half_extents)
            if isinstance(ob, Box):
                d = box_to_box(body, (ob.centre, ob.rotation, ob.half_extents), self.step)
            else:
                d = min(float((c - ob.point) @ ob.normal) for c in
                        (body[0] + body[1] @ (np.array(s) * body[2])
                         for s in itertools.product((-1, 1), repeat=3)))  # fmt: skip
            if d < out["platform"][0]:
                out["platform"] = (d, f"the platform's {part.name} and {ob.name}")
        for k, (d, what) in out.items():
            if what:
                where = f"p = {np.round(p, 4).tolist()} m, {turn}"
                self.least[k].see(d, what, where, cfg.clearance)
        return out


def positions(model: RobotModel, steps: tuple[float, float, float]) -> np.ndarray:
    """The ``[workspace]`` box every ``steps`` (m), its faces included."""
    lo, hi = model.workspace.position_min, model.workspace.position_max
    axes = [np.linspace(lo[k], hi[k], max(2, round((hi[k] - lo[k]) / s) + 1))
            for k, s in enumerate(steps)]  # fmt: skip
    return np.array(list(itertools.product(*axes)))


def turns(max_angle: float, fractions: list[float], n_random: int, seed: int = 0) -> list:
    """(group, label, rotation from the home orientation): none, the 26 axes at each fraction
    of ``max_angle`` (rad), then ``n_random`` seeded ones up to it."""
    axes = [np.array(v, float) / np.linalg.norm(v)
            for v in itertools.product((-1, 0, 1), repeat=3) if any(v)]  # fmt: skip
    home = "the home orientation"
    out = [(home, home, np.eye(3))]
    out += [(f"{f * max_angle:.3g} rad, 26 axes", f"{f * max_angle:.3g} rad about "
             f"{np.round(v, 3).tolist()}", rotation(v * f * max_angle))
            for f in fractions for v in axes]  # fmt: skip
    rng = np.random.default_rng(seed)
    for _ in range(n_random):
        v = rng.normal(size=3)
        a = rng.uniform(0.0, max_angle)
        rv = v / np.linalg.norm(v) * a
        group = f"{n_random} random up to {max_angle:g} rad"
        out.append((group, f"{np.round(rv, 4).tolist()} rad", rotation(rv)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("configs", nargs="+", type=Path, help="robot files")
    ap.add_argument("--step", type=float, nargs=3, default=None,
                    help="m: the grid's x, y, z steps (default: a tenth of the box's side, "
                    "11 points per axis)")  # fmt: skip
    ap.add_argument("--angles", type=float, nargs="*", default=[0.5, 1.0],
                    help="fractions of [workspace] max_angle to turn the grid by, about 26 axes "
                    "(none: the home orientation only)")  # fmt: skip
    ap.add_argument("--random", type=int, default=20,
                    help="random rotations up to max_angle beside those (seeded)")
    args = ap.parse_args()
    print(
        "| robot | poses | cables: least (mm), pair | body: least (mm), cable | "
        "below the clearance | s |\n| --- | --- | --- | --- | --- | --- |"
    )
    for path in args.configs:
        model = load_robot(path)
        span = model.workspace.position_max - model.workspace.position_min
        steps = tuple(args.step) if args.step else tuple(float(s) / 10 for s in span)
        check = Clearance(model)
        by_turn: dict[str, list[float]] = {}  # least cables, body (m); poses below, poses
        t0, n = time.perf_counter(), 0
        for group, label, dR in turns(model.workspace.max_angle, args.angles, args.random):
            R = dR @ model.home.rotation
            row = by_turn.setdefault(group, [math.inf, math.inf, 0, 0])
            for p in positions(model, steps):  # type: ignore[arg-type]
                d = check.at(p, R, label)
                row[0], row[1] = min(row[0], d["cables"][0]), min(row[1], d["body"][0])
                row[2] += min(v[0] for v in d.values()) < model.interference.clearance
                row[3] += 1
                n += 1
        c, b = check.least["cables"], check.least["body"]
        below = sum(int(row[2]) for row in by_turn.values())  # poses, whatever kind
        print(
            f"| {model.name} | {n} | {c.distance * 1e3:.2f}, {c.what} | "
            f"{f'{b.distance * 1e3:.2f}, {b.what}' if b.what else 'no body'} | {below} | "
            f"{time.perf_counter() - t0:.0f} |",
            flush=True,
        )
        for kind, x in check.least.items():  # the cell's two kinds: only where the file has one
            if x.what:
                print(f"    {kind}: least {x.distance * 1e3:.2f} mm, {x.what}: {x.where}",
                      file=sys.stderr)  # fmt: skip
        for label, (cab, body, below_n, poses) in by_turn.items():
            body_mm = f"body {body * 1e3:.2f} mm, " if math.isfinite(body) else ""
            print(f"    {label}: cables {cab * 1e3:.2f} mm, {body_mm}{below_n}/{poses} poses "
                  "below the clearance", file=sys.stderr)  # fmt: skip


if __name__ == "__main__":
    main()
