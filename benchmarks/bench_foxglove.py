"""Benchmark: what the live 3D view (`cdprctl run --foxglove`) costs the loop.

The daemon on the simulated robot (rowc, in-process, 500 Hz or --rate, the demo motion) runs
alternately without the view (A) and with it (B), a Foxglove-like client subscribed to every
channel for the whole of B (so the scene is built, encoded and sent at 30 Hz). Each run saves
its per-cycle timing (``--timing-file``). Reports per run and pooled: wake lateness p50/p99/max,
compute p50/p99, missed periods, the scene messages received, and the B/A ratios of the p99s.

Run: ``.venv/bin/python benchmarks/bench_foxglove.py [--rounds 3] [--seconds 20]``.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import free_port, machine_line

ROOT = Path(__file__).resolve().parents[1]



def client(url: str, stop: threading.Event, counts: dict[str, int]) -> None:
    import websockets

    async def main() -> None:
        async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"],
                                      max_size=None) as ws:  # fmt: skip
            channels: dict[int, str] = {}
            while len(channels) < 4:
                m = await ws.recv()
                if isinstance(m, str) and json.loads(m)["op"] == "advertise":
                    channels.update({c["id"]: c["topic"] for c in json.loads(m)["channels"]})
            subs = dict(enumerate(channels))
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": i, "channelId": c} for i, c in subs.items()]}))  # fmt: skip
            while not stop.is_set():
                try:
                    m = await asyncio.wait_for(ws.recv(), 0.5)
                except TimeoutError:
                    continue
                except websockets.ConnectionClosed:  # the daemon's run ended
                    return
                if isinstance(m, bytes) and m[0] == 1:
                    topic = channels[subs[int.from_bytes(m[1:5], "little")]]
                    counts[topic] = counts.get(topic, 0) + 1

    asyncio.run(main())


def run_once(seconds: float, view: bool, rate: float, timing: Path) -> tuple[dict, dict]:
    cmd = [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(ROOT / "config/rowc.toml"),
           "--sim", "--status", "0", "--duration", str(seconds), "--rate", str(rate),
           "--timing-file", str(timing)]  # fmt: skip
    port = free_port()
    if view:
        cmd += ["--foxglove", f"127.0.0.1:{port}"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop, counts, th = threading.Event(), {}, None
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("ready:") and view:
            th = threading.Thread(target=client, args=(f"ws://127.0.0.1:{port}", stop, counts))
            th.start()
        if line.startswith("summary:"):
            break
    lines += proc.stdout.readlines()
    stop.set()
    if th is not None:
        th.join()
    proc.wait()
    if proc.returncode != 0 or not timing.exists():
        raise RuntimeError("the daemon failed:\n" + "".join(lines)[-2000:])
    with np.load(timing) as z:
        return {k: z[k] for k in z.files}, counts


def stats(data: dict) -> dict[str, float]:
    t = data["deadline"]
    keep = t >= t[0] + 1.0
    late = data["lateness"][keep] * 1e6
    comp = data["compute"][keep] * 1e6
    gaps = np.round(np.diff(t) / float(data["period"])) - 1.0
    return {"late_p50": float(np.median(late)), "late_p99": float(np.percentile(late, 99)),
            "late_max": float(late.max()), "compute_p50": float(np.median(comp)),
            "compute_p99": float(np.percentile(comp, 99)), "missed": float(gaps[gaps > 0].sum()),
            "cycles": float(keep.sum())}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=500.0)
    args = ap.parse_args()
    print(machine_line())
    pooled: dict[bool, list[dict]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as d:
        for r in range(args.rounds):
            for view in (False, True):
                data, counts = run_once(args.seconds, view, args.rate, Path(d) / f"{r}{view}.npz")
                s = stats(data)
                pooled[view].append(data)
                scene = counts.get("/scene", 0)
                print(f"round {r + 1} {'B view ' if view else 'A none '}: lateness p50 "
                      f"{s['late_p50']:.0f} p99 {s['late_p99']:.0f} max {s['late_max']:.0f} µs;"
                      f" compute p50 {s['compute_p50']:.0f} p99 {s['compute_p99']:.0f} µs; "
                      f"missed {s['missed']:.0f} of {s['cycles']:.0f}"
                      + (f"; scene messages {scene} ({scene / (args.seconds - 1):.1f}/s)"
                         if view else ""))  # fmt: skip
    res = {}
    for view in (False, True):
        merged = {"deadline": np.concatenate([x["deadline"] - x["deadline"][0] + 1e4 * i
                                              for i, x in enumerate(pooled[view])]),
                  "lateness": np.concatenate([x["lateness"] for x in pooled[view]]),
                  "compute": np.concatenate([x["compute"] for x in pooled[view]]),
                  "period": pooled[view][0]["period"]}  # fmt: skip
        res[view] = stats(merged)
        res[view]["missed"] = sum(stats(x)["missed"] for x in pooled[view])
    a, b = res[False], res[True]
    print(f"pooled: lateness p99 A {a['late_p99']:.0f} µs, B {b['late_p99']:.0f} µs "
          f"(B/A {b['late_p99'] / a['late_p99']:.2f}); compute p99 A {a['compute_p99']:.0f}, "
          f"B {b['compute_p99']:.0f} µs (B/A {b['compute_p99'] / a['compute_p99']:.2f}); "
          f"missed A {a['missed']:.0f}, B {b['missed']:.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
