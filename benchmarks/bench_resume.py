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


def start_daemon(config: str, endpoint: str) -> tuple[subprocess.Popen, list[str]] | None:
    """``cdprctl run --sim`` on ``config`` with its gateway listening on ``endpoint`` and the
    timing at 20 Hz (windows of 50 ms, so a missed period is placed to 50 ms); with its
    output up to "ready", or None (the output printed) where it never got there."""
    import tempfile

    cfg = Path(tempfile.mkdtemp()) / "robot.toml"
    cfg.write_text(f'base = "{Path(config).resolve()}"\n[zenoh]\ntiming_rate = 20\n')
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
            return daemon, lines
    print("".join(lines))
    os.killpg(daemon.pid, signal.SIGTERM)
    daemon.wait(timeout=30)
    return None


class Client:
    """A Zenoh client of the daemon's gateway: its timing windows (each with the time it came)
    and its last state, the commands sent."""

    def __init__(self, endpoint: str, prefix: str):
        from cdprctl.telemetry.zenoh.session import open_session

        self.session = open_session(connect=[endpoint], multicast_scouting=False)
        self.prefix = prefix
        self.timing: list[tuple[float, dict[str, Any]]] = []
        self.state: dict[str, Any] = {}
        self.subs = [
            self.session.declare_subscriber(f"{prefix}/timing", self._on_timing),
            self.session.declare_subscriber(f"{prefix}/state", self._on_state),
        ]

    def _on_timing(self, sample: Any) -> None:
        self.timing.append((time.monotonic(), json.loads(sample.payload.to_bytes())))

    def _on_state(self, sample: Any) -> None:
        self.state.update(json.loads(sample.payload.to_bytes()))

    def put(self, kind: str, payload: dict[str, Any] | None = None) -> None:
        self.session.put(f"{self.prefix}/cmd/{kind}", json.dumps(payload or {}))

    def wait(self, what: Any, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while not what():
            if time.monotonic() > deadline:
                raise TimeoutError(json.dumps(self.state)[:500])
            time.sleep(0.02)

    def path_state(self) -> str:
        return str((self.state.get("path") or {}).get("state", ""))

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()
        self.session.close()


def rounds(c: Client, n: int) -> tuple[list[float], list[float]]:
    """``n`` rounds of the wipe path: run, pause, resume, abort; the times each pause and each
    resume was sent (s, monotonic)."""
    pauses, resumes = [], []
    time.sleep(1.0)
    c.put("enable")
    c.wait(lambda: c.state.get("state") == "enabled")
    text = (ROOT / "paths" / "rowc_wipe.csv").read_text()
    for _ in range(n):
        c.put("path", {"name": "wipe", "text": text})
        c.wait(lambda: c.path_state() == "running", 40.0)
        time.sleep(1.5)
        pauses.append(time.monotonic())
        c.put("pause")
        c.wait(lambda: c.path_state() == "paused" and c.state.get("state") == "enabled")
        time.sleep(1.5)
        resumes.append(time.monotonic())
        c.put("resume")
        c.wait(lambda: c.path_state() == "running")
        time.sleep(1.5)
        c.put("abort")
        c.wait(lambda: c.path_state() in ("aborted", "done") and c.state.get("state") == "enabled")
        time.sleep(0.5)
    return pauses, resumes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--config", default=str(ROOT / "config" / "rowc.toml"))
    a = ap.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = start_daemon(a.config, endpoint)
    if started is None:
        return 1
    daemon, lines = started
    prefix = "cdpr/" + next(x for x in lines if x.startswith("cdprctl run:")).split()[2].rstrip(",")
    client = Client(endpoint, prefix)
    try:
        pauses, resumes = rounds(client, a.rounds)
    finally:
        client.close()
        os.killpg(daemon.pid, signal.SIGTERM)
        daemon.wait(timeout=30)
    timing = client.timing

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
