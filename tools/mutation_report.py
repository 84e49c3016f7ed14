"""The mutation report, ``docs/mutation.md`` (tools/mutation.py): per module the mutants run,
killed, survived, equivalent and the score, then every survivor and every equivalent mutant;
the sessions at hand are kept in tools/mutation_results.json on the way."""

from __future__ import annotations

import json
import os
import platform
from dataclasses import dataclass, field
from pathlib import Path

import mutation_session as ms
from mutation_session import (
    KILLED,
    Mutant,
    Target,
    mark_equivalents,
    merge_survivors_run,
    module_digest,
    mutants_of,
    read_session,
    results_entry,
    session_date,
    session_is_stale,
)


@dataclass
class Tally:
    """What the modules' rows add up to, and the lists the report names below the table."""

    rows: list[str] = field(default_factory=list)
    survivors: list[tuple[bool, Mutant]] = field(default_factory=list)
    totals: list[int] = field(default_factory=lambda: [0, 0, 0, 0])  # run, killed, alive, equiv
    scoped: list[str] = field(default_factory=list)
    sampled: list[str] = field(default_factory=list)
    samples: int = 0  # complete modules that ran a sample
    not_sampled: int = 0  # the mutants they left
    by_rule: int = 0  # equivalent by a rule known beforehand: counted, never run
    waiting: list[str] = field(default_factory=list)  # modules the score does not yet hold, why
    out_of_date: set[str] = field(default_factory=set)  # of an older file: not listed


def gather(targets: list[Target], tree: Path) -> tuple[list[Mutant], dict, dict[str, int | None]]:
    """Every target's mutants (its session at hand, else the kept results), the kept results
    with the sessions at hand put in, and each module's session time (s)."""
    all_mutants: list[Mutant] = []
    kept = ms.load_results()
    seconds: dict[str, int | None] = {}
    for t in targets:
        took = ms.OUT / f"{t.name}.seconds"
        mutants = read_session(t, tree)
        if any(m.outcome == "kept" for m in mutants) and t.name in kept:  # survivors only
            kept[t.name] = merge_survivors_run(kept[t.name], mutants, session_date(t))
            mutants = mutants_of(kept[t.name])
            seconds[t.name] = kept[t.name]["seconds"]
        elif mutants and not session_is_stale(t, tree, mutants):  # at hand: its results kept
            seconds[t.name] = int(took.read_text()) if took.exists() else None
            kept[t.name] = results_entry(t, tree, mutants, seconds[t.name])
        elif not mutants and t.name in kept:
            mutants = mutants_of(kept[t.name])
            seconds[t.name] = kept[t.name]["seconds"]
        all_mutants += mutants
    return all_mutants, kept, seconds


def tally_module(t: Target, mutants: list[Mutant], tally: Tally, seconds: int | None) -> None:
    """``t``'s row of the table from its (current) mutants, and what it adds to the totals."""
    run = [m for m in mutants
           if m.outcome not in ("skipped", "pending", "out_of_scope", "unsampled")]
    outside = sum(m.outcome == "out_of_scope" for m in mutants)
    if outside:
        tally.scoped.append(f"- {t.name}: {outside} mutants outside {', '.join(t.scope)} left "
                            f"out — {t.left_out}")  # fmt: skip
    unsampled = sum(m.outcome == "unsampled" for m in mutants)
    # the mutants a session runs: not those of the operators left out nor outside a scope
    eligible = len(mutants) - outside - sum(m.outcome == "skipped" for m in mutants)
    if unsampled:
        tally.sampled.append(f"- {t.name}: {eligible - unsampled} of {eligible} mutants run, "
                             f"{unsampled} not: its {100 * t.sample:.0f} % sample and those an "
                             "earlier partial session ran or that share an operator and line "
                             f"with a survivor — {t.sample_why}")  # fmt: skip
    killed = [m for m in run if m.outcome in KILLED]
    equiv = [m for m in run if m.equivalent]
    alive = [m for m in run if m.outcome == "survived" and not m.equivalent]
    pending = sum(m.outcome == "pending" for m in mutants)
    denom = len(run) - len(equiv)
    score = f"{100.0 * len(killed) / denom:.1f} %" if denom else "—"
    if pending:
        score += f" ({pending} not run yet)"
    wall = f"{seconds / 60:.0f} min" if seconds else "?"
    tally.rows.append(f"| {t.name} | `{t.module}` | {len(run)} | {len(killed)} | {len(alive)} | "
                      f"{len(equiv)} | {score} | {wall} | {t.tests} |")  # fmt: skip
    tally.survivors += [(bool(pending), m) for m in alive]
    if pending:  # a partial session: listed, not yet in the score
        tally.waiting.append(f"{t.name} ({pending} of {eligible} not run yet)")
        return
    tally.samples += bool(unsampled)
    tally.not_sampled += unsampled
    tally.by_rule += sum(bool(m.equivalent) and not m.diff for m in run)
    for i, v in enumerate((len(run), len(killed), len(alive), len(equiv))):
        tally.totals[i] += v


