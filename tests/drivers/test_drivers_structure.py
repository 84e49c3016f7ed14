"""The shape of ``drivers/`` (issue 66, point 3): a driver is composed of parts that talk through
their public attributes — no module reaches into another object's ``_private`` fields — the
package's modules import one another without a circle, and none is over 400 lines, no function
over 80. Each rule is checked on a planted example too, so that it is not blind."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from import_graph import circles, imports_within

ROOT = Path(__file__).resolve().parent.parent.parent
DRIVERS = ROOT / "drivers"
PRIVATE = re.compile(r"^_[a-z]")  # _field, not __dunder__ (nor a _Class)
MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 80


def private_reaches(source: str) -> list[str]:
    """Each ``x._field`` in ``source`` where ``x`` is not ``self``, ``cls`` or ``super()``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not (isinstance(node, ast.Attribute) and PRIVATE.match(node.attr)):
            continue
        owner = node.value
        if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
            continue
        if (isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name)
                and owner.func.id == "super"):  # fmt: skip
            continue
        found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def modules() -> dict[str, Path]:
    out = {}
    for f in DRIVERS.rglob("*.py"):
        parts = f.relative_to(ROOT).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


def test_no_module_reaches_into_another_objects_private_fields():
    reaches = {
        str(f.relative_to(ROOT)): r
        for f in sorted(DRIVERS.rglob("*.py"))
        if (r := private_reaches(f.read_text()))
    }
    assert not reaches, reaches


def test_the_private_reach_check_is_not_blind():
    planted = "def f(drv, self):\n    drv._command[:] = 0\n    self._ok = super()._warm_up()\n"
    assert private_reaches(planted) == ["2: drv._command"]


def test_drivers_import_one_another_without_a_circle():
    mods = modules()
    graph = {name: imports_within(name, path, set(mods)) for name, path in mods.items()}
    assert "drivers.transport" in graph["drivers.cia402.driver"]  # the graph is not empty
    assert circles(graph) == []


def test_the_circle_check_is_not_blind():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_over_400_lines_no_function_over_80():
    long = []
    for f in sorted(DRIVERS.rglob("*.py")):
        source = f.read_text()
        where = str(f.relative_to(ROOT))
        if len(source.splitlines()) > MAX_MODULE_LINES:
            long.append(f"{where}: {len(source.splitlines())} lines")
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    long.append(f"{where}:{node.lineno} {node.name}: {n} lines")
    assert not long, long
