"""The drivers' contract across processes: ``cdprctl sim`` in its own process, the driver here,
over python-can's udp_multicast (this kernel has no vcan; lossy and slow: generous timeouts),
and on a real vcan0 when the machine has one."""

from __future__ import annotations

import dataclasses
import json
import os
import random
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CONFIG, end_processes, rest_of_output, without_table

from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot
from drivers import DriveState, Lifecycle, create_driver
from sim_backend.plant import equilibrium_tensions

GROUP = "239.74.163.2"


def _terminate(proc: subprocess.Popen, timeout: float) -> None:
    """SIGTERM, and SIGKILL when ``proc`` has not ended ``timeout`` s later."""
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def stopped_under_load(text: str) -> bool:
    """A run that did not finish its move stopped the safe way because of this VM's load: a
    controlled stop to a fault (the loop's own), or a drive's following-error fault with
    missed periods in the run's summary (the drive saw its targets late). These are functional
    tests in real time on a shared 2-core VM: the timing is the benchmarks' to judge; a drive
    fault without a missed period is a bug."""
    if "stopping -> fault" in text:
        return True
    missed = re.search(r"missed periods (\d+)", text)
    return ("fault 0x8611: following error" in text and missed is not None
            and int(missed.group(1)) > 0)  # fmt: skip

def relaxed(model, driver):
    drives = dataclasses.replace(
        model.drives,
        driver=driver,
        heartbeat_timeout=2.0,
        feedback_timeout=0.1,
        comm_timeout=1.0,
    )
    return dataclasses.replace(model, drives=drives)


@pytest.fixture
def sim_process(tmp_path):
    procs = []

    def start(config: Path, overrides: list[str]):
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "cdprctl.cli",
                "sim",
                "--config",
                str(config),
                "--status",
                "0",
                *overrides,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        procs.append(proc)
        for _ in range(5):
            line = proc.stdout.readline()
            if "ready" in line:
                return proc
        raise AssertionError(f"cdprctl sim did not start: {line}")

    yield start
    end_processes(procs)


def write_config(tmp_path, model_file, driver, mode="cst", assume_home=True):
    """The robot file with its drives on one udp_multicast bus, in ``mode``; the encoders
    trusted to read zero at home (``cdprctl sim`` starts there) unless ``assume_home`` is
    False."""
    text = without_table((CONFIG / model_file).read_text(), "drives")
    text += (
        f'\n[drives]\ndriver = "{driver}"\nmode = "{mode}"\n'
        f"assume_home_at_start = {'true' if assume_home else 'false'}\n"
        "heartbeat_timeout = 2.0\nfeedback_timeout = 0.1\n"
        'comm_timeout = 1.0\n[[drives.buses]]\ninterface = "udp_multicast"\n'
        f'channel = "{GROUP}"\ncables = ["1", "2", "3", "4", "5", "6", "7", "8"]\n'
        "node_ids = [1, 2, 3, 4, 5, 6, 7, 8]\n"
    )
    path = tmp_path / f"{driver}.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("driver", ["cia402", "odrive"])
def test_contract_over_udp_multicast(tmp_path, sim_process, driver):
    port = random.Random(os.getpid() * 7 + len(driver)).randrange(40000, 50000)
    config = write_config(tmp_path, "rowc.toml", driver)
    model = load_robot(config)
    opts = ["--can-option", f"port={port}"]
    sim_process(config, opts)
    period = 0.01
    drv = create_driver(model, period=period, bus_overrides={"options": {"port": port}})
    with drv:
        drv.configure(timeout=15.0)
        assert drv.lifecycle is Lifecycle.INACTIVE
        drv.activate(timeout=15.0)
        assert np.all(drv.states.state == DriveState.ENABLED)
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        r = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
        hold = r * equilibrium_tensions(model, kin)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            drv.read()
            drv.write(None, hold)
            time.sleep(period)
        drv.read()
        assert drv.lifecycle is Lifecycle.ACTIVE, drv.error
        np.testing.assert_allclose(drv.states.torque, hold, atol=0.01)
        drv.deactivate(timeout=5.0)
        assert np.all(drv.states.state != DriveState.ENABLED)


