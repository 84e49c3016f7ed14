"""The closed loop's frequency response, reference → the simulated platform's true pose, per
axis, in lock-step: a sine of small amplitude replaces the trajectory's reference (faded in
over 1 s, its velocity and acceleration fed forward as ruckig's would be), and the response's
gain and phase at that frequency are read off by a discrete Fourier coefficient.

    .venv/bin/python tools/frequency_response.py [--config config/rowc.toml] [--freqs 0.5,1.5,3]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from cdprctl.core.rotation import log_so3  # noqa: E402
from cdprctl.experiments.closed_loop import ClosedLoop  # noqa: E402
from cdprctl.model import RobotModel  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402

AMPLITUDE = (0.002, 0.002, 0.002, 0.01, 0.01, 0.01)  # m, rad
AXES = ("x", "y", "z", "roll", "pitch", "yaw")


def response(model: RobotModel, axis: int, f: float) -> tuple[float, float, str]:
    """(gain, phase in degrees, final state) of ``axis`` at ``f`` Hz."""
    with ClosedLoop(model) as cl:
        c, tr = cl.controller, cl.controller.trajectory
        cl.startup()
        cl.command("enable")
        cl.run(0.5, record=False)
        x0, w, t0, a = tr.position.copy(), 2 * math.pi * f, cl.net.time, AMPLITUDE[axis]

        def sine(dt: float = 0.0) -> None:
            t = cl.net.time - t0
            s = min(1.0, t)
            tr.position[:], tr.velocity[:], tr.acceleration[:] = x0, 0.0, 0.0
            tr.position[axis] += s * a * math.sin(w * t)
            tr.velocity[axis] = s * a * w * math.cos(w * t)
            tr.acceleration[axis] = -s * a * w * w * math.sin(w * t)

        tr.update = sine  # type: ignore[method-assign]
        ts: list[float] = []
        ys: list[float] = []
        home_R = model.home.rotation

        def sample(cl: ClosedLoop) -> None:
            t = cl.net.time - t0
            if t > 1.0 + 1.0 / f:
                ts.append(t)
                p = cl.plant
                ys.append(p.position[axis] if axis < 3 else log_so3(p.R @ home_R.T)[axis - 3])

        cycles = max(3, round(4 * f))
        cl.run(1.0 + (cycles + 1) / f, each=sample, record=False)
        t_arr, y = np.array(ts), np.array(ys) - np.mean(ys)
        re, im = 2 * np.mean(y * np.sin(w * t_arr)), 2 * np.mean(y * np.cos(w * t_arr))
        return math.hypot(re, im) / a, math.degrees(math.atan2(im, re)), c.data.state.value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "config" / "rowc.toml"))
    ap.add_argument("--freqs", default="0.5,1.5,3")
    args = ap.parse_args()
    model = load_robot(args.config)
    freqs = [float(x) for x in args.freqs.split(",")]
    print(f"{model.name}, drives {model.drives.mode}, {model.control.rate:g} Hz: gain ∠ phase")
    print("| axis | " + " | ".join(f"{f:g} Hz" for f in freqs) + " |")
    print("|---|" + "---|" * len(freqs))
    for axis, name in enumerate(AXES):
        cells = []
        for f in freqs:
            g, ph, state = response(model, axis, f)
            cells.append(f"{g:.2f} ∠ {ph:.0f}°" + ("" if state == "enabled" else f" ({state})"))
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
