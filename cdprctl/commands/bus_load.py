"""``cdprctl bus-load --config FILE [--rate HZ]``: the CAN load of each bus per control cycle."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report
from drivers.busload import MAX_LOAD, WARN_LOAD, bus_loads


def add_parser(sub: Any) -> None:
    limits = {"warn": f"{WARN_LOAD:.0%}", "refuse": f"{MAX_LOAD:.0%}"}
    description = (run.__doc__ or "").format(**limits)
    help = "CAN bus load per bus at a control rate"
    p = command_parser(sub, "bus-load", help, run, description=description)
    p.add_argument(
        "--rate", type=float, default=None, help="control rate in Hz (default: the config's)"
    )


def run(args: argparse.Namespace) -> int:
    """Bits per control cycle on each CAN bus (worst-case bit stuffing), the load at the
    control rate, and the verdict the daemon applies at start-up: warn above {warn}, refuse
    above {refuse}. Exit code 1 when a bus would be refused."""
    model = load_or_report(args.config)
    if model is None:
        return 1
    rate = model.control.rate if args.rate is None else args.rate
    if not (rate > 0):
        print(f"cdprctl bus-load: error: --rate = {rate} Hz must be > 0", file=sys.stderr)
        return 2
    refused = False
    print(f"{model.name}: driver {model.drives.driver}, control rate {rate:g} Hz")
    for bl in bus_loads(model.drives, rate, cells=model.sensors.load_cells):
        print(f"bus {bl.bus}: {bl.interface} {bl.channel}, {bl.bitrate} bit/s, {bl.drives} drives")
        print(f"  per cycle: {bl.frames}")
        print(f"  {bl.bits_per_cycle} bits per cycle, load {bl.load * 100:.1f} %  {bl.verdict}")
        refused |= bl.load > MAX_LOAD
    return 1 if refused else 0
