"""Mutation testing of the modules where a wrong line is unsafe or silent (``make mutation``).

Runs cosmic-ray (https://cosmic-ray.readthedocs.io) module by module, each against the test
files that cover it, in a scratch copy of the working tree (``out/mutation/tree-<module>``, made
when the module's turn comes, so tests written meanwhile are in it: cosmic-ray
writes each mutant into the file on disk, so the checkout itself is never touched). Numba
kernels are mutated like any other code: each mutant's process recompiles the kernels of the
mutated file (numba's cache is keyed on the source file's stamp), the other files' kernels
come from the copy's cache, warmed by a baseline run.

Writes ``docs/mutation.md``: per module the mutants run, killed, survived, equivalent and the
score (killed / (run − equivalent)), and every survivor that is not written down as equivalent
in ``tools/mutation_equivalents.toml`` (with why). A survivor is a bug no test would catch:
kill it with a test, or explain in that file why no behaviour can change.

A module whose every mutant would take many hours here (numba kernels recompiled per mutant,
closed-loop tests) runs a sample (``sample`` in tools/mutation.toml): the mutants whose key
hashes below the fraction, the same in every session, plus an earlier session's survivors;
the report says how many did not run and why.

A module's session takes up to an hour or two: stopped, it resumes where it stopped (the
session in out/mutation/); in a new checkout, where out/ is gone, the kills of a partial
session are taken from ``tools/mutation_results.json`` (commit the report written with
``--report``) as long as the module and its tests are as they were, so only the rest runs.

    .venv/bin/python tools/mutation.py                 # every module (hours: a benchmark-like job)
    .venv/bin/python tools/mutation.py supervisor torques --jobs 2
    .venv/bin/python tools/mutation.py --report        # the report again from the sessions kept
    .venv/bin/python tools/mutation.py --fresh torques # a new session (after the code changed)
    .venv/bin/python tools/mutation.py --survivors     # only the survivors again (after new tests)
    .venv/bin/python tools/mutation.py --list          # the modules and their tests
"""

from __future__ import annotations

import argparse
import ast
import datetime as dt
import hashlib
import json
import os
import platform
import re
import shutil
import sqlite3
import subprocess
import sys
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
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
    skip_all_but,
    skip_known_equivalents,
    skip_out_of_scope,
    skip_unsampled,
)

OUT = ROOT / "out" / "mutation"
REPORT = ROOT / "docs" / "mutation.md"
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


def sync_tree(dest: Path) -> None:
    """``dest`` ← the working tree's files (tracked and untracked, not ignored); what git no
    longer lists is removed, numba's caches are kept."""
    files = subprocess.run(
        ["git", "ls-files", "-z", "-co", "--exclude-standard"],
        cwd=ROOT, check=True, capture_output=True,
    ).stdout.decode().split("\0")  # fmt: skip
    keep = {f for f in files if f and (ROOT / f).is_file()}
    dest.mkdir(parents=True, exist_ok=True)
    for f in keep:
        src, dst = ROOT / f, dest / f
        if not dst.exists() or dst.read_bytes() != src.read_bytes():
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst)
    for p in dest.rglob("*"):
        rel = p.relative_to(dest).as_posix()
        if p.is_file() and rel not in keep and "__pycache__" not in rel and not rel.startswith(
            (".pytest_cache", "out/")
        ):
            p.unlink()


def config_text(t: Target, timeout: float, command: str) -> str:
    excludes = ",\n    ".join(json.dumps(e) for e in EXCLUDE_OPERATORS)
    return f"""[cosmic-ray]
module-path = "{t.module}"
timeout = {timeout:.0f}
excluded-modules = []
test-command = {json.dumps(command)}

[cosmic-ray.distributor]
name = "local"

[cosmic-ray.filters.operators-filter]
exclude-operators = [
    {excludes},
]
"""


def importers(tree: Path, module: str) -> set[str]:
    """The file stems of ``module`` and of every module of the tree that imports it, directly
    or through others (their numba kernels may have compiled the module's code in)."""
    names = {}
    for pkg in ("cdprctl", "drivers", "sim_backend"):
        for f in (tree / pkg).rglob("*.py"):
            rel = f.relative_to(tree).with_suffix("")
            parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
            names[".".join(parts)] = f
    deps: dict[str, set[str]] = {}
    for name, f in names.items():
        found = set()
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
        deps[name] = {d for d in found if d in names}
    target = ".".join(Path(module).with_suffix("").parts)
    hit, grew = {target}, True
    while grew:
        new = {n for n, d in deps.items() if n not in hit and d & hit}
        grew = bool(new)
        hit |= new
    return {names[n].stem for n in hit if names[n].stem != "__init__"}


