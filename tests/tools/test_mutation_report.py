"""The mutation report (tools/mutation_report.py) is made of the results kept in the
repository where no session is at hand, and refuses them once the module is no longer the
file they are of."""

from __future__ import annotations

import json
import sqlite3
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import mutation_report as mr  # noqa: E402
import mutation_session as mu  # noqa: E402


def kept_only(tmp_path, monkeypatch, t, mutants, seconds, equivalents=()):
    """The report's inputs with no session at hand: ``mutants`` kept as ``t``'s results (of
    a session dated by its file, then gone), ``equivalents`` as the written-down entries;
    returns the kept entry."""
    monkeypatch.setattr(mu, "OUT", tmp_path / "out")
    monkeypatch.setattr(mu, "RESULTS", tmp_path / "results.json")
    monkeypatch.setattr(mu, "load_equivalents", lambda: list(equivalents))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / f"{t.name}.sqlite").touch()  # the session's day
    entry = mu.results_entry(t, tmp_path, mutants, seconds)
    mu.RESULTS.write_text(json.dumps({t.name: entry}))
    (tmp_path / "out" / f"{t.name}.sqlite").unlink()
    return entry


def session_db(path: Path, specs: list[tuple[str, str, int]]) -> Path:
    """A session's two tables as cosmic-ray makes them (the columns the filters read), with
    ``specs`` (job id, operator, line) at column 0, occurrence 0, none with a result."""
    with sqlite3.connect(path) as con:
        con.execute("CREATE TABLE mutation_specs (job_id TEXT, operator_name TEXT, "
                    "start_pos_row INT, start_pos_col INT, occurrence INT)")  # fmt: skip
        con.execute("CREATE TABLE work_results (worker_outcome TEXT, output TEXT, "
                    "test_outcome TEXT, diff TEXT, job_id TEXT)")  # fmt: skip
        con.executemany("INSERT INTO mutation_specs VALUES (?, ?, ?, 0, 0)", specs)
    return path


def test_kept_results_make_the_report_until_the_module_changes(tmp_path, monkeypatch):
    module = tmp_path / "m.py"
    module.write_text("def f(x):\n    return x + 1\n")
    t = mu.Target("m", "m.py", "tests/test_m.py")
    survivor = mu.Mutant("m.py", "core/NumberReplacer", 2, "return x + 1",
                         "- return x + 1 / + return x + 2", "survived")  # fmt: skip
    killed = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Sub", 2, "return x + 1",
                       "- return x + 1 / + return x - 1", "killed")  # fmt: skip
    entry = kept_only(tmp_path, monkeypatch, t, [killed, killed, survivor], 60)
    assert entry["killed"] == 2 and len(entry["others"]) == 1
    text = mr.report([t], tmp_path)
    assert "| m | `m.py` | 3 | 2 | 1 | 0 | 66.7 % | 1 min |" in text
    assert "`m.py:2` NumberReplacer: `- return x + 1 / + return x + 2`" in text
    assert json.loads(mu.RESULTS.read_text())["m"] == entry  # kept as it was
    module.write_text("def f(x):\n    return x + 2\n")
    text = mr.report([t], tmp_path)
    assert "| m | `m.py` | not run (the file changed since its session: `--fresh m`)" in text


def test_mutants_outside_a_targets_scope_are_left_out_of_its_score_and_said(tmp_path, monkeypatch):
    source = "def kept(x):\n    return x + 1\n\n\ndef other(x):\n    return x * 2\n"
    (tmp_path / "m.py").write_text(source)
    from mutation_equivalents import scope_lines

    assert scope_lines(source, ["kept"]) == {1, 2}
    t = mu.Target("m", "m.py", "tests/test_m.py", scope=("kept",), left_out="too slow")
    killed = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Sub", 2, "return x + 1",
                       "- return x + 1 / + return x - 1", "killed")  # fmt: skip
    outside = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Mul_Add", 6, "return x * 2",
                        "- return x * 2 / + return x + 2", "out_of_scope")  # fmt: skip
    entry = kept_only(tmp_path, monkeypatch, t, [killed, outside, outside], 60)
    assert entry["killed"] == 1 and entry["out_of_scope"] == 2 and entry["others"] == []
    text = mr.report([t], tmp_path)
    assert "| m | `m.py` | 1 | 1 | 0 | 0 | 100.0 % | 1 min |" in text
    assert "- m: 2 mutants outside kept left out — too slow" in text
    monkeypatch.setattr(mu, "LEFT_OUT", [{"module": "n.py", "why": "slower still"}])
    assert "- `n.py`: slower still" in mr.report([t], tmp_path)


