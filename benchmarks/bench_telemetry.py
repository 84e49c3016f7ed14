"""Benchmark: what the Zenoh gateway and a command flood cost the loop.

The daemon on the simulated robot (in-process, 500 Hz or --rate, the 20 s demo motion) is run
twice per round: A without the gateway (telemetry off); B with it, publishing `state` at
100 Hz, while this process floods it with 1000 commands/s (mostly rejected by the gateway —
malformed JSON, targets outside the workspace — and 10/s valid `set_tda` that reach the loop)
in segments, on for ``--segment`` s, off for as long, and so on. Each run saves its per-cycle
timing (``cdprctl run --timing-file``), so the flood's cycles are compared with the quiet ones
of the same run — the VM's other tenants then weigh on both — and with run A.

Reports, pooled over the rounds and per round, wake lateness p50/p99/p99.9/max and the
periods missed, and the ratios of the p99s (goal: with the flood no more than 10 % worse).

Run: ``.venv/bin/python benchmarks/bench_telemetry.py [--rounds 3] [--seconds 30]``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import bench_parser, free_port, loop_options, machine_line

ROOT = Path(__file__).resolve().parents[1]



def flood(
    endpoint: str, stop: threading.Event, segment: float, on: list[tuple[float, float]]
) -> None:
    """1000 puts/s for ``segment`` s, then silence as long, until ``stop``; each flood
    interval appended to ``on`` (monotonic clock, shared with the daemon's)."""
    sys.path.insert(0, str(ROOT))
    import os

    from cdprctl.telemetry.zenoh.session import open_session

    # this thread (and the Zenoh threads its session starts) off the loop's CPU (the last):
    # the flood stands for operators on other machines, not for load on the robot PC
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) > 1:
        os.sched_setaffinity(0, set(cpus[:-1]))
    session = open_session(connect=[endpoint], multicast_scouting=False)
    bad = [b"{nonsense", json.dumps({"position": [9.0, 0.35, 0.5]}).encode()]
    good = json.dumps({"method": "barycenter"}).encode()
    period = 0.001
    i = 0
    try:
        while not stop.is_set():
            start = time.monotonic()
            end = start + segment
            next_t = start
            while not stop.is_set() and (now := time.monotonic()) < end:
                if now >= next_t:
                    if i % 100 == 0:
                        session.put("cdpr/rowc/cmd/set_tda", good)
                    else:
                        session.put("cdpr/rowc/cmd/move", bad[i % 2])
                    i += 1
                    next_t += period
                time.sleep(max(0.0, min(next_t, end) - time.monotonic()))
            on.append((start, time.monotonic()))
            stop.wait(segment)
    finally:
        session.close()


