"""A helper process of the daemon (the Zenoh gateway, the Foxglove view), started with spawn.

It ignores SIGINT: a terminal's Ctrl-C goes to the whole process group, and the daemon stops
its helpers itself, through their stop event (each helper printed a ``KeyboardInterrupt``
traceback, two interleaved during a start-up). It is born with SIGINT blocked (the parent
blocks it around the start: the mask survives spawn's exec), so a Ctrl-C while it imports its
modules, before it can ignore it, waits and is then dropped (1 start-up in ~9 printed a
traceback from the gateway's imports when it was ignored only once the target ran). A helper
that fails before it is ready says why in one line, which the daemon prints at once instead
of a traceback and a wait for a process that had already died."""

from __future__ import annotations

import multiprocessing as mp
import signal
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.snapshot import SharedSnapshot


def helper_entry(target: Callable[..., None], failed: Any, *args: Any) -> None:
    """The process's target: ``target(*args)``; an exception goes to ``failed`` (a queue) as
    one line and ends the process with status 1."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})  # a pending one is dropped
    try:
        target(*args)
    except Exception as exc:
        text = " ".join(str(exc).split())  # one line
        failed.put(text if isinstance(exc, OSError) and text else f"{type(exc).__name__}: {text}")
        sys.exit(1)


class HelperProcess:
    """One helper: ``target(*args)`` in a spawned process named ``name``; ``what`` it is in
    words ("the Zenoh gateway"). ``args`` include ``ready`` (an event of ``ctx``) for the
    target to set once it serves."""

    def __init__(self, ctx: Any, name: str, what: str, target: Callable[..., None],
                 args: tuple[Any, ...], ready: Any):  # fmt: skip
        self.what, self.ready = what, ready
        self.failed = ctx.SimpleQueue()
        self.process = ctx.Process(target=helper_entry, args=(target, self.failed, *args),
                                   name=name, daemon=True)  # fmt: skip
        self.failure = f"{what} did not start"

    def start(self, timeout: float) -> bool:
        """Start it and wait until it is ready (True) or failed, or ``timeout`` s passed:
        ``failure`` then says which, in one line."""
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # held, not lost
        try:
            self.process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        deadline = time.monotonic() + timeout
        while not self.ready.wait(0.05):
            if not self.process.is_alive():
                why = self.failed.get() if not self.failed.empty() else (
                    f"exit status {self.process.exitcode}")  # fmt: skip
                self.failure = f"{self.what} did not start: {why}"
                return False
            if time.monotonic() > deadline:
                self.failure = f"{self.what} did not start in {timeout:g} s"
                return False
        return True

    def stop(self) -> None:
        """After its stop event was set: joined, terminated if it does not end."""
        if self.process.pid is None:  # never started
            return
        self.process.join(timeout=5.0)
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout=2.0)


class SnapshotLink:
    """The daemon's side of a helper fed one way by the loop's shared-memory snapshot (the
    Zenoh gateway's ``TelemetryLink``, ``FoxgloveLink``, ``Ros2Link``): the snapshot, the stop
    and ready events, the queues made with ``queue``, wanted once a ``period`` s (``due``),
    and one order to close them in: the helper stopped before its queues and snapshot go.
    A subclass makes its process with ``start_helper``."""

    def __init__(self, model: RobotModel, period: float):
        self.ctx = mp.get_context("spawn")  # never fork a process that has threads
        self.model = model
        self.snapshot = SharedSnapshot(model.n_cables, g=len(model.grippers))
        self.stop = self.ctx.Event()
        self.ready = self.ctx.Event()
        self.period = period  # s
        self._rate = Decimator(period)
        self._queues: list[Any] = []

    def queue(self, maxsize: int) -> Any:
        """A queue to the helper or from it, closed with the link."""
        q = self.ctx.Queue(maxsize=maxsize)
        self._queues.append(q)
        return q

    def start_helper(self, name: str, what: str, target: Callable[..., None],
                     *args: Any) -> None:  # fmt: skip
        """The helper: ``target(*args)`` in a process ``name``, ``what`` it is in words."""
        self.helper = HelperProcess(self.ctx, name, what, target, args, self.ready)

    def due(self) -> bool:
        """Whether the link's period has come (then the caller ``write``s)."""
        return self._rate.due()

    def write(self, values: dict[str, Any], stats: Any = None) -> None:
        """The loop's values (``snapshot.controller_values``) into the snapshot."""
        self.snapshot.write(values)

    def close(self) -> None:
        self.stop.set()
        self.helper.stop()
        for q in self._queues:
            close_queue(q)
        self.snapshot.close()


def paced(stop: Any, period: float, alive: Callable[[], bool] | None = None) -> Iterator[float]:
    """A helper process's loop (the gateway, the Foxglove view, the ROS 2 view): a turn once a
    ``period`` s, each given its time (``time.monotonic``), until ``stop`` is set or
    ``alive()`` is false (the daemon is gone); a late turn is not caught up (a stall makes no
    burst)."""
    next_t = time.monotonic()
    while not stop.is_set() and (alive is None or alive()):
        yield time.monotonic()
        next_t = max(next_t + period, time.monotonic())
        time.sleep(max(0.0, next_t - time.monotonic()))


class Deadlines:
    """One rate among a helper's turns (``paced``): ``due(now)`` once a ``period`` s, on the
    grid that starts at its creation; after a stall the next is a period on (no burst)."""

    def __init__(self, period: float):
        self.period = period
        self.next = time.monotonic()

    def due(self, now: float) -> bool:
        if now < self.next:
            return False
        self.next += self.period
        if self.next < now:  # a stall
            self.next = now + self.period
        return True


class NewStates:
    """A view's publication of the loop's states: ``publish(s)`` for each state of the
    snapshot ``snap`` not published yet (its ``seq`` changed); one that fails is said once on
    stderr, by the process's ``name``, and does not end the view."""

    def __init__(self, snap: Any, name: str, publish: Callable[[Any], None]):
        self.snap, self.name, self.publish = snap, name, publish
        self.last_seq = -1.0
        self.failed = False  # said once

    def __call__(self) -> None:
        s = self.snap.read()
        if s is None or s["seq"][0] == self.last_seq:
            return
        self.last_seq = s["seq"][0]
        try:
            self.publish(s)
        except Exception as exc:  # a bad frame must not end the view
            if not self.failed:
                print(f"{self.name}: a frame failed: {type(exc).__name__}: {exc}",
                      file=sys.stderr, flush=True)  # fmt: skip
            self.failed = True


class Decimator:
    """A link's own rate out of the I/O thread's ticks: ``due()`` once a ``period`` (s)."""

    def __init__(self, period: float):
        self.period = period
        self._next = 0.0

    def due(self) -> bool:
        import time

        now = time.monotonic()
        # the I/O thread's ticks jitter around the period: a tick a little early still counts
        slack = 0.3 * self.period
        if now < self._next - slack:
            return False
        self._next = max(self._next + self.period, now - slack)
        return True


def close_queue(queue: Any, timeout: float = 2.0) -> None:
    """A ``multiprocessing`` queue closed and its feeder thread (ours, the one that writes
    what we put into the pipe) ended here, within ``timeout`` s. Left to end on its own (as
    ``cancel_join_thread`` leaves it), the feeder could end during the interpreter's exit,
    dropping the queue's last semaphores there, and be halted between a semaphore's unlink
    and its unregistering: multiprocessing's resource tracker then printed "1 leaked
    semaphore" after a clean Ctrl-C (2 fresh-clone test suites in 3). A feeder stuck on a
    pipe no one reads any more (its helper died with the pipe full) is not waited for."""
    queue.close()  # the feeder gets its sentinel once what it holds is written
    feeder = getattr(queue, "_thread", None)  # multiprocessing's; None: nothing was put
    if feeder is not None:
        feeder.join(timeout)
    if feeder is None or feeder.is_alive():
        queue.cancel_join_thread()

