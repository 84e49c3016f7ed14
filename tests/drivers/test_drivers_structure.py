"""The shape of ``drivers/`` (issue 66, point 3): a driver is composed of parts that talk through
their public attributes — no module reaches into another object's ``_private`` fields — the
package's modules import one another without a circle, and none is over 400 lines, no function
over 80. Each rule is checked on a planted example too, so that it is not blind."""

from __future__ import annotations

import ast
import re
from pathlib import Path

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


def imports_within(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of ``known`` that module ``name`` imports — anywhere in it, under
    ``TYPE_CHECKING`` too; ``from package import module`` is an import of the module."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*parts, base] if base else parts)
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.add(sub if sub in known else base)
    return {m for m in out if m in known and m != name}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


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
