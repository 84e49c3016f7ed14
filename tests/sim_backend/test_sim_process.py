"""``run --sim``'s simulated robot in a process of its own (sim_backend/process.py): the loop
never steps it, the daemon's requests reach it, it says when it was starved, and it never
outlives the daemon nor stops on the terminal's Ctrl-C."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from typing import Any

import numpy as np
import pytest
from conftest import CONFIG, rest_of_output

CLI = [sys.executable, "-m", "cdprctl.cli"]


def children_running(pid: int) -> list[int]:
    """The ``sim_backend.process`` children of ``pid``."""
    out = subprocess.run(["pgrep", "-P", str(pid), "-f", "sim_backend.process"],
                         capture_output=True, text=True).stdout  # fmt: skip
    return [int(x) for x in out.split()]


def await_child(proc: subprocess.Popen, within: float = 120.0) -> int:
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        found = children_running(proc.pid)
        if found:
            return found[0]
        assert proc.poll() is None, "the daemon ended before its simulated robot started"
        time.sleep(0.05)
    raise AssertionError("no simulated robot process")


def gone(pid: int, within: float) -> bool:
    deadline = time.monotonic() + within
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(")")[1].split()[0] == "Z":
                    return True  # ended, not yet reaped (its parent was killed: init reaps it)
        except (ProcessLookupError, FileNotFoundError):
            return True
        time.sleep(0.05)
    return False


def run_sim(args: list[str], during: Any = None, code: int = 0, config: str = "") -> str:
    """``cdprctl run --sim`` on rowc (or ``config``) with ``args``; ``during(daemon, child)``
    once the daemon is ready; the whole output. Asserts exit ``code`` and no simulated robot
    left running."""
    config = config or str(CONFIG / "rowc.toml")
    cmd = [*CLI, "run", "--config", config, "--sim", "--no-realtime", *args]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert proc.stdout is not None
        head = []
        while not head or "ready: pose" not in head[-1]:
            head.append(proc.stdout.readline())
            assert head[-1], "".join(head)
        if during is not None:
            during(proc, await_child(proc))
        out = "".join(head) + rest_of_output(proc, 120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == code, out
    assert not children_running(proc.pid)
    return out


def test_the_loop_never_steps_the_plant_and_the_jet_and_true_pose_cross(tmp_path):
    """``run --sim --disturbance 30``: the loop's timing is the controller's alone (the
    simulated robot a child process, found running), the true platform's tracking error is
    reported (the true pose crossed over), and the demo's lateral force reached the plant."""
    timing = tmp_path / "t.npz"
    out = run_sim(["--duration", "10", "--disturbance", "30", "--status", "0.5",
                   "--timing-file", str(timing)])  # fmt: skip
    assert "demo: 30 N lateral force on" in out and "FAULT" not in out, out
    rms = re.search(r"tracking error \(the simulated platform\) RMS ([\d.]+) mm", out)
    assert rms is not None and 0.0 < float(rms.group(1)) < 10.0, out
    ys = [float(m) for m in re.findall(r"true \[[\d.]+ ([\d.]+) [\d.]+\]", out)]
    assert min(ys) == pytest.approx(0.35, abs=1e-3) and max(ys) > 0.352  # pushed along y
    z = np.load(timing)
    assert len(z["compute"]) > 500 and "plant" not in z.files


def _lamp_robot(tmp_path) -> Any:
    """rowc with a 20 mm lamp standing in cable 1 at home, 0.3 m from its attachment."""
    robot = tmp_path / "rowc_lamp.toml"
    base = CONFIG / "rowc.toml"
    robot.write_text(f'base = "{base}"\n\n[[cell.obstacles]]\nname = "the lamp"\n'
                     'kind = "box"\ncentre = [1.1195, 0.3688, 0.3882]\n'
                     "half_extents = [0.01, 0.01, 0.01]\n")  # fmt: skip
    return robot


def test_a_contact_in_the_simulated_robot_is_the_exit_code(tmp_path):
    """A lamp standing in cable 1 at home (rowc, 0.3 m from the attachment): the run is
    otherwise clean (ready, 1 s, no demo), the simulated robot records the contact, and the
    exit is 5 with a line saying why (0 without the lamp: the other tests here; 4 is "not
    calibrated")."""
    from cdprctl.daemon.startup import NOT_CALIBRATED
    from sim_backend.contact import CONTACT_EXIT

    assert CONTACT_EXIT == 5 and CONTACT_EXIT not in (0, 1, 2, 3, NOT_CALIBRATED)
    robot = _lamp_robot(tmp_path)
    out = run_sim(["--no-demo", "--duration", "1"], code=5, config=str(robot))
    assert "the simulated robot: 1 contact(s), the first at t = " in out, out
    assert "cable 1 and the lamp: overlapping by " in out, out  # the lamp's 20 mm: how deep
    # and said at the start, before any motion: the robot stands under the clearance
    assert re.search(r"warning: at the start pose cable 1 and the lamp: overlapping by "
                     r"\d+\.\d\d mm, under the clearance 5\.00 mm: a motion may leave it, "
                     r"never closer than here \(a move home: than home\)", out), out  # fmt: skip
    assert out.rstrip().endswith("cdprctl run: exit 5: the simulated robot recorded 1 "
                                 "contact(s) (above)")  # fmt: skip