def tally_modules(targets: list[Target], tree: Path, all_mutants: list[Mutant], kept: dict,
                  seconds: dict[str, int | None]) -> Tally:  # fmt: skip
    """The table's rows: a module not run, one whose file changed since, or its figures."""
    tally = Tally()
    for t in targets:
        mutants = [m for m in all_mutants if m.module == t.module]
        if not mutants:
            tally.rows.append(f"| {t.name} | `{t.module}` | not run | | | | | | |")
            tally.waiting.append(f"{t.name} (not run)")
            continue
        changed = t.name in kept and kept[t.name]["sha256"] != module_digest(tree, t.module)
        if changed or session_is_stale(t, tree, mutants):  # figures of a file no longer there
            tally.out_of_date.add(t.module)
            tally.waiting.append(f"{t.name} (the file changed since its session: "
                                 f"`--fresh {t.name}`)")  # fmt: skip
            tally.rows.append(f"| {t.name} | `{t.module}` | not run (the file changed since "
                              f"its session: `--fresh {t.name}`) | | | | | | |")  # fmt: skip
            continue
        tally_module(t, mutants, tally, seconds.get(t.name))
    return tally


def score_lines(tally: Tally, n_targets: int) -> list[str]:
    """The score of the complete modules, what it is of, and which modules it does not hold."""
    totals = tally.totals
    denom = totals[0] - totals[3]
    complete = n_targets - len(tally.waiting)
    sampled = (f" ({tally.samples} of them a sample: {tally.not_sampled} mutants not run)"
               if tally.samples else "")  # fmt: skip
    return [
        (f"**Score: {100.0 * totals[1] / denom:.1f} % of {denom} non-equivalent mutants killed**"
         f" in the {complete} of {n_targets} modules whose session is complete{sampled}"
         " and of the file as it is") if denom
        else "**No module's session is complete yet.**",
        f"({totals[0]} mutants: {totals[1]} killed, {totals[2]} survived, {totals[3]} equivalent, "
        f"{tally.by_rule} of those by a rule known beforehand and not run).",
        *(["", f"Not yet in the score: {'; '.join(tally.waiting)}."] if tally.waiting else []),
    ]


def head_lines(tally: Tally, kept: dict, n_targets: int) -> list[str]:
    """The report down to its survivors: how to use it, the score, the table, what is left
    out or sampled."""
    return [
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
        *score_lines(tally, n_targets),
        "",
        "| module | file | mutants | killed | survived | equivalent | score | wall time | tests |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *tally.rows,
        "",
        "Operators: arithmetic among + − × ÷, bit operations among themselves, comparisons, "
        "and/or, not, unary minus, True/False, break/continue, numbers ±1, zero-iteration "
        "loops, exceptions replaced (`tools/mutation.toml` lists what is left out "
        "and why). A mutant is killed when a test fails or the tests exceed the module's "
        "timeout; incompetent mutants (that cannot run at all) count as killed.",
        "",
        *([*["Left out of a module (mutated in part, `scope` in `tools/mutation.toml`):"],
           *tally.scoped, ""] if tally.scoped else []),
        *([*["Sampled (a module's mutants whose key — operator, line, column — hashes below "
             "its `sample` in `tools/mutation.toml`: the same mutants in every session of the "
             "file; the score is of those run):"], *tally.sampled, ""] if tally.sampled else []),
        *(["Left out (not mutated, `left-out` in `tools/mutation.toml`):",
           *[f"- `{x['module']}`: {x['why']}" for x in ms.LEFT_OUT], ""] if ms.LEFT_OUT else []),
        "Modules outside these targets are checked independently: bugs planted one at a time "
        "in a scratch copy; those no test caught have tests now (`tests/test_unlisted_modules.py`"
        " lists them).",
        "",
    ]


def mutant_lines(tally: Tally, all_mutants: list[Mutant]) -> list[str]:
    """The survivors (a partial session's said so) and the equivalent mutants, with why."""
    lines = ["## Survivors", ""]
    if not tally.survivors:
        lines.append("None.")
    for partial, m in sorted(tally.survivors, key=lambda x: x[0]):
        note = " (its module's session is not complete: not yet in the score)" if partial else ""
        lines.append(f"- `{m.module}:{m.line}` {m.operator.removeprefix('core/')}: "
                     f"`{m.diff}`{note}")  # fmt: skip
    lines += ["", "## Equivalent mutants", ""]
    eq = [m for m in all_mutants if m.equivalent and m.module not in tally.out_of_date]
    if not eq:
        lines.append("None.")
    for m in eq:  # one equivalent by a rule known beforehand never ran: its line instead
        text = f"`{m.diff}`" if m.diff else f"not run, on `{m.source}`"
        lines.append(f"- `{m.module}:{m.line}` {m.operator.removeprefix('core/')}: {text} "
                     f"— {m.equivalent}")  # fmt: skip
    return lines


def report(targets: list[Target], tree: Path) -> str:
    """The report's text; the sessions at hand are kept in tools/mutation_results.json."""
    equivalents = ms.load_equivalents()
    all_mutants, kept, seconds = gather(targets, tree)
    stale = mark_equivalents(all_mutants, equivalents)
    tally = tally_modules(targets, tree, all_mutants, kept, seconds)
    lines = head_lines(tally, kept, len(targets)) + mutant_lines(tally, all_mutants)
    ms.RESULTS.write_text(json.dumps(kept, indent=1, sort_keys=True) + "\n")
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
