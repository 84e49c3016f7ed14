"""The simulated robot in a process of its own, for ``cdprctl run --sim``: drives have their
own processors, so their simulation takes nothing from the loop's thread.

Stepped in the daemon's loop before each cycle, the plant cost a 1 kHz rowc cycle ~260 µs
(p99 ~450 µs) of its 1 ms, and its step thrashed the caches the cycle then needed. Here it runs
as ``cdprctl sim`` does (``sim_backend.realtime.run_realtime``: real time, SCHED_FIFO one below
the loop, on the other CPU, saying when it was starved) on ``drivers/pair_bus.py``'s socket
pairs. The daemon keeps a control socket (the demo's lateral force, scheduled faults, the brakes'
closing time; the child's lines to print) and reads the plant's true position — for the
tracking error it reports — from a shared page.

``SimulatedRobotProcess`` is the daemon's handle; ``python -m sim_backend.process`` the child,
which reads its start-up (``Start``, pickled) from stdin.
"""

from __future__ import annotations

import contextlib
import dataclasses
import mmap
import os
import pickle
import select
import signal
import socket
import subprocess
import sys
import time
from typing import Any

import numpy as np

from cdprctl.model.robot import RobotModel
from drivers.pair_bus import socket_pair

# [sequence, simulated time s, x, y, z m in the world frame, the monotonic clock's s at the
# end of the last step, the contacts recorded so far]: the last two, each read alone, tell the
# daemon its drives were not run, and (at its end, even after a kill) how many contacts
POSE_FLOATS = 7
STEPPED_AT = 5
CONTACTS = 6
READY_WITHIN = 300.0  # s: a first start on a machine compiles the physics (about a minute)
STOP_WITHIN = 5.0  # s for the child to end after SIGTERM before it is killed
CONTROL_MAX = 1 << 16  # bytes of one control message


@dataclasses.dataclass
class Start:
    """What the child needs: the robot its drives are (``model``), the one its physics is
    (``as_built``), its buses' and control socket's and pose page's file descriptors, and
    where the daemon's loop runs (CPU index, SCHED_FIFO priority; ``realtime`` False: neither)."""

    model: RobotModel
    as_built: RobotModel | None
    bus_fds: list[int]
    control_fd: int
    pose_fd: int
    loop_cpu: int | None
    loop_priority: int
    realtime: bool
    daemon_pid: int = 0  # the daemon's process: the child ends when it is no longer its parent


class SimulatedRobotProcess:
    """The daemon's handle on the child: ``overrides`` (the buses a driver joins it on),
    ``disturb``, ``schedule``, ``set_brake_close_time``, ``position``, ``poll`` (its lines),
    ``close`` (then ``contacts``: how many it recorded). Blocks in the constructor until the
    child's drives are up."""

    def __init__(self, model: RobotModel, as_built: RobotModel | None, realtime: bool,
                 print_fn: Any = print) -> None:  # fmt: skip
        from cdprctl.core import realtime as rt

        self.print = print_fn
        self.contacts = 0  # the contacts the simulated robot recorded (read as it ends)
        ours, theirs = zip(*(socket_pair() for _ in model.drives.buses), strict=True)
        self._control, child_control = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
        pose_fd = os.memfd_create("cdprctl-sim-pose")
        os.ftruncate(pose_fd, mmap.PAGESIZE)
        self._page = mmap.mmap(pose_fd, mmap.PAGESIZE)
        self._pose = np.frombuffer(self._page, dtype=np.float64, count=POSE_FLOATS)
        fds = [s.fileno() for s in theirs] + [child_control.fileno(), pose_fd]
        start = Start(model, as_built, fds[:-2], fds[-2], pose_fd, rt.loop_cpu(model.control.cpu),
                      model.control.sched_priority, realtime, os.getpid())  # fmt: skip
        try:
            self.proc = subprocess.Popen([sys.executable, "-m", "sim_backend.process"],
                                         stdin=subprocess.PIPE, pass_fds=fds,
                                         start_new_session=True)  # fmt: skip
            assert self.proc.stdin is not None
            self.proc.stdin.write(pickle.dumps(start))
            self.proc.stdin.close()
        finally:
            for s in (*theirs, child_control):
                s.close()
            os.close(pose_fd)
        # each bus end handed to its PairBus, which owns it from then
        self.overrides: dict[str, Any] = {
            "interface": "socketpair", "channels": [str(s.detach()) for s in ours]}  # fmt: skip
        self._await_ready()

    def _await_ready(self) -> None:
        limit = time.monotonic() + READY_WITHIN
        while time.monotonic() < limit:
            if select.select([self._control], [], [], 0.2)[0]:
                kind, value = pickle.loads(self._control.recv(CONTROL_MAX))
                if kind == "ready":
                    return
                self.print(value)
            elif self.proc.poll() is not None:
                raise RuntimeError(f"the simulated robot's process ended (exit "
                                   f"{self.proc.returncode}) before its drives were up; its "
                                   "error is above")  # fmt: skip
        raise RuntimeError(f"the simulated robot's process was not up within {READY_WITHIN:g} s")

    # -- requests ---------------------------------------------------------------------------
    def _send(self, kind: str, value: Any) -> None:
        with contextlib.suppress(OSError):  # the child gone: its end is said at close
            self._control.send(pickle.dumps((kind, value)))

    def disturb(self, force: float) -> None:
        """A lateral force ``force`` N along y at the platform, ramped over 1 s from now."""
        self._send("disturb", force)

    def schedule(self, events: list) -> None:
        """``sim_backend.faults.FaultEvent``s (simulated time, s), beside those scheduled."""
        self._send("events", events)

    def set_brake_close_time(self, seconds: float) -> None:
        self._send("brake_close_time", seconds)

    @property
    def stepped_at(self) -> np.ndarray:
        """A view (one float, s of the monotonic clock) of when the child last stepped its
        drives: the liveness's word that a silence is a starved simulator's, not a drive's
        (``drivers.liveness.Liveness.drives_ran_at``)."""
        return self._pose[STEPPED_AT : STEPPED_AT + 1]

    @property
    def position(self) -> np.ndarray:
        """The platform's true position (m, world frame), as the child last wrote it."""
        for _ in range(100):
            seq = self._pose[0]
            value = self._pose[2:5].copy()
            if seq == self._pose[0] and seq % 2 == 0:
                return value
        return value

    def poll(self) -> None:
        """Print the child's lines that came since the last call (never blocks)."""
        while True:
            try:
                kind, value = pickle.loads(self._control.recv(CONTROL_MAX, socket.MSG_DONTWAIT))
            except (BlockingIOError, InterruptedError, OSError):
                return
            if kind == "say":
                self.print(value)

    def close(self) -> None:
        if self.proc.poll() is None:
            self._send("stop", None)
            try:
                self.proc.wait(STOP_WITHIN)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.poll()
        self.contacts = int(self._pose[CONTACTS])  # the page's: no message a full queue drops
        self._control.close()
        self._pose = np.zeros(POSE_FLOATS)  # the page's last view released before it closes
        with contextlib.suppress(BufferError):
            self._page.close()


