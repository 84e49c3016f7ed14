"""``cdprctl sim``: the simulated robot in real time, on any python-can bus."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report


def add_bus_arguments(p: argparse.ArgumentParser) -> None:
    """The bus overrides shared by ``cdprctl sim`` and ``cdprctl run``, so the two meet."""
    p.add_argument(
        "--can-interface",
        help="python-can interface replacing the config's (socketcan, virtual, udp_multicast, ...)",
    )
    p.add_argument(
        "--can-channel",
        help="channel replacing the config's (can0, vcan0, a "
        "udp_multicast group such as 239.74.163.2, ...)",
    )
    p.add_argument(
        "--can-option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="extra python-can argument, e.g. port=43113 (repeatable)",
    )


def bus_overrides(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if args.can_interface:
        out["interface"] = args.can_interface
    if args.can_channel:
        out["channel"] = args.can_channel
    options: dict[str, Any] = {}
    for item in args.can_option:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise SystemExit(f"--can-option {item!r}: expected KEY=VALUE")
        options[key] = int(value) if value.lstrip("-").isdigit() else value
    if options:
        out["options"] = options
    return out


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "sim", "run the simulated robot in real time on a CAN bus", run)
    add_bus_arguments(p)
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument(
        "--status",
        type=float,
        default=1.0,
        help="print a status line every this many seconds (0: never)",
    )
    p.add_argument(
        "--faults",
        type=float,
        default=0.0,
        metavar="RATE",
        help="random transient faults, RATE a second on average: frame-loss bursts, drive "
        "faults, silent drives, lateral pushes (sim_backend/faults.py)",
    )
    p.add_argument("--fault-seed", type=int, default=1, help="seed of --faults")


def run(args: argparse.Namespace) -> int:
    """The simulated robot of sim_backend: drive emulators (the protocol of the config's
    [drives]) on the config's buses, or on the bus given here, with the winch, cable and
    platform physics, in real time. The platform starts at rest at the home pose, cables
    pre-tensioned to the equilibrium. Stop with Ctrl-C or SIGTERM."""
    from drivers.errors import DriverError
    from sim_backend.realtime import run_realtime

    model = load_or_report(args.config)
    if model is None:
        return 1
    overrides = bus_overrides(args)
    print(
        f"cdprctl sim: {model.name}, {model.n_cables} {model.drives.driver} drives on "
        f"{overrides.get('interface') or model.drives.buses[0].interface} "
        f"{overrides.get('channel') or model.drives.buses[0].channel}",
        flush=True,
    )
    faults = None
    if args.faults > 0:
        from sim_backend.faults import FaultInjector

        faults = FaultInjector.random_faults(
            args.duration or 3600.0,
            model.n_cables,
            args.faults,
            args.fault_seed,
            kinds=("frame_loss", "drive_fault", "silent_drive", "external_wrench"),
        )
        print(f"cdprctl sim: {len(faults.events)} faults scheduled (seed {args.fault_seed})")
    try:
        net = run_realtime(model, overrides, args.duration, faults=faults, status_every=args.status)
    except DriverError as exc:
        print(f"cdprctl sim: error: {exc}", file=sys.stderr)
        return 1
    net.close()
    print("cdprctl sim: stopped", flush=True)
    return 0
