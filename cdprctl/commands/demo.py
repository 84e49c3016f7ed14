"""``cdprctl demo``: the offline TDA tools on the papers' robots (``make run`` runs the daemon
on the simulated robot)."""

from __future__ import annotations

import argparse
import inspect
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cdprctl.commands import tda as tda_cmd
from cdprctl.commands.check_config import summary
from cdprctl.commands.common import command_parser
from cdprctl.robot_file import load_robot

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"

EXAMPLES = """example:
  cdprctl demo            # prints both tables, writes out/energy.png and out/sotda_polygon.png
"""


def add_parser(sub: Any) -> None:
    command_parser(
        sub, "demo", "the offline TDA tools on the papers' robots (plots into out/)", command,
        config=False, description=inspect.cleandoc(command.__doc__ or ""), epilog=EXAMPLES,
    )  # fmt: skip


def command(args: argparse.Namespace) -> int:
    """Two tension distributions from the papers, offline (no robot, no daemon; a few seconds):
    the Sensors 2019 suspended robot (config/seed000.toml) with cable 8 held at 100 J and the
    least total energy, and the ARK 2020 window-cleaning robot (config/rowc.toml) under a 50 N
    water jet by SOTDA, ν = 0.9. Prints each robot's summary and the tensions; writes the
    plots to out/ under the current directory. The daemon on the simulated robot is make run
    (cdprctl run --config config/rowc.toml --sim)."""
    return run()


def cli_main(argv: Sequence[str]) -> int:
    """``cdprctl tda ARGS``, without going back up through the command line's module."""
    parser = argparse.ArgumentParser(prog="cdprctl")
    tda_cmd.add_parser(parser.add_subparsers())
    args = parser.parse_args(list(argv))
    return int(args.func(args))


def run(config_dir: Path = CONFIG_DIR, out_dir: Path = Path("out")) -> int:
    out_dir.mkdir(parents=True, exist_ok=True)
    seed = load_robot(config_dir / "seed000.toml")
    print(summary(seed)[0])
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
