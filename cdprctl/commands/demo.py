"""``cdprctl demo``: the offline TDA tools on the papers' robots (``make run`` runs the daemon
on the simulated robot)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

from cdprctl.commands import tda as tda_cmd
from cdprctl.commands.check_config import summary
from cdprctl.model import load_robot

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def cli_main(argv: Sequence[str]) -> int:
    """``cdprctl tda ARGS``, without going back up through the command line's module."""
    parser = argparse.ArgumentParser(prog="cdprctl")
    tda_cmd.add_parser(parser.add_subparsers())
    args = parser.parse_args(list(argv))
    return int(args.func(args))


def run(config_dir: Path = CONFIG_DIR, out_dir: Path = Path("out")) -> int:
    out_dir.mkdir(parents=True, exist_ok=True)
    seed = load_robot(config_dir / "seed000.toml")
    print(summary(seed))
    print("\n== Sensors 2019 §3: cable 8 held at 100 J, minimum total energy")
    code = cli_main(
        ["tda", "--config", str(config_dir / "seed000.toml"),
         *["--pose", "7,4,1.5,0.5235987755982988,0,0", "--wrench", "200,0,0,-0.5,0,0"],
         *["--method", "energy", "--impose", "8:energy=100", "--plot"], str(out_dir / "energy.png")]
    )
    print("\n== ARK 2020: window-cleaning robot at X0, 50 N water-jet force, SOTDA ν = 0.9")
    code |= cli_main(
        [
            "tda",
            "--config",
            str(config_dir / "rowc.toml"),
            "--pose",
            "1.5,0.35,0.59,0,0,0",
            "--wrench",
            "0,50,0,0,0,0",
            "--method",
            "sotda",
            "--nu",
            "0.9",
            "--plot",
            str(out_dir / "sotda_polygon.png"),
        ]
    )
    return code
