"""``cdprctl calibrate friction`` across processes in real time against the same in lock-step
(issue 68): a simulated robot whose winches' friction is off the file (``--plant-errors``'
draw for the seed, written into an as-built robot file per cable), run as ``cdprctl sim
--as-built`` over udp_multicast; the encoders' zeros (``calibrate known-pose``), the friction,
then ``cdprctl run`` on the same state directory, whose start-up must say the friction it
applies. Prints each winch's viscous and Coulomb terms across processes beside the lock-step
ones (``experiments/friction_on_plant.py``, the same plant) and their difference in %.

    .venv/bin/python tools/friction_across.py [--robot rowc] [--seed 1]
"""

from __future__ import annotations

import argparse
import json
import random
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from _tables import ROOT

from cdprctl.calibration.friction_record import stored_terms
from cdprctl.experiments.friction_on_plant import friction_on_plant
from cdprctl.model import RobotModel
from cdprctl.robot_file import load_robot
from sim_backend.plant_errors import PlantErrors

CLI = [sys.executable, "-m", "cdprctl.cli"]


def as_built_text(config: Path, terms: list[tuple[float, float, float]]) -> str:
    """The robot file at ``config`` with a ``[cables.winch]`` table closing each cable's block:
    its (viscous, Coulomb, Stribeck) friction."""
    out, k, inside = [], 0, False
    for line in [*config.read_text().splitlines(), "[end]"]:
        header = line.strip().startswith("[")
        if header and inside:
            v, c, s = terms[k]
            out += ["[cables.winch]", f"viscous_friction = {float(v)!r}",
                    f"coulomb_friction = {float(c)!r}",
                    f"stribeck_friction = {float(s)!r}", ""]  # fmt: skip
            k, inside = k + 1, False
        inside = inside or line.strip() == "[[cables]]"
        out.append(line)
    if k != len(terms):  # a file whose cables come from its base: not handled
        raise SystemExit(f"friction_across: {config} lists {k} cables of {len(terms)}")
    return "\n".join(out[:-1]) + "\n"


def cables_file(config: Path) -> Path:
    """The file of ``config``'s chain of ``base`` files that lists the cables."""
    import tomllib

    path = config
    while "[[cables]]" not in path.read_text():
        base = tomllib.loads(path.read_text()).get("base")
        if base is None:
            raise SystemExit(f"friction_across: no [[cables]] in {config} or its base files")
        path = (path.parent / base).resolve()
    return path


def as_built_of(model: RobotModel, config: Path, terms: list) -> str:
    """The as-built robot file: the cables' file of ``config`` with each winch's ``terms``,
    named as ``model`` (``cdprctl sim --as-built`` takes the same robot only: a file whose
    base lists the cables, such as rowc_load_cells.toml, is its base as built)."""
    text = as_built_text(cables_file(config), terms)
    lines = text.splitlines()
    k = next(i for i, x in enumerate(lines) if x.startswith("name ="))
    lines[k] = f"name = {json.dumps(model.name)}"
    return "\n".join(lines) + "\n"


def across(config: Path, truth: Path, state: Path) -> dict:
    """The friction calibration's JSON over udp_multicast (and the run's friction line)."""
    bus = ["--can-interface", "udp_multicast", "--can-channel", "239.74.163.7", "--can-option",
           f"port={random.randint(20000, 60000)}"]  # fmt: skip
    with_bus = ["--config", str(config), *bus, "--state-dir", str(state)]
    sim = subprocess.Popen([*CLI, "sim", "--config", str(config), "--as-built", str(truth),
                            "--status", "0", *bus], stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert sim.stdout is not None
        while "ready" not in sim.stdout.readline():
            if sim.poll() is not None:
                sys.exit("friction_across: cdprctl sim did not start")
        # read on: a full pipe would hold the simulated robot in its next line
        threading.Thread(target=sim.stdout.read, daemon=True).start()
        subprocess.run([*CLI, "calibrate", *with_bus, "known-pose"], check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        got = subprocess.run([*CLI, "calibrate", *with_bus, "friction", "--json"],
                             capture_output=True, text=True)  # fmt: skip
        if got.returncode != 0:  # a refused fit says why in its JSON (stdout)
            sys.exit(f"friction_across: calibrate friction failed:\n{got.stderr[-2000:]}"
                     f"{got.stdout[-3000:]}")
        run = subprocess.run([*CLI, "run", *with_bus, "--duration", "3", "--status", "0"],
                             capture_output=True, text=True)  # fmt: skip
        print(next((x for x in run.stdout.splitlines() if "friction:" in x), "no friction line"))
        return json.loads(got.stdout)
    finally:
        sim.terminate()
        sim.wait(timeout=10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robot", default="rowc",
                    help="a file of config/ (rowc, cogiro, rowc_load_cells, ...)")  # fmt: skip
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    config = ROOT / "config" / f"{args.robot}.toml"
    model = load_robot(config)
    truth = PlantErrors(args.seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    terms = [(c.winch.viscous_friction, c.winch.coulomb_friction, c.winch.stribeck_friction)
             for c in truth.cables]  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        built = Path(tmp) / "as_built.toml"
        built.write_text(as_built_of(model, config, terms))
        lock = friction_on_plant(model, load_robot(built))
        got = across(config, built, Path(tmp) / "state")
    print("winch | across: viscous, Coulomb | lock-step: viscous, Coulomb | difference %")
    worst = 0.0
    for w, f in zip(got["winches"], lock.fits, strict=True):
        v, c, _ = stored_terms(f)  # as the JSON gives them (a term below zero kept as 0)
        dv, dc = 100 * (w["viscous"] / v - 1), 100 * (w["coulomb"] / c - 1)
        worst = max(worst, abs(dv), abs(dc))
        print(f"{w['cable']} | {w['viscous']:.4g}, {w['coulomb']:.4g} | {v:.4g}, {c:.4g} | "
              f"{dv:+.1f}, {dc:+.1f}")  # fmt: skip
    print(f"accepted across processes: {got['accepted']}; the largest difference {worst:.1f} %")


if __name__ == "__main__":
    main()
