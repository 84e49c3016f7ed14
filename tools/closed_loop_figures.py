"""Closed-loop figures of issue 6 in lock-step (deterministic): point-to-point motions and a
30 N lateral force on the window-cleaning robot (rowc) and the Sensors 2019 robot (seed000).

    .venv/bin/python tools/closed_loop_figures.py

Per run: tracking error against the jerk-limited reference (RMS, max, mm), the commanded
tension range (N), the settling time (s, from the end of the reference until the platform
stays within 0.2 mm of the target) and, for the lateral force, the final deflection beside
K⁻¹ δw; SOTDA (ν = 0.9 along y) beside the barycenter.
"""

from __future__ import annotations

import numpy as np

from cdprctl.control.command_types import SetTdaCommand
from cdprctl.control.states import State
from cdprctl.core.rotation import log_so3
from cdprctl.experiments.ark2020 import deflection_reference
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.model import RobotModel
from cdprctl.robot_file import load_robot
from cdprctl.tda import TDAMethod, TDAOptions
from sim_backend.faults import FaultEvent, FaultInjector

MOVES = {
    "rowc": [[1.8, 0.35, 0.55], [1.0, 0.35, 0.45], [2.2, 0.35, 0.4], [1.5, 0.35, 0.35]],
    "seed000": [[7.1, 4.05, 1.55], [6.85, 3.9, 1.6]],
}
SECONDS = {"rowc": (4.0, 6.0), "seed000": (8.0, 12.0)}


def enabled(model: RobotModel) -> ClosedLoop:
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(0.5)
    return cl


def move(model: RobotModel, goal: list[float], seconds: float) -> str:
    with enabled(model) as cl:
        n0 = len(cl.log["t"])
        cl.command("move", pose=np.concatenate([goal, log_so3(model.home.rotation)]))
        done_at = None
        for _ in range(round(seconds / cl.period)):
            cl.run(cl.period)
            if done_at is None and cl.controller.trajectory.finished:
                done_at = len(cl.log["t"])
        a = cl.arrays()
        err = np.linalg.norm(a["p_true"][n0:] - a["p_des"][n0:], axis=1) * 1e3
        off = np.linalg.norm(a["p_true"] - np.array(goal), axis=1)
        outside = np.nonzero(off > 0.2e-3)[0]
        settle = (outside[-1] + 1 - (done_at or 0)) * cl.period if len(outside) else 0.0
        t = a["tensions"][n0:]
        return (
            f"| {model.name} | move to {goal} m | {cl.controller.data.state.value} | "
            f"{np.sqrt(np.mean(err**2)):.2f} | {err.max():.2f} | {t.min():.0f}-{t.max():.0f} | "
            f"{max(settle, 0.0):.2f} |"
        )


def lateral(model: RobotModel, tda: TDAOptions, seconds: float) -> str:
    with enabled(model) as cl:
        cl.controller.submit(SetTdaCommand(tda=tda))
        cl.run(2.0)
        y0 = cl.plant.position[1]
        n0 = len(cl.log["t"])
        FaultInjector(
            [FaultEvent(cl.net.time, "external_wrench", value=(0.0, 30.0, 0, 0, 0, 0), ramp=1.0)]
        ).attach(cl.net)
        cl.run(seconds)
        d = cl.controller.data
        a = cl.arrays()
        y = (a["p_true"][n0:, 1] - y0) * 1e3
        pred = deflection_reference(model, model.home.position, d.tensions, 30.0) * 1e3
        t = a["tensions"][n0:]
        name = tda.method.value + (f" ν={tda.nu}" if tda.method is TDAMethod.SOTDA else "")
        ok = d.state is State.ENABLED
        return (
            f"| {model.name} | {name} | {d.state.value} {'' if ok else d.fault_reason[:48]} | "
            f"{y.max():.2f} | {np.mean(y[-250:]):.2f} | {pred:.2f} | {t.min():.0f}-{t.max():.0f} |"
        )


def main() -> None:
    print("| robot | run | end state | tracking RMS mm | max mm | tensions N | settle s |")
    print("|---|---|---|---|---|---|---|")
    for name, goals in MOVES.items():
        model = load_robot(f"config/{name}.toml")
        for goal in goals:
            print(move(model, goal, SECONDS[name][0]), flush=True)
    print()
    print("| robot | TDA | end state | peak y mm | final y mm | K⁻¹δw mm | tensions N |")
    print("|---|---|---|---|---|---|---|")
    for name in MOVES:
        model = load_robot(f"config/{name}.toml")
        lat_s = SECONDS[name][1]
        for tda in (
            TDAOptions(method=TDAMethod.BARYCENTER),
            TDAOptions(method=TDAMethod.SOTDA, nu=0.9, direction=(0.0, 1.0, 0.0)),
        ):
            print(lateral(model, tda, lat_s), flush=True)


if __name__ == "__main__":
    main()
