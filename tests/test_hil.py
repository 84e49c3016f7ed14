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
from conftest import CONFIG, end_processes, without_table

from cdprctl.model import load_robot
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


def hil_config(tmp_path: Path, mode: str = "csp") -> Path:
    """rowc on vcan0 (its two buses on one channel: distinct node ids), with the time-outs a
    slow CPU needs: feedback 1 s (30 ms faulted at 100 Hz under User-Mode Linux, the issue's
    measurement; and a link taken down for 0.1 s stays down ~0.3 s there, `ip` being slow to
    start), heartbeat 2 s, the drives' communication 1 s, and the drives' following
    error 0.1 s beyond a 20 mm window (3 ms faulted the first move at 50 Hz: a cycle's write
    held up 39 ms, p99, its targets then a step)."""
    text = without_table((CONFIG / "rowc.toml").read_text(), "drives")
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
    for _ in range(8):
        line = sim.stdout.readline()
        if "ready" in line:
            return sim
    raise AssertionError(f"cdprctl sim did not start: {line}")


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
    import canopen

    config = hil_config(tmp_path)
    start_sim(processes, config)
    network = canopen.Network()
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
                           "--no-realtime")  # fmt: skip
        lines: list[str] = []
        reached = 0
        deadline = time.monotonic() + 150.0
        while time.monotonic() < deadline and reached < 2:
            line = daemon.stdout.readline()
            if not line:
                break
            lines.append(line)
            reached += "moving -> enabled: target reached" in line
            if "FAULT" in line or "fault" in line.split(":")[-1]:
                break
        daemon.send_signal(signal.SIGTERM)
        out, _ = daemon.communicate(timeout=60)
        text = "".join(lines) + out
    finally:
        dump.send_signal(signal.SIGINT)
        dump.wait(timeout=10)
    assert reached == 2, text
    assert "FAULT" not in text and "Traceback" not in text, text
    assert "drives disabled" in text and daemon.returncode == 0, text
    check_candump(log.read_text(), nodes=range(1, 9), rate=RATE)


FRAME = re.compile(r"\((\d+\.\d+)\) vcan0 ([0-9A-F]{3})#([0-9A-F]*)")


def check_candump(text: str, nodes: range, rate: float) -> None:
    """The candump log against CiA 301/402, from the frames alone: every node's SDO set-up
    (requests 0x600+n answered on 0x580+n, none aborted but optional objects), NMT
    pre-operational then start, SYNC at the loop's rate, one RPDO per node per SYNC, TPDO1
    answering each SYNC, heartbeats of every drive and of the controller (node 127 or the
    configured one), and no frame of an identifier nobody should send."""
    frames = [(float(t), int(i, 16), bytes.fromhex(d)) for t, i, d in FRAME.findall(text)]
    assert len(frames) > 1000, text[:500]
    ids = {i for _, i, _ in frames}
    expected = {0x000, 0x080} | {base + n for n in nodes for base in (
        0x080, 0x180, 0x200, 0x580, 0x600, 0x700)}  # fmt: skip
    controller_hb = {i for i in ids if 0x700 < i <= 0x77F and i - 0x700 not in nodes}
    assert len(controller_hb) == 1, sorted(hex(i) for i in controller_hb)
    unexpected = ids - expected - controller_hb - {0x280 + n for n in nodes}
    assert not unexpected, sorted(hex(i) for i in unexpected)
    nmt = [d for _, i, d in frames if i == 0x000]
    assert nmt[:2] == [bytes([0x80, 0]), bytes([0x01, 0])]  # pre-operational, then start
    for n in nodes:
        requests = [d for _, i, d in frames if i == 0x600 + n]
        answers = [d for _, i, d in frames if i == 0x580 + n]
        assert requests and len(answers) >= len(requests) - 2  # a retry may cross its answer
        aborts = [d for d in answers if d[0] == 0x80]
        assert all(int.from_bytes(d[4:8], "little") == 0x06020000 for d in aborts)
        assert any(i == 0x700 + n for _, i, _ in frames), f"no heartbeat of node {n}"
    syncs = [t for t, i, _ in frames if i == 0x080]
    cyclic = np.diff(syncs[len(syncs) // 4:])  # the loop's, past the set-up
    assert np.median(cyclic) == pytest.approx(1.0 / rate, rel=0.15)
    # over the loop's second half: a TPDO1 from every node for each SYNC, and at least one RPDO
    # before each (a late cycle's targets may go out twice: driver.py, resent_targets)
    last = max(t for t, _, _ in frames)
    window = [i for t, i, _ in frames if syncs[len(syncs) // 2] <= t < last - 1.0]
    n_syncs = window.count(0x080)
    assert n_syncs > 50
    for n in nodes:
        assert abs(window.count(0x180 + n) - n_syncs) <= 2, n
        assert window.count(0x200 + n) >= n_syncs - 2, n


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
                       "--rate", f"{RATE:g}", "--status", "0", "--no-realtime",
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
    subprocess.run([ip, "link", "set", "down", "vcan0"], check=True)
    time.sleep(0.1)
    subprocess.run([ip, "link", "set", "up", "vcan0"], check=True)
    time.sleep(1.0)
    daemon.send_signal(signal.SIGTERM)
    out, _ = daemon.communicate(timeout=60)
    text = "".join(lines) + out
    print(text)  # what it said (pytest -rP shows it)
    assert "Traceback" not in text, text
    refused = r"CAN frames the bus would not take: [1-9]\d*, reads it refused"
    assert re.search(refused, text), text
    assert "FAULT" not in text and daemon.returncode == 0, text  # ridden through
    assert sim.poll() is None, sim.stdout.read()  # the simulated drives rode through it too