def run_target(t: Target, tree: Path, log, fresh: bool, survivors: bool) -> None:
    """One module's session, kept in out/mutation/<name>.sqlite: the tests run unmutated first
    (they must pass; they also warm the numba cache every mutant starts from) and then as a
    mutant runs, then init, the filters, exec with a per-mutant timeout of
    ``max(t.timeout, 4 × that second run)``, each mutant on a copy of that cache without the
    entries that may hold the module's code (``tools/mutation_pytest.sh``)."""
    cfg, db = OUT / f"{t.name}.toml", OUT / f"{t.name}.sqlite"
    base = OUT / f"numba-{tree.name}"
    shutil.rmtree(base, ignore_errors=True)  # never a cache written while a mutant was on disk
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    # the vendors' files beside the checkout, not beside its copies (tests/local_drives.py)
    eds = Path(os.environ.get("CDPRCTL_VENDOR_EDS", ROOT.parent / "shared" / "vendor_eds"))
    if eds.is_dir():
        env["CDPRCTL_VENDOR_EDS"] = str(eds.resolve())
    else:
        log(f"{t.name}: no vendor EDS files at {eds}: the tests that read them skip and cannot "
            "kill a mutant (CDPRCTL_VENDOR_EDS=<folder> names them)")

    def run(*cmd: str, check: bool = True) -> subprocess.CompletedProcess:
        return subprocess.run(cmd, cwd=tree, env=env, check=check, capture_output=True, text=True)

    if survivors and not db.exists() and not fresh and kept_is_complete(t, tree) and not (
            kept_survivors(t, tree)):  # fmt: skip
        log(f"{t.name}: its kept session has no survivors left: nothing to run")
        return
    start = time.monotonic()
    base_run = subprocess.run(  # compiles every kernel into the cache
        f"{sys.executable} -m pytest -x -q -p no:cacheprovider {t.tests}", shell=True, cwd=tree,
        env={**env, "NUMBA_CACHE_DIR": str(base)}, capture_output=True, text=True,
    )  # fmt: skip
    if base_run.returncode != 0:
        log(f"{t.name}: the tests fail unmutated, skipped:\n{base_run.stdout[-3000:]}")
        db.unlink(missing_ok=True)
        return
    stems = " ".join(sorted(importers(tree, t.module)))
    command = (f"sh tools/mutation_pytest.sh {sys.executable} {base} '{stems}' "
               f"-x -q -p no:cacheprovider {t.tests}")  # fmt: skip
    # the timeout from the mutants' own command on the unmutated code (the warm cache but the
    # module's kernels recompiled): from the cold run it was 4 × 231 s for sim-axis, and each
    # mutant that hangs (a loop that no longer ends) took all of that
    warm = time.monotonic()
    subprocess.run(command, shell=True, cwd=tree, env=env, capture_output=True, text=True)
    baseline = time.monotonic() - warm
    cfg.write_text(config_text(t, max(t.timeout, 4.0 * baseline), command))
    if db.exists() and not has_mutants(db):  # made by a look into it before init, say
        db.unlink()
    if db.exists() and not fresh and session_is_stale(t, tree):
        log(f"{t.name}: {t.module} changed since its session was made: starting it anew")
        fresh = True
    if fresh or not db.exists():
        (OUT / f"{t.name}.sha256").write_text(module_digest(tree, t.module) + "\n")
        run(tool("cosmic-ray"), "init", str(cfg), str(db), "--force")
        run(tool("cr-filter-operators"), str(db), str(cfg))
        run(tool("cr-filter-pragma"), str(db))
        n = skip_known_equivalents(db, tree, t.module)
        log(f"{t.name}: {n} mutants equivalent by a known rule, not run")
        n = skip_out_of_scope(db, tree, t.module, list(t.scope), t.left_out)
        if n:
            log(f"{t.name}: {n} mutants outside {', '.join(t.scope)}, left out")
        n = 0 if fresh else resume_killed(db, t, tree)
        if n:
            log(f"{t.name}: {n} mutants killed in a kept partial session, not run again")
        if survivors and not fresh and kept_is_complete(t, tree):
            n = skip_all_but(db, kept_survivors(t, tree))
            log(f"{t.name}: only the kept session's survivors again ({n} mutants counted as "
                "kept)")
    else:
        if survivors:  # their results dropped: exec runs them again, against today's tests
            again = survivors_to_run(t, tree)
            with sqlite3.connect(db) as con:
                con.executemany("DELETE FROM work_results WHERE job_id = ?",
                                [(j,) for j in again])  # fmt: skip
            log(f"{t.name}: {len(again)} survivors to run again (those not written down as "
                "equivalent)")
        log(f"{t.name}: resuming the session kept in {db.relative_to(ROOT)}")
    n = skip_unsampled(db, t.sample, t.sample_why, kept_survivors(t, tree))  # after the kept
    # kills: those stay run
    if n:
        log(f"{t.name}: {n} mutants outside its {100 * t.sample:.0f} % sample, not run")
    run(tool("cosmic-ray"), "exec", str(cfg), str(db))
    took = time.monotonic() - start
    if fresh or not (OUT / f"{t.name}.seconds").exists():  # a whole session's time
        (OUT / f"{t.name}.seconds").write_text(f"{took:.0f}\n")
    log(f"{t.name}: done in {took:.0f} s (the tests alone: {baseline:.0f} s); {outcome(t, tree)}")


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


