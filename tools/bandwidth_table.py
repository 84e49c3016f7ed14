"""Prints the closed loop's frequency response per axis as a markdown table (lock-step,
``cdprctl/experiments/bandwidth.py``): gain and lag of the simulated platform against a 1 mm
(1 mrad) sinusoidal reference, and the −3 dB bandwidth.

    .venv/bin/python tools/bandwidth_table.py [--config config/rowc.toml] [--freqs 0.5,1,...]
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprctl.experiments.bandwidth import AXES, bandwidth, response  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default=str(ROOT / "config" / "rowc.toml"))
    ap.add_argument("--freqs", default="0.5,1,1.5,2,3,5,8,12,20", help="Hz, comma-separated")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    model = load_robot(args.config)
    freqs = [float(f) for f in args.freqs.split(",")]
    print(f"{model.name}, {model.drives.mode}, {model.control.rate:g} Hz: gain / lag (°)\n")
    print("| axis | " + " | ".join(f"{f:g} Hz" for f in freqs) + " | −3 dB |")
    print("|---" * (len(freqs) + 2) + "|")
    for axis, name in enumerate(AXES):
        rs = [response(model, axis, f) for f in freqs]
        cells = [
            f"{r.gain:.2f} / {math.degrees(r.phase):.0f}" if math.isfinite(r.gain) else r.state
            for r in rs
        ]
        bw = bandwidth(rs)
        cell = f"> {freqs[-1]:g} Hz" if bw == math.inf else f"{bw:.1f} Hz"
        print(f"| {name} | " + " | ".join(cells) + f" | {cell} |", flush=True)


if __name__ == "__main__":
    main()
