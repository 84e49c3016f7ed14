"""Hardware in the loop on a kernel SocketCAN: python-can's ``socketcan`` bus on vcan0, what our
users run before the robot moves steel. ``make hil`` runs these (``pytest -m hil``) natively
where the machine has vcan0, otherwise inside User-Mode Linux (tools/hil.py); elsewhere they
skip, saying so. Inside User-Mode Linux the kernel is one slow CPU (a python-can send and
receive 275 µs, the daemon's read and write phases ~1 ms each at 100 Hz): these tests are
functional, at a relaxed rate and time-outs (``hil_config``), never timing."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from candump_witness import check_candump
from conftest import CONFIG, canopen_network, end_processes, rest_of_output, without_table

from cdprctl.robot_file import load_robot
from drivers import create_driver
from drivers.vocabulary import DriveState, Lifecycle

pytestmark = [
    pytest.mark.hil,
    pytest.mark.skipif(
        not Path("/sys/class/net/vcan0").exists(),
        reason="no vcan0 here: `make hil` runs these on a kernel SocketCAN (this machine's "
        "vcan0, or inside User-Mode Linux)",
    ),
]
VCAN = ["--can-interface", "socketcan", "--can-channel", "vcan0"]
RATE = 50.0  # Hz: the daemon's rate here (one slow CPU under User-Mode Linux; docs/hil.md)
# The daemon with its real-time settings (SCHED_FIFO, as the systemd unit runs it) where
# permitted: at the normal scheduler the one slow CPU interleaved its writes with the simulated
# robot's and candump's work (write phase 7.6-11 ms median, 45-64 overruns, a fifth of the
# feedback a cycle late) and a drive sat at its torque limit: 5 of 10 demos faulted with the
# host's other core busy, and one in CI; at FIFO 8 of 8 passed (compute p99 ≤ 7.7 ms, no
# overrun)
REALTIME = [] if os.geteuid() == 0 else ["--no-realtime"]


def hil_config(tmp_path: Path, mode: str = "csp") -> Path:
    """rowc on vcan0 (its two buses on one channel: distinct node ids), with the time-outs a
    slow CPU needs: feedback 1 s (30 ms faulted at 100 Hz under User-Mode Linux, the issue's
    measurement; and a link taken down for 0.1 s stays down ~0.3 s there, `ip` being slow to
    start), heartbeat 2 s, the tension consistency check at half the range and the loop's
    feedback age 0.5 s (below), the
    drives' communication 1 s, and the drives' following error 0.1 s beyond a 20 mm window
    (3 ms faulted the first move at 50 Hz: a cycle's write held up 39 ms, p99, its targets
    then a step), and the tracking error 0.25 m (below)."""
    text = without_table((CONFIG / "rowc.toml").read_text(), "drives")
    # the drives' position loops fight while a cycle is held up (91 N beyond the commanded,
    # 0.4 s into a move: the consistency check's 10 % of the range is 19 N on rowc); a read
    # held up 120 ms (p99 36 ms) made the loop's feedback older than rowc's 50 ms
    text = text.replace("max_feedback_age = 0.05", "max_feedback_age = 0.5", 1)
    # CI's run on a busy host held cycles up (compute p99 40 ms, 24 overruns at FIFO: User-Mode
    # Linux is one host process, at no host priority) and the demo's second move faulted at
    # 83.5 mm against rowc's 80 mm: a tracking error the slow CPU makes, not the CAN path
    text = text.replace("max_position_error = 0.08", "max_position_error = 0.25", 1)
    text = text.replace("[control.safety]\n",
                        "[control.safety]\nmax_tension_disagreement = 0.5\n", 1)  # fmt: skip
    assert "max_tension_disagreement = 0.5" in text and "max_feedback_age = 0.5" in text
    assert "max_position_error = 0.25" in text
    text += (
        f'\n[drives]\ndriver = "cia402"\nmode = "{mode}"\nassume_home_at_start = true\n'
        "heartbeat_timeout = 2.0\nfeedback_timeout = 1.0\ncomm_timeout = 1.0\n"
        "following_error_timeout = 0.1\nfollowing_error_window = 0.02\n"
        '[[drives.buses]]\ninterface = "socketcan"\nchannel = "vcan0"\n'
        'cables = ["1", "2", "3", "4", "5", "6", "7", "8"]\nnode_ids = [1, 2, 3, 4, 5, 6, 7, 8]\n'
    )
    path = tmp_path / "rowc_vcan0.toml"
    path.write_text(text)
    return path


@pytest.fixture
def processes():
    """Start processes; every one is ended (SIGTERM, then SIGKILL) after the test."""
    procs: list[subprocess.Popen] = []

    def start(*argv: str, **kw) -> subprocess.Popen:
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, **kw)  # fmt: skip
        procs.append(proc)
        return proc

    yield start
    end_processes(procs, grace=20.0)


def start_sim(processes, config: Path) -> subprocess.Popen:
    sim = processes(sys.executable, "-m", "cdprctl.cli", "sim", "--config", str(config),
                    "--status", "0")  # fmt: skip
    said = []
    for _ in range(8):
        said.append(sim.stdout.readline())
        if "ready" in said[-1]:
            return sim
    raise AssertionError("cdprctl sim did not start:\n" + "".join(said))


def test_the_driver_contract_over_vcan0(tmp_path, processes):
    """Our driver against `cdprctl sim` in another process, through the kernel: set-up by
    SDO, enable, torques held for a second, disable."""
    config = hil_config(tmp_path, mode="cst")
    start_sim(processes, config)
    model = load_robot(config)
    drv = create_driver(model, period=1.0 / RATE)
    with drv:
        drv.configure(timeout=20.0)
        assert drv.lifecycle is Lifecycle.INACTIVE
        drv.activate(timeout=20.0)
        assert np.all(drv.states.state == DriveState.ENABLED)
        end = time.monotonic() + 1.0
        hold = np.full(model.n_cables, 0.5)
        while time.monotonic() < end:
            drv.read()
            drv.write(None, hold)
            time.sleep(1.0 / RATE)
        drv.read()
        assert drv.lifecycle is Lifecycle.ACTIVE, drv.error
        np.testing.assert_allclose(drv.states.torque, hold, atol=0.01)
        drv.deactivate(timeout=10.0)
        assert np.all(drv.states.state != DriveState.ENABLED)


def test_socketcan_does_not_echo_our_own_frames_and_stamps_what_it_receives():
    """python-can's socketcan bus: a frame we send is not read back on the sending socket
    (unless asked: receive_own_messages), another socket receives it, stamped by the kernel
    (the wall clock, within the test's own span)."""
    import can

    vcan = {"interface": "socketcan", "channel": "vcan0"}
    with can.Bus(**vcan) as a, can.Bus(**vcan) as b, \
            can.Bus(**vcan, receive_own_messages=True) as c:  # fmt: skip
        before = time.time()
        a.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        got = b.recv(2.0)
        after = time.time()
        assert got is not None and got.arbitration_id == 0x123 and bytes(got.data) == b"\x01\x02"
        assert before - 0.01 <= got.timestamp <= after + 0.01
        assert a.recv(0.2) is None  # not echoed to the sender
        assert c.recv(2.0).arbitration_id == 0x123  # c is another socket: it heard a
        c.send(can.Message(arbitration_id=0x124, data=b"", is_extended_id=False))
        own = c.recv(2.0)
        assert own is not None and own.arbitration_id == 0x124  # echoed when asked
        assert b.recv(2.0).arbitration_id == 0x124 and a.recv(2.0).arbitration_id == 0x124


def test_the_canopen_package_as_master_reads_the_simulated_drives(tmp_path, processes):
    """The `canopen` package over socketcan against `cdprctl sim`'s drives: its node scanner
    finds nodes 1-8, SDO reads identity and TPDO1's mapping as the shipped EDS says, an NMT
    start answered by heartbeats once 0x1017 is set; and `cdprctl drives scan` over the same
    kernel bus judges all eight able to run."""

    config = hil_config(tmp_path)
    start_sim(processes, config)
    network = canopen_network()
    network.connect(interface="socketcan", channel="vcan0")
    try:
        network.scanner.search()
        time.sleep(1.0)
        assert sorted(network.scanner.nodes) == list(range(1, 9))
        from sim_backend.drives.dictionary import EDS

        node = network.add_node(3, str(EDS))
        node.sdo.RESPONSE_TIMEOUT = 2.0
        assert node.sdo[0x1018][4].raw == 0x53494D03  # serial "SIM" + node
        count = node.sdo[0x1A00][0].raw
        assert [node.sdo[0x1A00][k].raw >> 16 for k in range(1, count + 1)] == [
            0x6041, 0x6077, 0x6064]  # fmt: skip
        node.sdo[0x1017].raw = 100  # ms
        for state in ("OPERATIONAL", "PRE-OPERATIONAL"):
            node.nmt.state = state  # the command; the heartbeats then say the state
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:  # one sent before the command came may be first
                if node.nmt.wait_for_heartbeat(timeout=3.0) == state:
                    break
            assert node.nmt.state == state
    finally:
        network.disconnect()
    scan = subprocess.run([sys.executable, "-m", "cdprctl.cli", "drives", "scan", "--config",
                           str(config), "--json", "--sdo-timeout", "2"],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert scan.returncode == 0, scan.stderr
    nodes = json.loads(scan.stdout)["buses"][0]["nodes"]
    assert [n["verdicts"] for n in nodes] == [{"csp": "yes", "cst": "yes"}] * 8


@pytest.mark.skipif(shutil.which("candump") is None, reason="no candump (apt-get install "
                    "can-utils; make hil installs it)")  # fmt: skip
def test_the_demo_over_vcan0_with_candump_as_witness(tmp_path, processes):
    """`cdprctl sim` and `cdprctl run --demo` across processes over vcan0, `candump -L` beside
    them: the demo's moves reach their targets, no FAULT, a clean stop with the drives
    disabled; and the log, decoded here against CiA 301/402, holds what it must."""
    config = hil_config(tmp_path)
    log = tmp_path / "candump.log"
    with log.open("w") as out:
        dump = subprocess.Popen(["candump", "-L", "vcan0"], stdout=out,
                                stderr=subprocess.STDOUT)  # fmt: skip
    try:
        time.sleep(0.3)
        start_sim(processes, config)
        daemon = processes(sys.executable, "-m", "cdprctl.cli", "run", "--config", str(config),
                           "--demo", "--rate", f"{RATE:g}", "--status", "0",
                           *REALTIME)  # fmt: skip
        lines: list[str] = []
        reached = 0
        deadline = time.monotonic() + 300.0  # a cold numba cache compiles ~3 min in there
        while time.monotonic() < deadline and reached < 2:
            line = daemon.stdout.readline()
            if not line:
                break
            lines.append(line)
            reached += "moving -> enabled: target reached" in line
            if "FAULT" in line or "fault" in line.split(":")[-1]:
                break
        daemon.send_signal(signal.SIGTERM)
        out = rest_of_output(daemon, 60)
        text = "".join(lines) + out
    finally:
        dump.send_signal(signal.SIGINT)
        dump.wait(timeout=10)
    assert reached == 2, text
    assert "FAULT" not in text and "Traceback" not in text, text
    assert "drives disabled" in text and daemon.returncode == 0, text
    check_candump(log.read_text(), nodes=range(1, 9), rate=RATE)


@pytest.mark.skipif(os.geteuid() != 0, reason="taking vcan0 down needs root")
def test_a_link_that_goes_down_is_said_and_never_crashes_the_daemon(tmp_path, processes):
    """vcan0 down for 0.1 s under the running daemon: the kernel refuses its frames and its
    reads (python-can raises CanOperationError, ENETDOWN); shorter than the feedback time-out
    (1 s here), the daemon rides through — counts them, says so in its summary, no FAULT, no
    traceback — and so does `cdprctl sim` (its frames lost while the link is down). (ENOBUFS,
    a full TX queue, cannot be had on vcan: it never queues — 200,000 frames went through a
    pfifo of 1 without one, measured under User-Mode Linux.)"""
    config = hil_config(tmp_path)
    sim = start_sim(processes, config)
    daemon = processes(sys.executable, "-m", "cdprctl.cli", "run", "--config", str(config),
                       "--rate", f"{RATE:g}", "--status", "0", *REALTIME,
                       "--duration", "20")  # fmt: skip
    lines = []
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline:
        line = daemon.stdout.readline()
        lines.append(line)
        if not line or "init -> ready" in line:
            break
    assert "init -> ready" in lines[-1], "".join(lines)
    ip = shutil.which("ip") or "/usr/sbin/ip"
    try:
        subprocess.run([ip, "link", "set", "down", "vcan0"], check=True)
        time.sleep(0.1)
    finally:  # never left down, whatever happens
        subprocess.run([ip, "link", "set", "up", "vcan0"], check=True)
    time.sleep(1.0)
    daemon.send_signal(signal.SIGTERM)
    out = rest_of_output(daemon, 60)
    text = "".join(lines) + out
    print(text)  # what it said (pytest -rP shows it)
    assert "Traceback" not in text, text
    refused = r"CAN frames the bus would not take: [1-9]\d*, reads it refused"
    assert re.search(refused, text), text
    assert "FAULT" not in text and daemon.returncode == 0, text  # ridden through
    assert sim.poll() is None, sim.stdout.read()  # the simulated drives rode through it too
