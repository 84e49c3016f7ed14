"""``cdprctl brake-test``: the holding brakes tested, the result kept in the state directory
(docs/safety.md, "Brake test")."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from cdprctl.commands.common import command_parser, load_or_report
from cdprctl.commands.sim import add_bus_arguments, bus_overrides


def add_parser(sub: Any) -> None:
    p = command_parser(
        sub, "brake-test", "test each winch's holding brake against a torque", run,
        epilog="examples:\n"
        "  cdprctl brake-test --config config/rowc.toml --sim\n"
        "  cdprctl brake-test --config config/rowc.toml --sim --weak-brake 5 --json\n"
        "  cdprctl brake-test --config ROBOT.toml --can-interface socketcan --can-channel can0\n"
        "\nexit codes: 0 every brake passed, 3 one failed (the record says which), 1 the test "
        "could not run,\n2 a bad option. A test with --sim is recorded as simulated: a real "
        "robot's start-up does not take it.",
    )  # fmt: skip
    p.add_argument("--state-dir", metavar="DIR",
                   help="where the result goes (default /var/lib/cdprctl/<robot>)")  # fmt: skip
    add_bus_arguments(p)
    p.add_argument("--sim", action="store_true",
                   help="on the simulated robot, in this process (lock-step)")  # fmt: skip
    p.add_argument("--weak-brake", type=int, metavar="INDEX",
                   help="with --sim: the brake of this cable (0-based index) worn, holding "
                   "less than the test torque")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the result as JSON")


def run(args: argparse.Namespace) -> int:
    """Per drive, with every brake closed by the master and the drives enabled against them:
    a test torque in the pay-out direction (default 1.3 × what the cable's tension limit puts
    on the brake, never above the drive's limit), held, and the motor's motion measured: a
    brake that lets it turn more than [safety] brake_test_max_counts fails. `cdprctl run`
    refuses to enable a real robot whose last passed test is older than [safety]
    brake_test_interval (8 h)."""
    from cdprctl.calibration.record import default_state_dir
    from cdprctl.safety.brake_test import BrakeTest, BrakeTestFailedError
    from cdprctl.safety.record import save
    from drivers.errors import DriverError

    who = "cdprctl brake-test"
    model = load_or_report(args.config, who)
    if model is None:
        return 1
    m = model.n_cables
    if args.weak_brake is not None and not args.sim:
        print(f"{who}: error: --weak-brake {args.weak_brake}: only with --sim (it wears a "
              "simulated brake)", file=sys.stderr)  # fmt: skip
        return 2
    if args.weak_brake is not None and not 0 <= args.weak_brake < m:
        print(f"{who}: error: --weak-brake {args.weak_brake}: must be a cable index in "
              f"0..{m - 1} (0-based; {model.name} has {m} cables)", file=sys.stderr)  # fmt: skip
        return 2
    state_dir = Path(args.state_dir) if args.state_dir else default_state_dir(model.name)
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    sim = None
    if args.sim:
        from sim_backend.network import LockStep

        sim = LockStep(model)
        if args.weak_brake is not None:
            sim.plant.weaken_brake(args.weak_brake)
        driver = sim.driver
    else:
        from drivers import create_driver

        driver = create_driver(model, period=model.control.period,
                               bus_overrides=bus_overrides(args))  # fmt: skip
    try:
        log(f"{who}: {model.name}: configuring the drives")
        driver.configure()
        record = BrakeTest(model, driver, log, simulated=args.sim).run()
    except (DriverError, BrakeTestFailedError) as exc:
        print(f"{who}: failed: {exc}", file=sys.stderr)
        return 1
    finally:
        driver.shutdown()
        if sim is not None:
            sim.net.close()
    path = save(record, state_dir)
    if args.json:
        print(json.dumps(record.summary()))
    else:
        failed = ", ".join(c.cable for c in record.cables if not c.passed)
        log(f"{'passed' if record.passed else 'FAILED: cable ' + failed}; record: {path}")
    return 0 if record.passed else 3
