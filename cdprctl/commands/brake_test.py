"""``cdprctl brake-test``: the holding brakes tested, the result kept in the state directory
(docs/safety.md, "Brake test")."""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report
from cdprctl.commands.records import (
    EXIT_STATE_DIR,
    drives_closed,
    procedure_start,
    save_or_keep,
)
from cdprctl.commands.sim import add_bus_arguments

WHO = "cdprctl brake-test"
KIND = "brake-test"
# what a stopped test's kept results were measured with, and where each is set
WHERE = {"torque": "[safety] brake_test_torque or brake_test_torque_factor",
         "max_counts": "[safety] brake_test_max_counts", "hold": "[safety] brake_test_hold"}


def plan_of(model: Any) -> dict[str, Any]:
    """What each cable's test follows: its torque (N·m), the bound (counts), the hold (s)."""
    from cdprctl.safety.brake_test import brake_test_torques

    return {"torque": [float(x) for x in brake_test_torques(model)[0]],
            "max_counts": model.safety.brake_test_max_counts,
            "hold": model.safety.brake_test_hold}  # fmt: skip


def _kept(args: argparse.Namespace, model: Any, state_dir: Any,
          log: Any) -> tuple[list[Any], float | None, list[Any]] | None:  # fmt: skip
    """(the cables kept, when the first was tested, the drives' identities then) with
    ``--resume``, ([], None, []) without; None after one line when it cannot resume."""
    from cdprctl.calibration.calibration_record import geometry_hash
    from cdprctl.commands.resume import load_to_resume, replaced_warning
    from cdprctl.safety.brake_record import CableResult

    if not args.resume:
        replaced_warning(state_dir, KIND, log, WHO)
        return [], None, []
    partial = load_to_resume(WHO, state_dir, KIND, model.name, geometry_hash(model),
                             plan_of(model), WHERE)  # fmt: skip
    if partial is None:
        return None
    kept = [CableResult(**c) for c in partial.data["cables"]]
    log(f"{WHO}: {model.name}: resuming the test stopped at {partial.stopped_at} (cables "
        f"{', '.join(c.cable for c in kept)} kept)")  # fmt: skip
    return kept, partial.started, partial.identities


def _stopped(args: argparse.Namespace, model: Any, exc: Any, state_dir: Any, simulated: bool,
             driver: Any, overrides: dict[str, Any]) -> None:  # fmt: skip
    """A test stopped midway: the cables tested kept, one line."""
    from cdprctl.commands.resume import keep, new_partial, resume_command, stopped_line

    n = model.n_cables
    at = f"cable {model.cables[min(exc.at, n - 1)].name} of {n}" if exc.at < n else "the end"
    data = {"cables": [dataclasses.asdict(r) for r in exc.results]}
    partial = new_partial(KIND, model, plan_of(model), str(exc), at, len(exc.results), data,
                          exc.started, simulated,
                          list(getattr(driver, "identities", [])))  # fmt: skip
    words = f"cables {', '.join(r.cable for r in exc.results)} ({len(exc.results)} of {n})"
    kept = keep(WHO, state_dir, partial, words)
    resume = resume_command(WHO, args, overrides, "--sim" if args.sim else "")
    print(stopped_line(WHO, at, str(exc), kept, exc.cause, resume,
                       kept.startswith(words + " kept")), file=sys.stderr)  # fmt: skip


def add_parser(sub: Any) -> None:
    p = command_parser(
        sub, "brake-test", "test each winch's holding brake against a torque", run,
        epilog="examples:\n"
        "  cdprctl brake-test --config config/rowc.toml --sim\n"
        "  cdprctl brake-test --config config/rowc.toml --sim --weak-brake 6 --json\n"
        "  cdprctl brake-test --config ROBOT.toml --can-interface socketcan --can-channel can0\n"
        "\nexit codes: 0 every brake passed, 3 one failed (the record says which), 1 the test "
        "could not run,\n2 a bad option, 4 the state directory cannot take the record. A "
        "simulated robot's test\n(--sim, or drives on udp_multicast) is recorded as simulated, "
        "in its own directory\n(~/.local/state/cdprctl/simulated/<robot>): never where a real "
        "robot's records live.",
    )  # fmt: skip
    p.add_argument("--state-dir", metavar="DIR",
                   help="where the result goes (default /var/lib/cdprctl/<robot>; a simulated "
                   "robot's: ~/.local/state/cdprctl/simulated/<robot>)")  # fmt: skip
    add_bus_arguments(p)
    p.add_argument("--sim", action="store_true",
                   help="on the simulated robot, in this process (lock-step)")  # fmt: skip
    p.add_argument("--weak-brake", metavar="CABLE",
                   help="with --sim: the brake of this cable (its name in the robot file, as "
                   "every report names it) worn, holding less than the test torque")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--resume", action="store_true",
                   help="go on from a test stopped midway: the cables it tested kept (their "
                   "results in the state directory), the next one first")  # fmt: skip


