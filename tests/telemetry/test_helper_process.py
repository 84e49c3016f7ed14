"""The daemon's helper processes' plumbing (cdprctl/telemetry/helper.py): the queues to them
closed with their feeder thread ended before the interpreter's exit, without ever hanging on
a helper that no longer reads."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import time

from cdprctl.telemetry.helper import close_queue


def test_a_queue_is_closed_with_its_feeder_ended_here():
    """What was put is written and the feeder thread ends in ``close_queue`` (left to end on its
    own it could end during the interpreter's exit, halted between a semaphore's unlink and
    its unregistering: a "leaked semaphore" warning after a clean stop)."""
    ctx = mp.get_context("spawn")
    q = ctx.Queue(maxsize=10)
    for i in range(5):
        q.put_nowait(i)
    feeder = q._thread
    assert feeder is not None and feeder.is_alive()
    close_queue(q)
    assert not feeder.is_alive() and not q._joincancelled  # it wrote them all and ended
    close_queue(ctx.Queue())  # nothing ever put: no feeder, nothing to wait for


def test_a_feeder_stuck_on_a_pipe_no_one_reads_is_not_waited_for():
    """A helper that died with the pipe full: ``close_queue`` gives up after its timeout and
    the feeder is not joined at exit either (the daemon would hang in its exit)."""
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    for _ in range(8):
        q.put_nowait(b"x" * 65536)  # 512 KiB: the pipe (64 KiB) fills, the feeder blocks
    time.sleep(0.2)
    feeder = q._thread
    t0 = time.monotonic()
    close_queue(q, timeout=0.3)
    assert 0.25 < time.monotonic() - t0 < 2.0
    assert feeder.is_alive() and q._joincancelled
    # the test's clean-up: read what is left; the feeder then ends, closing the reader
    # under this loop (from its thread: an OSError here)
    with contextlib.suppress(OSError):
        while feeder.is_alive():
            if q._reader.poll(0.1):
                q._reader.recv_bytes()
    feeder.join(5.0)
    assert not feeder.is_alive()
