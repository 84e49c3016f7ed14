"""The simulated robot in real time, as its own process (``cdprctl sim``).

Every ``step`` seconds of wall clock (default 0.5 ms) it handles the frames waiting on the
buses, each at the instant the kernel stamped its arrival (the physics stepped up to it),
ticks the drives, and integrates the physics up to now; it sleeps until the next step, waking
early when a frame arrives. Simulated time follows the monotonic clock (less the stalls of
this process beyond ``SimNetwork.MAX_CATCH_UP``).
"""

from __future__ import annotations

import gc
import math
import signal
import time
from typing import Any

import can

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
    plant: CdprPlant | None = None,
    encoders: str = "absolute",
) -> SimNetwork:
    """``plant``: the physics (default: the model's, at rest at home); ``encoders``:
    ``SimNetwork``'s."""
    plant = plant if plant is not None else CdprPlant(model)
    net = SimNetwork(model, plant, bus_overrides, encoders=encoders)
    if faults is not None:
        faults.attach(net)
    # one step before "ready": the physics kernels compile at their first call (seconds on a
    # cold cache, when the drives stood deaf for ~15 s after "ready")
    net.advance(step)
    print_fn("cdprctl sim: ready", flush=True)  # the buses are open: peers may start
    stop = {"flag": False}

    def _stop(*_: object) -> None:
        stop["flag"] = True

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    t0 = time.monotonic()
    next_status = status_every
    woke_on: Any = None
    # simulated time = monotonic − t0 − lag: a stall of this process up to the network's
    # MAX_CATCH_UP is simulated afterwards, frame by frame at their arrival instants (with
    # 10 ms, the frames of a longer stall were bunched at one instant: SYNC intervals of 0,
    # following-error faults); a longer one is lag
    lag = 0.0
    wall_minus_mono = time.time() - time.monotonic()

    def arrival(msg: can.Message) -> float:
        """s of simulated time a frame arrived at: its kernel receive stamp (wall clock)."""
        if msg.timestamp <= 0.0:
            return math.inf  # no stamp: handled now
        return msg.timestamp - wall_minus_mono - t0 - lag

    try:
        # what exists now (the compiled kernels' ~10⁵ objects) is never scanned again: a full
        # collection of it was ~80 ms here, several times that on one slow CPU, the drives deaf
        gc.collect()
        gc.freeze()
        last = t0
        while not stop["flag"]:
            now = time.monotonic()
            elapsed = now - last
            if elapsed > 0 or woke_on is not None:
                lag += max(0.0, elapsed - net.MAX_CATCH_UP)
                wall_minus_mono = time.time() - time.monotonic()
                net.advance_until(now - t0 - lag, arrival, first=woke_on)
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
                    f"brakes {int(plant.brake.sum())}/{len(plant.brake)}"
                    + ("  safety chain OPEN" if any(
                        getattr(getattr(d, "axis", None), "sto_open", False)
                        for d in net.drives) else ""),
                    flush=True,
                )
                next_status += status_every
            # sleep until the next step, or until a frame comes (one bus is enough to wake)
            wait = step - (time.monotonic() - now)
            if wait > 0:
                try:
                    woke_on = net.buses[0].recv(wait)  # handled at once by the next advance
                except can.CanError:  # the link down: the drives hear nothing meanwhile
                    time.sleep(wait)
                    woke_on = None
    finally:
        gc.unfreeze()
        for s, h in old.items():
            signal.signal(s, h)
    return net
