"""The clearance every cycle, against the simulated robot (issue 67): rowc holding 0.1 mm
outside the clearance of a planted obstacle rides through its estimate's noise; pushed
toward it, the supervisor stops it (``FaultKind.CLEARANCE``) while the plant, measuring the
same distances at its true pose (``sim_backend/contact.py``), has recorded no contact — and
the recorder itself records a contact where one happens."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from cdprctl.control.states import FaultKind, State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.geometry.interference import OBSTACLE, Interference, check_pose
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.interference import Box, InterferenceConfig
from cdprctl.robot_file import load_robot
from cdprctl.telemetry.foxglove.foxglove_messages import SceneMessages
from cdprctl.telemetry.foxglove.scene import SceneBuilder, SceneLayout
from cdprctl.telemetry.snapshot import SharedSnapshot, controller_values
from cdprctl.telemetry.zenoh.schema import clearance_parts, state_payload
from sim_backend.contact import ContactRecorder

ROOT = Path(__file__).resolve().parents[2]
HALF = 0.002  # m: the obstacle's half side
PUSH = 0  # the base axis the platform is pushed along (x: y is the ill-conditioned one)


def _with_box(model, gap: float, pose=None, cable: int = 0):
    """``model`` with a 4 mm cube ``gap`` m from cable ``cable`` at ``pose`` (position,
    rotation; default home), 0.1 m from its attachment, on the ``PUSH`` side (across the
    cable)."""
    kin = KinematicsData(model)
    p, R = pose if pose is not None else (np.asarray(model.home.position), model.home.rotation)
    inverse_kinematics(model, kin, p, R)
    b, u = p + kin.rbT[:, cable], kin.uT[:, cable]
    n = np.eye(3)[PUSH] - u * u[PUSH]
    n /= np.linalg.norm(n)
    cfg = model.interference
    centre = b + 0.1 * u + (gap + HALF) * n
    for _ in range(2):  # moved along n by what its corners add to the distance
        box = Box("the bracket", centre, np.full(3, HALF), np.eye(3))
        out = dataclasses.replace(model, interference=InterferenceConfig(
            cfg.clearance, cfg.attachment_exclusion, cfg.body, (*cfg.obstacles, box)))  # fmt: skip
        g = Interference(out)
        g.update(kin)
        centre = (
            centre + (gap - g.distance[_check(g, cable, len(out.interference.obstacles) - 1)]) * n
        )
    return out


def _check(g, cable, obstacle):
    """The row of ``g.checks`` of ``cable`` against ``obstacle`` (0-based)."""
    rows = (g.checks[:, 0] == OBSTACLE) & (g.checks[:, 1] == cable) & (g.checks[:, 2] == obstacle)
    return int(np.flatnonzero(rows)[0])


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def _rest(model):
    """The estimated pose where ``model`` holds at home, enabled (its sag)."""
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.5, record=False)
        return cl.controller.data.position.copy(), cl.controller.data.rotation.copy()


def test_pushed_toward_an_obstacle_the_robot_stops_before_any_contact(rowc):
    model = _with_box(rowc, rowc.interference.clearance + 0.0001, _rest(rowc))
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.5)
        d = cl.controller.data
        assert d.state is State.ENABLED, d.fault_reason  # holding: the noise rode through
        assert d.interference.minimum == pytest.approx(0.0051, abs=5e-5)
        held = cl.plant.contact.least
        _telemetry_names_the_pair(model, d)
        faulted = []

        def push(c):
            if d.fault_kind is not None and not faulted:
                faulted.append((c.net.time, c.plant.contact.least, list(c.plant.contact.contacts)))
            c.plant.ext_force[PUSH] = 0.0 if faulted else -300.0

        cl.run(2.0, each=push, until=lambda c: d.state is State.FAULT)
    assert d.fault_kind is FaultKind.CLEARANCE, d.fault_reason
    assert "cable 1 and the bracket" in d.fault_reason and "clearance 5.00 mm" in d.fault_reason
    _, least, contacts = faulted[0]
    assert contacts == [] and 0.0 < least < held
    assert cl.plant.contact.contacts == []  # nor after, the push removed at the stop


def _telemetry_names_the_pair(model, d):
    """The snapshot, the state payload and the Foxglove scene carry the least distance, its
    pair and its points (read back through the shared memory)."""
    snap = SharedSnapshot(model.n_cables)
    try:
        snap.write(controller_values(d))
        state = state_payload(snap.read(), [c.name for c in model.cables], "",
                              parts=clearance_parts(model))  # fmt: skip
    finally:
        snap.close()
    c = state["clearance"]
    g = d.interference
    assert c["distance"] == pytest.approx(g.minimum, abs=1e-6) and c["limit"] == 0.005
    assert c["kind"] == "obstacle" and c["between"] == ["1", "the bracket"]
    assert np.allclose(c["points"], g.closest[g.best[0]].reshape(2, 3), atol=1e-6)
    layout = SceneLayout.from_model(model)
    scene = SceneBuilder(layout).build(state)
    assert scene.closest[1] == f"cable 1 and the bracket: {g.minimum * 1e3:.1f} mm"
    assert scene.closest[2] is False  # not under the clearance: drawn amber
    wire = SceneMessages(layout).update(scene, 0).encode()  # protobuf: the entity and its label
    assert b"clearance" in wire and scene.closest[1].encode() in wire


def test_the_recorder_records_a_contact_and_says_it(rowc):
    model = _with_box(rowc, 0.004)
    rec = ContactRecorder(model)
    home, R = np.asarray(model.home.position, dtype=float), model.home.rotation
    g = check_pose(model, home, R)
    toward = g.closest[g.best[0], 3:] - g.closest[g.best[0], :3]  # cable → the bracket
    toward /= np.linalg.norm(toward)
    poses = [home + s * toward for s in np.arange(0.0, 0.012, 0.001)] + [home]  # in and back
    for k, p in enumerate(poses):
        rec.update(0.1 * k, p, R)
    depth = [check_pose(model, p, R).minimum for p in poses]
    first = next(k for k, d in enumerate(depth) if d <= 0.0)
    assert rec.least == min(depth) < 0.0 and len(rec.contacts) == 1  # one contact, entered once
    assert rec.contacts[0][0] == pytest.approx(0.1 * first)
    deepest = int(np.argmin(depth))
    assert rec.report() == (
        f"1 contact(s), the first at t = {0.1 * first:.3f} s (the simulated robot's clock): "
        "cable 1 and the bracket: "
        f"overlapping by {-depth[first] * 1e3:.2f} mm; the deepest: cable 1 and the bracket: "
        f"overlapping by {-depth[deepest] * 1e3:.2f} mm at t = {0.1 * deepest:.3f} s")
    clear = ContactRecorder(rowc)
    clear.update(0.0, home, R)
    assert clear.report().startswith("no contact; the closest: cables")


def test_pushed_toward_a_fixture_the_platform_stops_before_touching_it(rowc):
    """The platform's body against the cell: a 20 mm block 5.5 mm from the body's −x face at
    its rest pose (the face's middle, 5 cm and more from the cables at the corners). Held,
    clear; pushed toward it, the supervisor stops the robot under the clearance, the plant
    having recorded no contact, and the telemetry and the scene name the body and the block."""
    p, R = _rest(rowc)
    face = p + R @ np.array([-0.1, 0.0, 0.0])  # rowc's body: half extents 0.1, 0.05, 0.1 m
    block = Box("the fixture", face + R @ np.array([-0.0055 - 0.01, 0.0, 0.0]),
                np.full(3, 0.01), R.copy())  # fmt: skip
    cfg = rowc.interference
    model = dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body, (block,)))  # fmt: skip
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.5)
        d = cl.controller.data
        assert d.state is State.ENABLED, d.fault_reason
        g = d.interference
        assert g.minimum == pytest.approx(0.0055, abs=2e-4)
        assert g.describe().startswith("the platform's body and the fixture")
        state = _state(model, d)
        c = state["clearance"]
        assert c["kind"] == "platform" and c["between"] == ["body", "the fixture"]
        scene = SceneBuilder(SceneLayout.from_model(model)).build(state)
        assert scene.closest[1].startswith("the platform's body and the fixture: ")

        def push(c):
            c.plant.ext_force[PUSH] = 0.0 if d.fault_kind is not None else -300.0

        cl.run(2.0, each=push, until=lambda c: d.state is State.FAULT)
    assert d.fault_kind is FaultKind.CLEARANCE, d.fault_reason
    assert "the platform's body and the fixture" in d.fault_reason, d.fault_reason
    assert cl.plant.contact.contacts == [] and 0.0 < cl.plant.contact.least < 0.0055


def _state(model, d):
    """The state payload of ``d`` read back through the shared memory."""
    snap = SharedSnapshot(model.n_cables)
    try:
        snap.write(controller_values(d))
        return state_payload(snap.read(), [c.name for c in model.cables], "",
                             parts=clearance_parts(model))  # fmt: skip
    finally:
        snap.close()


def test_each_pair_that_begins_to_touch_is_a_contact_of_its_own(rowc):
    """The body resting in a crate, then a cable going through a beam as well: two contacts,
    both named (a newcomer's cable went through a beam unsaid: only the least pair's start
    was counted, and the body's was already under way)."""
    home, R = np.asarray(rowc.home.position, dtype=float), rowc.home.rotation
    kin = KinematicsData(rowc)
    inverse_kinematics(rowc, kin, home, R)
    lamp = home + rowc.attachments[0] + 0.5 * (kin.exit_points[0] - home - rowc.attachments[0])
    crate = Box("the crate", home + np.array([0.1 - 0.002 + 0.05, 0, 0]), np.full(3, 0.05),
                np.eye(3))  # fmt: skip
    cfg = rowc.interference
    model = dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body,
        (crate, Box("the beam", lamp + np.array([0.0, 0.0, 0.03]), np.full(3, 0.01),
                    np.eye(3)))))  # fmt: skip
    rec = ContactRecorder(model)
    rec.update(0.0, home, R)  # the body 2 mm in the crate; the beam 2 cm off cable 1
    for k, dz in enumerate(np.linspace(0.0, 0.04, 9)):  # up: cable 1 into the beam
        rec.update(0.1 * (k + 1), home + np.array([0.0, 0.0, dz]), R)
    said = [w.split(":")[0] for _, w in rec.contacts]
    assert said[0] == "the platform's body and the crate" and "cable 1 and the beam" in said
    assert len(said) == len(set(said))  # each pair once: each began once
    pairs = re.search(r"; (\d) pairs: (.*)$", rec.report())
    assert pairs and int(pairs.group(1)) == len(said) and pairs.group(2) == ", ".join(said)