def report(targets: list[Target], tree: Path) -> str:
    """The report's text; the sessions at hand are kept in tools/mutation_results.json."""
    equivalents = load_equivalents()
    rows, survivors, totals, scoped, sampled = [], [], [0, 0, 0, 0], [], []
    samples, not_sampled = 0, 0  # complete modules that ran a sample, the mutants they left
    by_rule = 0  # equivalent by a rule known beforehand: counted, never run
    waiting: list[str] = []  # modules the score does not yet hold, each with why
    all_mutants: list[Mutant] = []
    kept = load_results()
    seconds: dict[str, int | None] = {}
    for t in targets:
        took = OUT / f"{t.name}.seconds"
        ms = read_session(t, tree)
        if any(m.outcome == "kept" for m in ms) and t.name in kept:  # survivors only
            kept[t.name] = merge_survivors_run(kept[t.name], ms, session_date(t))
            ms = mutants_of(kept[t.name])
            seconds[t.name] = kept[t.name]["seconds"]
        elif ms and not session_is_stale(t, tree, ms):  # a session at hand: its results kept
            seconds[t.name] = int(took.read_text()) if took.exists() else None
            kept[t.name] = results_entry(t, tree, ms, seconds[t.name])
        elif not ms and t.name in kept:
            ms = mutants_of(kept[t.name])
            seconds[t.name] = kept[t.name]["seconds"]
        all_mutants += ms
    stale = mark_equivalents(all_mutants, equivalents)
    out_of_date: set[str] = set()  # modules whose session is of an older file: not listed
    for t in targets:
        ms = [m for m in all_mutants if m.module == t.module]
        if not ms:
            rows.append(f"| {t.name} | `{t.module}` | not run | | | | | | |")
            waiting.append(f"{t.name} (not run)")
            continue
        changed = t.name in kept and kept[t.name]["sha256"] != module_digest(tree, t.module)
        if changed or session_is_stale(t, tree, ms):  # figures of a file no longer there
            out_of_date.add(t.module)
            waiting.append(f"{t.name} (the file changed since its session: `--fresh {t.name}`)")
            rows.append(f"| {t.name} | `{t.module}` | not run (the file changed since its "
                        f"session: `--fresh {t.name}`) | | | | | | |")  # fmt: skip
            continue
        run = [m for m in ms
               if m.outcome not in ("skipped", "pending", "out_of_scope", "unsampled")]
        outside = sum(m.outcome == "out_of_scope" for m in ms)
        if outside:
            scoped.append(f"- {t.name}: {outside} mutants outside {', '.join(t.scope)} left "
                          f"out — {t.left_out}")  # fmt: skip
        unsampled = sum(m.outcome == "unsampled" for m in ms)
        # the mutants a session runs: not those of the operators left out nor outside a scope
        eligible = len(ms) - outside - sum(m.outcome == "skipped" for m in ms)
        if unsampled:
            sampled.append(f"- {t.name}: {eligible - unsampled} of {eligible} mutants run, "
                           f"{unsampled} not: its {100 * t.sample:.0f} % sample and those an "
                           "earlier partial session ran or that share an operator and line "
                           f"with a survivor — {t.sample_why}")  # fmt: skip
        killed = [m for m in run if m.outcome in KILLED]
        equiv = [m for m in run if m.equivalent]
        alive = [m for m in run if m.outcome == "survived" and not m.equivalent]
        pending = sum(m.outcome == "pending" for m in ms)
        denom = len(run) - len(equiv)
        score = f"{100.0 * len(killed) / denom:.1f} %" if denom else "—"
        if pending:
            score += f" ({pending} not run yet)"
        wall = f"{seconds[t.name] / 60:.0f} min" if seconds.get(t.name) else "?"
        rows.append(f"| {t.name} | `{t.module}` | {len(run)} | {len(killed)} | {len(alive)} | "
                    f"{len(equiv)} | {score} | {wall} | {t.tests} |")  # fmt: skip
        survivors += [(bool(pending), m) for m in alive]
        if pending:  # a partial session: listed, not yet in the score
            waiting.append(f"{t.name} ({pending} of {eligible} not run yet)")
            continue
        samples += bool(unsampled)
        not_sampled += unsampled
        by_rule += sum(bool(m.equivalent) and not m.diff for m in run)
        for i, v in enumerate((len(run), len(killed), len(alive), len(equiv))):
            totals[i] += v
    denom = totals[0] - totals[3]
    complete = len(targets) - len(waiting)
    lines = [
        "# Mutation testing",
        "",
        "Generated by `make mutation` (`tools/mutation.py`, cosmic-ray) — do not edit by hand.",
        "",
        "A survivor is a change of the code no test notices. Kill it with a test that fails on "
        "the mutant (apply it by hand, run the test, put the line back), then run "
        "`.venv/bin/python tools/mutation.py <module> --survivors`, which runs only the "
        "survivors again; or, where no behaviour can change, write it down in "
        "`tools/mutation_equivalents.toml` (module, operator, a regular expression of the "
        "original line, of the mutant where the line has several, and why) and run "
        "`--report`.",
        "",
        f"Sessions up to {max((e['date'] for e in kept.values()), default='—')} (each "
        f"module's day is in `tools/mutation_results.json`), Python {platform.python_version()}, "
        f"{os.cpu_count()} CPUs, cosmic-ray {cosmic_ray_version()}.",
        "",
        (f"**Score: {100.0 * totals[1] / denom:.1f} % of {denom} non-equivalent mutants killed**"
         f" in the {complete} of {len(targets)} modules whose session is complete"
         f"{f' ({samples} of them a sample: {not_sampled} mutants not run)' if samples else ''}"
         " and of the file as it is") if denom
        else "**No module's session is complete yet.**",
        f"({totals[0]} mutants: {totals[1]} killed, {totals[2]} survived, {totals[3]} equivalent, "
        f"{by_rule} of those by a rule known beforehand and not run).",
        *(["", f"Not yet in the score: {'; '.join(waiting)}."] if waiting else []),
        "",
        "| module | file | mutants | killed | survived | equivalent | score | wall time | tests |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
        "Operators: arithmetic among + − × ÷, bit operations among themselves, comparisons, "
        "and/or, not, unary minus, True/False, break/continue, numbers ±1, zero-iteration "
        "loops, exceptions replaced (`tools/mutation.toml` lists what is left out "
        "and why). A mutant is killed when a test fails or the tests exceed the module's "
        "timeout; incompetent mutants (that cannot run at all) count as killed.",
        "",
        *([*["Left out of a module (mutated in part, `scope` in `tools/mutation.toml`):"],
           *scoped, ""] if scoped else []),
        *([*["Sampled (a module's mutants whose key — operator, line, column — hashes below "
             "its `sample` in `tools/mutation.toml`: the same mutants in every session of the "
             "file; the score is of those run):"], *sampled, ""] if sampled else []),
        *(["Left out (not mutated, `left-out` in `tools/mutation.toml`):",
           *[f"- `{x['module']}`: {x['why']}" for x in LEFT_OUT], ""] if LEFT_OUT else []),
        "Modules outside these targets are checked independently: bugs planted one at a time "
        "in a scratch copy; those no test caught have tests now (`tests/test_unlisted_modules.py`"
        " lists them).",
        "",
        "## Survivors",
        "",
    ]
    if not survivors:
        lines.append("None.")
    for partial, m in sorted(survivors, key=lambda x: x[0]):
        note = " (its module's session is not complete: not yet in the score)" if partial else ""
        lines.append(f"- `{m.module}:{m.line}` {m.operator.removeprefix('core/')}: "
                     f"`{m.diff}`{note}")  # fmt: skip
    lines += ["", "## Equivalent mutants", ""]
    eq = [m for m in all_mutants if m.equivalent and m.module not in out_of_date]
    if not eq:
        lines.append("None.")
    for m in eq:  # one equivalent by a rule known beforehand never ran: its line instead
        text = f"`{m.diff}`" if m.diff else f"not run, on `{m.source}`"
        lines.append(f"- `{m.module}:{m.line}` {m.operator.removeprefix('core/')}: {text} "
                     f"— {m.equivalent}")  # fmt: skip
    RESULTS.write_text(json.dumps(kept, indent=1, sort_keys=True) + "\n")
    if stale:
        lines += ["", "Entries of `tools/mutation_equivalents.toml` that matched no survivor "
                  "(the code or the tests changed: delete or correct them):", ""]  # fmt: skip
        lines += [f"- entry {i + 1}: `{equivalents[i]['module']}` "
                  f"{equivalents[i]['operator']} `{equivalents[i]['line']}`" for i in sorted(stale)]

    return "\n".join(lines) + "\n"


