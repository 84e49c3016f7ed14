"""Mutants equivalent to the code (no test can kill them), for tools/mutation.py: the entries
of tools/mutation_equivalents.toml (each with why), and the rules known before running — a
``|`` inside an annotation, never evaluated — so such mutants cost no test run; and the
filters that leave mutants out of a session (a target's scope, its sample)."""

from __future__ import annotations

import ast
import hashlib
import re
import sqlite3
import tomllib
from collections.abc import Callable
from pathlib import Path

EQUIVALENTS = Path(__file__).resolve().parent / "mutation_equivalents.toml"


def load_equivalents() -> list[dict]:
    """The entries of tools/mutation_equivalents.toml."""
    if not EQUIVALENTS.exists():
        return []
    return tomllib.loads(EQUIVALENTS.read_text()).get("equivalent", [])


EQUIVALENT_PREFIX = "equivalent: "
ANNOTATION = "annotations are not evaluated (every module has from __future__ import annotations)"


def annotation_operators(source: str) -> set[tuple[int, int]]:
    """(line, column) of every ``|`` inside an annotation (``X | None``): never evaluated."""
    spots: set[tuple[int, int]] = set()
    annotations = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.arg | ast.AnnAssign) and node.annotation is not None:
            annotations.append(node.annotation)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.returns:
            annotations.append(node.returns)
    lines = source.splitlines()
    for ann in annotations:
        for op in ast.walk(ann):
            if isinstance(op, ast.BinOp) and isinstance(op.op, ast.BitOr):
                row, col = op.left.end_lineno or 0, op.left.end_col_offset or 0
                text = lines[row - 1]
                bar = text.index("|", col) if "|" in text[col:] else -1
                if bar >= 0:
                    spots.add((row, bar))
    return spots


def pending_mutants(con: sqlite3.Connection) -> list[tuple[str, str, int, int, int]]:
    """A session's mutants without a result: (job id, operator, row, column, occurrence)."""
    return con.execute(
        "SELECT m.job_id, m.operator_name, m.start_pos_row, m.start_pos_col, m.occurrence "
        "FROM mutation_specs m LEFT JOIN work_results r ON m.job_id = r.job_id "
        "WHERE r.job_id IS NULL"
    ).fetchall()


def skip_pending(db: Path, why_of: Callable[[str, int, int, int], str]) -> int:
    """Mark each pending mutant that ``why_of(operator, row, column, occurrence)`` gives a
    reason for as skipped, that reason its output (how the report tells the kinds apart).
    Returns how many."""
    with sqlite3.connect(db) as con:
        marks = [(why, job) for job, op, row, col, occurrence in pending_mutants(con)
                 if (why := why_of(op, row, col, occurrence))]  # fmt: skip
        con.executemany("INSERT INTO work_results (worker_outcome, output, test_outcome, diff, "
                        "job_id) VALUES ('SKIPPED', ?, NULL, NULL, ?)", marks)  # fmt: skip
    return len(marks)


def skip_known_equivalents(db: Path, tree: Path, module: str) -> int:
    """Mark the pending mutants that are equivalent by a rule known beforehand (``|`` in an
    annotation; the module-independent entries of the equivalents file without a ``mutant``
    pattern) as skipped, with why: they would survive every test, each at the full cost."""
    source = (tree / module).read_text()
    lines = source.splitlines()
    bars = annotation_operators(source)
    rules = [e for e in load_equivalents() if e["module"] == "*" and "mutant" not in e]

    def why_of(op: str, row: int, col: int, _: int) -> str:
        if op.startswith("core/ReplaceBinaryOperator_BitOr_") and (row, col) in bars:
            return EQUIVALENT_PREFIX + ANNOTATION
        text = lines[row - 1].strip()
        why = next((e["why"] for e in rules if re.fullmatch(e["operator"], op)
                    and re.fullmatch(e["line"], text)), "")  # fmt: skip
        return EQUIVALENT_PREFIX + why if why else ""

    return skip_pending(db, why_of)


OUT_OF_SCOPE_PREFIX = "out of scope: "


def scope_lines(source: str, functions: list[str]) -> set[int]:
    """The line numbers of the named functions (at any depth), decorators included."""
    rows: set[int] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.name in functions:
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            rows.update(range(first, (node.end_lineno or node.lineno) + 1))
    return rows


def skip_out_of_scope(db: Path, tree: Path, module: str, scope: list[str], why: str) -> int:
    """Mark the pending mutants outside the target's ``scope`` (function names) as skipped,
    with why they are left out: counted apart, never in the score."""
    if not scope:
        return 0
    inside = scope_lines((tree / module).read_text(), scope)
    return skip_pending(db, lambda _, row, __, ___: "" if row in inside
                        else OUT_OF_SCOPE_PREFIX + why)  # fmt: skip


def mutant_key(operator: str, row: int, col: int, occurrence: int) -> str:
    """A mutant named in any session of the same file: operator@row:col#occurrence."""
    return f"{operator}@{row}:{col}#{occurrence}"


UNSAMPLED_PREFIX = "not in the sample: "


def in_sample(key: str, fraction: float) -> bool:
    """Whether a mutant is in a module's sample: a hash of its key below ``fraction`` of the
    range, so the sample is the same in every session of the file (a resumed or re-run
    session runs the same mutants) and no random state is involved."""
    return int(hashlib.sha256(key.encode()).hexdigest()[:12], 16) < fraction * 16**12


def skip_unsampled(db: Path, fraction: float, why: str,
                   keep: frozenset[tuple[str, int]] = frozenset()) -> int:  # fmt: skip
    """Mark the pending mutants outside the module's sample (``in_sample``) as skipped, with
    why the module is sampled: counted apart, never in the score; those of ``keep``
    (operator, line: an earlier session's survivors) run whether sampled or not. The marks of
    an earlier run are dropped first, so a larger fraction runs the mutants it adds. Returns
    how many."""
    with sqlite3.connect(db) as con:
        con.execute("DELETE FROM work_results WHERE worker_outcome = 'SKIPPED' AND output LIKE ?",
                    (UNSAMPLED_PREFIX + "%",))  # fmt: skip

    def why_of(op: str, row: int, col: int, occurrence: int) -> str:
        sampled = (op, row) in keep or in_sample(mutant_key(op, row, col, occurrence), fraction)
        return "" if sampled else UNSAMPLED_PREFIX + why

    return 0 if fraction >= 1.0 else skip_pending(db, why_of)


KEPT_PREFIX = "counted in the kept results: "


def skip_all_but(db: Path, run: frozenset[tuple[str, int]]) -> int:
    """Mark every pending mutant but those of ``run`` (operator, line) as skipped, their
    outcome being the kept results' (a complete session's survivors run again in a new
    checkout, where the session itself is gone). Returns how many."""
    return skip_pending(db, lambda op, row, _, __: "" if (op, row) in run
                        else KEPT_PREFIX + "survivors only")  # fmt: skip