def plant_of(start: Start) -> Any:
    """The child's physics: the as-built robot's where one is given (``--as-built``: the
    geometry the controller does not know), else the model's; at rest at home."""
    from sim_backend.plant import CdprPlant

    return CdprPlant(start.as_built if start.as_built is not None else start.model)


def serve(start: Start) -> int:
    """The child: the simulated robot in real time until the daemon says stop or is gone.
    Signals do not stop it (and it is in a session of its own): a Ctrl-C to the terminal's
    process group, or systemd's SIGTERM to the unit's processes, would silence the drives while
    the daemon stops them."""
    from cdprctl.core import realtime as rt
    from sim_backend.faults import FaultEvent, FaultInjector
    from sim_backend.realtime import LateSteps, run_realtime

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    # the daemon's pid as it sent it: read here, a daemon already dead (a Ctrl-C during the
    # child's imports) gave init's, and the child ran on holding the daemon's output open
    parent = start.daemon_pid or os.getppid()
    control = socket.socket(fileno=start.control_fd)
    page = mmap.mmap(start.pose_fd, mmap.PAGESIZE)
    pose = np.frombuffer(page, dtype=np.float64, count=POSE_FLOATS)

    def publish(t: float) -> None:
        pose[0] += 1.0  # odd: being written (the reader retries)
        pose[1] = t
        pose[2:5] = plant.position
        pose[0] += 1.0
        pose[STEPPED_AT] = time.monotonic()  # one aligned float: read whole, no sequence
        pose[CONTACTS] = len(plant.contact.contacts)

    def say(text: str, **_: Any) -> None:
        kind = "ready" if text == "cdprctl sim: ready" else "say"
        if kind == "ready":
            publish(0.0)
        with contextlib.suppress(OSError):
            control.send(pickle.dumps((kind, text)), socket.MSG_DONTWAIT)

    if os.getppid() != parent:
        return 0  # the daemon is gone already
    def realtime() -> None:
        for w in rt.simulator_realtime(start.loop_cpu, start.loop_priority):
            say(f"cdprctl run: warning: the simulated robot: {w}")

    plant = plant_of(start)
    injector = FaultInjector([])

    def between(net: Any) -> bool:
        while True:
            try:
                kind, value = pickle.loads(control.recv(CONTROL_MAX, socket.MSG_DONTWAIT))
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # the daemon gone
                return False
            if kind == "stop":
                return False
            if kind == "disturb":
                wrench = (0.0, float(value), 0.0, 0.0, 0.0, 0.0)
                injector.events.append(FaultEvent(net.time, "external_wrench", value=wrench,
                                                  ramp=1.0))  # fmt: skip
            elif kind == "events":
                injector.events.extend(value)
            elif kind == "brake_close_time":
                plant.opt.brake_close_time = float(value)
        if os.getppid() != parent:  # the daemon killed: nothing left to simulate for
            return False
        publish(net.time)
        return True

    overrides = {"interface": "socketpair", "channels": [str(fd) for fd in start.bus_fds]}
    late = LateSteps(say)
    net = run_realtime(start.model, overrides, faults=injector, plant=plant, late=late,
                       print_fn=say, between=between, signals=False,
                       realtime=realtime if start.realtime else None)  # fmt: skip
    net.close()
    pose[CONTACTS] = len(plant.contact.contacts)
    say(f"cdprctl run: the simulated robot: {plant.contact.report()}")
    if late.count:
        say(late.summary().replace("cdprctl sim:", "cdprctl run: the simulated robot:"))
    return 0


def main() -> int:
    start: Start = pickle.load(sys.stdin.buffer)
    return serve(start)


if __name__ == "__main__":
    sys.exit(main())
