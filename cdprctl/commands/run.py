"""``cdprctl run``: the controller daemon (see cdprctl.daemon.service)."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import signal
import sys
from pathlib import Path
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report, os_error_text
from cdprctl.commands.sim import (
    add_as_built_argument,
    add_bus_arguments,
    as_built_model,
    bus_options,
    bus_overrides,
    refuse_in_process_bus,
)


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "run", "run the controller daemon", run)
    p.add_argument("--sim", action="store_true", help="run against the simulated robot")
    p.add_argument("--no-demo", action="store_true", help="with --sim: no demo motion")
    add_as_built_argument(p)
    add_demo_arguments(p)
    p.add_argument(
        "--duration",
        type=float,
        help="stop after this many seconds (the demo plays again while a round fits)",
    )
    p.add_argument(
        "--path",
        metavar="FILE",
        help="play this path once (CSV or G-code, docs/operating.md): checked whole before "
        "the drives are enabled, then enable, path, disable; exit 0 when it finished",
    )
    p.add_argument("--units", choices=("m", "mm", "in"), default="m",
                   help="a CSV path's lengths (speeds per s) when it has no row of units "
                   "(default m); `cdprctl path check` checks a path offline")  # fmt: skip
    p.add_argument("--rate", type=float, help="loop rate in Hz, replacing [control] rate")
    p.add_argument(
        "--state-dir",
        metavar="DIR",
        help="where the calibration record is (default /var/lib/cdprctl/<robot>; "
        "docs/homing.md)",
    )
    p.add_argument(
        "--status", type=float, default=0.5, help="status line every this many seconds (0: none)"
    )
    p.add_argument(
        "--no-realtime",
        action="store_true",
        help="do not ask for SCHED_FIFO, CPU pinning, locked memory",
    )
    add_bus_arguments(p)
    p.add_argument(
        "--timing-file",
        metavar="FILE",
        help="at exit, save the loop's per-cycle timing (deadline, wake lateness, compute, "
        "per phase; numpy .npz) to FILE",
    )
    p.add_argument(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="serve the live 3D view to Foxglove on this WebSocket (host default 127.0.0.1; "
        "[foxglove] listen in the config sets the same; docs/foxglove.md)",
    )
    p.add_argument(
        "--ros2",
        action="store_true",
        help="publish the robot to ROS 2 over DDS: /tf, /tf_static, joint_states, pose, "
        "wrench_estimate, state, /diagnostics ([ros2] in the config; docs/ros2.md)",
    )
    add_zenoh_arguments(p)


class NotStartedError(Exception):
    """``cdprctl run`` does not start: ``lines`` said on stderr (none: said already), exit
    status ``code``."""

    def __init__(self, code: int, *lines: str):
        super().__init__(*lines)
        self.code, self.lines = code, lines


def usage(text: str) -> NotStartedError:
    """An option refused (exit status 2)."""
    return NotStartedError(2, f"cdprctl run: error: {text}")


def run(args: argparse.Namespace) -> int:
    """The controller daemon: drives configured, pose estimated and checked, then the fixed-
    rate loop (read, estimate, trajectory, PID + feedforward, tension distribution, winch
    torques, write). With --sim the simulated robot runs in a process of its own (on the
    other CPU, as drives have processors of their own) and a demo motion is played
    (--disturbance N adds a lateral force; --no-demo: none). SIGTERM or Ctrl-C:
    controlled stop, drives disabled, exit 0."""
    from cdprctl.daemon.service import Daemon

    logging.basicConfig(
        level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr
    )
    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)  # warnings printed by us
    try:
        model, as_built, zenoh = checked_model(args)
        path, estop = checked_options(args, model)
    except NotStartedError as refused:
        for line in refused.lines:
            print(line, file=sys.stderr)
        return refused.code
    from cdprctl.daemon.startup import interrupt_the_start_up
    from drivers.errors import DriverError

    previous = interrupt_the_start_up()
    try:
        daemon = Daemon(
            model,
            args.sim,
            bus_overrides(args),
            realtime=not args.no_realtime,
            status_every=args.status,
            zenoh=args.zenoh or zenoh,
            timing_file=args.timing_file,
            state_dir=args.state_dir,
            foxglove=args.foxglove,
            as_built=as_built,
            ros2=args.ros2,
        )
        daemon.bus_hint = bus_options(bus_overrides(args))
        if daemon.sim is not None and args.brake_close_time is not None:
            daemon.sim.set_brake_close_time(args.brake_close_time)
        demo = (args.sim or args.demo) and not args.no_demo and path is None
        if estop is not None and daemon.sim is not None:
            daemon.sim.schedule([estop])
            closes = estop.time + estop.duration
            print(f"simulated robot: its drives' safety chain opens at {estop.time:g} s"
                  + (f", closes at {closes:g} s" if math.isfinite(closes) else "")
                  + " of its time", flush=True)  # fmt: skip
        return daemon.run(args.duration, demo, args.disturbance, path)
    except DriverError as exc:
        print(f"cdprctl run: {exc}", file=sys.stderr)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def checked_model(args: argparse.Namespace) -> tuple[Any, Any, bool]:
    """The robot as the options change it (its rate, its Zenoh settings), the simulated
    robot's as built (or None), and whether the options asked for Zenoh; ``NotStartedError`` where
    they cannot be."""
    model = load_or_report(args.config, "cdprctl run")
    if model is None:
        raise NotStartedError(1)
    as_built = None
    if args.as_built:
        if not args.sim:
            raise usage("--as-built is the simulated robot's: give --sim")
        as_built = as_built_model(model, args.as_built, "cdprctl run")
        if as_built is None:
            raise NotStartedError(1)
    if args.rate is not None:
        if not 1.0 <= args.rate <= 10000.0:
            raise usage(f"--rate = {args.rate} Hz must be in [1, 10000]")
        model = dataclasses.replace(
            model, control=dataclasses.replace(model.control, rate=args.rate)
        )
        from drivers.busload import check_bus_load

        # refused now, not after the start-up's minute: the drivers' own check (the same rule)
        _, overloaded = check_bus_load(model.drives, args.rate, model.sensors.load_cells)
        if overloaded:
            n = len(overloaded) - 1
            more = f" (and {n} more bus{'es' if n > 1 else ''})" if n else ""
            raise usage(f"--rate = {args.rate:g} Hz: {overloaded[0]}{more}")
    zo = zenoh_overrides(args)
    if zo:
        model = dataclasses.replace(model, zenoh=dataclasses.replace(model.zenoh, **zo))
    if args.zenoh or bool(zo) or model.zenoh.enabled:
        from cdprctl.telemetry.zenoh.security import command_security_problems
        from cdprctl.telemetry.zenoh.zenoh_files import missing_files

        problems = missing_files(model.zenoh.config_file) or command_security_problems(
            model.zenoh
        )
        if problems:
            raise NotStartedError(1, *(f"cdprctl run: refused: {p}" for p in problems))
    return model, as_built, bool(zo)


def zenoh_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The ``[zenoh]`` settings the options replace."""
    zo: dict[str, Any] = {}
    if args.zenoh_listen:
        zo["listen"] = tuple(args.zenoh_listen)
    if args.zenoh_connect:
        zo["connect"] = tuple(args.zenoh_connect)
    if args.no_multicast_scouting:
        zo["multicast_scouting"] = False
    if args.accept_commands:
        zo["commands"] = True
    if args.allow_unauthenticated_commands:
        zo["allow_unauthenticated_commands"] = True
    if args.zenoh_config:
        if not Path(args.zenoh_config).is_file():
            raise usage(f"--zenoh-config = {args.zenoh_config}: no such file")
        zo["config_file"] = str(Path(args.zenoh_config).resolve())
    return zo


