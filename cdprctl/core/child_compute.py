"""A computation of seconds in a process of its own, for a process whose loop holds drives
(the geometric calibration identifying its start while the platform is held).

In a thread of the loop's process it shared the interpreter's lock with the loop: at the
normal scheduler other work preempted it while it held that lock, and the loop waiting for it
sent no SYNC for over 100 ms (the drives' comm_timeout, EMCY 0x8130); at ``SCHED_FIFO`` its
seconds of computing spent the CPU's real-time budget (``sched_rt_runtime_us``: 950 ms a
second) and the kernel held the simulated robot there ("stepped 156 ms late"). A process of
its own shares neither. The task (a picklable callable: a module-level function, or a
``functools.partial`` of one) and its result go through files, so the caller never blocks on
a pipe the child has not read yet (its imports take seconds).

``compute_in_child(task)`` from the caller's thread; ``python -m cdprctl.core.child_compute
TASK RESULT`` the child. The child inherits the calling thread's scheduling policy, niceness
and CPUs: call it from a thread set up for long work (``realtime.worker_thread``).
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


class ChildComputationError(RuntimeError):
    """The child ended without a result (killed, or it could not start)."""


def compute_in_child(task: Callable[[], T]) -> T:
    """``task()`` run in a new Python process; its result, or its exception raised here (a
    ``ChildComputationError`` with the child's last words where it left none)."""
    with tempfile.TemporaryDirectory(prefix="cdprctl-compute-") as tmp:
        task_file, result_file = Path(tmp) / "task.pickle", Path(tmp) / "result.pickle"
        task_file.write_bytes(pickle.dumps(task))
        proc = subprocess.run(
            [sys.executable, "-m", "cdprctl.core.child_compute", str(task_file),
             str(result_file)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        if not result_file.is_file():
            said = proc.stderr.decode(errors="replace").strip().splitlines()
            raise ChildComputationError(
                f"the computation's process ended with exit {proc.returncode} and no result"
                + (f": {said[-1]}" if said else ""))  # fmt: skip
        kind, value = pickle.loads(result_file.read_bytes())
    if kind == "error":
        raise value
    return value


def _run(task_file: str, result_file: str) -> int:
    """The child: the task from ``task_file``, its result or exception to ``result_file``
    (written whole, then renamed: a result file is never half a result)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C is the caller's to handle
    task = pickle.loads(Path(task_file).read_bytes())
    outcome: tuple[str, Any]
    try:
        outcome = ("ok", task())
    except Exception as exc:  # handed to the caller, who raises it
        try:
            pickle.dumps(exc)
            outcome = ("error", exc)
        except Exception:
            outcome = ("error", ChildComputationError(f"{type(exc).__name__}: {exc}"))
    partial = result_file + ".part"
    Path(partial).write_bytes(pickle.dumps(outcome))
    os.replace(partial, result_file)
    return 0


if __name__ == "__main__":
    sys.exit(_run(sys.argv[1], sys.argv[2]))
