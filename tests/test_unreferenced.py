"""Nothing defined that no one reads: every function, method, class and module-level constant of
``cdprctl``, ``drivers`` and ``sim_backend`` is named somewhere besides its own definition — in
the packages, the tests, the benchmarks, the tools or ``pyproject.toml`` (an entry point), as
code or inside a string (``getattr``, a patch target). Read from the source with ``tokenize``
and ``ast``: nothing is imported. By name, so a definition whose name another one also carries
is taken as read (the check misses some dead code, never reports live code); what is called
from outside this tree by its name alone (a library's hook, a dunder) is listed below."""

from __future__ import annotations

import ast
import io
import re
import tokenize
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFINED_IN = ("cdprctl", "drivers", "sim_backend")
READ_IN = (*DEFINED_IN, "tests", "benchmarks", "tools")
WORD = re.compile(r"[A-Za-z_]\w*")

#: called by name from outside the tree: (module, name), each with why
ENTRY_POINTS: dict[tuple[str, str], str] = {}


def definitions(tree: ast.Module) -> list[tuple[str, int, int | None]]:
    """(name, line, column) of each function, method and class anywhere (no column: the name
    follows ``def``/``class``), and of each module-level assignment's target (a constant)."""
    out: list[tuple[str, int, int | None]] = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.append((node.name, node.lineno, None))
    for node in tree.body:
        targets = (node.targets if isinstance(node, ast.Assign)
                   else [node.target] if isinstance(node, ast.AnnAssign) else [])  # fmt: skip
        for t in targets:
            out += [(n.id, n.lineno, n.col_offset) for n in ast.walk(t) if isinstance(n, ast.Name)]
    return out


def uses(source: str, targets: set[tuple[int, int]]) -> Counter[str]:
    """Every identifier the source names, in code and as words inside strings, but the names
    it defines: those after ``def``/``class`` and the assignment ``targets`` (line, column)."""
    out: Counter[str] = Counter()
    prev = ""
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NAME:
            if prev not in ("def", "class") and tok.start not in targets:
                out[tok.string] += 1
        elif tok.type == tokenize.STRING or tok.type == getattr(tokenize, "FSTRING_MIDDLE", -1):
            out.update(WORD.findall(tok.string))
        if tok.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.COMMENT):
            prev = tok.string
    return out


def unreferenced() -> list[str]:
    """``module:line name`` of each definition in ``DEFINED_IN`` whose name nothing reads."""
    used: Counter[str] = Counter(WORD.findall((ROOT / "pyproject.toml").read_text()))
    candidates: list[tuple[str, str, int]] = []
    for top in READ_IN:
        for f in sorted((ROOT / top).rglob("*.py")):
            source = f.read_text()
            defined = definitions(ast.parse(source))
            used += uses(source, {(line, col) for _, line, col in defined if col is not None})
            if top in DEFINED_IN:
                module = ".".join(f.relative_to(ROOT).with_suffix("").parts)
                candidates += [(module, name, line) for name, line, _ in defined]
    return [f"{module}:{line} {name}" for module, name, line in candidates
            if not used[name] and not _exempt(module, name)]  # fmt: skip


def _exempt(module: str, name: str) -> bool:
    return (name.startswith("__") and name.endswith("__")) or (module, name) in ENTRY_POINTS


def test_every_definition_is_read_somewhere():
    assert unreferenced() == []


def test_the_check_sees_a_function_no_one_calls(tmp_path, monkeypatch):
    """The check itself can fail: a planted function and a constant nothing names are
    reported, a function that a string names is not."""
    pkg = tmp_path / "cdprctl"
    pkg.mkdir()
    (pkg / "x.py").write_text(
        "def never_called_anywhere():\n    return 1\n\n"
        "def named_in_a_string():\n    return 2\n\n"
        "HANDLERS = {'named_in_a_string': 1}\n"
    )
    (tmp_path / "pyproject.toml").write_text("")
    monkeypatch.setattr("test_unreferenced.ROOT", tmp_path)
    assert unreferenced() == ["cdprctl.x:1 never_called_anywhere", "cdprctl.x:7 HANDLERS"]