def _drivers(args: argparse.Namespace, model: Any, weak: int | None,
             overrides: dict[str, Any]) -> tuple[Any, Any]:  # fmt: skip
    """(the lock-step simulated robot with --sim, else None; the driver)."""
    if args.sim:
        from sim_backend.network import LockStep

        sim = LockStep(model)
        if weak is not None:
            sim.plant.weaken_brake(weak)
        return sim, sim.driver
    from drivers import create_driver

    return None, create_driver(model, period=model.control.period, bus_overrides=overrides)


def _weak_brake_index(who: str, name: str | None, sim: bool, model: Any) -> int | None:
    """The cable index ``--weak-brake NAME`` wears (None: none); -1 after saying in one line
    why the option is refused."""
    if name is None:
        return None
    if not sim:
        print(f"{who}: error: --weak-brake {name}: only with --sim (it wears a simulated "
              "brake)", file=sys.stderr)  # fmt: skip
        return -1
    names = [c.name for c in model.cables]
    if name not in names:
        print(f"{who}: error: --weak-brake {name}: not a cable of {model.name} (its cables: "
              f"{', '.join(names)})", file=sys.stderr)  # fmt: skip
        return -1
    return names.index(name)


def run(args: argparse.Namespace) -> int:
    """Per drive, with every brake closed by the master and the drives enabled against them:
    a test torque in the pay-out direction (default 1.3 × what the cable's tension limit puts
    on the brake, never above the drive's limit), held, and the motor's motion measured: a
    brake that lets it turn more than [safety] brake_test_max_counts fails. `cdprctl run`
    refuses to enable a real robot whose last passed test is older than [safety]
    brake_test_interval (8 h)."""
    from cdprctl.calibration.partial_session import (
        PartialSessionError,
        check_identities,
        clear_latched_fault,
        path_of,
        remove,
    )
    from cdprctl.safety.brake_record import save
    from cdprctl.safety.brake_test import BrakeTest, BrakeTestFailedError, BrakeTestStoppedError
    from drivers.errors import DriverError

    who = WHO
    model = load_or_report(args.config, who)
    if model is None:
        return 1
    weak = _weak_brake_index(who, args.weak_brake, args.sim, model)
    if weak == -1:
        return 2
    proc = procedure_start(who, model, args, args.sim)
    if isinstance(proc, int):
        return proc
    overrides, log = proc.overrides, proc.log
    resumed = _kept(args, model, proc.state_dir, log)
    if resumed is None:
        return 2
    kept, started, identities = resumed
    sim, driver = _drivers(args, model, weak, overrides)
    with drives_closed(driver, sim):
        try:
            state_dir = proc.configure(driver, model.name)
            if state_dir is None:
                return EXIT_STATE_DIR
            if kept:
                clear_latched_fault(driver, log, WHO)
                check_identities(identities, list(getattr(driver, "identities", [])),
                                 [c.name for c in model.cables], path_of(state_dir, KIND))
            test = BrakeTest(model, driver, log, simulated=proc.simulated)
            record = test.run(kept, started)
        except BrakeTestStoppedError as exc:
            _stopped(args, model, exc, proc.state_dir, proc.simulated, driver, overrides)
            return 1
        except PartialSessionError as exc:
            print(f"{WHO}: error: cannot resume: {exc}", file=sys.stderr)
            return 1
        except (DriverError, BrakeTestFailedError) as exc:
            print(f"{WHO}: failed: {exc}", file=sys.stderr)
            return 1
    if remove(state_dir, KIND):
        log(f"{WHO}: completed: the stopped test's results ({path_of(state_dir, KIND)}) "
            "removed")  # fmt: skip
    path = save_or_keep(who, save, record, state_dir, dataclasses.asdict(record))
    if path is None:
        return EXIT_STATE_DIR
    if args.json:
        print(json.dumps({**record.summary(), "record": str(path)}))
    else:
        failed = ", ".join(c.cable for c in record.cables if not c.passed)
        log(f"{'passed' if record.passed else 'FAILED: cable ' + failed}; record: {path}")
    return 0 if record.passed else 3