def test_daemon_against_sim_process_over_udp_multicast(tmp_path, sim_process):
    """The daemon and `cdprctl sim` in two processes over udp_multicast, in real time: start-up
    over the bus, enable, the demo's first move to its target (or, when the loaded machine
    makes the loop fault, a controlled stop), then SIGTERM → drives disabled, exit 0."""
    port = random.Random(os.getpid() * 11).randrange(40000, 50000)
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")  # as shipped
    opts = ["--can-option", f"port={port}"]
    sim = sim_process(config, opts)
    daemon = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cdprctl.cli",
            "run",
            "--config",
            str(config),
            "--demo",
            "--rate",
            "250",  # udp_multicast costs ~1 ms a cycle; 250 Hz leaves room on 2 cores
            "--status",
            "0",
            *opts,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: list[str] = []
    try:
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline:
            line = daemon.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "moving -> enabled: target reached" in line or "FAULT" in line:
                break
        daemon.send_signal(signal.SIGTERM)
        out = rest_of_output(daemon, 30)
        lines.append(out)
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait()
    text = "".join(lines)
    assert "init -> ready" in text and "ready -> enabling" in text, text
    assert "enabling -> enabled" in text and "enabled -> moving" in text, text
    # the move reaches its target; on a loaded 2-core VM the loop can still fault (an
    # infeasible wrench, docs/reliability.md): then it must have stopped the controlled way
    assert "moving -> enabled: target reached" in text or stopped_under_load(text), text
    assert "drives disabled" in text, text
    assert "Traceback" not in text, text
    assert daemon.returncode == 0, text
    assert sim.poll() is None  # the simulated robot outlives its controller


