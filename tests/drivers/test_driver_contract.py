"""The contract every registered driver keeps, run against the simulated drives of sim_backend
in lock-step (in-process, simulated time, deterministic)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode

from cdprctl.robot_file import load_robot
from drivers import DriveFaultError, DriverTimeoutError, DriveState, Lifecycle, driver_names
from sim_backend.network import LockStep


@pytest.fixture(params=driver_names())
def rig(request):
    model = load_robot(CONFIG / "rowc.toml")
    # the torque-mode contract (position mode: tests/control/cycle/test_cable_space.py)
    model = dataclasses.replace(
        model, drives=dataclasses.replace(model.drives, driver=request.param, mode="cst")
    )
    # ODrive CAN Simple streams two 8-byte frames per axis: 2,920 bits per cycle for 8 axes,
    # 147 % of 1 Mbit/s at 500 Hz (refused by the bus-load check), 58 % at 200 Hz
    period = 0.005 if request.param == "odrive" else 0.002
    with LockStep(model, period=period) as ls:
        yield ls


def hold_torques(ls):
    """Motor torques holding the current cable tensions (N·m)."""
    return ls.plant.drum_ratio * ls.plant.tension


def test_configure_reads_live_feedback(rig):
    d = rig.driver
    assert d.lifecycle is Lifecycle.UNCONFIGURED
    d.configure()
    assert d.lifecycle is Lifecycle.INACTIVE
    d.read(rig.net.time)
    cpr = rig.model.cables[0].winch.encoder_counts_per_rev
    np.testing.assert_allclose(d.states.position, rig.plant.theta, atol=2 * math.pi / cpr)
    assert np.all(d.states.feedback_age <= 2 * rig.period + 1e-12)
    assert np.all(d.states.state == DriveState.DISABLED)
    assert np.all(rig.plant.brake)


def test_activate_write_and_limits(rig):
    d = rig.driver
    d.configure()
    # commands are not applied before activation
    d.write(rig.net.time, np.full(8, 0.5))
    rig.net.advance(rig.period)
    assert np.all(rig.plant.motor_torque == 0.0)
    d.activate()
    assert d.lifecycle is Lifecycle.ACTIVE
    assert np.all(d.states.state == DriveState.ENABLED)
    tau = hold_torques(rig)
    tau[0] = 99.0  # beyond the 2.6 N·m limit
    tau[1] = math.nan  # never reaches the motor
    last_valid_1 = d._last_command[1]
    for _ in range(3):
        rig.cycle(tau)
    assert not np.any(rig.plant.brake)
    assert rig.plant.motor_torque[0] == pytest.approx(2.6, abs=0.01)
    assert rig.plant.motor_torque[1] == pytest.approx(last_valid_1, abs=0.01)
    np.testing.assert_allclose(rig.plant.motor_torque[2:], tau[2:], atol=0.003)  # per-mille
    assert d.stats.clamped_commands >= 3 and d.stats.rejected_commands >= 3
    assert np.all(np.isfinite(rig.plant.motor_torque))
    d.read(rig.net.time)
    np.testing.assert_allclose(d.states.torque[2:], tau[2:], atol=0.003)


def test_feedback_every_cycle_follows_the_plant(rig):
    d = rig.driver
    d.configure()
    d.activate()
    cpr = rig.model.cables[0].winch.encoder_counts_per_rev
    for _ in range(round(0.5 / rig.period)):
        sampled = rig.plant.theta.copy()  # what the drives sample at this cycle's SYNC
        rig.cycle(hold_torques(rig))
        d.read(rig.net.time)
        np.testing.assert_allclose(d.states.position, sampled, atol=2 * math.pi / cpr + 1e-9)
        assert np.all(d.states.feedback_age <= rig.period + 1e-9)
    assert d.stats.missed_feedback == 0
    assert d.lifecycle is Lifecycle.ACTIVE


def test_deactivate_closes_brakes_and_shutdown_twice(rig):
    d = rig.driver
    d.configure()
    d.activate()
    rig.cycle(hold_torques(rig))
    d.deactivate()
    assert d.lifecycle is Lifecycle.INACTIVE
    rig.net.advance(rig.period)
    assert np.all(rig.plant.brake)
    d.shutdown()
    d.shutdown()
    assert d.lifecycle is Lifecycle.FINALIZED
    d.read(rig.net.time)  # harmless after shutdown
    d.write(rig.net.time, np.zeros(8))


def test_drive_fault_then_recover(rig):
    d = rig.driver
    d.configure()
    d.activate()
    drive = rig.net.drives[4]
    frame = drive.inject_fault(0x2310 if d.name == "cia402" else 0x00001000)
    rig.net._send(rig.model.drives.node_of(4)[0], [frame])  # on the drive's own bus
    for _ in range(3):
        rig.cycle(hold_torques(rig))
    assert d.lifecycle is Lifecycle.ERROR
    assert isinstance(d.error, DriveFaultError) and d.error.cable == 4
    assert rig.plant.brake[4]  # the faulty drive holds its drum
    d.recover()
    assert d.lifecycle is Lifecycle.INACTIVE
    assert d.error is None
    d.activate()
    assert d.lifecycle is Lifecycle.ACTIVE


def test_silent_drive_is_detected(rig):
    d = rig.driver
    d.configure()
    d.activate()
    rig.net.drives[2].silent = True
    for _ in range(int(rig.model.drives.heartbeat_timeout / rig.period) + 10):
        rig.cycle(hold_torques(rig))
        if d.lifecycle is Lifecycle.ERROR:
            break
    assert isinstance(d.error, DriverTimeoutError) and d.error.cable == 2


def test_drives_stop_when_the_controller_dies(rig):
    """Drive-side safety: no more RPDO/SYNC (the daemon killed) → the drives stop applying
    torque and close their brakes within the communication timeout."""
    d = rig.driver
    d.configure()
    d.activate()
    for _ in range(10):
        rig.cycle(hold_torques(rig))
    timeout = rig.model.drives.comm_timeout
    t0 = rig.net.time
    while rig.net.time - t0 < timeout + 0.02:
        rig.net.advance(rig.period)  # the controller sends nothing any more
    assert np.all(rig.plant.brake)
    assert np.all(rig.plant.motor_torque == 0.0)


def test_context_manager_and_wrong_state_calls(rig):
    from drivers import DriverOperationError

    with pytest.raises(DriverOperationError, match="needs the inactive state"):
        rig.driver.activate()
    with rig.driver as d:
        d.configure()
    assert rig.driver.lifecycle is Lifecycle.FINALIZED


def test_two_buses_of_four_drives():
    """The same driver over two buses (same node ids on each), lock-step."""
    from cdprctl.model.drives import BusConfig

    model = in_torque_mode(load_robot(CONFIG / "seed000.toml"))
    buses = (
        BusConfig("socketcan", "can0", 1_000_000, (0, 1, 2, 3), (1, 2, 3, 4)),
        BusConfig("socketcan", "can1", 1_000_000, (4, 5, 6, 7), (1, 2, 3, 4)),
    )
    model = dataclasses.replace(model, drives=dataclasses.replace(model.drives, buses=buses))
    with LockStep(model, period=0.001) as ls:  # 1 kHz: 48 % per bus
        assert ls.driver.warnings == []
        ls.driver.configure()
        ls.driver.activate()
        tau = ls.plant.drum_ratio * ls.plant.tension
        for _ in range(20):
            ls.cycle(tau)
        assert ls.driver.lifecycle is Lifecycle.ACTIVE
        np.testing.assert_allclose(ls.plant.motor_torque, tau, atol=0.003)
        assert len(ls.driver.buses) == 2
