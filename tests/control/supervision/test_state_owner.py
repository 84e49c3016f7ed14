"""One owner of the state (issue 66): only the state machine
(``control/supervision/state_machine.py``) writes ``ControlData.state``; the desk, the supervisor
and the start-up ask it (``StateMachine.request``). Read from the source with ``ast``, like
``test_layers.py``; a planted write shows the check can fail."""

from __future__ import annotations

import ast
from pathlib import Path

from cdprctl.control.data import ControlData
from cdprctl.control.states import State
from cdprctl.control.supervision.state_machine import TRANSITIONS, StateMachine

ROOT = Path(__file__).resolve().parents[3]
OWNER = ROOT / "cdprctl" / "control" / "supervision" / "state_machine.py"
# the names the loop's data goes by where it is written (d, data, self.data, ctl.data, ...)
DATA_NAMES = ("d", "data")


def _is_data(node: ast.expr) -> bool:
    if isinstance(node, ast.Name):
        return node.id in DATA_NAMES
    return isinstance(node, ast.Attribute) and node.attr in DATA_NAMES


def state_writes(source: str) -> list[int]:
    """Lines that write ``<data>.state`` (assigned, augmented, ``setattr``) or call a
    ``set_state`` of anything."""
    out = []
    for node in ast.walk(ast.parse(source)):
        targets: list[ast.expr] = []
        if isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            targets = [node.target]
        elif isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Attribute) and f.attr == "set_state":
                out.append(node.lineno)
            if (
                isinstance(f, ast.Name) and f.id == "setattr" and len(node.args) > 1
                and isinstance(node.args[1], ast.Constant) and node.args[1].value == "state"
            ):  # fmt: skip
                out.append(node.lineno)
        for tgt in targets:
            for t in ast.walk(tgt):
                if isinstance(t, ast.Attribute) and t.attr == "state" and _is_data(t.value):
                    out.append(node.lineno)
    return out


def test_only_the_state_machine_writes_the_state():
    found = {}
    for pkg in ("cdprctl", "drivers", "sim_backend"):
        for f in sorted((ROOT / pkg).rglob("*.py")):
            if f == OWNER:
                continue
            lines = state_writes(f.read_text())
            if lines:
                found[str(f.relative_to(ROOT))] = lines
    assert found == {}, f"the state written outside the state machine: {found}"
    assert state_writes(OWNER.read_text()), "the state machine no longer writes the state?"


def test_the_check_sees_a_planted_write():
    planted = (
        "def f(ctl, d):\n"
        "    d.state = 1\n"
        "    ctl.data.state = 2\n"
        "    ctl.supervisor.set_state(3, 0.0, 'x')\n"
        "    setattr(d, 'state', 4)\n"
        "    self.state = 5  # an object's own state: not the loop's\n"
    )
    assert state_writes(planted) == [2, 3, 4, 5]


def test_the_machine_refuses_a_transition_not_in_its_table():
    d = ControlData(4, 0)
    machine = StateMachine(d)
    assert State.ENABLED not in TRANSITIONS[State.INIT]
    assert not machine.request(State.ENABLED, 1.0, "skip the start-up")
    assert d.state is State.INIT and "refused" in d.events[-1][1]
    assert machine.request(State.READY, 2.0, "pose found")
    assert d.state is State.READY and machine.entered == 2.0
