"""The daemon: the real-time loop's skipping rule, the systemd notification protocol over a
real unix socket, the watchdog's rule, SIGTERM → controlled stop → exit 0, the unit file."""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import io
import os
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CONFIG, ROOT

from cdprctl.control.lifecycle.loop import LoopStats, run_loop
from cdprctl.core import realtime as rt
from cdprctl.daemon.sdnotify import Watchdog, notify, watchdog_interval


def test_loop_skips_missed_periods_without_catching_up():
    """A step that stalls 3.5 periods once: the periods it covered are skipped (counted), the
    deadlines stay on the grid, the next cycles are not run back to back to catch up, and each
    step is given the time it runs at (a late cycle computes for when it sends)."""
    period = 0.005
    starts: list[float] = []
    times: list[float] = []
    calls = {"n": 0}

    def step(t: float) -> None:
        starts.append(time.monotonic())
        times.append(t)
        calls["n"] += 1
        if calls["n"] == 5:
            time.sleep(3.5 * period)

    stats = run_loop(
        period, step, lambda: calls["n"] >= 12, sleep_margin=0.001, stats=LoopStats(size=100)
    )
    deadlines = stats.deadline[: stats.count]
    assert stats.missed >= 2  # the deadlines 2.5 periods behind
    assert stats.overruns >= 1  # the stall (a loaded machine may add one)
    steps = np.diff(deadlines) / period
    assert np.allclose(steps, np.round(steps), atol=1e-6)  # on the grid
    assert steps.min() > 0.5  # every deadline used once
    assert np.round(steps).sum() == len(deadlines) - 1 + stats.missed  # skips all counted
    # each step's time: its deadline plus its lateness, when it began (the stall's next cycle
    # 2.5 periods late less the skipped ones: a deadline would be up to a period behind)
    late = stats.lateness[: stats.count]
    assert np.allclose(np.array(times) - deadlines, late, atol=1e-9) and late.max() > 1e-4
    # no burst: after the stall, no more cycles than the time elapsed allows
    assert len(starts) - 6 <= (starts[-1] - starts[5]) / period + 1


def test_watchdog_kicks_only_while_the_counter_advances():
    sent: list[str] = []
    counter = {"n": 0}
    wd = Watchdog(lambda: counter["n"], 0.01, send=lambda m: sent.append(m) or True)
    wd.start()
    for _ in range(10):
        counter["n"] += 1
        time.sleep(0.01)
    kicked = wd.kicks
    time.sleep(0.08)  # the loop "hangs": no more progress
    wd.stop()
    wd.join()
    assert kicked >= 3
    assert wd.kicks <= kicked + 1 and wd.withheld >= 3
    assert set(sent) == {"WATCHDOG=1"}


def test_notify_over_a_real_unix_socket(tmp_path):
    path = str(tmp_path / "notify.sock")
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as srv:
        srv.bind(path)
        assert notify("READY=1", env={"NOTIFY_SOCKET": path})
        assert srv.recv(100) == b"READY=1"
    assert not notify("READY=1", env={})
    assert watchdog_interval({"WATCHDOG_USEC": "2000000"}) == 1.0
    assert watchdog_interval({"WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"}) is None


