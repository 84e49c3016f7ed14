"""Prints the external-wrench estimate's error under the 30 N water jet, without and with load
cells, as a markdown table (lock-step; ``cdprctl/experiments/load_cells.py`` says the run):
each robot as its file says, then with its winches' friction 30-50 % off the file (seeded).

    .venv/bin/python tools/load_cell_table.py [--pairs rowc.toml:rowc_load_cells.toml,...]
        [--seeds 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprctl.experiments.load_cells import jet_run  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402

PAIRS = "rowc.toml:rowc_load_cells.toml,cogiro.toml:cogiro_load_cells.toml"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", default=PAIRS, help="without:with cells, robot files in config/")
    ap.add_argument("--seeds", type=int, default=5, help="friction draws (seeds 0..N-1)")
    args = ap.parse_args()
    print("| robot | winches' friction | cells | at rest, max N | moving, max N | state |")
    print("| --- | --- | --- | --- | --- | --- |")
    for pair in args.pairs.split(","):
        for name in pair.split(":"):
            model = load_robot(ROOT / "config" / name)
            runs = [(None, jet_run(model, None))]
            runs += [(s, jet_run(model, s)) for s in range(args.seeds)]
            worst_rest = max(r.at_rest for _, r in runs[1:]) if args.seeds else 0.0
            worst_move = max(r.moving for _, r in runs[1:]) if args.seeds else 0.0
            states = {r.state for _, r in runs}
            nominal = runs[0][1]
            cells = "yes" if model.sensors.load_cells else "no"
            print(f"| {model.name} | as the file | {cells} | {nominal.at_rest:.2f} | "
                  f"{nominal.moving:.2f} | {nominal.state} |")  # fmt: skip
            if args.seeds:
                print(f"| {model.name} | 30-50 % off, worst of {args.seeds} seeds | {cells} | "
                      f"{worst_rest:.2f} | {worst_move:.2f} | {', '.join(sorted(states))} |",
                      flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