def cosmic_ray_version() -> str:
    try:
        from importlib.metadata import version

        return version("cosmic-ray")
    except Exception:
        return "?"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    ap.add_argument("modules", nargs="*", help="module names (--list); default every one")
    ap.add_argument("--jobs", type=int, default=1, help="modules run at once (one tree each)")
    ap.add_argument("--report", action="store_true", help="only write the report again")
    ap.add_argument("--fresh", action="store_true",
                    help="start each module's session anew (default: resume what is kept)")
    ap.add_argument("--survivors", action="store_true",
                    help="run the kept sessions' survivors again (after new tests)")
    ap.add_argument("--list", action="store_true", help="list the modules and their tests")
    a = ap.parse_args(argv)
    if a.list:
        for t in TARGETS:
            print(f"{t.name:22} {t.module:38} {t.tests}")
        return 0
    unknown = set(a.modules) - {t.name for t in TARGETS}
    if unknown:
        print(f"mutation: unknown module(s) {', '.join(sorted(unknown))}; --list shows them")
        return 2
    if shutil.which(tool("cosmic-ray")) is None:
        print("mutation: cosmic-ray is not installed: run `make mutation` (it installs the "
              "project's [mutation] extra)")  # fmt: skip
        return 2
    by_name = {t.name: t for t in TARGETS}
    chosen = [by_name[n] for n in a.modules] if a.modules else list(TARGETS)  # in that order
    OUT.mkdir(parents=True, exist_ok=True)
    logfile = OUT / "log.txt"

    def log(msg: str) -> None:
        print(msg, flush=True)
        with logfile.open("a") as f:
            f.write(f"{dt.datetime.now().isoformat(timespec='seconds')} {msg}\n")

    if not a.report:
        queue = list(chosen)

        def worker(_: int) -> None:
            while queue:
                t = queue.pop(0)
                tree = OUT / f"tree-{t.name}"  # its own: runs of other modules may go on
                sync_tree(tree)
                log(f"{t.name}: {t.module} against {t.tests}")
                run_target(t, tree, log, a.fresh, a.survivors)

        jobs = max(1, a.jobs)
        with ThreadPoolExecutor(jobs) as pool:
            list(pool.map(worker, range(jobs)))
    # against the working tree: a copy may hold a mutant of a run going on (syncing it for the
    # report had put the original back under that mutant's tests)
    REPORT.write_text(report(TARGETS, ROOT))
    print(f"mutation: {REPORT.relative_to(ROOT)} written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
