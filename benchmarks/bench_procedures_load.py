"""Benchmark: the long procedures across processes beside the machine's other work (issue 64:
"``calibrate geometry`` across processes on rowc and CAROCA completes beside two hogs; a fault
midway resumes and completes").

For each robot: ``cdprctl sim`` on a udp_multicast group of its own, N busy Python processes
at normal priority beside (``--hog``), then ``cdprctl calibrate geometry`` in a third
process; its exit, its wall time, its missed periods and its first line of trouble. A
calibration that stops (a fault: it keeps its samples) is resumed with ``--resume`` up to
``--resumes`` times, each run reported. With ``--interrupt S`` the simulated robot is stopped S
seconds into the first calibration (as a drive that lost power) and started again.

Run: ``.venv/bin/python benchmarks/bench_procedures_load.py [--robots rowc,caroca] [--hog 2]
[--interrupt 40]``: a few minutes a robot.
"""

from __future__ import annotations

import argparse
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import busy_processes, machine_line

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "cdprctl.cli"]
GROUP = "239.74.163.11"


def start_sim(config: str, bus: list[str]) -> subprocess.Popen:
    sim = subprocess.Popen([*CLI, "sim", "--config", config, "--status", "0", *bus],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           cwd=ROOT)  # fmt: skip
    assert sim.stdout is not None
    while "ready" not in (line := sim.stdout.readline()):
        if not line and sim.poll() is not None:
            sys.exit("bench_procedures_load: cdprctl sim did not start")
    return sim


def stop(proc: subprocess.Popen | None) -> str:
    if proc is None:
        return ""
    proc.terminate()
    try:
        return proc.communicate(timeout=20)[0] or ""
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.communicate()[0] or ""


def calibrate(
    config: str, bus: list[str], state: str, out: str, resume: bool, interrupt: float,
    config_path: str, sim_box: list,
) -> tuple[int, float, str]:  # fmt: skip
    """One ``calibrate geometry`` (``--resume``); with ``interrupt`` > 0 the simulated robot in
    ``sim_box`` is stopped that many seconds in and started again once the calibration has
    stopped. Its exit code, wall time (s) and output."""
    cmd = [*CLI, "calibrate", "--config", config, "--state-dir", state, *bus, "geometry",
           "--out", out, *(["--resume"] if resume else [])]  # fmt: skip
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            cwd=ROOT)  # fmt: skip
    if interrupt > 0:
        try:
            text = proc.communicate(timeout=interrupt)[0]
        except subprocess.TimeoutExpired:
            stop(sim_box[0])  # the drives lose power mid-way
            text = proc.communicate(timeout=600)[0]
        sim_box[0] = start_sim(config_path, bus)
    else:
        text = proc.communicate(timeout=1800)[0]
    return proc.returncode, time.monotonic() - t0, text


def summary(code: int, seconds: float, text: str) -> str:
    lines = text.splitlines()
    end = next((x for x in reversed(lines) if x.strip()), "")
    missed = re.findall(r"(\d+) of (\d+) periods missed", text)
    trouble = next((x.strip() for x in lines if "stopped at pose" in x or "FAULT" in x), "")
    extra = f"; missed {missed[-1][0]} of {missed[-1][1]}" if missed else ""
    return (f"exit {code}, {seconds:.0f} s{extra}; last line: {end.strip()[:160]}"
            + (f"\n    trouble: {trouble[:300]}" if trouble else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default="rowc,caroca")
    ap.add_argument("--hog", type=int, default=2, help="busy processes beside everything")
    ap.add_argument("--interrupt", type=float, default=0.0,
                    help="s into the calibration the simulated robot is stopped (0: never)")
    ap.add_argument("--resumes", type=int, default=2,
                    help="times a stopped calibration is resumed (--resume)")
    args = ap.parse_args()
    print(machine_line())
    with busy_processes(args.hog):
        for robot in args.robots.split(","):
            config = str(ROOT / "config" / f"{robot}.toml")
            port = random.randint(20000, 60000)
            bus = ["--can-interface", "udp_multicast", "--can-channel", GROUP, "--can-option",
                   f"port={port}"]  # fmt: skip
            sim_box = [start_sim(config, bus)]
            with tempfile.TemporaryDirectory() as tmp:
                out = str(Path(tmp) / "built.toml")
                try:
                    first = calibrate(config, bus, tmp, out, False, args.interrupt, config,
                                      sim_box)  # fmt: skip
                    print(f"{robot}, {args.hog} hogs: {summary(*first)}", flush=True)
                    for attempt in range(args.resumes):  # stopped: resumed from its samples
                        if first[0] == 0:
                            break
                        first = calibrate(config, bus, tmp, out, True, 0.0, config, sim_box)
                        print(f"{robot}, resumed ({attempt + 1}): {summary(*first)}", flush=True)
                    print(f"{robot}: record written: {Path(out).is_file()}", flush=True)
                finally:
                    stop(sim_box[0])


if __name__ == "__main__":
    main()
