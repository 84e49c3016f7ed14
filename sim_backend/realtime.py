"""The simulated robot in real time, as its own process (``cdprctl sim``).

Every ``step`` seconds of wall clock (default 0.5 ms) it handles the frames waiting on the
buses, ticks the drives, and integrates the physics over the elapsed time; it sleeps until the
next step, waking early when a frame arrives. Simulated time follows the monotonic clock.
"""

from __future__ import annotations

import signal
import time
from typing import Any

from cdprctl.model.robot import RobotModel
from sim_backend.faults import FaultInjector
from sim_backend.network import SimNetwork
from sim_backend.plant import CdprPlant


def run_realtime(
    model: RobotModel,
    bus_overrides: dict[str, Any] | None = None,
    duration: float | None = None,
    step: float = 0.0005,
    faults: FaultInjector | None = None,
    status_every: float = 0.0,
    print_fn: Any = print,
) -> SimNetwork:
    plant = CdprPlant(model)
    net = SimNetwork(model, plant, bus_overrides)
    if faults is not None:
        faults.attach(net)
    print_fn("cdprctl sim: ready", flush=True)  # the buses are open: peers may start
    stop = {"flag": False}

    def _stop(*_: object) -> None:
        stop["flag"] = True

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    t0 = time.monotonic()
    next_status = status_every
    woke_on: Any = None
    try:
        last = t0
        while not stop["flag"]:
            now = time.monotonic()
            elapsed = now - last
            if elapsed > 0 or woke_on is not None:
                # a stall never becomes a huge physics step
                net.advance(min(elapsed, 0.01), first=woke_on)
                woke_on = None
                last = now
            sim_t = now - t0
            if duration is not None and sim_t >= duration:
                break
            if status_every and sim_t >= next_status:
                p = plant.position
                print_fn(
                    f"sim t={sim_t:7.2f} s  P=[{p[0]:.4f} {p[1]:.4f} {p[2]:.4f}] m  "
                    f"tensions {plant.tension.min():.1f}..{plant.tension.max():.1f} N  "
                    f"frames in/out {net.frames_in}/{net.frames_out}  "
                    f"brakes {int(plant.brake.sum())}/{len(plant.brake)}",
                    flush=True,
                )
                next_status += status_every
            # sleep until the next step, or until a frame comes (one bus is enough to wake)
            wait = step - (time.monotonic() - now)
            if wait > 0:
                woke_on = net.buses[0].recv(wait)  # handled at once by the next advance
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    return net
