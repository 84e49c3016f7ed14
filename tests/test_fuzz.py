"""Bad input that must never reach the motors: fuzzed command payloads (hypothesis) through
the gateway's validator, a flood of commands into the loop, random and malformed CAN frames
on the bus while the robot holds and moves (lock-step, seeded)."""

from __future__ import annotations

import json
import math
import random

import can
import numpy as np
from conftest import CONFIG
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdprctl.control.command_types import Command
from cdprctl.control.intake.desk import FULL
from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.robot_file import load_robot
from cdprctl.telemetry.zenoh.validate import KINDS, CommandError, CommandValidator

ROWC = load_robot(CONFIG / "rowc.toml")
VALIDATOR = CommandValidator(ROWC, commands_enabled=True)
STATES = ["ready", "enabled", "moving", "fault"]

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**12), 10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
)
values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=7), max_leaves=12)
keys = st.sampled_from(
    [
        "position",
        "rpy",
        "max_velocity",
        "max_acceleration",
        "method",
        "nu",
        "direction",
        "cable",
        "quantity",
        "value",
        "opening",
        "force",
        "id",
        "x",
    ]
)
payloads = st.dictionaries(keys, values, max_size=5)


def vector_like():
    return st.lists(st.floats(-5, 5, allow_nan=False), min_size=3, max_size=3)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from([*KINDS, "launch"]), payload=payloads, state=st.sampled_from(STATES))
def test_any_payload_is_accepted_sanely_or_rejected_with_a_reason(kind, payload, state):
    raw = json.dumps(payload, allow_nan=True).encode()
    try:
        d = VALIDATOR.parse(raw)
        cmd_kind, params = VALIDATOR.check(kind, d, state)
    except CommandError as exc:
        assert str(exc)  # a reason, never an empty rejection
        return
    # what passes is safe to execute
    if cmd_kind == "move":
        pose = np.array(params["pose"])
        assert np.all(np.isfinite(pose))
        ws = ROWC.workspace
        assert np.all(pose[:3] >= ws.position_min) and np.all(pose[:3] <= ws.position_max)
        assert 0.0 < params["speed"] <= 1.0 and 0.0 < params["accel"] <= 1.0
        assert state in ("enabled", "moving")
    elif cmd_kind == "set_tda":
        opts = params["tda"]
        assert opts.validate(ROWC) == []
        assert math.isfinite(opts.nu)


@settings(max_examples=150, deadline=None)
@given(
    position=vector_like(),
    rpy=st.lists(st.floats(-1, 1, allow_nan=False), min_size=3, max_size=3),
    v=st.floats(-1, 1, allow_nan=False),
)
def test_moves_near_the_limits(position, rpy, v):
    payload = {"position": position, "rpy": rpy, "max_velocity": v}
    try:
        _, params = VALIDATOR.check("move", payload, "enabled")
    except CommandError:
        return
    assert 0.0 < v <= ROWC.control.max_velocity
    assert np.allclose(params["pose"][:3], position)


def test_a_command_flood_never_stalls_or_breaks_the_loop():
    """Every cycle 100 commands (valid, invalid-for-the-state, garbage poses) while moving:
    the mailbox stays bounded, nothing raises, torques stay finite and within limits."""
    rng = np.random.default_rng(3)
    limit = np.array([c.winch.torque_limit for c in ROWC.cables])
    with ClosedLoop(ROWC) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(0.3)
        c = cl.controller
        refused = 0
        for _ in range(500):
            for _ in range(100):
                k = rng.integers(4)
                if k == 0:
                    cmd = Command("move", pose=np.array([np.nan, 0.35, 0.5, 0, 0, 0]))
                elif k == 1:
                    cmd = Command("reset")  # wrong state: ignored
                elif k == 2:
                    cmd = Command(
                        "move", pose=np.array([1.6 + 0.2 * rng.random(), 0.35, 0.5, 0, 0, 0])
                    )
                else:
                    cmd = Command("enable")
                refused += c.submit(cmd) is FULL
            cl.manager.step(cl.net.time)
            cl.net.advance(cl.period)
            assert len(c.desk.mailbox) <= 64
            assert np.all(np.isfinite(c.trajectory.target))  # the NaN moves never got in
            tq = c.data.torques
            assert np.all(np.isfinite(tq)) and np.all(np.abs(tq) <= limit + 1e-9)
        assert refused > 0  # the bound was reached
        assert c.data.state in (State.ENABLED, State.MOVING, State.STOPPING, State.FAULT)
        assert np.all(np.isfinite(c.trajectory.target))


def test_random_and_malformed_can_frames_change_nothing():
    """While the robot holds and moves: 20 random frames per cycle on the bus — random and
    foreign ids, extended and remote frames, every length, random bytes. The loop keeps
    working (the move completes), torques stay finite and within limits."""
    rnd = random.Random(11)
    limit = np.array([c.winch.torque_limit for c in ROWC.cables])
    with ClosedLoop(ROWC) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(0.3)
        cl.command("move", pose=np.array([1.7, 0.35, 0.55, 0.0, 0.0, 0.0]))
        c = cl.controller
        for _ in range(round(3.0 / cl.period)):
            frames = []
            for _ in range(20):
                ext = rnd.random() < 0.2
                frames.append(
                    can.Message(
                        arbitration_id=rnd.randrange(1 << (29 if ext else 11)),
                        is_extended_id=ext,
                        is_remote_frame=rnd.random() < 0.1,
                        data=bytes(rnd.randrange(256) for _ in range(rnd.randrange(9))),
                    )
                )
            cl.net._send(rnd.randrange(len(cl.net.buses)), frames)  # either bus
            cl.manager.step(cl.net.time)
            cl.net.advance(cl.period)
            tq = c.data.torques
            assert np.all(np.isfinite(tq)) and np.all(np.abs(tq) <= limit + 1e-9)
        drv = cl.rig.driver
        assert drv.stats.frames_ignored > 10_000
        # random frames can hit the drives' own ids (a corrupted TPDO, a false EMCY): then the
        # robot must have stopped safely; otherwise the move completed
        if c.data.state is State.ENABLED:
            assert np.linalg.norm(cl.plant.position - [1.7, 0.35, 0.55]) < 2e-3
        else:
            assert c.data.state in (State.STOPPING, State.FAULT), c.data.state
            assert c.data.fault_reason
