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
from collections.abc import Callable
from typing import Any

import can

from cdprctl.model.robot import RobotModel
from sim_backend.faults import FaultInjector
from sim_backend.network import SimNetwork
from sim_backend.plant import CdprPlant


class LateSteps:
    """The simulated robot's own word when it was not run in time: a real drive has its own
    processor, a simulated one shares the machine, and a starved simulator must never pass
    for a broken drive (its drives were deaf meanwhile: the daemon's feedback timeouts). A
    step later than ``SAY_AFTER`` is said, at most once a second, and all of them at the
    end."""

    SAY_AFTER = 0.010  # s beyond the step: 2.5 periods at 250 Hz, what no drive would miss

    def __init__(self, print_fn: Any = print):
        self.print = print_fn
        self.count = 0  # steps later than SAY_AFTER
        self.worst = 0.0  # s
        self._said_at = -math.inf  # s of simulated time
        self._unsaid = 0

    def step(self, t: float, elapsed: float) -> None:
        """A step at ``t`` s that came ``elapsed`` s after the last one."""
        if elapsed <= self.SAY_AFTER:
            return
        self.count += 1
        self.worst = max(self.worst, elapsed)
        self._unsaid += 1
        if t - self._said_at >= 1.0:
            more = f" ({self._unsaid - 1} more since the last said)" if self._unsaid > 1 else ""
            self.print(f"cdprctl sim: the simulated robot stepped {elapsed * 1e3:.1f} ms late "
                       f"at t={t:.2f} s{more}: this process was not run (a busy machine), its "
                       "drives deaf meanwhile — the simulator's lateness, not a drive's fault",
                       flush=True)  # fmt: skip
            self._said_at, self._unsaid = t, 0

    def summary(self) -> str:
        if not self.count:
            return f"cdprctl sim: every step within {self.SAY_AFTER * 1e3:.0f} ms"
        return (f"cdprctl sim: {self.count} steps later than {self.SAY_AFTER * 1e3:.0f} ms, "
                f"the latest {self.worst * 1e3:.1f} ms (the simulator starved, not the drives)")


class SimClock:
    """Simulated time = monotonic − ``t0`` − ``lag``: a stall of this process up to the
    network's MAX_CATCH_UP is simulated afterwards, frame by frame at their arrival instants
    (with 10 ms, the frames of a longer stall were bunched at one instant: SYNC intervals of
    0, following-error faults); a longer one is lag."""

    def __init__(self, t0: float):
        self.t0, self.lag = t0, 0.0
        self.wall_minus_mono = time.time() - time.monotonic()

    def arrival(self, msg: can.Message) -> float:
        """s of simulated time a frame arrived at: its kernel receive stamp (wall clock)."""
        if msg.timestamp <= 0.0:
            return math.inf  # no stamp: handled now
        return msg.timestamp - self.wall_minus_mono - self.t0 - self.lag


def status_line(sim_t: float, plant: CdprPlant, net: SimNetwork) -> str:
    """``cdprctl sim``'s status: the platform, the tensions, the frames, the brakes."""
    p = plant.position
    return (
        f"sim t={sim_t:7.2f} s  P=[{p[0]:.4f} {p[1]:.4f} {p[2]:.4f}] m  "
        f"tensions {plant.tension.min():.1f}..{plant.tension.max():.1f} N  "
        f"frames in/out {net.frames_in}/{net.frames_out}  "
        f"brakes {int(plant.brake.sum())}/{len(plant.brake)}"
        + ("  safety chain OPEN" if any(
            getattr(getattr(d, "axis", None), "sto_open", False)
            for d in net.drives) else "")
    )  # fmt: skip


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
    late: LateSteps | None = None,
    between: Callable[[SimNetwork], bool] | None = None,
    signals: bool = True,
    realtime: Callable[[], None] | None = None,
) -> SimNetwork:
    """``plant``: the physics (default: the model's, at rest at home); ``encoders``:
    ``SimNetwork``'s; ``late``: where its late steps are counted and said; ``between(net)``:
    called after each step (``run --sim``'s requests and true pose), False to stop;
    ``signals``: SIGINT and SIGTERM stop it (else only ``duration`` or ``between``);
    ``realtime()``: the process's real-time settings, applied once the kernels are loaded (a
    start-up of seconds at SCHED_FIFO held everything below it on its CPU meanwhile: another
    simulated robot, a daemon's helper threads)."""
    late = late if late is not None else LateSteps(print_fn)
    plant = plant if plant is not None else CdprPlant(model)
    net = SimNetwork(model, plant, bus_overrides, encoders=encoders)
    if faults is not None:
        faults.attach(net)
    # one step before "ready": the physics kernels compile at their first call (seconds on a
    # cold cache, when the drives stood deaf for ~15 s after "ready")
    net.advance(step)
    if realtime is not None:
        realtime()
    print_fn("cdprctl sim: ready", flush=True)  # the buses are open: peers may start
    stop = {"flag": False}

    def _stop(*_: object) -> None:
        stop["flag"] = True

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM) if signals}
    # what exists now (the compiled kernels' ~10⁵ objects) is never scanned again: a full
    # collection of it was ~80 ms here, several times that on one slow CPU, the drives deaf;
    # before the clock starts, or it was the first step's lateness (50 ms)
    gc.collect()
    gc.freeze()
    try:
        _loop(net, step, duration, late, status_every, print_fn, between, stop)
    finally:
        gc.unfreeze()
        for s, h in old.items():
            signal.signal(s, h)
    return net


def _loop(net: SimNetwork, step: float, duration: float | None, late: LateSteps,
          status_every: float, print_fn: Any, between: Callable[[SimNetwork], bool] | None,
          stop: dict[str, bool]) -> None:  # fmt: skip
    """The simulated robot in real time until ``stop["flag"]``, ``duration`` (s) or
    ``between``: each wake-up advances the network to the time now (the frames at their
    arrival), then it sleeps until the next ``step`` (s) or a frame."""
    plant = net.plant
    t0 = time.monotonic()
    next_status = status_every
    woke_on: Any = None
    clock = SimClock(t0)
    last = t0
    while not stop["flag"]:
        now = time.monotonic()
        elapsed = now - last
        if elapsed > 0 or woke_on is not None:
            late.step(now - t0, elapsed)
            clock.lag += max(0.0, elapsed - net.MAX_CATCH_UP)
            clock.wall_minus_mono = time.time() - time.monotonic()
            net.advance_until(now - t0 - clock.lag, clock.arrival, first=woke_on)
            woke_on = None
            last = now
            if between is not None and not between(net):
                break
        sim_t = now - t0
        if duration is not None and sim_t >= duration:
            break
        if status_every and sim_t >= next_status:
            print_fn(status_line(sim_t, plant, net), flush=True)
            next_status += status_every
        # sleep until the next step, or until a frame comes (one bus is enough to wake)
        wait = step - (time.monotonic() - now)
        if wait > 0:
            try:
                woke_on = net.buses[0].recv(wait)  # handled at once by the next advance
            except can.CanError:  # the link down: the drives hear nothing meanwhile
                time.sleep(wait)
                woke_on = None