def checked_options(args: argparse.Namespace, model: Any) -> tuple[Any, Any]:
    """The path to play (name, text, units; or None) and the simulated e-stop (a
    ``sim_backend.faults.FaultEvent``, or None); ``NotStartedError`` where an option cannot
    be."""
    if args.duration is not None and not args.duration > 0:
        raise usage(f"--duration = {args.duration} s must be > 0")
    path = None
    if args.path is not None:
        try:
            path = (args.path, Path(args.path).read_text(encoding="utf-8"), args.units)
        except (OSError, UnicodeDecodeError) as exc:
            raise usage(f"--path = {args.path}: {os_error_text(exc)}") from None
    if args.foxglove is not None:
        from cdprctl.model.foxglove import parse_listen

        try:
            parse_listen(args.foxglove)
        except ValueError as exc:
            raise usage(f"--foxglove = {exc}") from None
    estop: Any = None
    if args.estop is not None:
        from cdprctl.commands.sim import estop_event

        event = estop_event(args.estop, model.drives.driver) if args.sim else (
            "--estop needs --sim: a real robot's safety chain is opened by its e-stop button")
        if isinstance(event, str):
            raise usage(event)
        estop = event
    if args.brake_close_time is not None:
        from cdprctl.commands.sim import BRAKE_CLOSE_MAX, brake_close_rule

        why = ("--brake-close-time needs --sim: it sets the simulated brakes" if not args.sim
               else "" if 0.0 <= args.brake_close_time <= BRAKE_CLOSE_MAX
               else brake_close_rule(args.brake_close_time))  # fmt: skip
        if why:
            raise usage(why)
    if args.ros2 or model.ros2.enabled:
        problem = model.ros2.environment_problem()
        if problem is not None:
            raise NotStartedError(2, f"cdprctl run: --ros2: {problem}")
    if refuse_in_process_bus("cdprctl run", model, bus_overrides(args), args.sim):
        raise NotStartedError(2)
    return path, estop


