"""Every script in tools/ starts as a user starts it: after the tree's re-cut two of them
stopped at their imports (``No module named 'test_homing'``) and no test noticed. Each runs
in a fresh interpreter from a directory outside the checkout, with tools/ as the script's
own directory first on ``sys.path`` (as ``python tools/X.py`` has it): one that builds an
argument parser is run with ``--help`` (its imports, its parser, exit 0); the others (the
figures' scripts, the mutation tools' modules) are imported under their own name, so none of
their work runs. A script planted with a missing import shows the check fails."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOLS = sorted((ROOT / "tools").glob("*.py"))
#: s: the slowest measured 5.2 s (soak.py --help, load average 5.5 on 2 cores)
TIMEOUT = 120.0


def start(script: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``script --help`` when it is a script that parses arguments, else ``import script``
    (a helper module of the tools, such as ``_tables.py``'s parser options) with its
    directory first on the path; in a fresh interpreter with this one's environment."""
    text = script.read_text(encoding="utf-8")
    if "ArgumentParser(" in text and 'if __name__ == "__main__"' in text:
        argv = [sys.executable, str(script), "--help"]
    else:
        code = f"import sys; sys.path[0] = {str(script.parent)!r}; import {script.stem}"
        argv = [sys.executable, "-c", code]
    return subprocess.run(argv, cwd=cwd, env=dict(os.environ, MPLBACKEND="Agg"),
                          capture_output=True, text=True, timeout=TIMEOUT)  # fmt: skip


def test_there_are_tools_to_start():
    assert len(TOOLS) >= 20, TOOLS


@pytest.mark.parametrize("script", TOOLS, ids=[p.name for p in TOOLS])
def test_a_tool_starts(script, tmp_path):
    done = start(script, tmp_path)
    assert done.returncode == 0, f"{script.relative_to(ROOT)}:\n{done.stderr[-2000:]}"
    if "--help" in done.args:
        assert done.stdout.startswith("usage: "), done.stdout[:200]


def test_a_tool_that_cannot_import_fails_here(tmp_path):
    """The check against a planted script each way: a module that imports what is not there,
    and a parser behind an import of a test module the re-cut moved."""
    (tmp_path / "tools").mkdir()
    plain = tmp_path / "tools" / "figures.py"
    plain.write_text("import numpy\nimport no_such_module_here  # noqa\n")
    parsed = tmp_path / "tools" / "table.py"
    parsed.write_text("import argparse\nfrom test_homing_moved import robot_at  # noqa\n"
                      "argparse.ArgumentParser().parse_args()\n")  # fmt: skip
    for script, missing in ((plain, "no_such_module_here"), (parsed, "test_homing_moved")):
        done = start(script, tmp_path)
        assert done.returncode != 0 and f"No module named '{missing}'" in done.stderr