def test_a_partial_session_is_listed_but_not_scored_and_equivalents_match_as_printed(
    tmp_path, monkeypatch
):
    """A module whose session is not complete shows its survivors but stays out of the
    headline score, named with what is left; an equivalent written with the operator as the
    report prints it (no ``core/``) matches; an entry matching nothing is named by its line."""
    (tmp_path / "m.py").write_text("def f(x):\n    return x + 1\n")
    t = mu.Target("m", "m.py", "tests/test_m.py")
    monkeypatch.setattr(mu, "TARGETS", [t])
    equivalents = [
        {"module": "m.py", "operator": "NumberReplacer", "line": r"return x \+ 1",
         "why": "a test of the matching"},
        {"module": "m.py", "operator": "core/ReplaceTrueWithFalse", "line": "gone", "why": "-"},
    ]  # fmt: skip
    survivor = mu.Mutant("m.py", "core/NumberReplacer", 2, "return x + 1",
                         "- return x + 1 / + return x + 2", "survived")  # fmt: skip
    alive = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Mul", 2, "return x + 1",
                      "- return x + 1 / + return x * 1", "survived")  # fmt: skip
    pending = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Sub", 2, "return x + 1",
                        "- return x + 1 / + return x - 1", "pending")  # fmt: skip
    kept_only(tmp_path, monkeypatch, t, [survivor, alive, pending], None, equivalents)
    text = mr.report([t], tmp_path)
    assert "**No module's session is complete yet.**" in text
    assert "Not yet in the score: m (1 of 3 not run yet)." in text
    assert "`m.py:2` ReplaceBinaryOperator_Add_Mul: `- return x + 1 / + return x * 1`" in text
    assert "— a test of the matching" in text  # the NumberReplacer, written without core/
    assert "- entry 2: `m.py` core/ReplaceTrueWithFalse `gone`" in text


def test_a_partial_sessions_kills_are_kept_by_key_and_resumed_only_for_the_same_file_and_tests(
    tmp_path, monkeypatch
):
    """The sessions in out/ do not outlive a checkout: a partial session's kills are kept by
    key, and a new session of the same file and tests marks exactly those as killed."""
    module = tmp_path / "m.py"
    module.write_text("def f(x):\n    return x + 1\n")
    t = mu.Target("m", "m.py", "tests/test_m.py")
    add_sub = mu.mutant_key("core/ReplaceBinaryOperator_Add_Sub", 2, 13, 0)
    killed = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Sub", 2, "return x + 1",
                       "- return x + 1 / + return x - 1", "killed", key=add_sub)  # fmt: skip
    pending = mu.Mutant("m.py", "core/NumberReplacer", 2, "return x + 1",
                        "- return x + 1 / + return x + 2", "pending",
                        key=mu.mutant_key("core/NumberReplacer", 2, 15, 0))  # fmt: skip
    entry = kept_only(tmp_path, monkeypatch, t, [killed, pending], None)
    assert entry["killed_keys"] == {add_sub: "killed"}
    (tmp_path / "out" / "m.sqlite").touch()
    complete = mu.results_entry(t, tmp_path, [killed], None)
    assert "killed_keys" not in complete  # a complete session is never resumed

    def session() -> Path:
        db = tmp_path / "s.sqlite"
        db.unlink(missing_ok=True)
        with sqlite3.connect(db) as con:
            con.execute("CREATE TABLE mutation_specs (job_id, operator_name, occurrence, "
                        "start_pos_row, start_pos_col)")  # fmt: skip
            con.execute("CREATE TABLE work_results (worker_outcome, output, test_outcome, "
                        "diff, job_id)")  # fmt: skip
            con.executemany("INSERT INTO mutation_specs VALUES (?, ?, ?, ?, ?)",
                            [("a", "core/ReplaceBinaryOperator_Add_Sub", 0, 2, 13),
                             ("b", "core/NumberReplacer", 0, 2, 15),
                             ("c", "core/ReplaceBinaryOperator_Add_Sub", 1, 2, 13)])  # fmt: skip
        return db

    db = session()
    assert mu.resume_killed(db, t, tmp_path) == 1
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT job_id, test_outcome FROM work_results").fetchall() == [
            ("a", "KILLED")
        ]
    other_tests = mu.Target("m", "m.py", "tests/test_m.py tests/test_n.py")
    assert mu.resume_killed(session(), other_tests, tmp_path) == 0
    module.write_text("def f(x):\n    return x + 2\n")
    assert mu.resume_killed(session(), t, tmp_path) == 0


def test_a_sample_is_the_same_mutants_in_every_session_and_its_size(tmp_path):
    """``in_sample`` picks by a hash of the mutant's key: the same mutants every time, about
    the fraction asked, a larger fraction holding the smaller's; ``skip_unsampled`` marks the
    pending rest in a session (cosmic-ray's tables) but an earlier session's survivors, and drops
    its own marks when run again."""
    from mutation_equivalents import in_sample, skip_unsampled

    keys = [mu.mutant_key("core/NumberReplacer", row, col, 0)
            for row in range(1, 301) for col in range(10)]  # fmt: skip
    fifth = {k for k in keys if in_sample(k, 0.2)}
    assert 0.17 * len(keys) < len(fifth) < 0.23 * len(keys)
    assert fifth == {k for k in keys if in_sample(k, 0.2)}
    assert fifth < {k for k in keys if in_sample(k, 0.4)}
    assert all(in_sample(k, 1.0) for k in keys) and not any(in_sample(k, 0.0) for k in keys)

    db = session_db(tmp_path / "s.sqlite",
                    [(f"j{row}", "core/NumberReplacer", row) for row in range(1, 201)])
    with sqlite3.connect(db) as con:
        con.execute("INSERT INTO work_results VALUES ('NORMAL', '', 'KILLED', NULL, 'j1')")
    out = {f"j{row}" for row in range(2, 201)
           if not in_sample(mu.mutant_key("core/NumberReplacer", row, 0, 0), 0.3)}  # fmt: skip
    assert skip_unsampled(db, 0.3, "slow") == len(out) > 100
    assert skip_unsampled(db, 0.3, "slow") == len(out)  # its own marks dropped first
    survivor = int(min(out, key=lambda j: int(j[1:]))[1:])  # an earlier session's, unsampled
    keep = frozenset({("core/NumberReplacer", survivor)})
    assert skip_unsampled(db, 0.3, "slow", keep) == len(out) - 1
    assert skip_unsampled(db, 1.0, "") == 0
    with sqlite3.connect(db) as con:  # only the run one has a result
        assert con.execute("SELECT job_id FROM work_results").fetchall() == [("j1",)]