def add_zenoh_arguments(p: Any) -> None:
    """``cdprctl run``'s Zenoh options (the gateway's, ``[zenoh]`` in the config)."""
    z = p.add_argument_group("Zenoh (see docs/telemetry.md; [zenoh] in the config sets the same)")
    z.add_argument("--zenoh", action="store_true", help="start the Zenoh gateway")
    z.add_argument(
        "--zenoh-listen", action="append", metavar="ENDPOINT", help="e.g. tcp/0.0.0.0:7447"
    )
    z.add_argument("--zenoh-connect", action="append", metavar="ENDPOINT")
    z.add_argument("--zenoh-config", metavar="FILE", help="Zenoh JSON5: ACL, TLS, user/password")
    z.add_argument(
        "--no-multicast-scouting", action="store_true", help="find peers only by endpoints"
    )
    z.add_argument(
        "--accept-commands",
        action="store_true",
        help="take commands over Zenoh (zenoh.commands = true); refused unless the Zenoh "
        "config authenticates peers and denies by default (docs/telemetry.md)",
    )
    z.add_argument(
        "--allow-unauthenticated-commands",
        action="store_true",
        help="take commands from any peer (zenoh.allow_unauthenticated_commands = true): an "
        "isolated bench network only",
    )


def add_demo_arguments(p: Any) -> None:
    """The demo, and with --sim the simulated safety chain's e-stop and its brakes."""
    p.add_argument(
        "--demo",
        action="store_true",
        help="play the demo motion without --sim too (drives on the bus given)",
    )
    p.add_argument(
        "--disturbance",
        type=float,
        default=0.0,
        metavar="N",
        help="with the demo: a lateral force (N along y, ramped) at home",
    )
    p.add_argument(
        "--estop",
        metavar="AT[:RELEASE]",
        help="with --sim: the simulated drives' safety chain opens AT s of the simulated "
        "robot's time (from its start, a few tenths of a second before the loop's t = 0; an "
        "e-stop: safe torque off, brakes closed) and closes at RELEASE s (without: it stays "
        "open). The daemon stays in its e-stop state until a reset the drives take once the "
        "chain is closed; the demo never resets one: the run ends in the e-stop, exit 0 "
        "(docs/safety.md)",
    )
    p.add_argument(
        "--brake-close-time",
        type=float,
        metavar="S",
        help="with --sim: s the simulated holding brakes take to close when the safety "
        "chain cuts the torque (real ones 0.01-0.05; default 0: at once; docs/safety.md)",
    )