def test_the_simulated_robot_on_its_own_says_its_contacts_and_exits_5(tmp_path):
    """``cdprctl sim`` (the simulated robot of a cross-process or HIL set-up, its own
    command) with the same lamp through cable 1: it says the contact as it stops and exits 5
    (it said nothing: a newcomer drove a body into a crate across processes, both exit 0)."""
    robot = _lamp_robot(tmp_path)
    cmd = [*CLI, "sim", "--config", str(robot), "--duration", "1", "--no-realtime"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 5, out.stdout + out.stderr
    assert "cdprctl sim: 1 contact(s), the first at t = " in out.stdout
    assert "cable 1 and the lamp: overlapping by " in out.stdout


def stall_for(seconds: float, ctrl_c: bool = False) -> Any:
    """``during``: the daemon's simulated robot held up (SIGSTOP) for ``seconds``, then
    a Ctrl-C sent to it alone (``ctrl_c``)."""

    def stall(daemon: subprocess.Popen, child: int) -> None:
        time.sleep(0.3)  # a few hundred cycles of feedback first
        os.kill(child, signal.SIGSTOP)
        time.sleep(seconds)
        os.kill(child, signal.SIGCONT)
        if ctrl_c:
            os.kill(child, signal.SIGINT)

    return stall


def test_a_starved_simulated_robot_says_so_is_ridden_through_and_ignores_ctrl_c():
    """Held up for 60 ms (SIGSTOP: twice the feedback timeout) the simulated robot says so
    itself, in the daemon's output, and the daemon — told by the child's step stamp that its
    drives were not run — rides the silence through instead of faulting on a drive (it did:
    "no feedback for 32.0 ms", a starved simulator reported as a broken drive). A Ctrl-C sent
    to the child alone is ignored (the daemon stops it)."""
    out = run_sim(["--duration", "2", "--no-demo", "--status", "0"], stall_for(0.06, True))
    assert re.search(r"stepped \d+\.\d ms late", out), out
    assert "the simulator's lateness, not a drive's fault" in out
    # the stall at least (a loaded machine holds it up more often: each counted, and said at
    # most once a second, so the stall's own line may be one of the "more since")
    latest = re.search(r"the simulated robot: [1-9]\d* steps later than 10 ms, the latest "
                       r"(\d+\.\d) ms", out)  # fmt: skip
    assert latest is not None and 40.0 <= float(latest.group(1)) <= 2000.0, out
    ridden = re.search(r"(\d+) reads without feedback ridden through: the simulated robot "
                       r"was not run", out)  # fmt: skip
    assert ridden is not None and int(ridden.group(1)) >= 5, out  # 60 ms at 250 Hz: ~13
    assert "FAULT" not in out and "final state fault" not in out, out


def test_a_hung_simulated_robot_is_a_silent_drive_naming_it():
    """Held up beyond what the simulated robot catches up on (0.5 s), its drives' silence
    counts again: the daemon faults on the drives' timeouts (rowc's heartbeat's 0.5 s comes
    first), saying the simulator hung."""
    out = run_sim(["--duration", "3", "--no-demo", "--status", "0"], stall_for(0.9), code=3)
    assert "final state fault (drives: drive of cable index" in out, out
    assert "no feedback for" in out or "no heartbeat for" in out, out
    hung = re.search(r"the simulated robot has not stepped for (\d+) ms: its process hung", out)
    assert hung is not None and 500 <= int(hung.group(1)) < 900, out


@pytest.mark.parametrize("how", ["kill", "stop"])
def test_the_simulated_robot_ends_with_the_daemon(tmp_path, how):
    """Killed (SIGKILL: no close), the daemon's simulated robot ends by itself within a
    second; closed, at once."""
    script = tmp_path / "hold.py"
    script.write_text(
        "import sys, time\n"
        "from cdprctl.robot_file import load_robot\n"
        "from sim_backend.process import SimulatedRobotProcess\n"
        f"sim = SimulatedRobotProcess(load_robot({str(CONFIG / 'rowc.toml')!r}), None, False)\n"
        "p = sim.position\n"
        "print(sim.proc.pid, p[0], p[1], p[2], flush=True)\n"
        "if sys.argv[1] == 'stop':\n"
        "    sim.close(); print('closed', sim.proc.returncode, flush=True)\n"
        "time.sleep(60)\n"
    )
    proc = subprocess.Popen([sys.executable, str(script), how], stdout=subprocess.PIPE,
                            text=True)  # fmt: skip
    try:
        assert proc.stdout is not None
        child, *pos = proc.stdout.readline().split()
        from cdprctl.robot_file import load_robot

        home = load_robot(CONFIG / "rowc.toml").home.position
        assert np.allclose([float(x) for x in pos], home, atol=1e-3)  # the true pose read
        if how == "kill":
            proc.kill()
            assert gone(int(child), 3.0)
        else:
            lines = iter(proc.stdout.readline, "")  # its contact summary comes first
            assert next(x for x in lines if x.startswith("closed")).split() == ["closed", "0"]
            assert gone(int(child), 0.5)
    finally:
        proc.kill()
        proc.wait()
