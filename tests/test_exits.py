"""Every exit of ``cdprctl run`` and the tools as a user sees it, in a real process: the refusal
in one line (or one per problem) naming what and how to fix it, the exit code of the table in
docs/operating.md, no traceback, no library noise (a nanobind leak report, python-can's "not
properly shut down"), and back within a few seconds of knowing. Ctrl-C goes to the whole
process group, helpers included, as a terminal sends it."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ROWC = str(ROOT / "config" / "rowc.toml")
NOISE = ("Traceback", "nanobind", "leaked", "not properly shut down", "KeyboardInterrupt")


def cdprctl(*args: str, timeout: float = 120.0) -> tuple[int, str, float]:
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "cdprctl.cli", *args], capture_output=True,
                       text=True, timeout=timeout, cwd=ROOT)  # fmt: skip
    return p.returncode, p.stdout + p.stderr, time.monotonic() - t0


def assert_clean(out: str) -> None:
    for word in NOISE:
        assert word not in out, f"{word!r} in:\n{out}"


def group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.fixture
def group():
    """``start(*args)``: ``cdprctl *args`` in a process group of its own, as a terminal or
    systemd runs it (its helpers and multiprocessing's tracker in it too); the whole group is
    killed after the test, whatever happened."""
    started: list[subprocess.Popen] = []

    def start(*args: str) -> subprocess.Popen:
        p = subprocess.Popen([sys.executable, "-m", "cdprctl.cli", *args],
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             start_new_session=True, cwd=ROOT)  # fmt: skip
        started.append(p)
        return p

    yield start
    for p in started:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)
        p.wait()
        if p.stdout is not None:
            p.stdout.close()


def ended_with_its_group(p: subprocess.Popen) -> tuple[int, str]:
    """The exit status and the rest of the output of ``p``, once it and every process of its
    group ended (within 30 s and 5 s more; its output ends when the last of them does, so a
    helper left running fails the test at 30 s instead of hanging it)."""
    try:
        rest, _ = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        rest, _ = p.communicate()
        raise AssertionError(f"cdprctl or a process of its group still running:\n{rest}") from None
    code = p.returncode
    left = time.monotonic() + 5.0
    while group_alive(p.pid) and time.monotonic() < left:
        time.sleep(0.05)
    assert not group_alive(p.pid)  # the helpers (and multiprocessing's tracker) went too
    return code, rest


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_a_rejected_path_is_one_line_and_exit_2(tmp_path):
    """With the real-time set-up as a user runs it (the collector frozen before the refusal:
    ruckig's objects were then reported as 30 lines of leaks)."""
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z\n100,200,300\n")
    code, out, _ = cdprctl("run", "--config", ROWC, "--sim", "--path", str(bad))
    assert code == 2
    assert f"cdprctl run: path {bad} rejected: line 2 (the end of segment 1): waypoint" in out
    assert_clean(out)


def test_a_rate_no_bus_can_carry_is_refused_before_the_start_up():
    """``--rate 7000`` on rowc (four drives a bus): one line naming the bus, its load and the
    fix, exit 2, at once — it came after the start-up's simulated robot and drives, then a
    line of the simulated robot's contacts."""
    code, out, _ = cdprctl("run", "--config", ROWC, "--sim", "--rate", "7000")
    assert code == 2
    assert out.strip() == ("cdprctl run: error: --rate = 7000 Hz: CAN bus 0 (virtual "
                           "cdpr-rowc-a, 1000000 bit/s): 801.8 % load at 7000 Hz (1145 bits per "
                           "cycle, 4 drives): more than the bus can carry; lower the rate, split "
                           "the drives over more buses or raise the bitrate (and 1 more bus)")


def test_a_busy_view_port_fails_at_once_naming_the_port():
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        code, out, took = cdprctl("run", "--config", ROWC, "--sim", "--no-realtime",
                                  "--foxglove", f"127.0.0.1:{port}", "--duration", "2")  # fmt: skip
    assert code == 1
    assert f"the Foxglove view did not start: cannot serve on 127.0.0.1:{port}" in out
    assert "--foxglove HOST:PORT" in out
    assert took < 15.0  # was 20 s of waiting for a view that had died at once
    assert_clean(out)


@pytest.mark.parametrize(
    "args, words",
    [
        (["run", "--config", ROWC, "--sim", "--no-realtime", "--accept-commands",
          "--zenoh-config", "config/zenoh/gateway-tls.json5"],
         ["transport.link.tls.listen_private_key = /etc/cdprctl/tls/gateway.key: no such file",
          "tools/make_certs.sh"]),
        (["run", "--config", ROWC, "--sim", "--no-realtime", "--accept-commands",
          "--zenoh-config", "config/zenoh/gateway-acl.json5"],
         ["transport.auth.usrpwd.dictionary_file = ", "zenoh-users.txt.example"]),
        (["send", "--robot", "rowc", "--zenoh-config", "config/zenoh/operator-tls.json5",
          "enable"],
         ["transport.link.tls.connect_certificate = /etc/cdprctl/tls/operator.pem: no such file",
          "tools/make_certs.sh"]),
    ],
    ids=["gateway-tls", "gateway-acl", "operator-tls"],
)  # fmt: skip
def test_shipped_security_files_name_what_is_missing_and_how_to_make_it(args, words):
    """The shipped examples name files a fresh machine does not have: refused before any
    process starts (was: a traceback in the gateway's process, then 20 s of waiting)."""
    if "gateway-acl" in args[-1] and Path("/etc/cdprctl/zenoh-users.txt").exists():
        pytest.skip("this machine has the dictionary file")
    code, out, took = cdprctl(*args)
    assert code in (1, 2)
    for w in words:
        assert w in out, out
    assert took < 10.0
    assert_clean(out)


def test_ctrl_c_to_the_process_group_stops_cleanly_with_helpers(group):
    """SIGINT to the daemon and its helper processes (the Zenoh gateway, the Foxglove view)
    once it is running: a controlled stop, the summary, exit 0, no traceback from any of
    them."""
    zport, fport = free_port(), free_port()
    p = group("run", "--config", ROWC, "--sim", "--no-realtime", "--no-demo", "--foxglove",
              f"127.0.0.1:{fport}", "--zenoh", "--zenoh-listen", f"tcp/127.0.0.1:{zport}",
              "--no-multicast-scouting")  # fmt: skip
    lines = []
    assert p.stdout is not None
    deadline = time.monotonic() + 90.0
    for line in p.stdout:
        lines.append(line)
        if line.startswith("ready") or time.monotonic() > deadline:
            break
    assert any(x.startswith("ready") for x in lines), "".join(lines)
    time.sleep(0.5)
    os.killpg(p.pid, signal.SIGINT)
    t0 = time.monotonic()
    code, rest = ended_with_its_group(p)
    took = time.monotonic() - t0
    out = "".join(lines) + rest
    assert code == 0, out
    assert "summary:" in rest
    assert took < 10.0
    assert_clean(out)


def test_no_calibration_record_is_one_line_with_the_command_and_exit_4(tmp_path):
    """A robot that trusts no encoder zero at start and an empty state directory, with the
    real-time set-up: the refusal names the missing record and the command that makes it,
    exit 4 (systemd does not restart it), and no leak report after it."""
    config = tmp_path / "real.toml"
    config.write_text(f'base = "{ROWC}"\n[drives]\nassume_home_at_start = false\n')
    # on udp_multicast: the file's in-process bus is refused first (nothing could answer there)
    code, out, _ = cdprctl("run", "--config", str(config), "--state-dir", str(tmp_path / "s"),
                           "--duration", "2", "--can-interface", "udp_multicast", "--can-channel",
                           "239.74.163.9", "--can-option", "port=43119")  # fmt: skip
    assert code == 4, out
    assert "cdprctl run: refusing to enable the drives:" in out
    assert "cdprctl calibrate" in out
    assert_clean(out)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_during_the_start_up_closes_what_it_opened_in_one_line(sig, group):
    """SIGTERM (systemd's stop) or SIGINT to the daemon alone while it starts — here while it
    waits for drives that are not there (a CAN bus no drive is on), its Zenoh gateway
    running: one line, exit 0, and no process of its group left (SIGTERM had killed it
    mid-way, the gateway left running; Ctrl-C printed a traceback from a kernel's compile)."""
    zport = free_port()
    p = group("run", "--config", ROWC, "--no-realtime", "--can-interface", "udp_multicast",
              "--can-channel", "239.74.163.2", "--zenoh", "--zenoh-listen",
              f"tcp/127.0.0.1:{zport}", "--no-multicast-scouting")  # fmt: skip
    assert p.stdout is not None
    lines = []
    for line in p.stdout:
        lines.append(line)
        if line.startswith("start-up:"):
            break
    time.sleep(1.0)  # in the kernels' loading or the drives' set-up: both are start-up
    p.send_signal(sig)
    code, rest = ended_with_its_group(p)
    out = "".join(lines) + rest
    assert code == 0, out
    assert f"cdprctl run: stopped by {sig.name} during the start-up; the drives were not " \
        "enabled" in rest, out
    assert_clean(out)


@pytest.mark.parametrize("after", [0.3, 1.5, 3.0])
def test_ctrl_c_to_the_group_while_it_starts_with_helpers_is_clean(after, group):
    """A terminal's Ctrl-C (SIGINT to the whole group) at instants of the start-up of the
    simulated robot with the Zenoh gateway and the Foxglove view: while the simulated robot's
    buses are built (python-can warned "InProcessBus was not properly shut down") or a helper
    imports its modules (a KeyboardInterrupt traceback, 1 start-up in ~9): one line, exit 0,
    nothing else, no process of the group left."""
    zport, fport = free_port(), free_port()
    p = group("run", "--config", ROWC, "--sim", "--no-realtime", "--no-demo", "--foxglove",
              f"127.0.0.1:{fport}", "--zenoh", "--zenoh-listen", f"tcp/127.0.0.1:{zport}",
              "--no-multicast-scouting")  # fmt: skip
    assert p.stdout is not None
    first = p.stdout.readline()
    time.sleep(after)
    os.killpg(p.pid, signal.SIGINT)
    code, rest = ended_with_its_group(p)
    out = first + rest
    assert code == 0, out
    assert ("stopped by SIGINT during the start-up" in rest
            or "stop requested by SIGINT" in rest), out  # fmt: skip
    assert_clean(out)


def test_the_demo_stops_at_an_estop_and_says_so():
    """The safety chain opened mid-move (2 s, the demo's first move runs 1-4 s): the demo
    sends none of its remaining commands to the stopped robot — it sent three moves that were
    "ignored in state fault" — and one line says why it stopped; exit 0 (an e-stop is no
    fault of the controller's)."""
    code, out, _ = cdprctl("run", "--config", ROWC, "--sim", "--estop", "2", "--no-realtime",
                           "--status", "0")  # fmt: skip
    assert code == 0, out
    assert "state moving -> estop" in out, out
    assert "demo: stopped at the estop (emergency stop: the safety chain opened" in out, out
    assert "remaining 4 commands not sent" in out, out
    assert "ignored in state" not in out and "final state estop" in out, out
    assert_clean(out)
