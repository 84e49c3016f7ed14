"""``cdprctl load-cells zero``: the load cells' tare, kept in the state directory (docs/homing.md,
"Load cells")."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import sys
from typing import Any

from cdprctl.commands.common import load_or_report
from cdprctl.commands.parsing import command_parser
from cdprctl.commands.records import (
    EXIT_STATE_DIR,
    drives_closed,
    keep_record,
    procedure_start,
)
from cdprctl.commands.sim import add_bus_arguments

WHO = "cdprctl load-cells zero"
EXAMPLES = """examples:
  cdprctl load-cells zero --config config/rowc_load_cells.toml --sim
  cdprctl load-cells zero --config ROBOT.toml --can-interface socketcan --can-channel can0

exit codes: 0 the cells zeroed (the record written), 1 the tare could not run or was refused
(a cell silent, or its readings spread beyond its accuracy), 2 a bad option, 4 the state
directory cannot take the record. A simulated robot's record goes to its own directory
(~/.local/state/cdprctl/simulated/<robot>): never where a real robot's records live."""


def add_parser(sub: Any) -> None:
    p = sub.add_parser("load-cells", help="the cables' load cells: zero (tare)")
    actions = p.add_subparsers(dest="load_cells_action", metavar="ACTION", required=True)
    z = command_parser(actions, "zero", "tare every load cell, the platform resting on its "
                       "stand", zero, description=inspect.cleandoc(zero.__doc__ or ""),
                       epilog=EXAMPLES)  # fmt: skip
    z.set_defaults(cmd=WHO)
    z.add_argument("--state-dir", metavar="DIR",
                   help="where the record goes (default /var/lib/cdprctl/<robot>; a simulated "
                   "robot's: ~/.local/state/cdprctl/simulated/<robot>)")  # fmt: skip
    add_bus_arguments(z)
    z.add_argument("--sim", action="store_true",
                   help="on the simulated robot, in this process (lock-step), its platform on "
                   "its stand")  # fmt: skip
    z.add_argument("--seconds", type=float, default=1.0, metavar="S",
                   help="how long each cell is read and averaged (default 1)")  # fmt: skip
    z.add_argument("--json", action="store_true", help="print the result as JSON")


#: s: the shortest and longest reading of the cells for a tare
TARE_SECONDS = (0.2, 60.0)


def on_stand(model: Any) -> Any:
    """The lock-step simulated robot with its platform resting on its stand: the stand takes
    its weight (no gravity on it), its cables hang unloaded (zero tension), brakes closed."""
    import numpy as np

    from sim_backend.network import LockStep
    from sim_backend.plant import CdprPlant

    plant = CdprPlant(dataclasses.replace(model, gravity=np.zeros(3)))
    plant.set_pose(model.home.position, model.home.rotation, np.zeros(model.n_cables))
    return LockStep(model, plant=plant)


def zero(args: argparse.Namespace) -> int:
    """Tare the load cells ([[sensors.load_cells]]): with the platform resting on its stand
    and every cable unloaded (the drives stay disabled), each cell is read for --seconds and
    its offset made the one that reads 0 N; a cell that does not answer, or whose readings
    spread beyond its accuracy (the platform not at rest, a noisy cell), refuses the tare.
    The offsets go to the state directory (load_cells.json, beside the calibration record);
    `cdprctl run` applies them to the cells before the drives start."""
    from cdprctl.calibration.load_cells import LoadCellError, save, tare
    from drivers.errors import DriverError

    if not (TARE_SECONDS[0] <= args.seconds <= TARE_SECONDS[1]):  # NaN too
        print(f"{WHO}: error: --seconds = {args.seconds:g} s must be in [{TARE_SECONDS[0]:g}, "
              f"{TARE_SECONDS[1]:g}] s (the cells' readings averaged over it: a few hundred "
              "samples at least)", file=sys.stderr)  # fmt: skip
        return 2
    model = load_or_report(args.config, WHO)
    if model is None:
        return 1
    if not model.sensors.load_cells:
        print(f"{WHO}: error: {model.name} has no load cells: add [[sensors.load_cells]] to "
              f"{args.config} (docs/config.md)", file=sys.stderr)  # fmt: skip
        return 2
    proc = procedure_start(WHO, model, args, args.sim)
    if isinstance(proc, int):
        return proc
    sim = on_stand(model) if args.sim else None
    if sim is not None:
        driver = sim.driver
    else:
        from drivers import create_driver

        driver = create_driver(model, period=model.control.period, bus_overrides=proc.overrides)
    with drives_closed(driver, sim):
        try:
            state_dir = proc.configure(driver, None)
            if state_dir is None:
                return EXIT_STATE_DIR
            record = tare(model, driver, args.seconds, proc.simulated, proc.log)
        except (DriverError, LoadCellError) as exc:
            print(f"{WHO}: failed: {exc}", file=sys.stderr)
            return 1
    result: dict[str, Any] = {"offsets": record.offsets, "std": record.std}
    if not keep_record(WHO, save, record, state_dir, result):
        return EXIT_STATE_DIR
    if args.json:
        print(json.dumps(result))
    else:
        for name, offset in record.offsets.items():
            print(f"cable {name}: offset {offset:+.3f} N (readings ± {record.std[name]:.3f} N)")
        print(f"{WHO}: {len(record.offsets)} cells zeroed: {result['record']}")
    return 0