def test_daemon_sim_notify_and_sigterm(tmp_path):
    """`cdprctl run --sim` under a fake systemd: READY, watchdog kicks while it runs, then
    SIGTERM → controlled stop → STOPPING, drives disabled, exit code 0."""
    path = str(tmp_path / "notify.sock")
    srv = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    srv.bind(path)
    srv.settimeout(30.0)
    env = dict(os.environ, NOTIFY_SOCKET=path, WATCHDOG_USEC="400000")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cdprctl.cli",
            "run",
            "--config",
            str(CONFIG / "rowc.toml"),
            "--sim",
            "--no-demo",
            "--no-realtime",
            "--status",
            "0",
            "--timing-file",
            str(tmp_path / "timing.npz"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    try:
        messages = []
        deadline = time.monotonic() + 60.0
        # three kicks (0.2 s apart): the loop has run well over 100 cycles when it is stopped
        # (two gave exactly 100 once on a loaded VM)
        while time.monotonic() < deadline and messages.count("WATCHDOG=1") < 3:
            messages.append(srv.recv(100).decode())
        assert messages[0] == "READY=1"
        assert messages.count("WATCHDOG=1") >= 3
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=30)
        while True:
            msg = srv.recv(100).decode()
            if msg == "STOPPING=1":
                break
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        srv.close()
    assert proc.returncode == 0, out
    assert "ready: pose" in out and "summary:" in out
    # where the gains come from, said at start: rowc's from its model
    assert "gains from the model: drives hold the lengths" in out
    assert "force feedback 19.9 rad/s" in out and "external-wrench estimate 0.529 Hz" in out
    # --timing-file: every cycle of the summary, on the period's grid, in order
    timing = np.load(tmp_path / "timing.npz")
    cycles = int(re.search(r"cycles (\d+)", out).group(1))
    period = float(timing["period"])
    steps = np.diff(timing["deadline"]) / period
    assert len(timing["lateness"]) == cycles > 100
    assert np.all(steps > 0.999) and np.allclose(steps, np.round(steps), atol=1e-6)
    assert round(float(np.sum(np.round(steps) - 1))) <= int(timing["missed"])
    assert np.all(timing["lateness"] >= 0) and np.all(timing["compute"] > 0)
    assert timing["phases"].shape == (cycles, 7)


def test_daemon_bad_config_exit_code(tmp_path, capsys):
    from cdprctl.cli import main

    bad = tmp_path / "bad.toml"
    bad.write_text((CONFIG / "rowc.toml").read_text().replace("mass = 8.0", "mass = -8.0"))
    assert main(["run", "--config", str(bad), "--sim"]) == 1
    assert "platform.mass = -8 kg must be > 0" in capsys.readouterr().err


def test_the_udev_rule_opens_the_wake_up_latency_to_the_units_group():
    """systemd/99-cdprctl.rules: the device the daemon holds (core/cpu_idle.py), writable by
    the group the unit runs as — a rule naming another device or group grants nothing."""
    from cdprctl.core.cpu_idle import PM_QOS_DEVICE

    unit = (ROOT / "systemd" / "cdprctl.service").read_text()
    (group,) = re.findall(r"^Group=(\S+)$", unit, re.M)
    rules = [line for line in (ROOT / "systemd" / "99-cdprctl.rules").read_text().splitlines()
             if line.strip() and not line.startswith("#")]  # fmt: skip
    assert rules == [f'KERNEL=="{Path(PM_QOS_DEVICE).name}", GROUP="{group}", MODE="0660"']


def test_unit_file_verifies(tmp_path):
    exe = shutil.which("systemd-analyze")
    if exe is None:
        pytest.skip("systemd-analyze is not installed on this machine")
    text = (ROOT / "systemd" / "cdprctl.service").read_text()
    lines = []
    for line in text.splitlines():
        if line.startswith("ExecStart="):  # an existing executable, as the verifier requires
            line = f"ExecStart={sys.executable} -m cdprctl.cli run --config {CONFIG / 'rowc.toml'}"
        if line.startswith(("User=", "Group=")):
            line = line.split("=")[0] + "=root"
        lines.append(line)
    unit = tmp_path / "cdprctl.service"
    unit.write_text("\n".join(lines) + "\n")
    res = subprocess.run([exe, "verify", str(unit)], capture_output=True, text=True)
    # systemd-analyze exits 0 on warnings: any output is a failure
    assert res.returncode == 0 and res.stdout == "" and res.stderr == "", res.stdout + res.stderr
    assert "Type=notify" in text and "WatchdogSec=" in text and "Restart=on-failure" in text


def test_demo_script_moves_inside_the_workspace():
    """The demo is a script of the commands an operator would send (and, on the simulated
    robot, a lateral force on and off): ordered, enable first and disable last, every move
    inside the workspace box, fresh commands on every call."""
    from cdprctl.daemon.scripts import Disturbance, demo_script
    from cdprctl.robot_file import load_robot

    model = load_robot(CONFIG / "rowc.toml")
    script = demo_script(model, force=30.0)
    assert [t for t, _ in script] == sorted(t for t, _ in script)
    commands = [s for _, s in script if not isinstance(s, Disturbance)]
    kinds = [c.kind for c in commands]
    assert kinds[0] == "enable" and kinds[-1] == "disable" and kinds.count("move") == 4
    assert [s.force for _, s in script if isinstance(s, Disturbance)] == [30.0, 0.0]
    ws = model.workspace
    for c in commands:
        if c.kind == "move":
            assert c.pose.shape == (6,)
            assert np.all(c.pose[:3] >= ws.position_min) and np.all(c.pose[:3] <= ws.position_max)
    again = demo_script(model, force=30.0)
    assert all(a[1] is not b[1] for a, b in zip(script, again, strict=True))
    assert not any(isinstance(s, Disturbance) for _, s in demo_script(model))


