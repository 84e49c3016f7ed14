"""Benchmark: a command flood from an authorised peer (the example ACL's operator) into the
daemon's gateway — memory of the gateway process (RSS) before, during and after, the commands
the daemon answered, and the journal lines it wrote (docs/telemetry.md, "Security").

Run: ``.venv/bin/python benchmarks/bench_command_flood.py [--commands 20000]``.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line

ROOT = Path(__file__).resolve().parents[1]


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--commands", type=int, default=20000)
    args = ap.parse_args()
    print(machine_line())
    from cdprctl.telemetry.zenoh.session import open_session

    tmp = Path(tempfile.mkdtemp())
    (tmp / "users.txt").write_text("operator:op-secret\n")
    gw = (ROOT / "config" / "zenoh" / "gateway-acl.json5").read_text()
    (tmp / "gw.json5").write_text(
        gw.replace("/etc/cdprctl/zenoh-users.txt", str(tmp / "users.txt"))
    )
    (tmp / "op.json5").write_text(
        '{transport: {auth: {usrpwd: {user: "operator", password: "op-secret"}}}}'
    )
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    proc = subprocess.Popen(
        [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(ROOT / "config" / "rowc.toml"),
         "--sim", "--no-demo", "--status", "0", "--duration", "120", "--no-realtime",
         "--zenoh-listen", endpoint, "--no-multicast-scouting", "--accept-commands",
         "--zenoh-config", str(tmp / "gw.json5")],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT,
    )  # fmt: skip
    lines: list[str] = []
    threading.Thread(
        target=lambda: lines.extend(x.rstrip() for x in proc.stdout), daemon=True
    ).start()  # type: ignore[union-attr]
    while not any(x.startswith("ready:") for x in lines):
        if proc.poll() is not None:
            sys.exit("\n".join(lines))
        time.sleep(0.1)
    gateway = children(proc.pid)
    session = open_session(
        connect=[endpoint], multicast_scouting=False, config_file=str(tmp / "op.json5")
    )
    replies = {"n": 0}
    sub = session.declare_subscriber(
        "cdpr/rowc/reply/*", lambda s: replies.__setitem__("n", replies["n"] + 1)
    )
    time.sleep(1.0)

    def rss() -> int:
        return sum(rss_kib(p) for p in gateway if Path(f"/proc/{p}").exists())

    before = rss()
    peak = before
    t0 = time.monotonic()
    for i in range(args.commands):
        # four of five invalid (rejected by the gateway), one a valid set_tda (to the mailbox)
        if i % 5 == 0:
            session.put("cdpr/rowc/cmd/set_tda", json.dumps({"method": "barycenter", "id": i}))
        else:
            session.put("cdpr/rowc/cmd/move", json.dumps({"position": "nowhere", "id": i}))
        if i % 1000 == 0:
            peak = max(peak, rss())
    sent = time.monotonic() - t0
    time.sleep(3.0)
    after = rss()
    sub.undeclare()
    session.close()
    proc.terminate()
    proc.wait(timeout=30)
    logged = sum("cdprctl-zenoh: command" in x for x in lines)
    summarised = sum("more commands rejected" in x for x in lines)
    print(
        f"{args.commands} commands in {sent:.2f} s ({args.commands / sent:.0f}/s) from the operator"
    )
    mib = [x / 1024 for x in (before, peak, after)]
    print("gateway RSS: before {:.1f} MiB, peak {:.1f} MiB, 3 s after {:.1f} MiB".format(*mib))
    print(f"replies received {replies['n']}; journal: {logged} lines, {summarised} summaries")
    print(f"daemon exit code {proc.returncode}")


if __name__ == "__main__":
    main()
