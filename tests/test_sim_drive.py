"""The simulated CiA 402 drive's own reactions, in lock-step through our driver: the torque it
reports is the one it applies (after 0x6072), and losing the controller ends where 0x6007
says (CiA 402 §6.4.1)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.model import load_robot
from drivers.cia402 import protocol as p
from sim_backend.network import LockStep


def enabled_rig(config: str) -> LockStep:
    model = load_robot(CONFIG / config)
    rig = LockStep(model, period=model.control.period)
    rig.driver.configure()
    rig.driver.activate()
    return rig


def cycles(rig: LockStep, torques: np.ndarray, n: int) -> None:
    for _ in range(n):
        t = rig.net.time
        rig.driver.read(t)
        rig.driver.write(t, torques, targets=rig.driver.states.position.copy())
        rig.net.advance(rig.period)
    rig.driver.read(rig.net.time)


def test_torque_actual_is_the_torque_applied_after_0x6072():
    """Torque mode (seed000): 0x6072 := half the winch's limit on drive 1, the full limit
    commanded: the drive applies half and reports half (it reported the target)."""
    with enabled_rig("seed000.toml") as rig:
        drive = rig.net.drives[0]
        limit = rig.model.cables[0].winch.torque_limit
        half_pm = round(0.5 * limit / drive.rated_torque * 1000)
        reply = drive.on_sdo(p.sdo_download(p.OD_MAX_TORQUE, 0, half_pm, 2))
        assert reply is not None and reply.data[0] == 0x60
        torques = np.full(rig.model.n_cables, 0.9 * limit)
        cycles(rig, torques, 5)
        assert rig.plant.motor_torque[0] == pytest.approx(0.5 * limit, rel=1e-3)
        assert rig.plant.motor_torque[1] == pytest.approx(0.9 * limit, rel=1e-3)
        assert rig.driver.states.torque[0] == pytest.approx(0.5 * limit, rel=0.01)
        assert rig.driver.states.torque[1] == pytest.approx(0.9 * limit, rel=0.01)


@pytest.mark.parametrize(
    ("option", "state", "emcy"),
    [
        (0, p.PowerState.OPERATION_ENABLED, False),
        (1, p.PowerState.FAULT, True),
        (2, p.PowerState.SWITCH_ON_DISABLED, True),
        (3, p.PowerState.QUICK_STOP_ACTIVE, True),
    ],
)
def test_the_abort_connection_option_decides_the_reaction(option, state, emcy):
    """The controller goes silent: after the drives' communication timeout each reacts as
    its 0x6007 says — 1 (fault signal) ends in FAULT, not in "disable voltage"."""
    with enabled_rig("rowc.toml") as rig:
        drive = rig.net.drives[3]
        assert drive.od[(p.OD_ABORT_CONNECTION, 0)] == 3  # the driver's choice: quick stop
        reply = drive.on_sdo(p.sdo_download(p.OD_ABORT_CONNECTION, 0, option, 2))
        assert reply is not None and reply.data[0] == 0x60
        hold = rig.plant.drum_ratio * rig.plant.tension
        cycles(rig, hold, 10)
        assert drive.state is p.PowerState.OPERATION_ENABLED
        frames: list[int] = []
        for _ in range(round(3 * rig.model.drives.comm_timeout / rig.period)):
            rig.net.advance(rig.period)  # no frame from the controller
            while (msg := rig.driver.buses[rig.net.bus_index_of(3)].recv(0)) is not None:
                if msg.arbitration_id == p.EMCY + drive.node_id:
                    frames.append(p.EMCY_STRUCT.unpack(msg.data)[0])
        assert drive.state is state
        assert (0x8130 in frames) is emcy
        if option == 1:
            assert drive.fault_code == 0x8130


def test_an_abort_connection_option_beyond_the_standard_is_refused():
    model = load_robot(CONFIG / "rowc.toml")
    with LockStep(model, period=model.control.period) as rig:
        reply = rig.net.drives[0].on_sdo(p.sdo_download(p.OD_ABORT_CONNECTION, 0, 7, 2))
        assert reply is not None and reply.data[0] == 0x80
        assert int.from_bytes(reply.data[4:8], "little") == 0x06090031
