"""What the long procedures' commands share about a stop midway (``calibrate geometry``,
``calibrate self``, ``calibrate friction``, ``brake-test``): the state directory its partial
session goes to, the session read back for ``--resume`` and checked against this run's robot
and options, the partial session written when the procedure stops, and the one line that says
where it stopped, why, what was kept and how to go on (docs/homing.md, docs/safety.md,
docs/friction.md)."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cdprctl.calibration import partial_session as ps
from cdprctl.core.state_dir import StateDirError, check_writable, state_dir_for
from cdprctl.core.state_file import iso_utc


def state_dir_or_warn(who: str, robot: str, given: str | None, simulated: bool,
                      log: Callable[[str], None]) -> Path | None:  # fmt: skip
    """The state directory, for a command that writes no record there (``calibrate geometry``
    without ``--out``): None after a warning line when it cannot be written — the procedure
    runs, but a stop then keeps nothing."""
    try:
        path = state_dir_for(robot, given, simulated)
        check_writable(path)
    except StateDirError as exc:
        log(f"{who}: warning: {exc}; a stop midway could not keep its samples")
        return None
    return path


def load_to_resume(who: str, state_dir: Path, kind: str, robot: str, geometry_hash: str,
                   options: dict[str, Any],
                   where: dict[str, str]) -> ps.PartialSession | None:  # fmt: skip
    """The partial session of ``kind`` in ``state_dir``, if it is this robot's with these
    options; else None after one line saying why (the caller exits 2)."""
    path = ps.path_of(state_dir, kind)
    try:
        partial = ps.load(state_dir, kind)
        ps.check_plan(partial, path, robot, geometry_hash, options, where)
    except ps.PartialSessionError as exc:
        text = str(exc)
        if text.startswith("no stopped session"):
            text += " (run it without --resume: nothing stopped there)"
        print(f"{who}: error: cannot resume: {text}", file=sys.stderr)
        return None
    return partial


def replaced_warning(state_dir: Path | None, kind: str, log: Callable[[str], None],
                     who: str) -> None:  # fmt: skip
    """A run started over where a stopped one's samples are: said (a stop overwrites them, a
    completion removes them)."""
    if state_dir is not None and ps.path_of(state_dir, kind).exists():
        log(f"{who}: note: {ps.path_of(state_dir, kind)} holds a stopped session's samples; "
            "this run starts over (--resume goes on from them) and replaces them")  # fmt: skip


def keep(who: str, state_dir: Path | None, partial: ps.PartialSession, words: str) -> str:
    """``partial`` (``words``: what it holds) written to ``state_dir``: "WORDS kept in FILE",
    or why it was not."""
    if partial.kept == 0:  # a run started over: an earlier stop's file goes, as it was told
        if state_dir is not None and ps.remove(state_dir, partial.kind):
            return ("nothing measured yet to keep (the earlier stopped session's file, which "
                    "this run replaces, removed)")  # fmt: skip
        return "nothing measured yet to keep"
    if state_dir is None:
        return f"{words} measured, not kept (no state directory to write: give --state-dir DIR)"
    try:
        return f"{words} kept in {ps.save(partial, state_dir)}"
    except OSError as exc:
        return f"{words} measured, not kept ({exc.strerror or exc} writing to {state_dir})"


def stopped_line(who: str, at: str, fault: str, kept: str, cause: str, resume: str,
                 resumable: bool) -> str:  # fmt: skip
    """The one line of a stop midway: where, the fault, what was kept, the cause when it
    points at the machine's load, and the command that goes on."""
    line = f"{who}: stopped at {at}: {fault}; {kept}"
    if cause:
        line += f"; {cause}"
    return line + (f"; resume: {resume}" if resumable else "; run it again")


def new_partial(kind: str, model: Any, options: dict[str, Any], fault: str, at: str,
                kept: int, data: dict[str, Any], started: float, simulated: bool,
                identities: list[Any]) -> ps.PartialSession:  # fmt: skip
    from cdprctl.calibration.calibration_record import geometry_hash

    return ps.PartialSession(kind=kind, robot=model.name, geometry_hash=geometry_hash(model),
                             options=options, fault=fault, stopped_at=at, kept=kept,
                             data=data, time=iso_utc(), started=started,
                             simulated=simulated, identities=identities)  # fmt: skip


def resume_command(head: str, args: Any, overrides: dict[str, Any], tail: str) -> str:
    """The command that resumes: ``head`` (``cdprctl calibrate``), the robot file, the state
    directory and bus options this run was given, then ``tail`` (the method, its options)."""
    from cdprctl.commands.sim import bus_options

    invoked = sys.argv[0] if sys.argv else ""
    if Path(invoked).name == "cdprctl" and head.startswith("cdprctl "):
        head = invoked + head[len("cdprctl"):]  # as typed: .venv/bin/cdprctl pastes, cdprctl not
    parts = [head, "--config", str(args.config)]
    if getattr(args, "state_dir", None):
        parts += ["--state-dir", str(args.state_dir)]
    bus = bus_options(overrides)
    return " ".join(parts + ([bus] if bus else []) + [tail, "--resume"])
