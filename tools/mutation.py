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
import json
import os
import shutil
import sqlite3
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

# run as a script, tools/ is on sys.path
import mutation_equivalents as eqv
import mutation_session as ms
from mutation_report import report
from mutation_session import OUT, ROOT, TARGETS, Target, tool

REPORT = ROOT / "docs" / "mutation.md"


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
    excludes = ",\n    ".join(json.dumps(e) for e in ms.EXCLUDE_OPERATORS)
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



def test_env(t: Target, log) -> dict[str, str]:
    """The environment the module's tests run in: no bytecode written into the copy, and the
    vendors' EDS files beside the checkout, not beside its copies (tests/local_drives.py)."""
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    eds = Path(os.environ.get("CDPRCTL_VENDOR_EDS", ROOT.parent / "shared" / "vendor_eds"))
    if eds.is_dir():
        env["CDPRCTL_VENDOR_EDS"] = str(eds.resolve())
    else:
        log(f"{t.name}: no vendor EDS files at {eds}: the tests that read them skip and cannot "
            "kill a mutant (CDPRCTL_VENDOR_EDS=<folder> names them)")
    return env


def mutant_command(t: Target, tree: Path, env: dict[str, str], base: Path, log
                   ) -> tuple[str, float] | None:  # fmt: skip
    """The command each mutant's tests run with and how long it takes on the unmutated code
    (s); None, said in the log, where the tests fail unmutated. The first run compiles every
    kernel into the cache ``base`` the mutants start from."""
    base_run = subprocess.run(  # compiles every kernel into the cache
        f"{sys.executable} -m pytest -x -q -p no:cacheprovider {t.tests}", shell=True, cwd=tree,
        env={**env, "NUMBA_CACHE_DIR": str(base)}, capture_output=True, text=True,
    )  # fmt: skip
    if base_run.returncode != 0:
        log(f"{t.name}: the tests fail unmutated, skipped:\n{base_run.stdout[-3000:]}")
        return None
    stems = " ".join(sorted(importers(tree, t.module)))
    command = (f"sh tools/mutation_pytest.sh {sys.executable} {base} '{stems}' "
               f"-x -q -p no:cacheprovider {t.tests}")  # fmt: skip
    # the timeout from the mutants' own command on the unmutated code (the warm cache but the
    # module's kernels recompiled): from the cold run it was 4 × 231 s for sim-axis, and each
    # mutant that hangs (a loop that no longer ends) took all of that
    warm = time.monotonic()
    subprocess.run(command, shell=True, cwd=tree, env=env, capture_output=True, text=True)
    return command, time.monotonic() - warm


def init_session(t: Target, tree: Path, cfg: Path, db: Path, run, log, fresh: bool,
                 survivors: bool) -> None:  # fmt: skip
    """A new session: cosmic-ray's init and filters, then the mutants known beforehand (a
    known equivalent, outside the scope, killed in a kept partial session, or, for
    ``survivors``, all but the kept session's survivors) marked so that exec skips them."""
    (OUT / f"{t.name}.sha256").write_text(ms.module_digest(tree, t.module) + "\n")
    run(tool("cosmic-ray"), "init", str(cfg), str(db), "--force")
    run(tool("cr-filter-operators"), str(db), str(cfg))
    run(tool("cr-filter-pragma"), str(db))
    n = eqv.skip_known_equivalents(db, tree, t.module)
    log(f"{t.name}: {n} mutants equivalent by a known rule, not run")
    n = eqv.skip_out_of_scope(db, tree, t.module, list(t.scope), t.left_out)
    if n:
        log(f"{t.name}: {n} mutants outside {', '.join(t.scope)}, left out")
    n = 0 if fresh else ms.resume_killed(db, t, tree)
    if n:
        log(f"{t.name}: {n} mutants killed in a kept partial session, not run again")
    if survivors and not fresh and ms.kept_is_complete(t, tree):
        n = eqv.skip_all_but(db, ms.kept_survivors(t, tree))
        log(f"{t.name}: only the kept session's survivors again ({n} mutants counted as "
            "kept)")


def resume_session(t: Target, tree: Path, db: Path, log, survivors: bool) -> None:
    """A kept session goes on; with ``survivors`` its survivors' results are dropped so that
    exec runs them again, against today's tests."""
    if survivors:
        again = ms.survivors_to_run(t, tree)
        with sqlite3.connect(db) as con:
            con.executemany("DELETE FROM work_results WHERE job_id = ?",
                            [(j,) for j in again])  # fmt: skip
        log(f"{t.name}: {len(again)} survivors to run again (those not written down as "
            "equivalent)")
    log(f"{t.name}: resuming the session kept in {db.relative_to(ROOT)}")


def run_target(t: Target, tree: Path, log, fresh: bool, survivors: bool) -> None:
    """One module's session, kept in out/mutation/<name>.sqlite: the tests run unmutated first
    (they must pass; they also warm the numba cache every mutant starts from) and then as a
    mutant runs, then init, the filters, exec with a per-mutant timeout of
    ``max(t.timeout, 4 × that second run)``, each mutant on a copy of that cache without the
    entries that may hold the module's code (``tools/mutation_pytest.sh``)."""
    cfg, db = OUT / f"{t.name}.toml", OUT / f"{t.name}.sqlite"
    base = OUT / f"numba-{tree.name}"
    shutil.rmtree(base, ignore_errors=True)  # never a cache written while a mutant was on disk
    env = test_env(t, log)

    def run(*cmd: str, check: bool = True) -> subprocess.CompletedProcess:
        return subprocess.run(cmd, cwd=tree, env=env, check=check, capture_output=True, text=True)

    if survivors and not db.exists() and not fresh and ms.kept_is_complete(t, tree) and not (
            ms.kept_survivors(t, tree)):  # fmt: skip
        log(f"{t.name}: its kept session has no survivors left: nothing to run")
        return
    start = time.monotonic()
    measured = mutant_command(t, tree, env, base, log)
    if measured is None:
        db.unlink(missing_ok=True)
        return
    command, baseline = measured
    cfg.write_text(config_text(t, max(t.timeout, 4.0 * baseline), command))
    if db.exists() and not ms.has_mutants(db):  # made by a look into it before init, say
        db.unlink()
    if db.exists() and not fresh and ms.session_is_stale(t, tree):
        log(f"{t.name}: {t.module} changed since its session was made: starting it anew")
        fresh = True
    if fresh or not db.exists():
        init_session(t, tree, cfg, db, run, log, fresh, survivors)
    else:
        resume_session(t, tree, db, log, survivors)
    n = eqv.skip_unsampled(db, t.sample, t.sample_why, ms.kept_survivors(t, tree))  # after the kept
    # kills: those stay run
    if n:
        log(f"{t.name}: {n} mutants outside its {100 * t.sample:.0f} % sample, not run")
    run(tool("cosmic-ray"), "exec", str(cfg), str(db))
    took = time.monotonic() - start
    if fresh or not (OUT / f"{t.name}.seconds").exists():  # a whole session's time
        (OUT / f"{t.name}.seconds").write_text(f"{took:.0f}\n")
    log(f"{t.name}: done in {took:.0f} s (the tests alone: {baseline:.0f} s); "
        f"{ms.outcome(t, tree)}")


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