def test_a_sampled_module_is_scored_on_what_ran_and_says_how_much_did_not(tmp_path, monkeypatch):
    (tmp_path / "m.py").write_text("def f(x):\n    return x + 1\n")
    t = mu.Target("m", "m.py", "tests/test_m.py", sample=0.5, sample_why="slow kernels")
    killed = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Sub", 2, "return x + 1",
                       "- return x + 1 / + return x - 1", "killed")  # fmt: skip
    unsampled = mu.Mutant("m.py", "core/NumberReplacer", 2, "return x + 1",
                          "- return x + 1 / + return x + 2", "unsampled")  # fmt: skip
    left_out = mu.Mutant("m.py", "core/ReplaceBinaryOperator_Add_Pow", 2, "return x + 1", "",
                         "skipped")  # an operator left out: in no sample  # fmt: skip
    entry = kept_only(tmp_path, monkeypatch, t, [killed, unsampled, unsampled, left_out], 60)
    assert entry["killed"] == 1 and len(entry["others"]) == 3  # the unsampled kept whole
    text = mr.report([t], tmp_path)
    assert "| m | `m.py` | 1 | 1 | 0 | 0 | 100.0 % | 1 min |" in text
    assert "in the 1 of 1 modules whose session is complete (1 of them a sample: 2 mutants " \
        "not run)" in text
    assert "- m: 1 of 3 mutants run, 2 not: its 50 % sample and those an earlier" in text
    assert text.count("slow kernels") == 1
    # an entry for a mutant the sample left out is not stale: it may be of that one
    entry_of_unsampled = {"module": "m.py", "operator": "NumberReplacer",
                          "line": r"return x \+ 1", "why": "y"}  # fmt: skip
    monkeypatch.setattr(mu, "load_equivalents", lambda: [entry_of_unsampled])
    monkeypatch.setattr(mu, "TARGETS", [t])
    assert "matched no survivor" not in mr.report([t], tmp_path)
    entry_of_unsampled["line"] = r"return x \+ 3"  # of no mutant at all: stale
    assert "matched no survivor" in mr.report([t], tmp_path)


def test_a_survivors_only_run_moves_the_killed_out_of_the_kept_survivors_once(tmp_path):
    """In a new checkout a complete session's survivors run alone (``skip_all_but`` marks the
    rest as counted in the kept results); each that dies moves to the killed, once, however
    often the report is written; one that survives again stays."""
    from mutation_equivalents import skip_all_but

    db = session_db(tmp_path / "s.sqlite", [("a", "core/NumberReplacer", 2),
                                            ("b", "core/NumberReplacer", 3),
                                            ("c", "core/AddNot", 2)])  # fmt: skip
    assert skip_all_but(db, frozenset({("core/NumberReplacer", 2)})) == 2
    with sqlite3.connect(db) as con:
        assert sorted(con.execute("SELECT job_id FROM work_results").fetchall()) == [
            ("b",), ("c",)]  # fmt: skip

    def mutant(line: int, diff: str, outcome: str) -> mu.Mutant:
        return mu.Mutant("m.py", "core/NumberReplacer", line, "x = 1", diff, outcome)

    def kept(m: mu.Mutant) -> dict:
        return {"operator": m.operator, "line": m.line, "source": m.source, "diff": m.diff,
                "outcome": m.outcome, "equivalent": ""}  # fmt: skip

    dies, lives = mutant(2, "- x = 1 / + x = 2", "survived"), mutant(3, "- y = 1 / + y = 2",
                                                                     "survived")  # fmt: skip
    entry = {"killed": 10, "others": [kept(dies), kept(lives)], "date": "2026-12-01"}
    run = [mutant(2, dies.diff, "killed"), mutant(3, lives.diff, "survived"),
           mutant(4, "- z = 1 / + z = 2", "kept")]  # fmt: skip
    once = mu.merge_survivors_run(entry, run, "2026-12-06")
    assert once["killed"] == 11 and once["others"] == [kept(lives)]
    assert once["date"] == "2026-12-06" and entry["killed"] == 10  # the kept one untouched
    assert mu.merge_survivors_run(once, run, "2026-12-07") == once