def run_once(
    seconds: float, gateway: bool, rate: float, segment: float, timing: Path
) -> tuple[dict[str, np.ndarray], list[tuple[float, float]], str]:
    """One daemon run; its per-cycle timing, the flood's intervals, its output."""
    cmd = [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(ROOT / "config/rowc.toml")]
    cmd += ["--sim", "--status", "0", "--duration", str(seconds), "--rate", str(rate)]
    cmd += ["--timing-file", str(timing)]
    endpoint = ""
    if gateway:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        cmd += ["--zenoh", "--accept-commands", "--allow-unauthenticated-commands"]
        cmd += ["--zenoh-listen", endpoint]
        cmd += ["--no-multicast-scouting"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop = threading.Event()
    on: list[tuple[float, float]] = []
    flooder = None
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("ready:") and gateway:
            flooder = threading.Thread(target=flood, args=(endpoint, stop, segment, on))
            flooder.start()
        if line.startswith("summary:"):
            break
    lines += proc.stdout.readlines()
    stop.set()
    if flooder is not None:
        flooder.join()
    proc.wait()
    text = "".join(lines)
    if proc.returncode != 0 or not timing.exists():
        raise RuntimeError("the daemon failed:\n" + text[-2000:])
    with np.load(timing) as z:
        data = {k: z[k] for k in z.files}
    return data, on, text


def split(
    data: dict[str, np.ndarray], on: list[tuple[float, float]], segment: float, skip: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per cycle (the first ``skip`` s left out): lateness (µs), periods missed just before,
    whether the flood was on at its deadline, and the index of its segment (each flood
    interval, each quiet one between them; runs without a flood in ``segment`` s windows)."""
    t, late = data["deadline"], data["lateness"] * 1e6
    gaps = np.concatenate([[0.0], np.round(np.diff(t) / float(data["period"])) - 1.0])
    keep = t >= t[0] + skip
    flooded = np.zeros(len(t), dtype=bool)
    for a, b in on:
        flooded |= (t >= a) & (t < b)
    if on:
        seg = np.cumsum(np.concatenate([[0], flooded[1:] != flooded[:-1]]))
    else:
        seg = np.floor((t - t[0]) / segment).astype(int)
    return late[keep], gaps[keep], flooded[keep], seg[keep]


def segment_p99(late: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """The p99 lateness (µs) of each segment with at least 100 cycles."""
    return np.array(
        [np.percentile(late[seg == k], 99) for k in np.unique(seg) if np.sum(seg == k) >= 100]
    )


def describe(late: np.ndarray, gaps: np.ndarray) -> str:
    if len(late) == 0:
        return "no cycles"
    missed = 100.0 * gaps.sum() / (len(late) + gaps.sum())
    return (
        f"p50 {np.percentile(late, 50):.1f} p99 {np.percentile(late, 99):.1f} "
        f"p99.9 {np.percentile(late, 99.9):.0f} max {late.max():.0f} us, "
        f"missed {missed:.3f} % ({len(late)} cycles)"
    )


def main() -> None:
    ap = bench_parser(__doc__)
    ap.add_argument("--rounds", type=int, default=3)
    loop_options(ap, seconds=30.0, rate=500.0)
    ap.add_argument("--segment", type=float, default=3.0, help="flood on/off segments, s")
    args = ap.parse_args()
    print(machine_line())
    pooled: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {"A": [], "on": [], "off": []}
    segments: dict[str, list[np.ndarray]] = {"A": [], "on": [], "off": []}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for gateway in (False, True):
                data, on, _ = run_once(
                    args.seconds, gateway, args.rate, args.segment, Path(tmp) / f"{r}{gateway}.npz"
                )
                late, gaps, flooded, seg = split(data, on, args.segment)
                if gateway:
                    parts = {"on": flooded, "off": ~flooded}
                else:
                    parts = {"A": np.ones(len(late), dtype=bool)}
                for key, sel in parts.items():
                    pooled[key].append((late[sel], gaps[sel]))
                    segments[key].append(segment_p99(late[sel], seg[sel]))
                    print(f"round {r + 1} {LABELS[key]}: {describe(late[sel], gaps[sel])}")
    print("\npooled over the rounds:")
    p99, typical = {}, {}
    for key, runs in pooled.items():
        late = np.concatenate([x[0] for x in runs])
        gaps = np.concatenate([x[1] for x in runs])
        p99[key] = float(np.percentile(late, 99))
        seg = np.concatenate(segments[key])
        typical[key] = float(np.median(seg))
        print(
            f"  {LABELS[key]}: {describe(late, gaps)}; per {args.segment:g} s segment p99: "
            f"median {typical[key]:.1f} us, {np.mean(seg > 50.0) * 100:.0f} % of {len(seg)} "
            "segments above 50 us"
        )
    for key, what in (("off", "the same runs' quiet cycles"), ("A", "no gateway (runs A)")):
        print(
            f"  with the flood / {what}: p99 of all cycles {p99['on'] / p99[key]:.2f}, "
            f"median segment p99 {typical['on'] / typical[key]:.2f}"
        )


LABELS = {
    "A": "A no gateway            ",
    "off": "B gateway, no flood     ",
    "on": "B gateway + 1000 cmd/s  ",
}


if __name__ == "__main__":
    main()
