"""Issue 9's evidence, lock-step (deterministic): the §4.1 tension planner, the §4.2 gripper
sweeps open and closed, and grasp sensing over object sizes and stiffnesses
(Sensors 2019, 19, 3403). Prints the tables of docs/gripper.md, writes PNGs to out/gripper/.

    .venv/bin/python tools/gripper_figures.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cdprctl.experiments import gripper_experiments as ge
from cdprctl.geometry.gripper_mechanics import GripperSet, gripper_travel
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "gripper"
SIZES = (0.06, 0.08, 0.10)  # m, L21
STIFFNESSES = (math.inf, 3000.0, 1000.0)  # N/m, the object's own (K_B = 1000 N/m in series)


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(parents=True, exist_ok=True)
    planner(load_robot(ROOT / "config" / "seed000.toml"), plt)
    travel_and_sensing(load_robot(ROOT / "config" / "seed000_grippers.toml"), plt)
    print(f"\nfigures: {OUT}")


def planner(seed, plt) -> None:
    """§4.1: the energy TDA's tension planner on seed000 (cable 1's tension, cable 8's
    spring), printed and drawn (planner.png)."""
    pl = ge.tension_planner(seed, sweep=20.0)
    print("## §4.1 tension planner (seed000, 20 s sweep)")
    print(f"cable 1 energy range: ({pl['u_range'][0]:.2f}, {pl['u_range'][1]:.2f}) J")
    print(
        f"cable 1 plant tension: start {pl['t_plant'][0]:.1f} N, min {pl['t_plant'].min():.1f} N, "
        f"end {pl['t_plant'][-1]:.1f} N (desired {pl['t_desired'][-1]:.1f} N)"
    )
    print(f"cable 8 spring: {pl['held_def'].min():.4f}-{pl['held_def'].max():.4f} m")
    print(f"platform: {pl['pos_err'].max() * 1e3:.2f} mm, {pl['ang_err'].max() * 1e3:.2f} mrad")
    fig, ax = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    ax[0].plot(pl["t"], pl["t_desired"], label="imposed (energy TDA)")
    ax[0].plot(pl["t"], pl["t_plant"], label="plant")
    ax[0].axhline(182.4, ls=":", c="k", label="paper's ADAMS end, 182.4 N")
    ax[0].set_ylabel("cable 1 tension (N)")
    ax[0].legend()
    ax[1].plot(pl["t"], pl["held_def"] * 1e3)
    ax[1].axhline(447, ls=":", c="k")
    ax[1].set_ylabel("cable 8 spring (mm)")
    ax[1].set_xlabel("t (s)")
    fig.suptitle("Sensors 2019 §4.1: tension planner (Fig. 19-20), our loop and plant")
    fig.savefig(OUT / "planner.png", dpi=110)


def travel_and_sensing(grip, plt) -> None:
    """§4.2: gripper 1's travel against the actuator energy, open (eq. 37) and closed on a
    rigid object (eq. 41), and the grasp sensing's table over object sizes and stiffnesses
    (travel_energy.png, sensing.png)."""
    gs = GripperSet(grip)
    fig, ax = plt.subplots(figsize=(7, 5))
    open_run = ge.gripper_sweep(grip, 0, hold={1: 0.447})
    p = gs.params(0, math.inf)
    e = open_run["energy"]
    print("\n## §4.2 gripper 1, open (gripper 8 held at 0.447 m)")
    print(f"range here: {open_run['range'][0] * 1e3:.1f}-{open_run['range'][1] * 1e3:.1f} mm")
    dev = np.abs(open_run["deformation"] - [gripper_travel(p, u) for u in e]).max()
    print(f"max |δ − eq. (37)(U)|: {dev * 1e3:.2f} mm")
    ax.plot(e, open_run["deformation"] * 1e3, label="open: plant δ")
    ax.plot(e, [gripper_travel(p, u) * 1e3 for u in e], "k:", label="eq. (37)")
    print("\n## grasp sensing (gripper 1 closing at 20 mm/s onto the object, gripper 8 held)")
    print("| L21 (mm) | object (N/m) | detected after (mm) | force (N) | estimate error (N) |")
    print("| --- | --- | --- | --- | --- |")
    for L21 in SIZES:
        for k in STIFFNESSES:
            run = ge.gripper_sweep(
                grip, 0, object_travel=L21, object_stiffness=k, travel_to=L21 + 0.06
            )
            d = ge.detection(run)
            ks = "rigid" if math.isinf(k) else f"{k:.0f}"
            print(
                f"| {L21 * 1e3:.0f} | {ks} | {d['detected_after'] * 1e3:.1f} | "
                f"{d['force_true']:.1f} | {d['force_error']:+.2f} |"
            )
            if L21 == 0.10 and math.isinf(k):
                pc = gs.params(0, L21)
                ec = run["energy"]
                dc = run["deformation"]
                u40 = ec - pc.f_parallel * np.maximum(dc - L21, 0.0)
                dev41 = np.abs(dc - [gripper_travel(pc, u) for u in u40]).max()
                dev_paper = np.abs(dc - [gripper_travel(pc, u) for u in ec]).max()
                closed = (dev41, dev_paper)
                ax.plot(ec, dc * 1e3, label="closed on a rigid object at 100 mm: plant δ")
                ax.plot(ec, [gripper_travel(pc, u) * 1e3 for u in ec], "r:", label="eq. (41)")
                fig2, ax2 = plt.subplots(figsize=(7, 4))
                ax2.plot(run["t"], run["contact"], label="plant contact force")
                ax2.plot(run["t"], run["force_est"], label="estimated from the drives")
                ax2.set_xlabel("t (s)")
                ax2.set_ylabel("N")
                ax2.legend()
                fig2.suptitle("Grasp sensing: gripper 1 closing on a rigid object at 100 mm")
                fig2.savefig(OUT / "sensing.png", dpi=110)
    print(
        f"\nclosed at 100 mm: max |δ − eq. (41)(U − F∥(δ − L21))| {closed[0] * 1e3:.2f} mm; "
        f"eq. (41) on U as measured: {closed[1] * 1e3:.1f} mm"
    )
    ax.set_xlabel("actuator energy U = U0 + ∫τ dδ (J)")
    ax.set_ylabel("travel δ (mm)")
    ax.legend()
    fig.suptitle("Sensors 2019 §4.2 (Fig. 22-24): gripper 1 against actuator energy")
    fig.savefig(OUT / "travel_energy.png", dpi=110)


if __name__ == "__main__":
    main()
