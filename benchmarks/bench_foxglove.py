"""Benchmark: what the live 3D view (`cdprctl run --foxglove`) costs the loop.

The daemon on the simulated robot (rowc, in-process, 500 Hz or --rate, the demo motion) runs
alternately without the view (A) and with it (B), a Foxglove-like client subscribed to every
channel for the whole of B (so the scene is built, encoded and sent at 30 Hz). Each run saves
its per-cycle timing (``--timing-file``). Reports per run and pooled: wake lateness p50/p99/max,
compute p50/p99, missed periods, the scene messages received, and the B/A ratios of the p99s.

Run: ``.venv/bin/python benchmarks/bench_foxglove.py [--rounds 3] [--seconds 20]``.
"""

from __future__ import annotations

import asyncio
import json
import sys
import tempfile
import threading
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import (
    ab_arguments,
    free_port,
    loop_stats,
    machine_line,
    pooled_loop_stats,
    timed_daemon_run,
)

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
    port = free_port()
    args = ["--duration", str(seconds), "--rate", str(rate)]
    args += ["--foxglove", f"127.0.0.1:{port}"] if view else []
    stop, counts = threading.Event(), {}

    def start() -> threading.Thread | None:
        if not view:
            return None
        th = threading.Thread(target=client, args=(f"ws://127.0.0.1:{port}", stop, counts))
        th.start()
        return th

    try:
        data = timed_daemon_run(args, timing, start)
    finally:
        stop.set()
    return data, counts


def main() -> None:
    args = ab_arguments()
    print(machine_line())
    pooled: dict[bool, list[dict]] = {False: [], True: []}
    with tempfile.TemporaryDirectory() as d:
        for r in range(args.rounds):
            for view in (False, True):
                data, counts = run_once(args.seconds, view, args.rate, Path(d) / f"{r}{view}.npz")
                s = loop_stats(data)
                pooled[view].append(data)
                scene = counts.get("/scene", 0)
                print(f"round {r + 1} {'B view ' if view else 'A none '}: lateness p50 "
                      f"{s['late_p50']:.0f} p99 {s['late_p99']:.0f} max {s['late_max']:.0f} µs;"
                      f" compute p50 {s['compute_p50']:.0f} p99 {s['compute_p99']:.0f} µs; "
                      f"missed {s['missed']:.0f} of {s['cycles']:.0f}"
                      + (f"; scene messages {scene} ({scene / (args.seconds - 1):.1f}/s)"
                         if view else ""))  # fmt: skip
    res = {view: pooled_loop_stats(pooled[view]) for view in (False, True)}
    a, b = res[False], res[True]
    print(f"pooled: lateness p99 A {a['late_p99']:.0f} µs, B {b['late_p99']:.0f} µs "
          f"(B/A {b['late_p99'] / a['late_p99']:.2f}); compute p99 A {a['compute_p99']:.0f}, "
          f"B {b['compute_p99']:.0f} µs (B/A {b['compute_p99'] / a['compute_p99']:.2f}); "
          f"missed A {a['missed']:.0f}, B {b['missed']:.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
