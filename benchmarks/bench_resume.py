"""Missed periods around a path's pause and resume, in real time (``cdprctl run --sim`` with its
gateway, a Zenoh client here).

A resume plans the rest of the path (checked again, thousands of samples) outside the loop —
in the daemon's I/O thread, which shares the interpreter's lock with the loop's thread: the
loop waited for it. The figure: the periods missed in the timing windows within 1 s after each
resume, against the same after each pause (the control: a pause plans nothing).

    .venv/bin/python benchmarks/bench_resume.py [--rounds 4] [--config config/rowc.toml]
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--config", default=str(ROOT / "config" / "rowc.toml"))
    a = ap.parse_args()
    import tempfile

    from cdprctl.telemetry.zenoh.session import open_session

    # the timing at 20 Hz: windows of 50 ms, so a missed period is placed to 50 ms
    cfg = Path(tempfile.mkdtemp()) / "robot.toml"
    cfg.write_text(f'base = "{Path(a.config).resolve()}"\n[zenoh]\ntiming_rate = 20\n')
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    daemon = subprocess.Popen(
        [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(cfg), "--sim", "--no-demo",
         "--status", "0", "--zenoh-listen", endpoint, "--no-multicast-scouting",
         "--accept-commands", "--allow-unauthenticated-commands"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
        start_new_session=True,
    )  # fmt: skip
    lines: list[str] = []
    assert daemon.stdout is not None
    for line in daemon.stdout:
        lines.append(line)
        if line.startswith("ready"):
            break
    else:
        print("".join(lines))
        return 1
    session = open_session(connect=[endpoint], multicast_scouting=False)
    prefix = "cdpr/" + next(x for x in lines if x.startswith("cdprctl run:")).split()[2].rstrip(",")
    timing: list[tuple[float, dict[str, Any]]] = []
    state: dict[str, Any] = {}

    def on_timing(sample: Any) -> None:
        timing.append((time.monotonic(), json.loads(sample.payload.to_bytes())))

    def on_state(sample: Any) -> None:
        state.update(json.loads(sample.payload.to_bytes()))

    subs = [session.declare_subscriber(f"{prefix}/timing", on_timing),
            session.declare_subscriber(f"{prefix}/state", on_state)]  # fmt: skip

    def put(kind: str, payload: dict[str, Any] | None = None) -> None:
        session.put(f"{prefix}/cmd/{kind}", json.dumps(payload or {}))

    def wait(what: Any, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not what():
            if time.monotonic() > deadline:
                raise TimeoutError(json.dumps(state)[:500])
            time.sleep(0.02)

    def path_state() -> str:
        return str((state.get("path") or {}).get("state", ""))

    pauses, resumes = [], []
    try:
        time.sleep(1.0)
        put("enable")
        wait(lambda: state.get("state") == "enabled")
        text = (ROOT / "paths" / "rowc_wipe.csv").read_text()
        for _ in range(a.rounds):
            put("path", {"name": "wipe", "text": text})
            wait(lambda: path_state() == "running", 40.0)
            time.sleep(1.5)
            pauses.append(time.monotonic())
            put("pause")
            wait(lambda: path_state() == "paused" and state.get("state") == "enabled")
            time.sleep(1.5)
            resumes.append(time.monotonic())
            put("resume")
            wait(lambda: path_state() == "running")
            time.sleep(1.5)
            put("abort")
            wait(lambda: path_state() in ("aborted", "done") and state.get("state") == "enabled")
            time.sleep(0.5)
    finally:
        for s in subs:
            s.undeclare()
        session.close()
        os.killpg(daemon.pid, signal.SIGTERM)
        daemon.wait(timeout=30)

    # the timing's "missed" counts from the start: each window's own is the difference
    stamps = [t for t, _ in timing]
    total = [int(m.get("missed", 0)) for _, m in timing]
    new = [0] + [b - a for a, b in itertools.pairwise(total)]

    def missed_after(t0: float) -> int:
        """In the windows reported from t0 (the command sent) to 1 s after it."""
        return sum(n for t, n in zip(stamps, new, strict=True) if t0 <= t <= t0 + 1.0)

    quiet = (total[-1] - total[0]) / max(stamps[-1] - stamps[0], 1e-9) if total else 0.0

    after_pause = [missed_after(t) for t in pauses]
    after_resume = [missed_after(t) for t in resumes]
    load = os.getloadavg()[0]
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} cores, load average {load:.2f}; "
          f"{a.rounds} rounds of path, pause, resume, abort ({Path(a.config).name}, real time)")
    print(f"missed periods within 1 s after a pause:  {after_pause} "
          f"(median {statistics.median(after_pause):g})")
    print(f"missed periods within 1 s after a resume: {after_resume} "
          f"(median {statistics.median(after_resume):g}); over the whole run {quiet:.1f} per s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
