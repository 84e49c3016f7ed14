"""A module's mutation session (tools/mutation.py): the targets of tools/mutation.toml, a
session read back from cosmic-ray's database, and each module's results kept in
tools/mutation_results.json, from which a new checkout resumes and the report is made."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import re
import sqlite3
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
from mutation_equivalents import (  # noqa: E402
    EQUIVALENT_PREFIX,
    KEPT_PREFIX,
    OUT_OF_SCOPE_PREFIX,
    UNSAMPLED_PREFIX,
    load_equivalents,
    mutant_key,
    pending_mutants,
)

OUT = ROOT / "out" / "mutation"
# each module's last results, kept in the repository (the sessions in out/ are not): what the
# report is made of where no session is at hand, as long as the module is the file it was
RESULTS = ROOT / "tools" / "mutation_results.json"


@dataclass(frozen=True)
class Target:
    name: str
    module: str  # path from the repository's root
    tests: str  # pytest arguments: the test files (and selection) that cover the module
    timeout: float = 30.0  # s per mutant's test run at least: a mutant that hangs is killed
    why: str = ""
    # the functions mutated, where the rest of the module cannot be run per mutant (empty:
    # the whole module), and why the rest is left out
    scope: tuple[str, ...] = ()
    left_out: str = ""
    # the fraction of the mutants run (``in_sample``) where all of them cannot be, and why
    sample: float = 1.0
    sample_why: str = ""


TARGETS_FILE = ROOT / "tools" / "mutation.toml"
_SPEC = tomllib.loads(TARGETS_FILE.read_text())
TARGETS = [Target(**{**t, "scope": tuple(t.get("scope", ()))}) for t in _SPEC["target"]]
EXCLUDE_OPERATORS: list[str] = _SPEC["exclude-operators"]
LEFT_OUT: list[dict[str, str]] = _SPEC.get("left-out", [])  # modules not mutated, with why


def tool(name: str) -> str:
    """A cosmic-ray command beside this interpreter (the venv's), else on PATH."""
    here = Path(sys.executable).parent / name
    return str(here) if here.exists() else name


def outcome(t: Target, tree: Path) -> str:
    """A module's session in a line: what ran and the survivors no equivalent explains."""
    mutants = read_session(t, tree)
    mark_equivalents(mutants, load_equivalents())
    killed = sum(m.outcome in KILLED for m in mutants)
    pending = sum(m.outcome == "pending" for m in mutants)
    alive = sum(m.outcome == "survived" and not m.equivalent for m in mutants)
    left = f", {pending} not run yet" if pending else ""
    return (f"{killed} killed, {alive} survivors to kill or write down as equivalent{left} "
            "(docs/mutation.md lists them)")


def has_mutants(db: Path) -> bool:
    """Whether the file is a session that cosmic-ray's init filled."""
    try:
        with sqlite3.connect(db) as con:
            return con.execute("SELECT count(*) FROM mutation_specs").fetchone()[0] > 0
    except sqlite3.Error:
        return False


def survivors_to_run(t: Target, tree: Path) -> list[str]:
    """The job ids of the session's survivors that no entry of the equivalents file explains
    (an explained one would survive again, at the full selection's cost)."""
    mutants = read_session(t, tree)
    mark_equivalents(mutants, load_equivalents())
    return [m.job for m in mutants if m.outcome == "survived" and not m.equivalent and m.job]


def module_digest(tree: Path, module: str) -> str:
    return hashlib.sha256((tree / module).read_bytes()).hexdigest()


def old_lines(diff: str) -> dict[int, str]:
    """The unmutated file's lines a unified diff shows (context and removed), by number."""
    out: dict[int, str] = {}
    n = 0
    for x in diff.splitlines():
        hunk = re.match(r"@@ -(\d+)", x)
        if hunk:
            n = int(hunk.group(1))
        elif n and x[:1] in (" ", "-") and not x.startswith("---"):
            out[n] = x[1:]
            n += 1
    return out


def session_is_stale(t: Target, tree: Path, mutants: list[Mutant] | None = None) -> bool:
    """Whether the module changed since its session was made: its digest then (kept beside
    the session), or, for a session without one, a line of the session's diffs that no longer
    reads as it did (``mutants``: the session, when already read)."""
    digest = OUT / f"{t.name}.sha256"
    if digest.exists():
        return digest.read_text().strip() != module_digest(tree, t.module)
    source = [*(tree / t.module).read_text().splitlines(), ""]  # diffs show the end's ""
    session = read_session(t, tree) if mutants is None else mutants
    lines = (item for m in session for item in old_lines(m.raw_diff).items())
    return any(n > len(source) or source[n - 1] != text for n, text in lines)


# the outcomes that count as killed: a test failed, the tests timed out, the mutant cannot run
KILLED = ("killed", "timeout", "incompetent")


@dataclass
class Mutant:
    module: str
    operator: str
    line: int
    source: str  # the mutated line as the session found it (stripped)
    diff: str  # the changed line(s), "- old / + new"
    outcome: str  # killed, survived, timeout, incompetent, skipped
    raw_diff: str = ""  # cosmic-ray's unified diff of the mutant
    equivalent: str = ""  # why, where it is written down as equivalent
    key: str = ""  # operator@row:col#occurrence: the mutant in any session of the same file
    job: str = ""  # its job id in the session


def read_session(t: Target, tree: Path) -> list[Mutant]:
    db = OUT / f"{t.name}.sqlite"
    if not db.exists():
        return []
    out = subprocess.run([tool("cosmic-ray"), "dump", str(db)], cwd=tree, check=True,
                         capture_output=True, text=True).stdout  # fmt: skip
    source = (tree / t.module).read_text().splitlines()
    mutants = []
    for row in out.splitlines():
        job, result = json.loads(row)
        mu = job["mutations"][0]
        line = int(mu["start_pos"][0])
        if result is None:
            outcome = "pending"
        elif result.get("worker_outcome") == "skipped":
            outcome = "skipped"
            if (result.get("output") or "").startswith(EQUIVALENT_PREFIX):
                outcome = "survived"  # not run: equivalent by a rule known beforehand
            elif (result.get("output") or "").startswith(OUT_OF_SCOPE_PREFIX):
                outcome = "out_of_scope"
            elif (result.get("output") or "").startswith(UNSAMPLED_PREFIX):
                outcome = "unsampled"
            elif (result.get("output") or "").startswith(KEPT_PREFIX):
                outcome = "kept"
        elif result.get("test_outcome") == "killed":
            outcome = "timeout" if result.get("output") == "timeout" else "killed"
        else:
            outcome = result.get("test_outcome") or result.get("worker_outcome") or "?"
        changed = [x for x in ((result or {}).get("diff") or "").splitlines()
                   if x[:1] in "+-" and not x.startswith(("+++", "---"))]  # fmt: skip
        raw = (result or {}).get("diff") or ""
        before = old_lines(raw)  # the line as the session found it, else as it is now
        text = before.get(line, source[line - 1] if line <= len(source) else "").strip()
        key = mutant_key(mu["operator_name"], line, int(mu["start_pos"][1]), mu["occurrence"])
        mutants.append(Mutant(t.module, mu["operator_name"], line, text,
                              " / ".join(c.strip() for c in changed), outcome, raw, "", key,
                              job["job_id"]))  # fmt: skip
        output = (result or {}).get("output") or ""
        if outcome == "survived" and output.startswith(EQUIVALENT_PREFIX):
            mutants[-1].equivalent = output.removeprefix(EQUIVALENT_PREFIX)
    return mutants


def load_results() -> dict[str, dict]:
    return json.loads(RESULTS.read_text()) if RESULTS.exists() else {}


def results_entry(t: Target, tree: Path, mutants: list[Mutant], seconds: int | None) -> dict:
    """A module's results for tools/mutation_results.json: the digest of the file they are of,
    the killed as a count, every other mutant whole (survivors and equivalents are listed);
    for a session not yet complete also the killed by key, so that a later session of the same
    file and tests need not run them again (``resume_killed``)."""
    killed = sum(m.outcome in KILLED for m in mutants)
    rest = [{"operator": m.operator, "line": m.line, "source": m.source, "diff": m.diff,
             "outcome": m.outcome, "equivalent": m.equivalent}
            for m in mutants
            if m.outcome not in (*KILLED, "out_of_scope")]  # fmt: skip
    return {"module": t.module, "sha256": module_digest(tree, t.module),
            "date": session_date(t), "seconds": seconds, "tests": t.tests, "killed": killed,
            "out_of_scope": sum(m.outcome == "out_of_scope" for m in mutants),
            "others": rest,
            **({"killed_keys": {m.key: m.outcome for m in mutants
                                if m.outcome in KILLED and m.key}}
               if any(m.outcome == "pending" for m in mutants) else {})}  # fmt: skip


RESUMED = "resumed from tools/mutation_results.json: "


def resume_killed(db: Path, t: Target, tree: Path) -> int:
    """Mark the pending mutants that a kept, partial session of the same file and the same
    tests killed as killed again (the sessions in out/ do not outlive a checkout; a kill by
    today's tests is a kill tomorrow as long as neither changed). Returns how many."""
    entry = load_results().get(t.name, {})
    done = entry.get("killed_keys", {})
    if not done or entry["sha256"] != module_digest(tree, t.module) or entry["tests"] != t.tests:
        return 0
    marked = 0
    with sqlite3.connect(db) as con:
        for job, op, row, col, occurrence in pending_mutants(con):
            outcome = done.get(mutant_key(op, row, col, occurrence))
            if outcome is None:
                continue
            test = "INCOMPETENT" if outcome == "incompetent" else "KILLED"
            output = "timeout" if outcome == "timeout" else RESUMED + entry["date"]
            con.execute("INSERT INTO work_results (worker_outcome, output, test_outcome, diff, "
                        "job_id) VALUES ('NORMAL', ?, ?, NULL, ?)", (output, test, job))
            marked += 1
    return marked


def kept_survivors(t: Target, tree: Path) -> frozenset[tuple[str, int]]:
    """(operator, line) of the survivors a kept session of the same file found and no
    equivalent explains: a sample runs them again whether it holds them or not (a known
    survivor never drops out of it)."""
    entry = load_results().get(t.name, {})
    if entry.get("sha256") != module_digest(tree, t.module):
        return frozenset()
    mutants = mutants_of(entry)
    mark_equivalents(mutants, load_equivalents())
    return frozenset((m.operator, m.line) for m in mutants
                     if m.outcome == "survived" and not m.equivalent)  # fmt: skip


def kept_is_complete(t: Target, tree: Path) -> bool:
    """Whether tools/mutation_results.json holds a complete session of this file and tests."""
    entry = load_results().get(t.name, {})
    return (entry.get("sha256") == module_digest(tree, t.module) and entry["tests"] == t.tests
            and "killed_keys" not in entry)  # fmt: skip


def merge_survivors_run(entry: dict, mutants: list[Mutant], date: str) -> dict:
    """A kept complete session's results with a survivors-only session's outcomes: each
    kept survivor that now dies moves to the killed (idempotent: one already moved is not
    found among the survivors again)."""
    entry = {**entry, "others": list(entry["others"])}
    for m in mutants:
        if m.outcome not in KILLED:
            continue
        for o in entry["others"]:
            if o["outcome"] == "survived" and (o["operator"], o["line"], o["diff"]) == (
                    m.operator, m.line, m.diff):  # fmt: skip
                entry["others"].remove(o)
                entry["killed"] += 1
                entry["date"] = date
                break
    return entry


def session_date(t: Target) -> str:
    """The day the module's session was last written to."""
    db = OUT / f"{t.name}.sqlite"
    return dt.date.fromtimestamp(db.stat().st_mtime).isoformat()


def mutants_of(entry: dict) -> list[Mutant]:
    """The mutants a kept entry stands for (the killed without their text)."""
    killed = [Mutant(entry["module"], "", 0, "", "", "killed")] * entry["killed"]
    outside = entry.get("out_of_scope", 0)
    killed += [Mutant(entry["module"], "", 0, "", "", "out_of_scope")] * outside
    rest = [Mutant(entry["module"], o["operator"], o["line"], o["source"], o["diff"],
                   o["outcome"], "", o["equivalent"]) for o in entry["others"]]  # fmt: skip
    return killed + rest


def mark_equivalents(mutants: list[Mutant], equivalents: list[dict]) -> set[int]:
    """Survivors written down as equivalent (module or "*", and regular expressions of the
    operator, with or without cosmic-ray's ``core/``, and of the line's text, stripped);
    returns the indices of the entries that matched nothing (stale) — an entry that may be of
    a mutant a sample left out (its operator and line) is not stale."""
    used: set[int] = set()
    for m in mutants:
        if m.outcome not in ("survived", "unsampled"):
            continue
        for i, e in enumerate(equivalents):
            operator = "core/" + e["operator"].removeprefix("core/")
            if not (e["module"] in ("*", m.module) and re.fullmatch(operator, m.operator)
                    and re.fullmatch(e["line"], m.source)):  # fmt: skip
                continue
            if m.outcome == "unsampled":  # not run: its mutant's text is not known
                used.add(i)
            elif re.search(e.get("mutant", ""), m.diff.split(" / +")[-1]):
                m.equivalent = e["why"]
                used.add(i)
                break
    return {i for i, e in enumerate(equivalents) if i not in used
            and any(e["module"] in ("*", t.module) for t in TARGETS)}  # fmt: skip