def test_loop_stats_window_follows_the_ring():
    """summary(last=n): percentiles over the n newest cycles, across the ring's wrap; the
    totals stay whole-run."""
    rng = np.random.default_rng(7)
    st = LoopStats(size=50, phases=1)
    late = rng.exponential(1e-5, 130)
    for i, x in enumerate(late):
        st.record(x, 2 * x, None, float(i))
    st.missed = 3
    s = st.summary(last=20)
    assert s["cycles"] == 130 and s["missed"] == 3
    assert s["lateness_p99_us"] == pytest.approx(np.percentile(late[-20:] * 1e6, 99))
    assert s["lateness_max_us"] == pytest.approx(late[-20:].max() * 1e6)
    assert s["compute_p50_us"] == pytest.approx(np.median(late[-20:]) * 2e6)
    whole = st.summary()  # the ring holds the 50 newest
    assert whole["lateness_p50_us"] == pytest.approx(np.median(late[-50:]) * 1e6)


def test_after_hook_runs_once_per_cycle_after_the_step():
    """run_loop(after=...): called after every step (the daemon's I/O thread waits for it)."""
    order: list[str] = []
    run_loop(
        0.002,
        lambda t: order.append("step"),
        lambda: len(order) >= 20,
        sleep_margin=0.0005,
        stats=LoopStats(size=50),
        after=lambda: order.append("after"),
    )
    assert order == ["step", "after"] * 10


def test_compute_is_the_step_and_an_overrun_a_step_longer_than_a_period():
    """run_loop's figures on a simulated clock (each read advances it by 10 µs, each step by
    a known amount): compute is the step's duration, an overrun a step beyond the period.
    (``--sim``'s simulated robot runs in a process of its own: nothing else is timed.)"""
    now = [0.0]
    steps: list[float] = []

    def clock() -> float:
        now[0] += 10e-6
        return now[0]

    def step(t: float) -> None:
        steps.append(t)
        now[0] += 200e-6 if len(steps) < 6 else 2100e-6  # the last cycle: beyond a period

    st = run_loop(0.002, step, lambda: len(steps) >= 6, 0.0, stats=LoopStats(size=10),
                  clock=clock)  # fmt: skip
    tick = 10e-6
    assert st.compute[:5] == pytest.approx(200e-6 + tick, abs=tick)
    assert st.compute[5] == pytest.approx(2100e-6 + tick, abs=tick) and st.overruns == 1
    assert st.summary()["compute_p50_us"] == pytest.approx(210.0, abs=10.0)


def test_helper_thread_leaves_the_loop_cpu_and_priority():
    """A thread started by the pinned, real-time loop thread moves to the other CPUs and below
    the loop's priority (SCHED_FIFO where permitted, else the normal scheduler)."""
    cpus = sorted(rt.ALLOWED_CPUS)
    if len(cpus) < 2:
        pytest.skip("one CPU: nowhere else to go")
    loop_cpu = cpus[-1]
    seen: dict[str, object] = {}

    def helper() -> None:
        os.sched_setaffinity(0, {loop_cpu})  # as inherited from the pinned loop thread
        rt.helper_thread(loop_cpu, 50)
        seen["cpus"] = os.sched_getaffinity(0)
        seen["policy"] = os.sched_getscheduler(0)
        seen["priority"] = os.sched_getparam(0).sched_priority

    th = threading.Thread(target=helper)
    th.start()
    th.join()
    assert loop_cpu not in seen["cpus"] and seen["cpus"] == set(cpus[:-1])
    if seen["policy"] == os.SCHED_FIFO:
        assert seen["priority"] == 49
    else:
        assert seen["policy"] == os.SCHED_OTHER


