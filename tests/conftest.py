"""Shared fixtures: the shipped robots and the paper data of ../shared/robots/."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from cdprctl.model import RobotModel
from cdprctl.robot_file import load_robot

# The tests mirror the package tree (tests/<package>/test_<module>.py); a test may use another
# test module's helpers by its name (names are unique across the tree: pytest's default import
# mode needs that too), so every test directory is importable.
sys.path[1:1] = sorted({str(f.parent) for f in Path(__file__).parent.rglob("test_*.py")})

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "config"
ROBOT_FILES = sorted(p.name for p in CONFIG.glob("*.toml"))
SHARED_ROBOTS = ROOT.parent / "shared" / "robots"


def in_torque_mode(model: RobotModel) -> RobotModel:
    """``model`` with its drives in cyclic synchronous torque (``[drives] mode = "cst"``): the
    tests of the torque-mode drive and frames, on a robot that ships in position mode."""
    return dataclasses.replace(model, drives=dataclasses.replace(model.drives, mode="cst"))


@pytest.fixture(scope="session", params=ROBOT_FILES)
def robot(request: pytest.FixtureRequest) -> RobotModel:
    return load_robot(CONFIG / request.param)


@pytest.fixture(scope="session")
def seed000() -> RobotModel:
    return load_robot(CONFIG / "seed000.toml")


@pytest.fixture(scope="session")
def rowc() -> RobotModel:
    return load_robot(CONFIG / "rowc.toml")


@pytest.fixture(scope="session")
def seed000_expected() -> dict:
    """Expected numbers of Sensors 2019 §3 (reconstructed, see the file's notes).

    Copied into tests/data so the suite runs without ../shared; the copy is checked against
    the shared file when that is present."""
    local = ROOT / "tests" / "data" / "seed000_expected.json"
    return json.loads(local.read_text())


def random_poses(model: RobotModel, n: int, rng: np.random.Generator, tilt: float = 0.15):
    """Seeded random poses inside the model's workspace box, tilted up to ``tilt`` rad."""
    from cdprctl.core.rotation import exp_so3

    ws = model.workspace
    R0 = model.home.rotation
    for _ in range(n):
        p = rng.uniform(ws.position_min, ws.position_max)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = exp_so3(axis * rng.uniform(0.0, tilt)) @ R0
        yield p, R


class FakeDrives:
    """The drives as the control side sees them (``control.supervisor.DrivePort``), recording
    what it asks of them; ``lifecycle`` as given."""

    def __init__(self, m: int, lifecycle=None):
        from drivers.vocabulary import Lifecycle, WinchStates

        self.lifecycle = Lifecycle.ACTIVE if lifecycle is None else lifecycle
        self.error = None
        self.states = WinchStates(m)
        self.states.feedback_age[:] = 0.0
        self.states.sampled_at[:] = 0.0
        self.calls: list[str] = []

    def begin_activate(self) -> None:
        self.calls.append("activate")

    def begin_deactivate(self) -> None:
        from drivers.vocabulary import Lifecycle

        self.calls.append("deactivate")
        if self.lifecycle is Lifecycle.ACTIVE:
            self.lifecycle = Lifecycle.INACTIVE

    def begin_recover(self, settle: float = 0.5) -> None:
        self.calls.append("recover")


def without_table(text: str, name: str) -> str:
    """A robot file's ``text`` without its ``[name]`` table (and sub-tables), for tests that
    write their own."""
    out, skipping = [], False
    for line in text.splitlines(keepends=True):
        head = line.strip()
        if head.startswith("["):
            key = head.strip("[]").split("]")[0].strip()
            skipping = key == name or key.startswith(name + ".")
        if not skipping:
            out.append(line)
    return "".join(out)


def end_processes(procs: list[subprocess.Popen], grace: float = 10.0) -> None:
    """Every process a test started, ended: SIGTERM, then SIGKILL after ``grace`` s."""
    for proc in procs:
        if proc.poll() is None:
            proc.terminate()
            wait_or_kill(proc, grace)


def wait_or_kill(proc: subprocess.Popen, timeout: float) -> None:
    """``proc`` ended by itself within ``timeout`` s, else killed."""
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def rest_of_output(proc: subprocess.Popen, timeout: float) -> str:
    """What ``proc`` still writes to its text ``stdout`` until it ends (killed after ``timeout``
    s), read through the same buffered stream as the test's ``readline`` calls before it.
    ``communicate(timeout=...)`` reads the raw pipe instead and loses what ``readline`` had
    already buffered: a warning written just after ``ready:`` went missing that way."""
    assert proc.stdout is not None
    out: list[str] = []
    reader = threading.Thread(target=lambda: out.append(proc.stdout.read()), daemon=True)
    reader.start()
    wait_or_kill(proc, timeout)
    reader.join(timeout=10)
    return "".join(out)


def canopen_network():
    """The `canopen` package's Network, its receive thread polling every 50 ms: disconnecting
    waits for one poll, and the package's 1 s poll made each test's teardown a second."""
    import canopen

    network = canopen.Network()
    network.NOTIFIER_CYCLE = 0.05  # s: the notifier's receive time-out
    return network
