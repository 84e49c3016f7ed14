"""The ROS 2 link (cdprctl/telemetry/ros2/ros2_view.py, docs/ros2.md) as a ROS 2 node sees it: an
independent subscriber (tests/ros2_subscriber.py: its own types from ROS 2's message
definitions, its own DDS participant, another process) on domain 37 receives the topics the
link publishes, with the values the loop wrote; ``cdprctl run --sim --ros2`` publishes at its
rate. The ``[ros2]`` section's checks."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cdprctl.model.errors import ConfigError
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "config"
SUBSCRIBER = ROOT / "tests" / "ros2_subscriber.py"
DOMAIN = 37


# Cyclone DDS on the loopback interface alone: what rmw_cyclonedds configures a ROS 2 node
# with under ROS_LOCALHOST_ONLY=1 (written here, not taken from cdprctl)
LOOPBACK_ONLY = ('<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"'
                 "/></Interfaces></General></Domain></CycloneDDS>")


def subscribe(namespace: str, seconds: float, loopback: bool = False) -> subprocess.Popen:
    env = {**os.environ, **({"CYCLONEDDS_URI": LOOPBACK_ONLY} if loopback else {})}
    return subprocess.Popen([sys.executable, str(SUBSCRIBER), str(DOMAIN), namespace,
                             str(seconds)], stdout=subprocess.PIPE, text=True,
                            env=env)  # fmt: skip


def robot_file(tmp_path: Path, namespace: str) -> Path:
    f = tmp_path / "rowc_ros2.toml"
    f.write_text(f'base = "{CONFIG / "rowc.toml"}"\n[ros2]\nenabled = true\n'
                 f'domain_id = {DOMAIN}\nnamespace = "{namespace}"\n')  # fmt: skip
    return f


def test_the_ros2_section_is_checked(tmp_path, monkeypatch):
    model = load_robot(CONFIG / "rowc.toml")
    assert not model.ros2.enabled and model.ros2.topic_namespace("rowc") == "cdpr/rowc"
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert model.ros2.domain() == 42  # ROS 2's own variable, as a ROS 2 node reads it
    for bad in ("not a number", "233", "-1"):  # ROS 2 refuses these; so does the link
        monkeypatch.setenv("ROS_DOMAIN_ID", bad)
        with pytest.raises(ValueError):
            model.ros2.domain()
        assert model.ros2.environment_problem() == (
            f"ROS_DOMAIN_ID = {bad!r} is not a ROS 2 domain (0-232): set it to one, unset it "
            "(domain 0), or give [ros2] domain_id")
    monkeypatch.setenv("ROS_DOMAIN_ID", " ")
    assert model.ros2.domain() == 0 and model.ros2.environment_problem() is None
    f = robot_file(tmp_path, "lab/cdpr_1")
    m = load_robot(f)
    assert (m.ros2.enabled, m.ros2.domain(), m.ros2.topic_namespace("rowc")) == (
        True, DOMAIN, "lab/cdpr_1")  # fmt: skip
    for bad, words in (('enabled = "yes"', "ros2.enabled"),
                       ("domain_id = 233", "ros2.domain_id = 233 must be <= 232"),
                       ('namespace = "1lab"', "must be a ROS 2 name"),
                       ("rate = 0", "ros2.rate = 0 Hz must be > 0"),
                       ("topics = 1", "ros2.topics is not a known key")):  # fmt: skip
        f.write_text(f'base = "{CONFIG / "rowc.toml"}"\n[ros2]\n{bad}\n')
        with pytest.raises(ConfigError) as exc:
            load_robot(f)
        assert any(words in e for e in exc.value.errors), exc.value.errors


@pytest.mark.parametrize("localhost", [False, True], ids=["network", "localhost only"])
def test_an_independent_subscriber_decodes_what_the_link_was_given(tmp_path, monkeypatch,
                                                                    localhost):
    """The link fed known values (as the daemon's I/O thread feeds it): the pose, the target,
    the tensions, the state decoded by the other process within 0.1 mm, the cables' lengths
    the inverse kinematics' at that pose, the anchors on /tf_static. Under ROS 2's
    localhost-only setting the link is on the loopback interface, where a subscriber so set
    hears it (on the machine's other interface it hears nothing)."""
    if localhost:
        monkeypatch.setenv("ROS_LOCALHOST_ONLY", "1")
    from cdprctl.core.rotation import rpy_to_matrix
    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
    from cdprctl.telemetry.ros2.ros2_view import Ros2Link

    model = load_robot(robot_file(tmp_path, "test/link"))
    link = Ros2Link(model)
    sub = None
    try:
        assert link.helper.start(timeout=20.0), link.helper.failure
        sub = subscribe("test/link", 2.5, loopback=localhost)
        position, rpy = [1.4, 0.33, 0.62], [0.01, -0.02, 0.03]
        tensions = np.linspace(100.0, 135.0, 8)
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            if link.due():
                link.write({"position": position, "rpy": rpy, "state": 3, "tensions": tensions,
                            "target": [1.5, 0.35, 0.59, 0.0, 0.0, 0.0]})  # fmt: skip
            time.sleep(0.005)
        out = json.loads(sub.communicate(timeout=20)[0])
    finally:
        if sub is not None and sub.poll() is None:
            sub.kill()
        link.close()
    assert all(out["counts"][k] >= 20 for k in ("joint_states", "pose", "tf", "state")), out
    assert np.allclose(out["pose"][:3], position, atol=1e-4)
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(rpy_to_matrix(*rpy)).as_quat()
    assert np.allclose(out["pose"][3:], q if q[3] >= 0 else -q, atol=1e-9)
    assert out["tf"]["rowc_platform"][0] == "rowc_base"
    assert np.allclose(out["tf"]["rowc_target"][1:], [1.5, 0.35, 0.59])
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, np.array(position), rpy_to_matrix(*rpy))
    assert out["joints"]["name"] == [c.name for c in model.cables]
    assert np.allclose(out["joints"]["position"], kin.length, atol=1e-9)
    assert np.allclose(out["joints"]["effort"], tensions)
    assert np.allclose(out["anchors"]["rowc_anchor_5"], model.anchors[4])


def test_the_daemon_on_the_simulated_robot_publishes_to_ros2_at_its_rate(tmp_path):
    """``cdprctl run --sim --ros2`` (the file's domain 37), no demo: at least 20 joint_states
    and tf messages a second reach the independent subscriber, the platform's frame at the
    estimated pose the daemon said it was ready at."""
    f = robot_file(tmp_path, "test/daemon")
    sub = subscribe("test/daemon", 12.0)
    try:
        run = subprocess.run(
            [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(f), "--sim", "--ros2",
             "--no-demo", "--duration", "6", "--status", "0", "--no-realtime"],
            capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        out = json.loads(sub.communicate(timeout=30)[0])
    finally:
        if sub.poll() is None:
            sub.kill()
    assert run.returncode == 0, run.stderr[-2000:]
    ready = next(x for x in run.stdout.splitlines() + run.stderr.splitlines()
                 if x.startswith("ready: pose"))  # fmt: skip
    pose = [float(v) for v in ready.split("[")[1].split("]")[0].split(",")]
    for k in ("joint_states", "tf"):
        rate = out["counts"][k] / out["since_first"][k]
        assert out["counts"][k] >= 20 * 4 and rate >= 10, (k, out["counts"], out["since_first"])
    assert np.allclose(out["tf"]["rowc_platform"][1:], pose, atol=1e-4)
    assert np.allclose(out["pose"][:3], pose, atol=1e-4)
    assert "ros2: domain 37" in run.stdout


def test_run_refuses_a_ros_domain_id_that_is_not_a_domain_in_one_line():
    run = subprocess.run(
        [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(CONFIG / "rowc.toml"),
         "--sim", "--ros2", "--duration", "1"],
        capture_output=True, text=True, timeout=60, env={**os.environ, "ROS_DOMAIN_ID": "abc"},
    )  # fmt: skip
    assert run.returncode == 2
    assert run.stderr == ("cdprctl run: --ros2: ROS_DOMAIN_ID = 'abc' is not a ROS 2 domain "
                          "(0-232): set it to one, unset it (domain 0), or give [ros2] "
                          "domain_id\n")  # fmt: skip


@pytest.mark.parametrize(("env", "expected"), [
    ({}, None),
    ({"ROS_LOCALHOST_ONLY": "0"}, None),
    ({"ROS_LOCALHOST_ONLY": "1"}, "LOOPBACK"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "localhost"}, "LOOPBACK"),
    ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}, None),
    ({"ROS_LOCALHOST_ONLY": "1", "CYCLONEDDS_URI": "file:///etc/cyclone.xml"},
     "file:///etc/cyclone.xml,LOOPBACK"),
])  # fmt: skip
def test_the_dds_configuration_follows_ros2s_localhost_setting(monkeypatch, env, expected):
    from cdprctl.model.ros2 import dds_config

    for k in ("ROS_LOCALHOST_ONLY", "ROS_AUTOMATIC_DISCOVERY_RANGE", "CYCLONEDDS_URI"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    want = None if expected is None else expected.replace("LOOPBACK", LOOPBACK_ONLY)
    assert dds_config() == want
