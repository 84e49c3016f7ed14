"""The emergency stop end to end in lock-step (issue 40): rowc mid-move, the simulated drives'
safety chain opens (safe torque off, ``FaultEvent`` "estop", what `--estop` schedules). The
daemon enters its e-stop state — no FAULT, the drop onto the brakes measured against the
plant's — takes no enable while the chain is open, and a reset then is refused by the drives
and said so; once the chain closes a reset is taken and the robot enables and moves again."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.robot_file import load_robot
from sim_backend.faults import FaultEvent, FaultInjector


def events(cl) -> list[str]:
    return [e for _, e in cl.controller.data.events]


def test_an_estop_mid_move_is_its_own_state_until_the_chain_closes_and_a_reset():
    model = load_robot(CONFIG / "rowc.toml")
    with ClosedLoop(model) as cl:
        c = cl.controller
        cl.startup()
        cl.command("enable")
        cl.run(0.5)
        cl.command("move", pose=np.array([1.8, 0.35, 0.5, 0.0, 0.0, 0.0]))
        cl.run(0.4)  # mid-move: ~0.2 m/s
        speed = float(np.linalg.norm(cl.plant.v))  # m/s, the COM
        assert speed > 0.1
        opened = cl.net.time
        FaultInjector([FaultEvent(opened, "estop", duration=3.0)]).attach(cl.net)
        p0 = cl.plant.position.copy()
        cl.run(1.0)
        assert c.data.state is State.ESTOP
        said = events(cl)
        assert not any("FAULT" in e for e in said), said
        entry = next(e for e in said if e.startswith("EMERGENCY STOP"))
        assert "0x8A88" in entry and "safe torque off" in entry
        assert bool(np.all(cl.plant.brake)) and not np.any(cl.plant.motor_torque)
        # the drop onto the brakes: the estimate's against the plant's, within 1 mm
        rest = next(e for e in said if e.startswith("emergency stop: on the brakes"))
        drop = (cl.plant.position - p0) * 1e3
        assert np.allclose(c.supervisor.estop.drop * 1e3, drop, atol=1.0), (rest, drop)
        assert c.supervisor.estop.settled
        # no enable while the chain is open; a reset is refused by the drives, and said
        cl.command("enable")
        cl.run(0.1)
        assert c.data.state is State.ESTOP and "command enable ignored in state estop" in events(
            cl)[-1]  # fmt: skip
        cl.command("reset")
        cl.run(1.0)
        assert c.data.state is State.ESTOP
        assert any("the safety chain is still open" in e for e in events(cl)[-3:]), events(cl)
        # the chain closes: a reset is taken, then enable and a move work
        cl.run(opened + 3.2 - cl.net.time)
        cl.command("reset")
        cl.run(1.0)
        assert c.data.state is State.READY, events(cl)[-4:]
        cl.command("enable")
        cl.run(0.5)
        assert c.data.state is State.ENABLED, events(cl)[-4:]
        cl.command("move", pose=np.array([1.6, 0.35, 0.55, 0.0, 0.0, 0.0]))
        cl.run(3.0)
        assert c.data.state is State.ENABLED
        assert np.linalg.norm(cl.plant.position - [1.6, 0.35, 0.55]) < 2e-3
        assert not any("FAULT" in e for e in events(cl)), events(cl)


def test_the_estops_drop_is_where_the_platform_went_with_its_sign():
    """The e-stop's report: from where the chain opened to where the platform came to rest,
    signed per axis in the base frame (a platform that sank 3.2 mm reads −3.2 in z), once
    at rest for REST_FOR s."""
    from cdprctl.control.supervision.estop import EmergencyStop
    from drivers.errors import SafeTorqueOffError

    stop = EmergencyStop()
    start = np.array([1.5, 0.35, 0.59])
    stop.enter(0.0, start, SafeTorqueOffError(2, 3, 0x8A88, "STO"))
    fell = start + np.array([0.001, 0.0, -0.0032])
    assert stop.watch(0.1, fell, speed=0.05) is None  # moving
    t = 0.2
    while (event := stop.watch(t, fell, speed=0.0)) is None:
        t += 0.01
        assert t < 1.0
    np.testing.assert_allclose(stop.drop, [0.001, 0.0, -0.0032], atol=1e-12)
    assert "[+1.0, +0.0, -3.2] mm" in event and "3.4 mm from where the chain opened" in event


def test_the_checks_alone_take_an_estop_where_no_position_is_given():
    """The supervisor's checks called without an estimate (a test of the checks alone): the
    e-stop is entered and watched from the origin (m, three coordinates), the default
    shared by every call left as it was."""
    from conftest import FakeDrives

    from cdprctl.control.data import ControlData
    from cdprctl.control.supervision import supervisor as sv
    from cdprctl.geometry.forward_kinematics import FKStatus
    from drivers.errors import SafeTorqueOffError
    from drivers.vocabulary import Lifecycle

    model = load_robot(CONFIG / "rowc.toml")
    d = ControlData(model.n_cables, 0)
    d.state = State.ENABLED
    drives = FakeDrives(model.n_cables, Lifecycle.ERROR)
    drives.error = SafeTorqueOffError(2, 3, 0x8A88, "STO")
    s = sv.Supervisor(model.control, d, drives)
    s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, False)
    assert d.state is State.ESTOP
    np.testing.assert_array_equal(s.estop.start, np.zeros(3))
    t = 1.0
    while (said := s.estop.watch(t, sv._NOWHERE, 0.0)) is None:
        t += 0.01
        assert t < 3.0
    assert "[+0.0, +0.0, +0.0] mm" in said
    assert sv._NOWHERE.shape == (3,) and not sv._NOWHERE.flags.writeable
    with pytest.raises(ValueError):
        sv._NOWHERE[0] = 1.0  # the default of every call: nobody may move it
