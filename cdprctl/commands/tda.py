"""``cdprctl tda``: one tension distribution, offline, with optional JSON and plot."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

from cdprctl.commands.common import command_parser, load_or_report, pose_or_why
from cdprctl.core.rotation import rpy_to_matrix
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics, kinematics_ok
from cdprctl.model import RobotModel
from cdprctl.tda import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TDAOutput,
    TensionDistributor,
)

DESCRIPTION = """\
Compute the cable tensions of one static pose with a tension distribution algorithm.

--wrench is the EXTERNAL wrench applied to the platform (N, N·m), at its reference point, in
the base frame; the platform's own weight (mass, COM and gravity of the config) is added to
it. The cables must balance the sum: W t + w_ext + w_weight = 0.
Cables are named as in the config file (or by 1-based index)."""

EPILOG = """\
examples (Sensors 2019 §3; the printed moment -500 is N·mm, i.e. -0.5 N·m):
  cdprctl tda --config config/seed000.toml --pose 7,4,1.5,0.5235987755982988,0,0 \\
      --wrench 200,0,0,-0.5,0,0 --method energy --impose 8:energy=100 --json
  cdprctl tda --config config/rowc.toml --pose 1.5,0.35,0.59,0,0,0 --wrench 0,50,0,0,0,0 \\
      --method sotda --nu 0.9 --plot polygon.png"""


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "tda", "compute cable tensions for one pose and wrench (offline)",
                       run, description=DESCRIPTION, epilog=EPILOG)  # fmt: skip
    p.add_argument(
        "--pose", metavar="X,Y,Z,ROLL,PITCH,YAW",
        help="m and rad (or an angle ending in deg), base frame (default: the home pose)",
    )  # fmt: skip
    p.add_argument(
        "--wrench",
        default="0,0,0,0,0,0",
        metavar="FX,FY,FZ,MX,MY,MZ",
        help="external wrench fx,fy,fz,mx,my,mz in N and N·m on the platform at its reference "
        "point, base frame; the platform's weight is added (default: 0)",
    )
    p.add_argument(
        "--method",
        default="barycenter",
        choices=[m.value for m in TDAMethod],
        help="tension distribution method (default: barycenter)",
    )
    p.add_argument(
        "--nu",
        type=float,
        default=1.0,
        help="sotda: 0 = barycenter .. 1 = stiffness-oriented corner (default 1)",
    )
    p.add_argument(
        "--direction",
        default="0,1,0",
        help="sotda: dx,dy,dz, direction of the displacement to minimise (default y)",
    )
    p.add_argument(
        "--variant",
        default="vertices",
        choices=["vertices", "grid"],
        help="sotda: real-time vertex search or full grid search",
    )
    p.add_argument(
        "--impose",
        action="append",
        default=[],
        metavar="CABLE:QUANTITY=VALUE",
        help="energy: impose energy (J), tension (N) or deformation (m) on a cable, e.g. "
        "8:energy=100; repeat for up to r cables",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", metavar="FILE.png", help="draw the feasible polygon / energy line")


class UsageError(Exception):
    pass


def parse_floats(text: str, n: int, name: str, unit: str) -> np.ndarray:
    parts = text.split(",")
    if len(parts) != n:
        raise UsageError(f"--{name} = {text!r}: needs {n} comma-separated numbers ({unit})")
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise UsageError(f"--{name} = {text!r}: not numbers ({unit})") from None
    if not np.all(np.isfinite(values)):
        raise UsageError(f"--{name} = {text!r}: must be finite ({unit})")
    return values


def parse_imposition(text: str, model: RobotModel) -> Imposition:
    try:
        cable, rest = text.split(":", 1)
        quantity, value = rest.split("=", 1)
    except ValueError:
        raise UsageError(
            f"--impose {text!r}: expected CABLE:QUANTITY=VALUE, e.g. 8:energy=100"
        ) from None
    names = [c.name for c in model.cables]
    if cable in names:
        index = names.index(cable)
    elif cable.isdigit() and 1 <= int(cable) <= model.n_cables:
        index = int(cable) - 1
    else:
        raise UsageError(f"--impose {text!r}: no cable {cable!r} (cables: {', '.join(names)})")
    try:
        q = ImposedQuantity(quantity)
    except ValueError:
        raise UsageError(
            f"--impose {text!r}: quantity must be energy (J), tension (N) or deformation (m)"
        ) from None
    try:
        v = float(value)
    except ValueError:
        raise UsageError(f"--impose {text!r}: value {value!r} is not a number") from None
    return Imposition(index, q, v)


def run(args: argparse.Namespace) -> int:
    model = load_or_report(args.config)
    if model is None:
        return 1
    try:
        result, ctx = compute(model, args)
    except UsageError as exc:
        print(f"cdprctl tda: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_text(model, result))
    if args.plot:
        from cdprctl.tda.plots.tda_plot import plot_tda

        plot_tda(args.plot, model, ctx)
        if not args.json:
            print(f"plot written to {args.plot}")
    return 0 if result["status"] == "OK" else 3


def compute(model: RobotModel, args: argparse.Namespace) -> tuple[dict[str, Any], dict[str, Any]]:
    if args.pose:
        pose = pose_or_why(args.pose)
        if isinstance(pose, str):
            raise UsageError(f"--pose = {args.pose!r}: {pose}")
        position, R = pose[:3], rpy_to_matrix(*pose[3:])
    else:
        position, R = model.home.position, model.home.rotation
    w_ext = parse_floats(args.wrench, 6, "wrench", "N, N, N, N·m, N·m, N·m")
    direction = parse_floats(args.direction, 3, "direction", "unit vector")
    impositions = tuple(parse_imposition(t, model) for t in args.impose)
    # SOTDA's δw_e: the external wrench itself (Picard et al. 2020 §4: "δw_e amounts to the
    # total external wrench due to water pressure"), or 1 N along the direction without one.
    along = abs(float(w_ext[:3] @ direction)) > 1e-12
    options = TDAOptions(
        method=TDAMethod(args.method),
        nu=args.nu,
        direction=(float(direction[0]), float(direction[1]), float(direction[2])),
        delta_wrench=tuple(float(x) for x in w_ext) if along else None,
        sotda_variant=args.variant,
        impositions=impositions,
    )
    errors = options.validate(model)
    if errors:
        raise UsageError("; ".join(errors))
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, position, R)
    if not kinematics_ok(kin):
        raise UsageError("--pose: a cable has zero length there")
    w_total = w_ext + model.gravity_wrench(R)
    wrench = -w_total
    k = model.cable_stiffness(kin.length)
    td = TensionDistributor(model, options)
    out = td.solve(kin.W, wrench, k=k, kin=kin)
    result = to_json(model, out, options, w_total, k)
    ctx = {
        "out": out,
        "options": options,
        "kin": kin,
        "k": k,
        "wrench": wrench,
        "N": td.ns.N.copy(),
        "t0": td.ns.t0.copy(),
        "direction": direction / np.linalg.norm(direction),
    }
    return result, ctx


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def to_json(
    model: RobotModel, out: TDAOutput, options: TDAOptions, w_total: np.ndarray, k: np.ndarray
) -> dict[str, Any]:
    names = [c.name for c in model.cables]
    imposed = {imp.cable for imp in options.impositions}
    result: dict[str, Any] = {
        "robot": model.name,
        "method": options.method.value,
        "status": out.status.name,
        "message": out.message,
        "cables": names,
        "tensions": [round(float(t), 9) for t in out.tensions],
        "tension_min": model.tension_min.tolist(),
        "tension_max": model.tension_max.tolist(),
        "wrench_total_external": w_total.tolist(),
        "wrench_residual": out.residual,
        "energy_total": _num(out.energy_total),
        "energy_per_cable": [_num(e) for e in out.energies],
        "stiffness": k.tolist(),
        "lambda": out.lam.tolist(),
    }
    if len(out.polygon):
        result["polygon"] = out.polygon.tolist()
        result["polygon_area"] = out.area
        result["barycenter"] = list(out.barycenter)
    if options.method is TDAMethod.SOTDA:
        result["sotda_displacement"] = _num(out.sotda_displacement)
        result["nu"] = options.nu
    if options.method is TDAMethod.ENERGY:
        result["energy_range"] = {
            names[i]: [_num(out.energy_range[i, 0]), _num(out.energy_range[i, 1])]
            for i in range(model.n_cables)
            if i not in imposed
        }
        result["impositions"] = [
            {"cable": names[i.cable], "quantity": i.quantity.value, "value": i.value}
            for i in options.impositions
        ]
        if np.all(np.isfinite(out.segment_ends)):
            result["segment_ends"] = out.segment_ends.tolist()
        result["free_directions"] = out.free_directions.T.tolist()
    if out.max_violation > 0:
        result["max_violation"] = out.max_violation
    return result


def format_text(model: RobotModel, r: dict[str, Any]) -> str:
    lines = [
        f"{r['robot']}: method {r['method']}, status {r['status']}"
        + (f" ({r['message']})" if r["message"] else ""),
        f"wrench residual ‖W t − w‖/‖w‖ = {r['wrench_residual']:.2e}",
    ]
    if r.get("energy_total") is not None:
        lines.append(f"total elastic energy {r['energy_total']:.3f} J")
    if "sotda_displacement" in r and r["sotda_displacement"] is not None:
        lines.append(
            f"displacement along the direction under δw: {r['sotda_displacement'] * 1e3:.4f} mm"
        )
    ranges = r.get("energy_range", {})
    lines.append("")
    lines.append(
        f"{'cable':>6} {'tension N':>10} {'min N':>8} {'max N':>8} {'energy J':>10}"
        + (f" {'energy range J':>20}" if ranges else "")
    )
    for i, name in enumerate(r["cables"]):
        e = r["energy_per_cable"][i]
        row = (
            f"{name:>6} {r['tensions'][i]:10.3f} {r['tension_min'][i]:8.1f} "
            f"{r['tension_max'][i]:8.1f} {(e if e is not None else math.nan):10.3f}"
        )
        if ranges:
            rg = ranges.get(name)
            row += " " + (
                f"({rg[0]:8.3f}, {rg[1]:8.3f})" if rg and rg[0] is not None else f"{'imposed':>20}"
            )
        lines.append(row)
    return "\n".join(lines)
