"""What a procedure (calibration, brake test) does with its record: decide whether the robot it
drove is simulated (a simulation never writes where a real robot's records live), check the
directory before anything moves, and, when the write still fails after the motion, say so in
one line and keep the result on standard output."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from cdprctl.core.state_dir import StateDirError, check_writable, state_dir_for

EXIT_STATE_DIR = 4  # docs/operating.md, "Exit codes"


def records_dir(who: str, robot: str, given: str | None, simulated: bool) -> Path | None:
    """The writable directory the record of ``robot`` goes to, or None after saying in one
    line why not (the caller exits :data:`EXIT_STATE_DIR`)."""
    try:
        path = state_dir_for(robot, given, simulated)
        check_writable(path)
    except StateDirError as exc:
        print(f"{who}: error: {exc}", file=sys.stderr)
        return None
    return path


def keep_record(who: str, save: Callable[[Any, Path], Path], record: Any, state_dir: Path,
                result: dict[str, Any]) -> bool:  # fmt: skip
    """``save_or_keep`` of a dataclass ``record`` beside the command's ``result``: True with
    the record's file in ``result["record"]``, False when it could not be written (then the
    result and the whole record were printed as JSON)."""
    path = save_or_keep(who, save, record, state_dir, {**result, "record": asdict(record)})
    if path is None:
        return False
    result["record"] = str(path)
    return True


def save_or_keep(who: str, save: Callable[[Any, Path], Path], record: Any, state_dir: Path,
                 result: dict[str, Any]) -> Path | None:  # fmt: skip
    """``save(record, state_dir)``; when it fails (the directory checked before the motion
    went away, a full disk), one line and ``result`` as JSON on standard output: what the
    motion measured is kept. None then (the caller exits :data:`EXIT_STATE_DIR`)."""
    try:
        return save(record, state_dir)
    except OSError as exc:
        why = exc.strerror or str(exc)
        print(f"{who}: error: the record could not be written to {state_dir} ({why}); the "
              "result follows as JSON on standard output: keep it, fix the directory (or "
              "give --state-dir) and run again", file=sys.stderr)  # fmt: skip
        print(json.dumps(result))
        return None


def bus_and_records(who: str, model: Any, args: Any,
                    in_process: bool) -> tuple[dict[str, Any], bool, Path] | int:  # fmt: skip
    """The bus overrides of ``args``, whether the robot on them is simulated (``in_process``:
    this process's own, lock-step) and the directory its records go to; an exit code after
    one line when the bus (an in-process bus without ``--sim``) or the directory is refused.
    A simulated robot's records never go where a real robot's are."""
    from cdprctl.commands.sim import bus_overrides, refuse_in_process_bus
    from drivers.simulated import simulated_robot

    overrides = bus_overrides(args)
    if refuse_in_process_bus(who, model, overrides, in_process):
        return 2
    simulated = in_process or simulated_robot(model, overrides)
    state_dir = records_dir(who, model.name, args.state_dir, simulated)
    if state_dir is None:
        return EXIT_STATE_DIR
    return overrides, simulated, state_dir


@dataclass
class Procedure:
    """Where a procedure (brake test, tare, calibration) keeps its record and says what it does,
    from ``procedure_start``; ``simulated`` and ``state_dir`` found again by :meth:`configure`."""

    who: str
    model: Any
    args: Any
    overrides: dict[str, Any]
    simulated: bool
    state_dir: Path
    log: Callable[[str], None]

    def configure(self, driver: Any, doing: str | None) -> Path | None:
        """``driver`` configured, then the record's directory (``records_after_configure``):
        None when it is refused, said in one line (the caller exits :data:`EXIT_STATE_DIR`).
        ``doing``: what the procedure is doing, said with "configuring the drives" and where a
        simulated robot's record goes; None says neither."""
        if doing is not None:
            self.log(f"{self.who}: {doing}: configuring the drives")
        driver.configure()
        self.simulated, state_dir = records_after_configure(
            self.who, self.model, self.args, self.overrides, driver, self.simulated,
            self.state_dir, None if doing is None else self.log)  # fmt: skip
        if state_dir is not None:
            self.state_dir = state_dir
        return state_dir


@contextmanager
def drives_closed(driver: Any, sim: Any = None) -> Iterator[None]:
    """However a procedure on the drives ends (its except clauses having said why): the drives
    shut down (disabled, brakes on) and the in-process simulated robot's bus, if any, closed."""
    try:
        yield
    finally:
        driver.shutdown()
        if sim is not None:
            sim.net.close()


def procedure_start(who: str, model: Any, args: Any, in_process: bool) -> Procedure | int:
    """``bus_and_records`` (the record's directory may still change once the drives say they
    are simulated: :meth:`Procedure.configure`), and where the procedure says what it does:
    standard error when its result goes to standard output as JSON (``--json``), else
    standard output."""
    where = bus_and_records(who, model, args, in_process)
    if isinstance(where, int):
        return where
    overrides, simulated, state_dir = where
    log = (lambda s: print(s, file=sys.stderr, flush=True)) if args.json else print
    return Procedure(who, model, args, overrides, simulated, state_dir, log)


def records_after_configure(who: str, model: Any, args: Any, overrides: dict[str, Any],
                            driver: Any, simulated: bool, state_dir: Path | None,
                            log: Callable[[str], None] | None = None,
                            ) -> tuple[bool, Path | None]:  # fmt: skip
    """(simulated, the record's directory) once the configured drives have said who they are:
    simulated drives behind a kernel CAN interface (HIL) write where a simulated robot's
    records go (None: refused, said in one line; the caller exits :data:`EXIT_STATE_DIR`).
    ``log``: where a simulated robot's directory is said, if anywhere."""
    from drivers.simulated import simulated_robot

    if not simulated and simulated_robot(model, overrides, driver):
        simulated = True
        state_dir = records_dir(who, model.name, args.state_dir, simulated)
    if log is not None and simulated and state_dir is not None:
        log(f"{who}: a simulated robot: the record goes to {state_dir}")
    return simulated, state_dir
