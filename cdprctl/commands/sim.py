"""``cdprctl sim``: the simulated robot in real time, on any python-can bus."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report


def buses_text(model: Any, overrides: dict[str, Any]) -> str:
    """Where the simulated drives are: every bus (interface, channel, its drives), or the one
    the command line put them all on; a ``virtual`` bus is this process's alone (a daemon or a
    calibration in another process reaches the drives only on a shared bus)."""
    iface, channel = overrides.get("interface"), overrides.get("channel")
    buses = model.drives.buses
    if iface or channel:
        names = {(iface or b.interface, channel or b.channel) for b in buses}
        text = ", ".join(f"{i} {c}" for i, c in sorted(names))
    else:
        text = ", ".join(f"{b.interface} {b.channel} ({len(b.cables)})" for b in buses)
    if any((iface or b.interface) == "virtual" for b in buses):
        text += (" — virtual: in this process only; for a daemon or a calibration in another "
                 "process give both --can-interface udp_multicast --can-channel 239.74.163.9")
    return text


def refuse_in_process_bus(who: str, model: Any, overrides: dict[str, Any], sim: bool,
                          has_sim: bool = True) -> bool:  # fmt: skip
    """True after one line when, without ``--sim``, every bus of ``model`` is in-process
    (python-can's ``virtual``): no drive and no ``cdprctl sim`` of another process can answer
    there, and a scan or a start-up would only time out on silent node ids. ``has_sim``: the
    command takes ``--sim`` (``drives scan`` does not: it is offered no such way)."""
    from drivers.simulated import in_process_only

    if sim or not in_process_only(model, overrides):
        return False
    config = model.source_file or "ROBOT.toml"
    sim_way = "use --sim (the simulated robot in this process), or " if has_sim else ""
    print(f"{who}: error: the buses of {config} are python-can's in-process 'virtual' bus: no "
          f"drive and no other process can answer there; {sim_way}start `cdprctl sim --config "
          f"{config} --can-interface "
          f"udp_multicast --can-channel 239.74.163.9` and give these same two options here, "
          f"or a real robot's bus (--can-interface socketcan --can-channel can0)",
          file=sys.stderr)  # fmt: skip
    return True


def add_bus_arguments(p: argparse.ArgumentParser, default: Any = None) -> None:
    """The bus overrides shared by ``cdprctl sim``, ``run``, ``calibrate`` and ``drives
    scan``, so they meet (``default``: ``argparse.SUPPRESS`` on a sub-command that repeats
    its parent's; there a ``--can-option`` list replaces the parent's, it is not added)."""
    p.add_argument(
        "--can-interface",
        default=default,
        help="python-can interface replacing the config's (socketcan, virtual, udp_multicast, ...)",
    )
    p.add_argument(
        "--can-channel",
        default=default,
        help="channel replacing the config's (can0, vcan0, a "
        "udp_multicast group such as 239.74.163.2, ...)",
    )
    p.add_argument(
        "--can-option",
        action="append",
        default=[] if default is None else default,
        metavar="KEY=VALUE",
        help="extra python-can argument, e.g. port=43113 (repeatable)",
    )


def bus_options(overrides: dict[str, Any]) -> str:
    """``bus_overrides``'s result as the options that give it (for a command to repeat)."""
    out = [f"--can-interface {overrides['interface']}"] if "interface" in overrides else []
    out += [f"--can-channel {overrides['channel']}"] if "channel" in overrides else []
    out += [f"--can-option {k}={v}" for k, v in overrides.get("options", {}).items()]
    return " ".join(out)


def bus_overrides(args: argparse.Namespace) -> dict[str, Any]:
    out: dict[str, Any] = {}
    if args.can_interface:
        out["interface"] = args.can_interface
    if args.can_channel:
        out["channel"] = args.can_channel
    options: dict[str, Any] = {}
    for item in args.can_option:
        key, sep, value = item.partition("=")
        if not sep or not key:  # bad input: 2, as every refused option (docs/operating.md)
            print(f"cdprctl {args.cmd}: error: --can-option {item!r}: expected KEY=VALUE",
                  file=sys.stderr)  # fmt: skip
            raise SystemExit(2)
        options[key] = int(value) if value.lstrip("-").isdigit() else value
    if options:
        out["options"] = options
    return out


def add_parser(sub: Any) -> None:
    p = command_parser(sub, "sim", "run the simulated robot in real time on a CAN bus", run)
    add_bus_arguments(p)
    p.add_argument("--duration", type=float, help="stop after this many seconds")
    p.add_argument("--no-realtime", action="store_true",
                   help="do not ask for SCHED_FIFO (one below the daemon's [control] "
                   "sched_priority) on the CPUs but the daemon's: a simulated robot that the "
                   "machine's other work holds up says so, 'stepped N ms late'")  # fmt: skip
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
    p.add_argument(
        "--estop",
        metavar="AT[:RELEASE]",
        help="open the drives' safety chain (their STO inputs: an e-stop) AT s after the start "
        "and close it at RELEASE s: no torque, brakes closed, each energised drive in FAULT "
        "with maxon EPOS4's STO error 0x8A88 until a fault reset after the release "
        "(CiA 402 drives; docs/safety.md)",
    )
    p.add_argument(
        "--brake-close-time",
        type=float,
        default=0.0,
        metavar="S",
        help="s the holding brakes take to close when the safety chain cuts the torque "
        "(real ones 0.01-0.05; default 0: at once): the drums turn freely meanwhile "
        "(docs/safety.md)",
    )
    h = p.add_argument_group("start and errors (docs/homing.md)")
    h.add_argument(
        "--start-pose",
        metavar="X,Y,Z,ROLL,PITCH,YAW",
        help="the platform at rest there (m, rad), held with feasible tensions, brakes on "
        "(default: the home pose)",
    )
    h.add_argument(
        "--encoders",
        choices=("incremental", "absolute"),
        help="incremental: each counter reads zero at start and after a drive reset (the "
        "default with --start-pose); absolute: zero where the cable has its home length "
        "(the default otherwise)",
    )
    h.add_argument(
        "--plant-errors",
        type=int,
        metavar="SEED",
        help="the simulated robot differs from the config: anchors offset (all but the "
        "reference anchors, which define the robot's frame) and drum radii scaled at random "
        "(seeded)",
    )
    add_as_built_argument(h)
    h.add_argument("--anchor-error", type=float, default=0.005, help="m, with --plant-errors")
    h.add_argument(
        "--drum-error", type=float, default=0.005, help="fraction, with --plant-errors"
    )


def add_as_built_argument(p: Any) -> None:
    p.add_argument(
        "--as-built",
        metavar="TRUTH.toml",
        help="the simulated robot as built: its geometry (anchors, attachments, each drum's "
        "radius, the platform, its body and the cell's obstacles its contacts are measured "
        "on) from this robot file, the same robot as --config's (its name and cables), the "
        "drives and buses from --config (docs/homing.md, \"Geometric calibration\"; "
        "docs/simulator.md, \"Contacts\")",
    )


def as_built_model(model: Any, path: str, who: str) -> Any:
    """The robot of ``path`` for the plant, checked to be ``model``'s robot (the same cables,
    by name and order); None after printing why not."""
    truth = load_or_report(path, who)
    if truth is None:
        return None
    names, truth_names = [c.name for c in model.cables], [c.name for c in truth.cables]
    if truth.name != model.name:
        print(f"{who}: error: --as-built = {path}: robot {truth.name!r}, the config's is "
              f"{model.name!r} (the same robot, as built)", file=sys.stderr)  # fmt: skip
        return None
    if names != truth_names:
        print(f"{who}: error: --as-built = {path}: its cables {truth_names} are not the "
              f"config's {names} (the same robot, as built: the same cables in the same "
              "order)", file=sys.stderr)  # fmt: skip
        return None
    return truth


def run(args: argparse.Namespace) -> int:
    """The simulated robot of sim_backend: drive emulators (the protocol of the config's
    [drives]) on the config's buses, or on the bus given here, with the winch, cable and
    platform physics, in real time. The platform starts at rest at the home pose, cables
    pre-tensioned to the equilibrium. Stop with Ctrl-C or SIGTERM."""
    from drivers.errors import DriverError
    from sim_backend.contact import CONTACT_EXIT
    from sim_backend.realtime import LateSteps, run_realtime

    model = load_or_report(args.config)
    if model is None:
        return 1
    estop = None if args.estop is None else estop_event(args.estop, model.drives.driver)
    if isinstance(estop, str):
        print(f"cdprctl sim: error: {estop}", file=sys.stderr)
        return 2
    if not 0.0 <= args.brake_close_time <= BRAKE_CLOSE_MAX:
        print(f"cdprctl sim: error: {brake_close_rule(args.brake_close_time)}", file=sys.stderr)
        return 2
    overrides = bus_overrides(args)
    print(f"cdprctl sim: {model.name}, {model.n_cables} {model.drives.driver} drives on "
          f"{buses_text(model, overrides)}", flush=True)  # fmt: skip
    print("cdprctl sim: building the simulated robot (the first start on a machine compiles "
          "its physics: about a minute)", flush=True)  # fmt: skip
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
    if estop is not None:
        from sim_backend.faults import FaultInjector

        faults = faults or FaultInjector([])
        faults.events.append(estop)
        print(f"cdprctl sim: the safety chain opens at {estop.time:g} s"
              + (f", closes at {estop.time + estop.duration:g} s"
                 if math.isfinite(estop.duration) else ""), flush=True)  # fmt: skip
    plant, encoders = start_state(model, args)
    plant.opt.brake_close_time = args.brake_close_time

    def realtime() -> None:
        from cdprctl.core import realtime as rt

        ctl = model.control
        for w in rt.simulator_realtime(rt.loop_cpu(ctl.cpu), ctl.sched_priority):
            print(f"cdprctl sim: warning: {w}", file=sys.stderr, flush=True)

    late = LateSteps()
    try:
        net = run_realtime(
            model,
            overrides,
            args.duration,
            faults=faults,
            status_every=args.status,
            plant=plant,
            encoders=encoders,
            late=late,
            realtime=None if args.no_realtime else realtime,
        )
    except DriverError as exc:
        print(f"cdprctl sim: error: {exc}", file=sys.stderr)
        return 1
    net.close()
    print(late.summary(), flush=True)
    print(f"cdprctl sim: {plant.contact.report()}", flush=True)
    print("cdprctl sim: stopped", flush=True)
    return CONTACT_EXIT if plant.contact.contacts else 0


BRAKE_CLOSE_MAX = 0.5  # s


def brake_close_rule(value: float) -> str:
    return (f"--brake-close-time = {value:g} s must be in [0, {BRAKE_CLOSE_MAX:g}] s (real "
            "holding brakes close in 0.01-0.05 s)")  # fmt: skip


def estop_event(text: str, driver: str) -> Any:
    """``--estop AT[:RELEASE]`` (s) as a ``FaultEvent``, or why not (a one-line message)."""
    from sim_backend.faults import FaultEvent

    if driver != "cia402":
        return (f"--estop: the simulated {driver} drives have no safety chain (CiA 402 "
                "drives only)")  # fmt: skip
    parts = text.split(":")
    rule = "must be AT or AT:RELEASE in s, 0 <= AT < RELEASE (e.g. 8:12)"
    try:
        at = float(parts[0])
        release = float(parts[1]) if len(parts) == 2 else math.inf
    except ValueError:
        return f"--estop = {text!r} is not a time: {rule}"
    if len(parts) > 2 or not (math.isfinite(at) and at >= 0.0) or not release > at:
        return f"--estop = {text!r}: {rule}"
    return FaultEvent(at, "estop", value=0, duration=release - at)


def start_state(model: Any, args: argparse.Namespace) -> tuple[Any, str]:
    """The plant (with ``--plant-errors``, of a robot that differs from the config) at rest at
    ``--start-pose``, and the encoders' kind."""
    import numpy as np

    from cdprctl.commands.common import parse_pose
    from cdprctl.core.rotation import rpy_to_matrix
    from sim_backend.plant import CdprPlant
    from sim_backend.plant_errors import PlantErrors

    plant_model = model
    if args.as_built and args.plant_errors is not None:
        raise SystemExit("cdprctl sim: error: --as-built and --plant-errors: give one (the "
                         "robot as built, or random errors of the config's)")  # fmt: skip
    if args.as_built:
        plant_model = as_built_model(model, args.as_built, "cdprctl sim")
        if plant_model is None:
            raise SystemExit(1)
        print(f"cdprctl sim: the robot as built: {args.as_built}", flush=True)
    if args.plant_errors is not None:
        from cdprctl.model.calibration import reference_anchors

        # the reference anchors define the robot's frame (docs/homing.md): moved too, the
        # platform's pose in the plant's frame is not the one any calibration can find (a
        # new user's check of `run`'s ready pose against this status line: 5.6 mm apart)
        ref = reference_anchors(model.calibration, np.array([c.anchor for c in model.cables]))
        errors = PlantErrors(args.plant_errors, args.anchor_error, args.drum_error, tuple(ref))
        plant_model, drawn = errors.apply(model)
        scales = np.array(drawn["drum_scales"])
        print(
            f"cdprctl sim: plant errors (seed {args.plant_errors}): anchors up to "
            f"{np.max(np.abs(drawn['anchor_offsets'])) * 1e3:.1f} mm off (the reference "
            f"anchors {', '.join(model.cables[i].name for i in ref)} as drawn: they define "
            f"the robot's frame), drum radii x{scales.min():.4f}..{scales.max():.4f}",
            flush=True,
        )
    plant = CdprPlant(plant_model)
    encoders = args.encoders or "absolute"
    if args.start_pose:
        pose = parse_pose(args.start_pose, "--start-pose", model)
        plant.set_pose(pose[:3], rpy_to_matrix(*pose[3:]), None)
        encoders = args.encoders or "incremental"
        print(f"cdprctl sim: start pose {args.start_pose}, {encoders} encoders", flush=True)
    return plant, encoders