def test_a_signal_ends_the_loop_even_when_the_io_thread_hangs():
    """The I/O thread normally ends the run after a signal (controlled stop); when it hangs,
    the loop itself ends STOP_FALLBACK after the signal and the drives are shut down."""
    from cdprctl.daemon.service import Daemon
    from cdprctl.robot_file import load_robot

    model = load_robot(CONFIG / "rowc.toml")
    d = Daemon(model, sim=True, overrides={}, realtime=False, status_every=0.0, out=io.StringIO())
    d.STOP_FALLBACK = 0.3
    release = threading.Event()
    d._io_loop = lambda *a: release.wait(30.0)  # a hung I/O thread
    signalled: dict[str, float] = {}
    ended = threading.Event()

    def signal_when_running() -> None:
        deadline = time.monotonic() + 60.0
        while d.stats.count < 50 and time.monotonic() < deadline:
            time.sleep(0.01)
        signalled["at"] = time.monotonic()
        d._on_signal(signal.SIGTERM, None)
        if not ended.wait(20.0):  # without the fallback the loop would run on: end it,
            d.finished.set()  # and let the timing assertion fail

    th = threading.Thread(target=signal_when_running)
    th.start()
    try:
        code = d.run(duration=None, demo=False)
        end = time.monotonic()
    finally:
        ended.set()
        release.set()
        th.join()
    assert code == 0
    assert d.stats.count >= 50
    # the loop ran until the fallback, then stopped (io.join waits ≤ 2 s for the hung thread)
    assert 0.3 <= end - signalled["at"] < 0.3 + 2.0 + 5.0
    last = d.stats.deadline[(d.stats.count - 1) % d.stats.size]
    assert last - signalled["at"] < 0.3 + 1.0  # the loop's last cycle: soon after the deadline
    assert d.driver.lifecycle.value == "finalized"


def test_a_stop_signal_a_library_swallowed_still_ends_the_start_up():
    """A signal during the start-up whose exception a library swallowed (raised inside
    llvmlite's ctypes callback during a compile, it was printed as "Exception ignored" and the
    daemon went on to ``ready``): the start-up's next step ends it — one line, exit 0, the
    drives never enabled, the loop never run."""
    from cdprctl.control.lifecycle.manager import ControllerManager
    from cdprctl.daemon.service import Daemon
    from cdprctl.daemon.startup import (
        StartupInterrupted,
        interrupt_the_start_up,
        stop_if_interrupted,
    )
    from cdprctl.robot_file import load_robot

    def swallowed() -> None:
        with contextlib.suppress(StartupInterrupted):  # as a C callback: it goes nowhere
            signal.raise_signal(signal.SIGTERM)

    startup = ControllerManager.startup

    def startup_swallowing(self, *a, **k):
        startup(self, *a, **k)
        swallowed()

    previous = interrupt_the_start_up()
    try:
        swallowed()
        with pytest.raises(StartupInterrupted, match="SIGTERM"):
            stop_if_interrupted()
        for when in ("before", "during"):  # the kernels' loading; the drives' set-up (last)
            interrupt_the_start_up()  # as `cdprctl run` does, each run from a clean slate
            out = io.StringIO()
            d = Daemon(load_robot(CONFIG / "rowc.toml"), sim=True, overrides={},
                       realtime=False, status_every=0.0, out=out)  # fmt: skip
            with pytest.MonkeyPatch.context() as mp:
                if when == "before":
                    swallowed()
                else:
                    mp.setattr(ControllerManager, "startup", startup_swallowing)
                code = d.run(duration=1.0, demo=False)
            assert code == 0
            assert d.stats.count == 0 and "ready:" not in out.getvalue(), when
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    assert signal.getsignal(signal.SIGTERM) is previous[signal.SIGTERM]


