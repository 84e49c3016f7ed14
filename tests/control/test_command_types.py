"""One frozen command type per kind (issue 66): a kind carries only its own fields, a command is
never written after it is built, and ``Command(kind, **fields)`` builds the kind's type, so the
gateway's parsing, the scripts and the tests name a kind the same way."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cdprctl.control.command_types import (
    ACCEPTED_IN,
    COMMAND_TYPES,
    Command,
    CommandKind,
    GripKind,
    GripperCommand,
    MoveCommand,
    StopCommand,
    command,
)

# each kind's fields, written out (not read from the types)
FIELDS = {
    CommandKind.ENABLE: set(), CommandKind.DISABLE: set(), CommandKind.RESET: set(),
    CommandKind.PAUSE: set(), CommandKind.RESUME: set(), CommandKind.ABORT: set(),
    CommandKind.STOP: {"category"},
    CommandKind.MOVE: {"pose", "speed", "accel"},
    CommandKind.SET_TDA: {"tda"},
    CommandKind.GRIPPER: {"gripper", "grip", "value"},
    CommandKind.JOG: {"velocity", "frame"},
    CommandKind.PATH: {"text", "name", "plan"},
}  # fmt: skip


def test_each_kind_has_its_type_with_only_its_fields():
    assert set(COMMAND_TYPES) == set(CommandKind) == set(ACCEPTED_IN)
    for kind, t in COMMAND_TYPES.items():
        assert t.kind is kind and issubclass(t, Command)
        assert {f.name for f in dataclasses.fields(t)} == FIELDS[kind], kind


def test_command_by_kind_builds_the_kinds_type_and_refuses_anothers_field():
    m = Command("move", pose=np.zeros(6), speed=0.5)
    assert type(m) is MoveCommand and m.speed == 0.5 and m.accel == 1.0
    assert type(command(CommandKind.STOP, category=0)) is StopCommand
    g = Command(CommandKind.GRIPPER, grip="force", value=3.0)
    assert type(g) is GripperCommand and g.grip is GripKind.FORCE
    with pytest.raises(TypeError, match="pose"):
        Command("enable", pose=np.zeros(6))
    with pytest.raises(ValueError):
        Command("teleport")
    with pytest.raises(ValueError):
        GripperCommand(grip="squash")


def test_a_command_is_not_written_after_it_is_built():
    m = MoveCommand(pose=np.zeros(6))
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.speed = 2.0  # type: ignore[misc]
