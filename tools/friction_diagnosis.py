"""Where ``cdprctl calibrate friction``'s error comes from, on one seeded simulated robot in
lock-step (docs/friction.md, "What it measures"): the calibration run as shipped, the simulated
robot's motor angles, speeds, tensions and applied torques recorded at every sample's instant
(the drives' angles and torques are one period old when read: matched by the angle), then the
worst winch's viscous and Coulomb error (% of the simulated robot's term) of

* the fit as shipped;
* the torques minus r × the simulated tensions, winch by winch (least squares on the friction
  law's terms, the acceleration and a constant): what the torques say once the tensions are
  known;
* the same with the tension a period late (the pairing in time);
* torques made of the simulated tensions and the exact law, through the fit's statics and
  projection: what taking the tensions out costs alone.

    .venv/bin/python tools/friction_diagnosis.py [--robot rowc] [--seed 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from cdprctl.calibration import friction_procedure as fp  # noqa: E402
from cdprctl.core.numerics import friction_regressors  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402
from sim_backend.network import LockStep  # noqa: E402
from sim_backend.plant import CdprPlant  # noqa: E402
from sim_backend.plant_errors import PlantErrors  # noqa: E402


def record(robot: str, seed: int) -> dict:
    """One calibration with the fit's inputs and the simulated robot's state at every read."""
    model = load_robot(ROOT / "config" / f"{robot}.toml")
    truth = PlantErrors(seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    plant = CdprPlant(truth)
    plant.set_pose(model.home.position, model.home.rotation, None)
    got: dict = {"states": {}}
    fit, motion = fp.fit_winches, fp.motion_of

    def fit_spy(*a: object) -> object:
        got["fit"] = a
        return fit(*a)

    def motion_spy(theta: np.ndarray, t: np.ndarray, period: float) -> object:
        got["t"] = t.copy()
        return motion(theta, t, period)

    fp.fit_winches, fp.motion_of = fit_spy, motion_spy  # type: ignore[assignment]
    try:
        with LockStep(model, plant=plant) as ls:
            ls.driver.configure()
            clock = ls.driver.clock

            def spy() -> float:
                p = ls.plant
                got["states"][ls.net.time] = np.r_[p.theta, p.theta_dot, p.tension, p.servo.applied]
                return clock()

            ls.driver.clock = spy  # type: ignore[method-assign]
            start = np.r_[model.home.position, 0.0, 0.0, 0.0]
            cal = fp.friction_calibrate(model, ls.driver, np.zeros(model.n_cables), start,
                                        log=lambda s: None)  # fmt: skip
            got["period"] = ls.period
    finally:
        fp.fit_winches, fp.motion_of = fit, motion
    got["cal"], got["winches"] = cal, [c.winch for c in truth.cables]
    return got


def worst(terms: np.ndarray, winches: list) -> str:
    """'viscous / Coulomb' worst error (%) of ``terms`` (m, 2) against the simulated robot's."""
    v = [abs(x / w.viscous_friction - 1) for x, w in zip(terms[:, 0], winches, strict=True)]
    c = [abs(x / w.coulomb_friction - 1) for x, w in zip(terms[:, 1], winches, strict=True)]
    return f"{100 * max(v):.1f} / {100 * max(c):.1f} %"


def per_winch(y: np.ndarray, w: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """(m, 2): viscous and Coulomb of each column of ``y`` (N·m) by least squares on the law's
    terms at ``w``, the acceleration and a constant."""
    out = []
    for i in range(y.shape[1]):
        X = np.c_[friction_regressors(w[:, i]), acc[:, i], np.ones(len(y))]
        out.append(np.linalg.lstsq(X, y[:, i], rcond=None)[0][:2])
    return np.array(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--robot", default="rowc")
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    got = record(args.robot, args.seed)
    s, line, Q, w, acc, tau, noise, wrap = got["fit"]
    winches, m = got["winches"], w.shape[1]
    times = np.array(sorted(got["states"]))
    rows = np.array([got["states"][x] for x in times])
    at = np.searchsorted(times, got["t"]) - 1  # the read's values are a period old
    theta_dot, tension = rows[at, m : 2 * m], rows[at, 2 * m : 3 * m]
    late = rows[np.minimum(at + 1, len(rows) - 1), 2 * m : 3 * m]
    r = np.array([x.drum_radius / x.gear_ratio for x in winches])
    law = np.array([[x.viscous_friction, x.coulomb_friction, x.stribeck_friction]
                    for x in winches])  # fmt: skip
    exact = np.einsum("kia,ia->ki", friction_regressors(theta_dot), law)
    print(f"{args.robot}, seed {args.seed}: worst winch, viscous / Coulomb")
    shipped = np.array([[f.viscous, f.coulomb] for f in got["cal"].fits])
    print(f"  the fit as shipped: {worst(shipped, winches)}")
    known = per_winch(tau - r * tension, w, acc)
    print(f"  torques minus r t, winch by winch: {worst(known, winches)}")
    print(f"  ... the tension a period late: {worst(per_winch(tau - r * late, w, acc), winches)}")
    made = fp.fit_winches(s, line, Q, theta_dot, acc, r * tension + exact, noise, wrap)
    terms = np.array([[f.viscous, f.coulomb] for f in made])
    print(f"  r t + the exact law through the statics and the projection: {worst(terms, winches)}")


if __name__ == "__main__":
    sys.exit(main())
