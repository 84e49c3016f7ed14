"""What an operator can ask of the controller: the command kinds, the command record, and in
which states each kind is acted on — one table, read by the controller and the gateway."""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Any

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


@dataclass
class Command:
    kind: CommandKind
    pose: FloatArray | None = None  # move: x, y, z (m), roll, pitch, yaw (rad)
    speed: float = 1.0  # move: fraction of the velocity limits
    accel: float = 1.0  # move: fraction of the acceleration limits
    tda: TDAOptions | None = None
    gripper: int = 0  # gripper: index in [[grippers]]
    grip: GripKind = GripKind.TRAVEL
    value: float = 0.0  # gripper: travel (m) or squeeze force (N)
    # jog: velocity vx, vy, vz (m/s), ωx, ωy, ωz (rad/s) in ``frame`` ("base" or "platform")
    velocity: FloatArray | None = None
    frame: str = "base"
    category: int = 2  # stop: IEC 60204-1's stop category (0, 1, 2; docs/safety.md)
    text: str = ""  # path: the file's content (CSV or G-code, motion/path_file.py)
    name: str = ""  # path: where it came from, for the messages
    # path: (plan, offset) checked already from where the robot rests (the gateway, --path)
    plan: Any = None

    def __post_init__(self) -> None:
        # built outside the loop (the gateway, the daemon, a test): the kinds are checked
        # here, once, so the cycle never meets an unknown one
        self.kind = CommandKind(self.kind)
        self.grip = GripKind(self.grip)


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
