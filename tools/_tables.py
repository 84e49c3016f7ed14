"""What the tools that write a table docs/ quotes (tools/homing_table.py,
tools/geometry_table.py) share: the homing tests' simulated robots importable
(tests/calibration/test_homing.py and its conftest), the options (how many seeds, where the
table goes) and the table's head and file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the homing tests' helpers (robot_at, start_pose, pose_error), and the conftest they import,
# after the project's own packages: tests/drivers/ would otherwise stand for drivers/
sys.path[:0] = [str(ROOT)]
sys.path += [str(ROOT / "tests"), str(ROOT / "tests" / "calibration")]


def table_options(name: str, seeds: int) -> argparse.ArgumentParser:
    """``--seeds`` (how many seeded runs a robot, default ``seeds``) and ``--out`` (the
    table's file, default docs/``name``)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=seeds)
    ap.add_argument("--out", default=str(ROOT / "docs" / name))
    return ap


def markdown_head(head: str) -> list[str]:
    """A Markdown table's first two lines: ``head`` ("| a | b |") and the separator under
    each of its columns."""
    return [head, "|" + " --- |" * (head.count("|") - 1)]


def write_table(out: str, lines: list[str]) -> None:
    """The table's ``lines`` written to ``out``, one a line."""
    Path(out).write_text("\n".join(lines) + "\n")
