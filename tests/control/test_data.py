"""One writer per field of ``ControlData`` (issue 66): every field the cycle publishes is written
by one module, so a reader knows where a value comes from. Read from the source with ``ast``,
like ``tests/control/supervision/test_state_owner.py``: a write is an assignment (plain,
augmented, into a slice) to ``<data>.<field>``, ``np.copyto(<data>.<field>, ...)`` or a
mutating method of it (``fill``, ``append``, ...). An array handed to a stage as a named output
in a call (``cycle_io.py``) is the caller's to name, not a write here. Only the layers that may
import ``ControlData`` are read (control and above: ``tests/test_layers.py``); a planted
second writer shows the check can fail."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

from cdprctl.control.data import ControlData

ROOT = Path(__file__).resolve().parents[2]
OWNER = ROOT / "cdprctl" / "control" / "data.py"
PACKAGES = ("control", "daemon", "telemetry", "experiments", "calibration", "safety",
            "commands")  # fmt: skip
# the names the loop's data goes by where it is written (d, data, self.data, ctl.data, ...)
DATA_NAMES = ("d", "data")
MUTATORS = ("fill", "append", "appendleft", "extend", "clear", "popleft", "pop", "sort")
# Logs, not values: every part reports into them and the daemon drains them (popleft).
LOGS = {"events", "faults"}
# Compiles every stage once before the first cycle and puts back what it wrote (warm_up.py).
RESTORER = "cdprctl/control/lifecycle/warm_up.py"


def _field(node: ast.expr) -> str | None:
    """``<data>.<field>`` → the field, else None."""
    if not isinstance(node, ast.Attribute):
        return None
    v = node.value
    if (isinstance(v, ast.Name) and v.id in DATA_NAMES) or (
        isinstance(v, ast.Attribute) and v.attr in DATA_NAMES
    ):
        return node.attr
    return None


def field_writes(source: str) -> dict[str, list[int]]:
    """The lines of ``source`` that write each field of the loop's data."""
    out: dict[str, list[int]] = defaultdict(list)
    for node in ast.walk(ast.parse(source)):
        written: list[ast.expr] = []
        if isinstance(node, ast.Assign):
            written = [t for tgt in node.targets for t in ast.walk(tgt)]
        elif isinstance(node, (ast.AugAssign, ast.AnnAssign)):
            written = list(ast.walk(node.target))
        elif isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Attribute) and f.attr == "copyto" and node.args:
                written = [node.args[0]]
            elif isinstance(f, ast.Attribute) and f.attr in MUTATORS:
                written = [f.value]
        for t in written:
            name = _field(t)
            if name is not None:
                out[name].append(node.lineno)
    return dict(out)


def writers() -> dict[str, set[str]]:
    """Each field → the modules (paths from the repository's root) that write it."""
    found: dict[str, set[str]] = defaultdict(set)
    for pkg in PACKAGES:
        for f in sorted((ROOT / "cdprctl" / pkg).rglob("*.py")):
            if f == OWNER:
                continue
            for name in field_writes(f.read_text()):
                found[name].add(str(f.relative_to(ROOT)))
    return found


def fields() -> set[str]:
    return set(vars(ControlData(4, 1)))


def shared(found: dict[str, set[str]]) -> dict[str, list[str]]:
    """The fields more than one module writes (the logs and the restorer aside)."""
    return {
        name: sorted(mods - {RESTORER})
        for name, mods in found.items()
        if name not in LOGS and len(mods - {RESTORER}) > 1
    }


def test_each_field_has_one_writer():
    known = fields()
    found = writers()
    assert set(found) <= known, f"not ControlData's: {set(found) - known}"
    assert shared(found) == {}, f"fields with more than one writer: {shared(found)}"
    # the exemptions stay true: the logs have several reporters, the restorer restores
    assert all(len(found[name]) > 1 for name in LOGS)
    assert any(RESTORER in mods for mods in found.values())


def test_the_check_sees_a_planted_second_writer():
    planted = (
        "import numpy as np\n"
        "def f(ctl, d, x):\n"
        "    d.tensions[:] = x\n"
        "    ctl.data.saturation = 1.0\n"
        "    np.copyto(self.data.torques, x)\n"
        "    d.wrench += x\n"
        "    d.events.append((0.0, 'x'))\n"
        "    self.tensions = x  # an object's own array: not the loop's\n"
        "    d.tensions.sum()  # a read\n"
    )
    assert field_writes(planted) == {
        "tensions": [3], "saturation": [4], "torques": [5], "wrench": [6], "events": [7]
    }  # fmt: skip
    # the tree as it is, with that source planted as a module of the desk's package
    found = writers()
    for name in field_writes(planted):
        found[name].add("cdprctl/control/intake/planted.py")  # events: a log
    plant = "cdprctl/control/intake/planted.py"
    assert shared(found) == {
        "tensions": ["cdprctl/control/cycle/distribution.py", plant],
        "saturation": ["cdprctl/control/cycle/distribution.py", plant],
        "torques": ["cdprctl/control/cycle/controller.py", plant],
        "wrench": ["cdprctl/control/cycle/distribution.py", plant],
    }
