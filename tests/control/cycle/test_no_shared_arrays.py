"""No stage of the cycle keeps another's arrays (issue 66): after construction, walk what each
component of the controller holds (its attributes, into tuples, lists, dicts, bound methods
and the helper objects it owns) and list every pair where one holds another component or an
array another holds. The declared bundles are not components: ``ControlData`` (the outputs
every reader reads), the robot's description (frozen; arrays of it are configuration), the
ports the supervisor asks (the drives' view, the state machine), and ``Controller.io``
(``cycle_io.py``: the controller builds them and hands them to the stages in each call; no
stage keeps one).

What is left of the old wiring is listed in ``LEFT_HELD`` and ``LEFT_SHARED`` and must match
exactly: a link that goes is taken off the list, a new one fails."""

from __future__ import annotations

import enum
import types

import numpy as np
import pytest
from conftest import CONFIG, FakeDrives, in_torque_mode

from cdprctl.control.cycle.controller import Controller
from cdprctl.control.data import ControlData
from cdprctl.robot_file import load_robot
from drivers.vocabulary import Lifecycle

COMPONENTS = (
    "estimator", "trajectory", "reference", "pose", "winches", "distribution", "observer",
    "cable_space", "grippers", "supervisor", "limits", "jog", "path",
)  # fmt: skip
# Links still there (issue 66 has them as the next steps), holder → held: the grippers
# read the estimate, the working pose (position mode: the reference), the trajectory, the
# winches, and impose on the distribution.
LEFT_HELD = {
    ("grippers", "estimator"), ("grippers", "trajectory"), ("grippers", "winches"),
    ("grippers", "distribution"),
    # the winch law's terms a friction calibration replaces at start-up: one set, read by the
    # torques, the cable space, the grasp sensing and the observer alike (docs/friction.md)
    ("observer", "winches"),
}  # fmt: skip
POSITION_MODE_HELD = {("grippers", "reference")}
# arrays two components share: the known external wrench (the controller's, which the
# gripper experiment sets in place) is the grippers' and the soft limits'
LEFT_SHARED = {frozenset({"grippers", "limits"})}


def _root(a: np.ndarray) -> int:
    while isinstance(a.base, np.ndarray):
        a = a.base
    return id(a)


def _declared(x: object) -> bool:
    """A declared bundle or a leaf the walk does not enter."""
    mod = type(x).__module__ or ""
    return (
        isinstance(x, (ControlData, str, bytes, int, float, complex, bool, enum.Enum, type))
        or x is None
        or isinstance(x, (types.FunctionType, types.BuiltinFunctionType, types.ModuleType))
        or mod.startswith(("cdprctl.model", "numba", "ruckig", "drivers", "builtins"))
        or mod in ("cdprctl.control.lifecycle.drive_view",
                   "cdprctl.control.supervision.state_machine")
    )


def reach(obj: object, components: dict[int, str]) -> tuple[set[int], set[str]]:
    """The arrays (by the id of the memory's owner) and the other components ``obj`` holds."""
    arrays: set[int] = set()
    held: set[str] = set()
    seen = {id(obj)}
    stack = [v for v in vars(obj).values()]
    while stack:
        x = stack.pop()
        if id(x) in seen:
            continue
        seen.add(id(x))
        if id(x) in components:
            held.add(components[id(x)])
        elif isinstance(x, np.ndarray):
            arrays.add(_root(x))
        elif isinstance(x, types.MethodType):
            stack.append(x.__self__)
        elif isinstance(x, (tuple, list, set, frozenset)):
            stack.extend(x)
        elif isinstance(x, dict):
            stack.extend(x.values())
        elif not _declared(x) and hasattr(x, "__dict__"):
            stack.extend(vars(x).values())
    return arrays, held


def model_arrays(model: object) -> set[int]:
    out: set[int] = set()
    stack, seen = [model], set()
    while stack:
        x = stack.pop()
        if id(x) in seen:
            continue
        seen.add(id(x))
        if isinstance(x, np.ndarray):
            out.add(_root(x))
        elif isinstance(x, (tuple, list)):
            stack.extend(x)
        elif isinstance(x, dict):
            stack.extend(x.values())
        elif hasattr(x, "__dict__") and not isinstance(x, type):
            stack.extend(vars(x).values())
    return out


def links(c: Controller) -> tuple[set[tuple[str, str]], set[frozenset[str]]]:
    """(holder, held) components; the pairs that share an array."""
    comps = {id(getattr(c, n)): n for n in COMPONENTS}
    config = model_arrays(c.model)
    found: dict[str, tuple[set[int], set[str]]] = {}
    for n in COMPONENTS:
        arrays, held = reach(getattr(c, n), {k: v for k, v in comps.items() if v != n})
        found[n] = (arrays - config, held)
    holds = {(a, b) for a, (_, held) in found.items() for b in held}
    shared = {
        frozenset({a, b})
        for i, a in enumerate(COMPONENTS)
        for b in COMPONENTS[i + 1 :]
        if found[a][0] & found[b][0]
    }
    return holds, shared


ROBOTS = {"rowc": ("rowc.toml", False), "rowc-torque": ("rowc.toml", True),
          "seed000_grippers": ("seed000_grippers.toml", False)}  # fmt: skip


@pytest.mark.parametrize("robot", list(ROBOTS))
def test_no_component_keeps_another_components_arrays(robot):
    file, torque = ROBOTS[robot]
    model = load_robot(CONFIG / file)
    model = in_torque_mode(model) if torque else model
    c = Controller(model, FakeDrives(model.n_cables, Lifecycle.INACTIVE))
    holds, shared = links(c)
    assert holds == LEFT_HELD | (POSITION_MODE_HELD if model.drives.holds_lengths else set())
    assert shared == LEFT_SHARED


def test_the_walk_sees_a_planted_alias():
    """The check can fail: the pose controller given the trajectory's reference array at
    construction (as it was before issue 66) is a link."""
    model = load_robot(CONFIG / "rowc.toml")
    c = Controller(model, FakeDrives(model.n_cables, Lifecycle.INACTIVE))
    c.pose._ref = (c.trajectory.position, c.trajectory.velocity)
    assert frozenset({"pose", "trajectory"}) in links(c)[1]
    c.pose._ref = None
    c.pose.at = c.estimator  # a component held outright
    assert ("pose", "estimator") in links(c)[0]