class Lines:
    """A child process's output lines, read by a thread (so waits never block on a pipe)."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.lines: list[tuple[float, str]] = []
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append((time.monotonic(), line.rstrip()))

    def wait_for(self, text: str, timeout: float, after: float = 0.0) -> tuple[float, str] | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for t, line in list(self.lines):
                if t >= after and text in line:
                    return t, line
            time.sleep(0.05)
        return None

    def text(self) -> str:
        return "\n".join(line for _, line in self.lines)


def test_daemon_sigkilled_mid_motion_then_restarted(tmp_path):
    """Across processes, in real time: the daemon is SIGKILLed while the platform moves; the
    simulated drives' communication timeout (1 s here) disables them and closes the brakes;
    a new daemon finds the pose, enables and holds it without a jump (its status lines)."""
    port = random.Random(os.getpid() * 13).randrange(40000, 50000)
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")  # as shipped
    opts = ["--can-option", f"port={port}"]
    cli = [sys.executable, "-m", "cdprctl.cli"]
    procs: list[subprocess.Popen] = []

    def start(args: list[str]) -> Lines:
        p = subprocess.Popen(
            [*cli, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        procs.append(p)
        return Lines(p)

    try:
        sim = start(["sim", "--config", str(config), "--status", "0.1", *opts])
        assert sim.wait_for("cdprctl sim: ready", 60), sim.text()
        run = ["run", "--config", str(config), "--rate", "250", *opts]
        first = start([*run, "--demo", "--status", "0"])
        assert first.wait_for("enabled -> moving", 90), first.text()
        time.sleep(0.3)
        first.proc.kill()  # SIGKILL: no stop, no disable frame
        first.proc.wait()
        killed = time.monotonic()
        braked = sim.wait_for("brakes 8/8", 10, after=killed)
        assert braked is not None, sim.text()[-2000:]
        assert braked[0] - killed < 2.5  # s: comm_timeout 1 s, status every 0.1 s, slack
        time.sleep(1.0)  # the platform settles on its brakes
        # the restarted daemon: the demo enables at 0.3 s and, with --duration 0.9, ends
        # before its first move — the hold after enabling is what is watched
        second = start([*run, "--demo", "--status", "0.1", "--duration", "0.9"])
        ready = second.wait_for("ready: pose", 60)
        assert ready is not None, second.text()
        sim_p = [line for _, line in sim.lines if "P=[" in line][-1]
        p_sim = np.array(sim_p.split("P=[")[1].split("]")[0].split(), dtype=float)
        p_ready = np.array(ready[1].split("[")[1].split("]")[0].split(","), dtype=float)
        # the pose found: x and z within 2 mm; y (held by elasticity alone) within 15 mm — the
        # brakes locked in tensions no drive measures, and once in 16 runs the braked platform
        # swung 105 mm along y and the estimate missed it by 10.6 mm (docs/reliability.md)
        assert abs(p_ready[0] - p_sim[0]) < 2e-3 and abs(p_ready[2] - p_sim[2]) < 2e-3, sim_p
        assert abs(p_ready[1] - p_sim[1]) < 15e-3, (ready[1], sim_p)
        assert second.wait_for("enabling -> enabled", 60), second.text()
        code = second.proc.wait(timeout=60)
        if code == 3:  # a fault on a loaded machine: it must have stopped the controlled way
            assert "-> stopping" in second.text() and "stopping -> fault" in second.text()
            return
        assert code == 0, second.text()
        errs = [
            float(line.split(" err ")[1].split(" mm")[0])
            for _, line in second.lines
            if " enabled " in line and " err " in line
        ]
        # mm: held without a jump. The brakes locked in whatever tensions the motion had and
        # no drive measures them, so taking over with the TDA's tensions can move the
        # platform along its elastic y by mm (2.6 mm in 1 run of 10; 0.1 mm usually)
        assert errs and max(errs) < 15.0, second.text()
        print(f"brakes {braked[0] - killed:.2f} s after SIGKILL; hold error max {max(errs)} mm")
        assert "Traceback" not in first.text() + second.text()
    finally:
        for p in procs:
            if p.poll() is None:
                _terminate(p, 10.0)


def test_calibrate_then_run_across_processes(tmp_path, sim_process):
    """`cdprctl sim --start-pose` (incremental encoders), `cdprctl calibrate ... self --json`,
    `cdprctl brake-test --json`, `cdprctl run --demo` on CAROCA over udp_multicast: every
    brake holds, the pose `run` prints at ready within 2 mm of the simulator's start, and the
    demo's first move reaches its target."""
    port = random.Random(os.getpid() * 17).randrange(40000, 50000)  # its own port
    config = write_config(tmp_path, "caroca.toml", "cia402", mode="csp", assume_home=False)
    opts = ["--can-option", f"port={port}"]
    start = [0.06, -0.04, 1.05, 0.03, -0.02, 0.04]
    sim_process(config, [*opts, "--start-pose", ",".join(map(str, start))])
    state = tmp_path / "state"
    cli = [sys.executable, "-m", "cdprctl.cli"]
    common = ["--config", str(config), "--state-dir", str(state), *opts]
    cal = subprocess.run(
        [*cli, "calibrate", *common, "self", "--json"],
        capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert cal.returncode == 0, cal.stderr
    found = json.loads(cal.stdout)
    assert found["method"] == "self" and found["condition"] < 1e4
    assert np.linalg.norm(np.array(found["pose"][:3]) - start[:3]) < 3e-3, found
    # a real robot (no assume_home) is enabled only after a passed brake test: over SDO to
    # the simulated drives' 0x60FE, the drives enabled against their closed brakes
    brakes = subprocess.run(
        [*cli, "brake-test", *common, "--json"], capture_output=True, text=True, timeout=120
    )
    assert brakes.returncode == 0, brakes.stderr
    tested = json.loads(brakes.stdout)
    assert tested["passed"] and all(c["motion"] == 0.0 for c in tested["cables"]), tested
    daemon = subprocess.Popen(
        [*cli, "run", *common, "--demo", "--rate", "250", "--status", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    out = Lines(daemon)
    try:
        ready = out.wait_for("ready: pose [", 120.0)
        reached = ready and out.wait_for("moving -> enabled: target reached", 60.0)
    finally:
        _terminate(daemon, 30.0)
    text = out.text()
    assert ready is not None, text
    pose = [float(v) for v in ready[1].split("[", 1)[1].split("]", 1)[0].split(",")]
    assert np.linalg.norm(np.array(pose) - start[:3]) < 2e-3, (pose, text)
    assert reached is not None or stopped_under_load(text), text
    assert "Traceback" not in text, text


def test_run_path_across_processes(tmp_path, sim_process):
    """`cdprctl sim` and `cdprctl run --path` (rowc over udp_multicast, real time): the path
    is checked, played to its end, the drives disabled, exit 0. On this shared 2-core VM a run
    can still stop on a timing fault (a drive's following error or old feedback after a stall:
    issue 17's known cost, docs/control.md); such a run must have stopped the controlled way
    (a fault state, drives disabled, exit 3, the path not finished), and one of three runs,
    each against a fresh simulated robot (the last keeps its faulted drive), must finish."""
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")
    path = tmp_path / "triangle.ngc"
    path.write_text("G21 G90\nG1 X1600 Z640 F6000\nG4 P0.2\nG1 X1400 Z640\nG1 X1500 Z590\nM2\n")
    texts = []
    for attempt in range(3):
        port = random.Random(os.getpid() * 23 + attempt).randrange(40000, 50000)  # its own
        opts = ["--can-option", f"port={port}"]
        sim = sim_process(config, opts)
        proc = subprocess.run(
            [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(config), "--path",
             str(path), "--rate", "250", "--status", "0", *opts],
            capture_output=True, text=True, timeout=180,
        )  # fmt: skip
        sim.terminate()
        text = proc.stdout + proc.stderr
        texts.append(text)
        assert f"path {path}: 3 segments" in text and "checked at" in text, text
        assert "drives disabled" in text and "Traceback" not in text, text
        if proc.returncode == 0:
            assert "enabled -> moving: path" in text and f"path {path}: done" in text, text
            break
        assert proc.returncode == 3 and "-> fault" in text, text
        assert f"path {path}: done" not in text, text
    else:
        raise AssertionError("\n----\n".join(texts))


def test_an_estop_across_processes_is_the_daemons_estop_state(tmp_path, sim_process):
    """`cdprctl sim --estop 12` (the chain opens 12 s after the simulated robot started; the
    daemon is enabled by then, or enables into it) and `cdprctl run --demo` over udp_multicast
    in real time: the daemon says EMERGENCY STOP and ends in its e-stop state — no FAULT, no
    traceback, exit 0."""
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")
    texts = []
    for attempt in range(2):  # a timing fault of this VM before the e-stop: once more
        port = random.Random(os.getpid() * 29 + attempt).randrange(40000, 50000)
        opts = ["--can-option", f"port={port}"]
        sim = sim_process(config, [*opts, "--estop", "12"])
        proc = subprocess.run(
            [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(config), "--demo",
             "--duration", "22", "--rate", "250", "--status", "0", *opts],
            capture_output=True, text=True, timeout=180,
        )  # fmt: skip
        sim.terminate()
        text = proc.stdout + proc.stderr
        texts.append(text)
        if not stopped_under_load(text.split("EMERGENCY STOP")[0]):
            break
    assert proc.returncode == 0, "\n----\n".join(texts)
    assert "EMERGENCY STOP: the safety chain is open" in text and "0x8A88" in text, text
    assert "-> estop" in text and "final state estop" in text, text
    assert "FAULT" not in text and "Traceback" not in text, text


def test_a_scan_on_another_group_finds_none_of_a_robots_drives(tmp_path, sim_process, capsys):
    """`cdprctl sim` on group .97; `drives scan` on .98 of the same port finds nothing (it
    found the eight drives of .97 before the bus joined its own group alone), on .97 all
    eight."""
    from cdprctl.cli import main

    port = random.Random(os.getpid() * 31).randrange(40000, 50000)
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")
    sim_process(config, ["--can-channel", "239.74.163.97", "--can-option", f"port={port}"])
    found = {}
    for group in ("239.74.163.98", "239.74.163.97"):
        code = main(["drives", "scan", "--config", str(config), "--can-channel", group,
                     "--can-option", f"port={port}", "--listen", "0.5", "--json"])  # fmt: skip
        found[group] = (code, json.loads(capsys.readouterr().out)["summary"])
    assert found["239.74.163.98"] == (1, "0 of 8 configured drives found, 0 can run their "
                                         "configured mode"), found  # fmt: skip
    assert found["239.74.163.97"][1].startswith("8 of 8 configured drives found"), found


def test_a_starved_simulated_robot_says_so_itself(tmp_path, sim_process):
    """`cdprctl sim` held up (SIGSTOP for 0.15 s: what a busy machine does to it) says
    it stepped late, and how late, in its own words — not as a drive fault — and counts it
    at the end."""
    port = random.Random(os.getpid() * 37).randrange(40000, 50000)
    config = write_config(tmp_path, "rowc.toml", "cia402", mode="csp")
    sim = sim_process(config, ["--can-option", f"port={port}", "--no-realtime"])
    time.sleep(0.3)
    sim.send_signal(signal.SIGSTOP)
    time.sleep(0.15)
    sim.send_signal(signal.SIGCONT)
    time.sleep(0.3)
    sim.send_signal(signal.SIGTERM)
    out = rest_of_output(sim, 20)
    said = re.search(r"the simulated robot stepped ([\d.]+) ms late at t=[\d.]+ s: this "
                     r"process was not run \(a busy machine\)", out)  # fmt: skip
    assert said and float(said[1]) >= 140.0, out
    assert re.search(r"cdprctl sim: [1-9]\d* steps? later than 10 ms, the latest", out), out
