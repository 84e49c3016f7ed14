"""The daemon's scripted clients of the command mailbox: the demo (``cdprctl run --sim``) and
``--path``. They send the same commands an operator would over Zenoh and read only
``ControlData``: what they do, a user's script can do."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.control.command_types import (
    Command,
    DisableCommand,
    EnableCommand,
    MoveCommand,
    PathCommand,
)
from cdprctl.control.data import ControlData
from cdprctl.control.states import State
from cdprctl.core.realtime import sharing_the_interpreter
from cdprctl.model.robot import RobotModel


@dataclass(frozen=True)
class Disturbance:
    """A lateral force ``force`` N along y on the simulated platform, ramped over 1 s like the
    ARK 2020 water jet (0: off again); nothing on a real robot."""

    force: float


Step = tuple[float, Command | Disturbance]  # (s from the script's start, what to do)


def demo_targets(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """The demo's two move targets (m, base frame): 0.3 m along x and 0.1 m down, 0.2 m back
    along x, from home, within the workspace."""
    home = model.home.position
    lo, hi = model.workspace.position_min, model.workspace.position_max
    a = np.clip(home + np.array([0.3, 0.0, -0.1]), lo, hi)
    b = np.clip(home + np.array([-0.2, 0.0, 0.0]), lo, hi)
    return a, b


def demo_script(model: RobotModel, force: float = 0.0) -> list[Step]:
    """Enable, a move and back, optionally a lateral disturbance at home (``force`` N along y),
    a move, home, disable. New commands on every call (a command is consumed by ``submit``)."""
    home = model.home.position
    a, b = demo_targets(model)

    def move(p: np.ndarray) -> Command:
        return MoveCommand(pose=np.concatenate([p, model.home.rpy]))

    return [
        (0.3, EnableCommand()),
        (1.0, move(a)),
        (4.0, move(home)),
        *([(7.0, Disturbance(force))] if force else []),
        (10.0, move(b)),
        (13.0, move(home)),
        *([(16.0, Disturbance(0.0))] if force else []),
        (19.0, DisableCommand()),
    ]


class PathScript:
    """``cdprctl run --path``: the path planned and checked whole from where the robot stands
    (``planner(start pose)`` → (plan, "") or (None, why not)), then enable, the path, and done
    once it ended, or a fault ended it; ``rejected`` says why when the check refused it."""

    def __init__(self, name: str, text: str, planner: Callable[[np.ndarray], tuple[Any, str]]):
        self.name, self.text, self.planner = name, text, planner
        self.plan: Any = None
        self.rejected = ""
        self._enable_sent = self._path_sent = False
        self._sent_cycle = 0
        self.done = False

    def step(self, d: ControlData) -> Command | None:
        """The next command to submit, if any; sets ``done`` once the path ended."""
        if d.state in (State.FAULT, State.ESTOP):  # said at the end (Daemon.run)
            self.done = True
            return None
        if self.plan is None and d.state is State.READY:  # planned before any enable
            with sharing_the_interpreter():  # the loop keeps its period meanwhile
                self.plan, self.rejected = self.planner(d.reference.copy())
            self.done = self.plan is None
            return None
        if self.plan is None:
            return None
        if not self._path_sent:
            if d.state is State.READY and not self._enable_sent:
                self._enable_sent = True
                return EnableCommand()
            if d.state is State.ENABLED and not d.motion:  # enabled and holding
                self._path_sent = True
                self._sent_cycle = d.cycle
                return PathCommand(text=self.text, name=self.name,
                                   plan=(self.plan, 0))  # fmt: skip
            return None
        if d.cycle < self._sent_cycle + 3:  # the loop has not taken it yet
            return None
        ended = d.path_state in ("done", "aborted", "stopped", "")
        self.done = ended and d.state is State.ENABLED
        return None