def test_the_loop_alone_runs_at_sched_fifo(tmp_path):
    """The start-up (a minute of compiles on a first run) and the shut-down run at the normal
    scheduler; only the loop at SCHED_FIFO, pinned (a start-up at FIFO held a second daemon's
    loop on the same CPU for 0.7 s: a lost heartbeat, a fault), and only the loop holds the
    CPUs' wake-up latency (cdprctl/core/cpu_idle.py)."""
    from cdprctl.control.lifecycle.manager import ControllerManager
    from cdprctl.core import cpu_idle
    from cdprctl.daemon.service import Daemon
    from cdprctl.robot_file import load_robot
    from tests.core.test_cpu_idle import open_on

    seen: dict[str, int] = {}
    model = load_robot(CONFIG / "rowc.toml")  # not the test process's memory locked for good
    control = dataclasses.replace(model.control, lock_memory=False, freeze_gc=False)
    d = Daemon(dataclasses.replace(model, control=control), sim=True, overrides={},
               realtime=True, status_every=0.0, out=io.StringIO())  # fmt: skip
    startup, run = ControllerManager.startup, ControllerManager.run

    def watched_startup(self, *a, **k):
        seen["start-up"] = os.sched_getscheduler(0)
        return startup(self, *a, **k)

    device = tmp_path / "cpu_dma_latency"
    device.write_bytes(b"")

    def watched_run(self, *a, **k):
        seen["loop"] = os.sched_getscheduler(0)
        seen["awake in the loop"] = open_on(device)
        return run(self, *a, **k)

    shutdown = d.driver.shutdown

    def watched_shutdown() -> None:  # right after the loop
        seen["shut-down"] = os.sched_getscheduler(0)
        seen["cpus"] = len(os.sched_getaffinity(0))
        seen["awake after"] = open_on(device)
        shutdown()

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cpu_idle, "PM_QOS_DEVICE", str(device))
        mp.setattr(ControllerManager, "startup", watched_startup)
        mp.setattr(ControllerManager, "run", watched_run)
        mp.setattr(d.driver, "shutdown", watched_shutdown)
        try:
            assert d.run(duration=0.2, demo=False) == 0
        finally:
            rt.leave_realtime()
    assert seen["start-up"] == os.SCHED_OTHER
    assert seen["awake in the loop"] and not seen["awake after"]
    assert device.read_bytes() == struct.pack("=i", 0)  # the default: the CPUs never halt
    if seen["loop"] != os.SCHED_FIFO:
        pytest.skip("SCHED_FIFO not permitted here")
    assert seen["shut-down"] == os.SCHED_OTHER and seen["cpus"] == len(rt.ALLOWED_CPUS)


def test_the_collector_is_frozen_for_the_loop_without_realtime_too():
    """``--no-realtime`` (no privileges asked) still runs the loop with the garbage collector
    disabled and what the start-up built frozen — a full collection after a first run's
    compile held the loop 0.6 s on a slow CPU (the HIL demo under User-Mode Linux: a
    feedback fault) — and gives the collector back after the run."""
    from cdprctl.control.lifecycle.manager import ControllerManager
    from cdprctl.daemon.service import Daemon
    from cdprctl.robot_file import load_robot

    seen: dict[str, object] = {}
    model = load_robot(CONFIG / "rowc.toml")
    d = Daemon(model, sim=True, overrides={}, realtime=False, status_every=0.0,
               out=io.StringIO())  # fmt: skip
    run = ControllerManager.run

    def watched_run(self, *a, **k):
        seen["enabled"], seen["frozen"] = gc.isenabled(), gc.get_freeze_count()
        return run(self, *a, **k)

    assert gc.isenabled()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ControllerManager, "run", watched_run)
        assert d.run(duration=0.2, demo=False) == 0
    assert seen["enabled"] is False and seen["frozen"] > 10_000
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_the_collector_is_given_back_when_the_start_up_fails_unexpectedly():
    """A start-up that fails after the collector was frozen with an error no one foresaw (here
    the drives' identity lines raising) still gives the collector back: an in-process run
    (the tests, the lock-step harness) leaves the interpreter as it found it."""
    from cdprctl.daemon.service import Daemon
    from cdprctl.robot_file import load_robot

    d = Daemon(load_robot(CONFIG / "rowc.toml"), sim=True, overrides={}, realtime=False,
               status_every=0.0, out=io.StringIO())  # fmt: skip

    def broken(*_a, **_k):
        raise RuntimeError("unforeseen")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("cdprctl.daemon.startup.identity_lines", broken)
        with pytest.raises(RuntimeError, match="unforeseen"):
            d.run(duration=0.2, demo=False)
    d._close_buses()
    assert gc.isenabled() and gc.get_freeze_count() == 0
