"""The geometric calibration on a robot whose winches' friction is not the file's (issue 68): is
its equilibrium check refused, or is the geometry biased, and does an identified friction put
it right? In lock-step: the robot as built (seed 2: non-reference anchors ±20 mm, drums ±1 %)
with each winch's viscous and Coulomb friction 30-50 % off the file (seeded, a Stribeck term
half the Coulomb one); `cdprctl calibrate friction` on it first (``--travel``: the as-built
geometry brings a tension near its limit sooner than the file's), then the geometric
calibration (``--poses``, the start 4 cm from home) with the controller given the file's friction,
the friction identified, and the plant's own. Prints a line per run: accepted, the equilibrium
residuals over their noise, the worst anchor's error (mm) against the plant's.

    .venv/bin/python tools/friction_geometry.py [--robot rowc] [--seeds 1,2,3] [--travel 0.25]
        [--poses 12]
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np
from _tables import ROOT  # test_homing on the path
from test_homing import robot_at

from cdprctl.calibration.friction_procedure import FrictionOptions
from cdprctl.calibration.friction_record import stored_terms
from cdprctl.calibration.geometry_plan import GeometryOptions
from cdprctl.calibration.geometry_procedure import geometry_calibrate
from cdprctl.calibration.session import CalibrationFailedError
from cdprctl.experiments.friction_on_plant import friction_on_plant
from cdprctl.model.calibration import reference_anchors
from cdprctl.model.robot import RobotModel
from cdprctl.robot_file import load_robot
from sim_backend.plant_errors import PlantErrors


def with_friction(model: RobotModel, terms: list[tuple[float, float, float]]) -> RobotModel:
    """``model`` with each winch's (viscous, Coulomb, Stribeck) friction replaced."""
    cables = [dataclasses.replace(c, winch=dataclasses.replace(
        c.winch, viscous_friction=v, coulomb_friction=cf, stribeck_friction=st))
        for c, (v, cf, st) in zip(model.cables, terms, strict=True)]  # fmt: skip
    return dataclasses.replace(model, cables=cables)


def friction_of(model: RobotModel) -> list[tuple[float, float, float]]:
    w = [c.winch for c in model.cables]
    return [(x.viscous_friction, x.coulomb_friction, x.stribeck_friction) for x in w]


def identified(model: RobotModel, truth: RobotModel, travel: float) -> list[tuple] | None:
    """Each winch's friction as ``calibrate friction`` finds it on ``truth`` (at home), the
    terms as the record keeps them; None when the fit is refused (said)."""
    cal = friction_on_plant(model, truth, FrictionOptions(travel=travel))
    pairs = zip(cal.fits, friction_of(truth), strict=True)
    worst = max(abs(f.viscous / w[0] - 1.0) for f, w in pairs)
    print(f"  friction identified: {'accepted' if cal.accepted else 'refused: ' + cal.reason}, "
          f"the worst viscous term {100 * worst:.1f} % off the plant's", flush=True)  # fmt: skip
    return [stored_terms(f) for f in cal.fits] if cal.accepted else None


def geometry_line(name: str, model: RobotModel, truth: RobotModel, start: np.ndarray,
                  poses: int) -> str:  # fmt: skip
    with robot_at(model, start, model.home.rotation, truth) as ls:
        ls.driver.configure()
        try:
            cal = geometry_calibrate(model, ls.driver, GeometryOptions.of(model, poses=poses),
                                     log=lambda s: None)  # fmt: skip
        except CalibrationFailedError as exc:
            return f"  controller with {name}: stopped: {exc}"
    r = cal.result
    err = np.max(np.linalg.norm(np.asarray(r.anchors) - np.asarray(truth.anchors), axis=1))
    return (f"  controller with {name}: accepted {cal.accepted}, equilibrium "
            f"{cal.equilibrium_over_noise:.2f}x its noise, force RMS {r.force_rms:.3f} N, worst "
            f"anchor {err * 1e3:.2f} mm off" + ("" if cal.accepted else f" ({cal.reason})"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="rowc")
    ap.add_argument("--seeds", default="1,2,3", help="the winches' friction draws")
    ap.add_argument("--travel", type=float, default=0.25, help="m: the friction run's lines")
    ap.add_argument("--poses", type=int, default=12, help="the geometric calibration's")
    args = ap.parse_args()
    model = load_robot(ROOT / "config" / f"{args.robot}.toml")
    built = PlantErrors(2, 0.02, 0.01, reference_anchors(model.calibration, model.anchors)
                        ).apply(model)[0]  # fmt: skip
    start = np.asarray(model.home.position) + np.array([0.02, 0.03, -0.02])
    print(f"{args.robot} as built (seed 2), the file's friction:", flush=True)
    print(geometry_line("the file's friction", model, built, start, args.poses), flush=True)
    for seed in (int(s) for s in args.seeds.split(",")):
        drawn = PlantErrors(seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
        truth = with_friction(built, friction_of(drawn))
        print(f"{args.robot} as built, each winch's friction 30-50 % off (seed {seed}):")
        for name, terms in (("the file's friction", friction_of(model)),
                            ("the friction identified", identified(model, truth, args.travel)),
                            ("the plant's friction", friction_of(truth))):  # fmt: skip
            if terms is not None:
                print(geometry_line(name, with_friction(model, terms), truth, start,
                                    args.poses), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
