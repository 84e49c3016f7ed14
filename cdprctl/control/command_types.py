"""What an operator can ask of the controller: the command kinds, one frozen type per kind
(``Command`` the union; ``command`` builds one by kind), and in which states each kind is acted
on — one table, read by the controller and the gateway."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any, ClassVar, dataclass_transform

from cdprctl.control.states import State
from cdprctl.core.rotation import FloatArray
from cdprctl.tda import TDAOptions


class CommandKind(enum.StrEnum):
    ENABLE = "enable"
    DISABLE = "disable"
    STOP = "stop"
    RESET = "reset"
    MOVE = "move"
    SET_TDA = "set_tda"
    GRIPPER = "gripper"
    JOG = "jog"
    PATH = "path"
    PAUSE = "pause"
    RESUME = "resume"
    ABORT = "abort"


class GripKind(enum.StrEnum):
    TRAVEL = "travel"  # value: the jaw's travel (m)
    FORCE = "force"  # value: squeeze force (N) on a sensed object
    RELEASE = "release"  # as open as the redundancy allows


class _ByKind(type):
    """``Command(kind, **fields)`` builds the kind's own type (``command``)."""

    def __call__(cls, *args: Any, **fields: Any) -> Any:
        if cls is Command:
            return command(*args, **fields)
        return super().__call__(*args, **fields)


@dataclass_transform(frozen_default=True, eq_default=False)
class Command(metaclass=_ByKind):
    """What an operator asks: one frozen type per kind below, each with only its own fields
    (built outside the loop: the gateway's parsing, the daemon's scripted clients, a test);
    the desk dispatches on ``kind``. ``Command(kind, **fields)`` builds the kind's type.
    Each type is made a frozen dataclass here, compared by identity (``eq=False``): a command
    is an event, and its arrays have no truth value."""

    kind: ClassVar[CommandKind]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        dataclass(frozen=True, eq=False)(cls)


class EnableCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.ENABLE


class DisableCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.DISABLE


class StopCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.STOP
    category: int = 2  # IEC 60204-1's stop category (0, 1, 2; docs/safety.md)


class ResetCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.RESET


class MoveCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.MOVE
    pose: FloatArray | None = None  # x, y, z (m), roll, pitch, yaw (rad)
    speed: float = 1.0  # fraction of the velocity limits
    accel: float = 1.0  # fraction of the acceleration limits


class SetTdaCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.SET_TDA
    tda: TDAOptions | None = None


class GripperCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.GRIPPER
    gripper: int = 0  # index in [[grippers]]
    grip: GripKind = GripKind.TRAVEL
    value: float = 0.0  # travel (m) or squeeze force (N)

    def __post_init__(self) -> None:  # checked once here: the cycle never meets an unknown
        object.__setattr__(self, "grip", GripKind(self.grip))


class JogCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.JOG
    # velocity vx, vy, vz (m/s), ωx, ωy, ωz (rad/s) in ``frame`` ("base" or "platform")
    velocity: FloatArray | None = None
    frame: str = "base"


class PathCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.PATH
    text: str = ""  # the file's content (CSV or G-code, motion/path_file.py)
    name: str = ""  # where it came from, for the messages
    plan: Any = None  # (plan, offset) checked already from where the robot rests (--path)


class PauseCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.PAUSE


class ResumeCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.RESUME


class AbortCommand(Command):
    kind: ClassVar[CommandKind] = CommandKind.ABORT


#: each kind's type
COMMAND_TYPES: dict[CommandKind, type[Command]] = {
    t.kind: t
    for t in (EnableCommand, DisableCommand, StopCommand, ResetCommand, MoveCommand,
              SetTdaCommand, GripperCommand, JogCommand, PathCommand, PauseCommand,
              ResumeCommand, AbortCommand)
}  # fmt: skip


def command(kind: CommandKind | str, **fields: Any) -> Command:
    """A command of ``kind`` (a ``CommandKind`` or its name) with ``fields``, those of its
    kind only (another's: TypeError naming it)."""
    return COMMAND_TYPES[CommandKind(kind)](**fields)


@dataclass(frozen=True)
class Plan:
    """What the desk's ``submit`` planned for a command (outside the loop), queued with it and
    handed to its handler in the cycle; the command itself is never written. ``target``: a
    move's or a jog's end, trajectory coordinates (x, y, z m, the rotation vector from home
    rad; a jog's None: a stop); ``limits``: a jog's segment limits per coordinate (velocity,
    acceleration); ``path``: a path's or a resume's checked plan and its segment offset."""

    target: FloatArray | None = None
    limits: tuple[list[float], list[float]] | None = None
    path: tuple[Any, int] | None = None


#: a command with nothing to plan (enable, stop, a TDA switch, ...)
NOTHING = Plan()

_MOTION = frozenset({State.ENABLED, State.MOVING})

#: the states in which each kind is acted on; in any other it is ignored (with an event)
ACCEPTED_IN: dict[CommandKind, frozenset[State]] = {
    CommandKind.ENABLE: frozenset({State.READY}),
    # STOPPING: after a category 2 stop, holding (desk.py refuses them before)
    CommandKind.DISABLE: frozenset({State.ENABLED, State.MOVING, State.ENABLING, State.STOPPING}),
    CommandKind.STOP: _MOTION | {State.ENABLING, State.DISABLING},
    CommandKind.RESET: frozenset({State.FAULT, State.ESTOP, State.STOPPING}),
    CommandKind.MOVE: _MOTION,
    CommandKind.GRIPPER: _MOTION,
    CommandKind.SET_TDA: frozenset(State),
    CommandKind.JOG: _MOTION,
    CommandKind.PATH: frozenset({State.ENABLED}),  # from rest: the plan starts where it stands
    CommandKind.PAUSE: frozenset({State.MOVING}),
    CommandKind.RESUME: frozenset({State.ENABLED}),
    CommandKind.ABORT: _MOTION,
}


def accepted(kind: CommandKind, state: State) -> bool:
    """Whether a command of ``kind`` is acted on in ``state`` (``ACCEPTED_IN``)."""
    return state in ACCEPTED_IN[kind]
