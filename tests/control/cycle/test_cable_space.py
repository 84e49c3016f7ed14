"""The fast loop in cable space (control/cycle/cable_space.py) and the drives' position mode
(CiA 402 cyclic synchronous position: the simulated drive's loop, the driver's RPDO)."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.cycle.cable_space import (
    after_stall_kernel,
    disturbance_bandwidth,
    measured_tension_kernel,
    motor_target_kernel,
)
from cdprctl.control.cycle.cycle_io import reference_args
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.control.cycle.reference_pose import ReferencePose
from cdprctl.control.states import State
from cdprctl.core.rotation import rpy_to_matrix
from cdprctl.experiments.closed_loop import ClosedLoop, ramped_force
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.geometry.stiffness import cable_stiffnesses
from cdprctl.motion.trajectory import Trajectory
from cdprctl.robot_file import load_robot
from drivers.cia402 import protocol as p
from sim_backend.network import LockStep
from sim_backend.plant import CdprPlant


def rowc_csp():
    """rowc as shipped: drives in position mode on two buses, 250 Hz."""
    model = load_robot(CONFIG / "rowc.toml")
    assert model.drives.mode == "csp" and model.control.rate == 250.0
    return model


def sotda(model):
    """``model`` with SOTDA ν = 0.9 as its configured distribution."""
    control = dataclasses.replace(model.control, tda_method="sotda", tda_nu=0.9)
    return dataclasses.replace(model, control=control)


def enabled(model, seconds: float) -> ClosedLoop:
    """A lock-step closed loop started, enabled and run ``seconds``."""
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(seconds)
    return cl


@pytest.fixture
def rig():
    model = rowc_csp()
    with LockStep(model, period=model.control.period) as ls:
        yield ls


def test_position_mode_is_configured_by_sdo(rig):
    rig.driver.configure()
    for drive in rig.net.drives:
        assert drive.od[(p.OD_MODES_OF_OPERATION, 0)] == p.MODE_CSP
        shown = drive.on_sdo(p.sdo_upload(p.OD_MODES_DISPLAY, 0))  # as a master reads it
        assert shown.data[0] & 0xE0 == 0x40 and shown.data[4] == p.MODE_CSP
    assert all(len(msg.data) == 8 for msg in rig.driver._rpdo)
    assert rig.driver.media == [0, 1]  # two buses, two media: a SYNC on each


def test_the_following_error_is_configured_by_sdo(rig):
    """0x6065 (counts) and 0x6066 (ms) from ``[drives] following_error_*``; the default window
    is the error at which the drive's loop alone asks for the full torque: torque_limit / kp."""
    rig.driver.configure()
    model = rig.model
    w = model.cables[0].winch
    kp = model.drives.position_gains(w.rotor_inertia)[0]
    assert kp == pytest.approx(w.rotor_inertia * (2 * math.pi * 50.0) ** 2)
    counts = round(w.torque_limit / kp / (2 * math.pi) * w.encoder_counts_per_rev)
    for drive in rig.net.drives:
        assert drive.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] == counts  # 1,832 on rowc
        assert drive.od[(p.OD_FOLLOWING_ERROR_TIMEOUT, 0)] == 3


def test_a_mode_the_drive_does_not_have_is_refused(rig):
    drive = rig.net.drives[0]
    reply = drive.on_sdo(p.sdo_download(p.OD_MODES_OF_OPERATION, 0, 3, 1))  # profile velocity
    assert reply is not None and reply.data[0] == 0x80  # abort
    assert int.from_bytes(reply.data[4:8], "little") == 0x06090030
    assert drive.axis.mode == 0


def test_the_drive_holds_its_position_target(rig):
    """A target 0.05 rad (0.45 mm of cable) from where a motor stands, with the holding torque
    as offset: the drive's own loop brings the motor there and reports the torque it takes."""
    d, plant = rig.driver, rig.plant
    d.configure()
    d.activate()
    d.read(rig.net.time)
    hold = plant.drum_ratio * plant.tension
    start = d.states.position.copy()
    target = start.copy()
    target[0] += 0.05
    for _ in range(round(0.5 / rig.period)):
        t = rig.net.time
        d.read(t)
        d.write(t, hold, targets=target)
        rig.net.advance(rig.period)
    d.read(rig.net.time)
    cpr = rig.model.cables[0].winch.encoder_counts_per_rev
    # a PD loop (no integral): each motor sits a little short of its target under the load
    # the offset does not carry, the same for all; cable 0 has made the 0.05 rad step
    lag = plant.theta - target
    assert np.all(np.abs(lag) < 0.01)
    assert abs(lag[0] - np.median(lag[1:])) < 0.005
    np.testing.assert_allclose(d.states.position, plant.theta, atol=2 * 2 * math.pi / cpr)
    # the shortened cable 0 pulls harder: the torque actual is the loop's, not the offset
    assert d.states.torque[0] > hold[0] + 0.05
    # a non-finite target never reaches a drive: the last valid one is kept
    bad = target.copy()
    bad[2] = math.nan
    d.write(rig.net.time, hold, targets=bad)
    assert d.targets[2] == target[2]


def test_the_loop_never_sends_two_syncs_within_half_a_period(rig):
    """A late cycle followed at once by the next: the second one's RPDOs go out, its SYNC does
    not (the drives' time base stays regular); the set-up's own cycling is not held back."""
    d = rig.driver
    d.configure()  # set-up writes: a SYNC each, whatever their spacing
    syncs: list[float] = []
    send = d._send

    def counting(b, msg):
        if msg.arbitration_id == p.SYNC:
            syncs.append(rig.net.time)
        return send(b, msg)

    d._send = counting
    zeros = np.zeros(rig.model.n_cables)
    for gap in (rig.period, 0.0, rig.period, 0.4 * rig.period, 0.6 * rig.period):
        rig.net.advance(gap)
        d.read(rig.net.time)
        d.write(rig.net.time, zeros)
    assert len(syncs) == 3 * len(d.media), syncs  # the 0 and 0.4-period ones held back


def test_a_lost_rpdo_the_drive_goes_on_at_the_targets_rate(rig):
    """A SYNC without a new target (its RPDO lost): the drive's target goes on at its last
    rate, as across a late SYNC, instead of stopping for a period and catching up after."""
    d, plant = rig.driver, rig.plant
    d.configure()
    d.activate()
    hold = plant.drum_ratio * plant.tension
    target = d.states.position.copy()
    speed = 1.0  # rad/s at the motor, cable 0 (1 mm of cable in the run: 40 N more)
    drive = rig.net.drives[0]
    for k in range(40):
        t = rig.net.time
        d.read(t)
        target[0] += speed * rig.period
        d.write(t, hold, targets=target)
        if k == 30:  # this cycle's RPDO to cable 0 never arrives
            rig.net.rx_filter = lambda msg, t: msg.arbitration_id != p.RPDO1 + drive.node_id
        rig.net.advance(rig.period)
        rig.net.rx_filter = None
        if k == 30:
            assert plant.servo.rate[0] == pytest.approx(speed, rel=0.05)
    assert drive.sync.period == pytest.approx(rig.period, rel=1e-6)
    assert drive.axis.state is p.PowerState.OPERATION_ENABLED
    assert abs(plant.servo.target[0] - plant.theta[0]) < 0.05


@pytest.mark.parametrize("next_rpdo_lost", [True, False], ids=["then its RPDO", "RPDO arrives"])
def test_after_a_lost_sync_a_target_for_it_is_not_taken_late(rig, next_rpdo_lost):
    """A SYNC lost (its RPDO arrived), then the next cycle's RPDO lost too: the target waiting
    at the next SYNC was for the lost one. The SYNC counter (0x1019, set by the driver) tells
    the drive it missed a SYNC and that fewer RPDOs came than were sent, so it does not take
    it (it would run a period behind and its catch-up overshoot) and goes on at the targets'
    rate. When the next RPDO does arrive, it is taken: one more RPDO than lost SYNCs."""
    d, plant = rig.driver, rig.plant
    d.configure()
    d.activate()
    drive = rig.net.drives[0]
    assert drive.od[(p.OD_SYNC_COUNTER_OVERFLOW, 0)] == p.SYNC_COUNTER_OVERFLOW
    hold = plant.drum_ratio * plant.tension
    target = d.states.position.copy()
    speed = 1.0  # rad/s at the motor, cable 0
    lose = {
        30: lambda msg, t: msg.arbitration_id != p.SYNC,
        31: lambda msg, t: msg.arbitration_id != p.RPDO1 + drive.node_id or not next_rpdo_lost,
    }
    for k in range(40):
        t = rig.net.time
        d.read(t)
        target[0] += speed * rig.period
        d.write(t, hold, targets=target)
        rig.net.rx_filter = lose.get(k)
        rig.net.advance(rig.period)
        rig.net.rx_filter = None
        if k == 31:
            assert drive.stale_targets == int(next_rpdo_lost)
            assert plant.servo.rate[0] == pytest.approx(speed, rel=0.05)
            # the motor's target goes on where the targets go (the one sent at k = 31,
            # reached a period after its SYNC)
            assert plant.servo.target[0] == pytest.approx(target[0] - speed * rig.period, abs=0.01)
    assert drive.axis.state is p.PowerState.OPERATION_ENABLED
    assert abs(plant.servo.target[0] - plant.theta[0]) < 0.05


def test_the_realtime_simulator_handles_frames_at_their_arrival(rig):
    """Frames read in one burst (a simulator woken late) are handled at the instants they
    arrived, the physics stepped up to each: the drives see SYNCs a period apart."""
    d, net = rig.driver, rig.net
    d.configure()
    net.process()  # the set-up's last frames
    sent: list[float] = []
    drive = net.drives[0]
    on_sync = drive.on_sync

    def seen(t, data=b""):
        sent.append(t)
        return on_sync(t, data)

    drive.on_sync = seen
    t0 = net.time
    zeros = np.zeros(rig.model.n_cables)
    for k in range(3):  # three cycles' frames waiting at once
        d._write_cycle(t0 + k * rig.period, zeros, setup=True)
    syncs_before: dict[str, int] = {}

    def when(msg):  # stamped a period apart: cycle k's frames at t0 + k period (per bus)
        k = syncs_before.get(msg.channel, 0)
        if msg.arbitration_id == p.SYNC:
            syncs_before[msg.channel] = k + 1
        return t0 + k * rig.period

    net.advance_until(t0 + 3 * rig.period, when, first=None)
    assert len(sent) == 3
    np.testing.assert_allclose(np.diff(sent), rig.period, atol=1e-12)
    assert net.time == pytest.approx(t0 + 3 * rig.period)


def test_motor_targets_match_the_plants_cable_law():
    """The targets for a reference pose and tensions are the motor angles at which the
    simulator, which solves its cable law its own way (``CdprPlant.set_pose``), holds that
    pose with those tensions; the reference pose's rotation, wrench matrix and stiffnesses
    are those of the pose as roll-pitch-yaw (``inverse_kinematics``, ``cable_stiffnesses``)
    where the estimate agrees with it."""
    from types import SimpleNamespace

    model = rowc_csp()
    plant = CdprPlant(model)
    rng = np.random.default_rng(7)
    est = Estimator(model)
    tr = Trajectory(model, model.control.period)
    reference = ReferencePose(model)
    kin = KinematicsData(model)
    for _ in range(5):
        pos = model.home.position + rng.uniform(-0.2, 0.2, 3) * [1, 0.1, 1]
        rpy = rng.uniform(-0.05, 0.05, 3)
        tensions = rng.uniform(20.0, 180.0, model.n_cables)
        R = rpy_to_matrix(*rpy)
        plant.set_pose(pos, R, tensions)
        tr.reset(np.concatenate([pos, rpy_to_rotvec(rpy, model.home.rotation)]))
        reference.update(reference_args(tr.position, tr.velocity, tr.acceleration),
                         SimpleNamespace(position=pos, rotation=R))  # no deviation
        out = np.zeros(model.n_cables)
        motor_target_kernel(
            reference.reference_kin.length, tensions, est._law, est.l_home, est.drum_ratio,
            np.zeros(model.n_cables), out,
        )  # fmt: skip
        np.testing.assert_allclose(out, plant.theta, atol=1e-9)
        inverse_kinematics(model, kin, pos, R)
        np.testing.assert_allclose(reference.rotation, R, atol=1e-12)
        np.testing.assert_allclose(reference.kin.W, kin.W, atol=1e-12)
        np.testing.assert_allclose(reference.k, cable_stiffnesses(model, kin), rtol=1e-12)


def rpy_to_rotvec(rpy, R_home):
    """The trajectory's rotation coordinates of ``rpy``: the rotation vector from ``R_home``
    (scipy's, independent of ours)."""
    from scipy.spatial.transform import Rotation

    R = rpy_to_matrix(*rpy)
    return Rotation.from_matrix(R @ np.asarray(R_home).T).as_rotvec()


def test_water_jet_held_by_the_cables_at_250_hz():
    """ARK 2020's 30 N lateral force on rowc, ramped in over 1 s like the demo's, at 250 Hz:
    no fault, the transient within the 15 mm the issue asks (55 mm with the pose loop alone
    at 500 Hz, a fault at 250 Hz). What the cables exert beyond what was commanded is
    integrated into the external wrench (``[control] disturbance_bandwidth``); fed forward,
    the TDA holds the jet and the elastic deflection goes; then a move under the jet."""
    model = rowc_csp()
    with enabled(model, 1.0) as cl:
        c = cl.controller
        y0 = cl.plant.position[1]
        t0 = cl.net.time
        jet = ramped_force(t0, 30.0)
        cl.run(5.0, each=jet)
        a = cl.arrays()
        dy = a["p_true"][a["t"] >= t0, 1] - y0
        assert c.data.state.value == "enabled", c.data.fault_reason
        assert np.max(np.abs(dy)) < 0.015  # the transient
        assert abs(dy[-1]) < 0.001  # the deflection gone
        est = c.data.ext_estimate
        assert est[1] == pytest.approx(30.0, abs=1.5)  # N along y
        assert np.abs(est[[0, 2]]).max() < 1.5 and np.abs(est[3:]).max() < 0.3
        pose = np.concatenate([np.add(model.home.position, [0.3, 0.0, -0.1]), model.home.rpy])
        cl.command("move", pose=pose)
        cl.run(3.0, each=jet)
        a = cl.arrays()
        err = np.linalg.norm(a["p_true"] - a["p_des"], axis=1)[a["t"] >= t0 + 5.0]
        assert c.data.state.value == "enabled", c.data.fault_reason
        assert err.max() < 0.002  # m: the move under the jet (10 mm uncompensated)
        assert np.all(np.isfinite(a["torques"]))


def test_internal_part_is_the_null_space_projection():
    """``internal_part_kernel`` against scipy: ``e − W⁺ W e`` (the part of a tension error no
    wrench explains), with the null space the loop's own QR gives."""
    from scipy.linalg import null_space

    from cdprctl.control.cycle.cable_space import internal_part_kernel
    from cdprctl.geometry.kinematics import inverse_kinematics
    from cdprctl.tda.nullspace import NullSpace

    model = rowc_csp()
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    ns = NullSpace(model.n_cables)
    assert ns.update(kin.W, np.zeros(6))
    rng = np.random.default_rng(3)
    for _ in range(5):
        e = rng.normal(0.0, 50.0, model.n_cables)
        out, leverage = np.zeros(model.n_cables), np.zeros(model.n_cables)
        internal_part_kernel(ns.N, e, out, leverage)
        np.testing.assert_allclose(out, e - np.linalg.pinv(kin.W) @ (kin.W @ e), atol=1e-9)
        Ns = null_space(kin.W)
        np.testing.assert_allclose(out, Ns @ (Ns.T @ e), atol=1e-9)
        np.testing.assert_allclose(leverage, np.diag(Ns @ Ns.T), atol=1e-12)


def test_a_snapped_cable_is_caught_by_its_tension_and_a_jet_is_not():
    """Position mode: the drives hold every motor where its target says, so a snapped cable
    leaves the encoders agreeing with a pose; the measured tensions do not — the supervisor's
    cable-tension check stops the robot. A 50 N jet (beyond the paper's 30 N) changes the
    tensions along range(Wᵀ) and passes."""
    from sim_backend.faults import FaultEvent, FaultInjector

    model = rowc_csp()
    with enabled(model, 0.5) as cl:
        FaultInjector(
            [FaultEvent(cl.net.time, "external_wrench", value=(0, 50.0, 0, 0, 0, 0), ramp=1.0)]
        ).attach(cl.net)
        cl.run(2.5)
        c = cl.controller
        assert c.data.state.value == "enabled", c.data.fault_reason
        assert np.abs(c.data.internal_tension_error).max() < 5.0  # N (limit: 19 N)
        t_snap = cl.net.time
        FaultInjector([FaultEvent(t_snap, "cable_snap", cable=2)]).attach(cl.net)
        cl.run(1.0, until=lambda cl: cl.controller.data.fault_kind is not None)
        d = c.data
        assert d.fault_kind is not None and d.fault_kind.value == "cable tension", d.fault_reason
        assert cl.net.time - t_snap < 0.3


def test_two_buses_on_one_medium_get_one_sync_a_cycle():
    """rowc's two buses put on one channel by an override (as ``--can-interface
    udp_multicast --can-channel ...`` does across processes): the driver sends SYNC, NMT and
    its heartbeat once per medium, so every drive sees one SYNC a cycle, not two — two would
    make each drive latch and answer twice."""
    from drivers import create_driver
    from drivers.buses import media_of
    from sim_backend.network import SimNetwork

    model = rowc_csp()
    shared = {"interface": "inprocess", "channel": f"shared-{id(model)}"}
    apart = {"interface": "inprocess", "channels": ["a", "b"]}
    assert media_of(model.drives.buses, shared) == [0]
    assert media_of(model.drives.buses, apart) == [0, 1]
    plant = CdprPlant(model)
    net = SimNetwork(model, plant, shared)
    syncs: list[float] = []
    drive = net.drives[6]  # on the second bus
    on_sync = drive.on_sync
    drive.on_sync = lambda t, data=b"": (syncs.append(t), on_sync(t, data))[1]
    period = model.control.period
    drv = create_driver(model, period=period, clock=lambda: net.time, wait=net.advance,
                        bus_overrides=shared)  # fmt: skip
    try:
        drv.configure()
        drv.activate()
        for k in range(51):
            if k == 1:
                syncs.clear()  # from here on, one cycle's frames per advance
            t = net.time
            drv.read(t)
            drv.write(t, plant.drum_ratio * plant.tension)
            net.advance(period)
        assert len(syncs) == 50  # one per cycle (a SYNC per bus would be 100)
        assert drv.buses[0] is drv.buses[1]  # one socket: every frame received once
        assert drv.lifecycle.value == "active", drv.error
    finally:
        drv.shutdown()
        net.close()


@pytest.mark.parametrize("drives_watch", [True, False], ids=["following error", "torque limit"])
def test_beyond_capacity_the_brakes_close_at_once(drives_watch):
    """400 N along y, far beyond what rowc's cables hold: in position mode the drives cannot
    follow their targets. Drives that watch their following error (CiA 402 0x6065/0x6066, set
    by the driver) fault and brake on their own (EMCY 0x8611); drives that do not sit at their
    torque limit, and after 30 ms of that the supervisor disables them at once (the brakes hold
    more than the motors) instead of a controlled stop the platform would drag — 540 mm of
    excursion with the stop, 1,436 mm in torque mode (docs/reliability.md)."""
    from sim_backend.faults import FaultEvent, FaultInjector

    model = rowc_csp()
    with ClosedLoop(model) as cl:
        cl.startup()
        if not drives_watch:
            for drive in cl.net.drives:
                off = p.sdo_download(p.OD_FOLLOWING_ERROR_WINDOW, 0, p.FOLLOWING_ERROR_OFF, 4)
                drive.on_sdo(off)
        cl.command("enable")
        cl.run(0.5)
        c = cl.controller
        p0 = cl.plant.position.copy()
        t0 = cl.net.time
        FaultInjector([FaultEvent(t0, "external_wrench", value=(0, 400.0, 0, 0, 0, 0))]).attach(
            cl.net
        )
        cl.run(1.0, until=lambda cl: cl.controller.data.fault_kind is not None)
        assert c.data.fault_kind is not None
        if drives_watch:
            d = c.data
            assert d.fault_kind.value == "drive fault" and "following error" in d.fault_reason
            # how far, against the window the driver wrote to 0x6065 (one count's rounding)
            found = re.search(r"following error: ([\d.]+) mm of cable \(([\d.]+) rad at the "
                              r"motor\) off its position target, beyond \[drives\] "
                              r"following_error_window = ([\d.]+) mm", d.fault_reason)  # fmt: skip
            assert found, d.fault_reason
            w = model.cables[0].winch
            window_mm = 1e3 * model.drives.following_error_window_rad(w) * w.drum_radius / (
                w.gear_ratio)  # fmt: skip
            assert float(found[3]) == pytest.approx(window_mm, rel=0.02)
            assert float(found[1]) > 0.0
        else:
            assert c.data.fault_kind.value == "beyond capacity", c.data.fault_reason
        assert cl.net.time - t0 < 0.2
        assert c.data.state.value == "fault" and bool(np.all(cl.plant.brake))
        cl.run(1.0)
        assert np.linalg.norm(cl.plant.position - p0) < 0.2  # m: held by the brakes


@pytest.mark.parametrize("config", ["rowc.toml", "rowc_1khz.toml"])
def test_a_robot_parked_by_its_own_distribution_enables_without_a_step(config):
    """The simulated robot is parked by the robot's own TDA (the brakes hold what it last
    commanded): with SOTDA ν = 0.9 configured, the controller's holding tensions are the ones
    the cables carry, so enabling does not step the drives' targets. Parked by the barycenter
    it stepped them by 0.24 rad, and at 1 kHz the drive faulted on its following error."""
    with ClosedLoop(sotda(load_robot(CONFIG / config))) as cl:
        cl.startup()
        plant = cl.net.plant
        np.testing.assert_allclose(plant.tension, cl.controller.data.hold_tensions, atol=0.1)
        cl.command("enable")
        worst = 0.0
        for _ in range(round(0.05 / cl.period)):
            cl.manager.step(cl.net.time)
            cl.net.advance(cl.period)
            if plant.servo.kp[0] > 0.0:  # the drives hold their targets
                worst = max(worst, float(np.max(np.abs(plant.servo.target - plant.theta))))
        assert cl.controller.data.state.value == "enabled", cl.manager.driver.error
        assert worst < 0.01  # rad (it was 0.24)


@pytest.mark.parametrize("config", ["rowc.toml", "rowc_1khz.toml"])
def test_enabling_after_a_change_of_distribution_settles_without_a_step(config):
    """A real robot parked by another distribution than the one now configured (the brakes
    hold the barycenter's tensions, the daemon restarted with SOTDA ν = 0.9): the controller's
    tensions differ from the cables' by up to 87 N of internal force, which no pose explains.
    Enabling starts the drives where the motors are and takes the cables to the commanded
    tensions over ``ENABLE_SETTLE``: no step of the targets (0.24 rad and, at 1 kHz, a
    following-error fault), no tension-disagreement fault on the way, and the cables carry
    the commanded tensions after it."""
    from cdprctl.control.cycle.cable_space import CableSpace
    from cdprctl.tda.hold import equilibrium_tensions

    model = load_robot(CONFIG / config)
    with ClosedLoop(sotda(model)) as cl:
        plant = cl.net.plant
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, plant.position.copy(), plant.R.copy())
        parked = equilibrium_tensions(model, kin)  # the barycenter's, as shipped
        plant.set_pose(plant.position.copy(), plant.R.copy(), parked)
        cl.startup()
        c = cl.controller
        assert np.max(np.abs(parked - c.data.hold_tensions)) > 50.0  # N: a real difference
        cl.command("enable")
        worst = 0.0
        for _ in range(round((CableSpace.ENABLE_SETTLE + 0.5) / cl.period)):
            cl.manager.step(cl.net.time)
            cl.net.advance(cl.period)
            if plant.servo.kp[0] > 0.0:  # the drives hold their targets
                worst = max(worst, float(np.max(np.abs(plant.servo.target - plant.theta))))
        assert c.data.state.value == "enabled", (cl.manager.driver.error, list(c.data.events)[-3:])
        # rad: the drives' largest error on the way, 0.045: their loops carry the internal
        # force the torque feed-forward (the commanded tensions) lacks until the settle has
        # gone (87 N through kp); stepped, 0.155 at 250 Hz and a fault at 1 kHz
        assert worst < 0.06
        # the cables now carry what the controller commands (SOTDA's)
        np.testing.assert_allclose(plant.tension, c.data.tensions, atol=5.0)


@pytest.mark.parametrize("error", [-0.004, 0.004])
def test_a_length_the_model_has_wrong_settles_within_the_tension_range(error):
    """A cable whose zero length the controller has 4 mm wrong (40 kN/m: 160 N of stretch):
    the settle at enable would expect the cable to carry 67 N below its minimum or 65 N above
    its maximum; the expected tensions stay within [t_min, t_max], and the supervisor stops on
    the disagreement (a length not what its encoder says) instead of riding it."""
    model = rowc_csp()
    with ClosedLoop(model) as cl:
        cl.startup()
        c = cl.controller
        c.estimator.l_zero[0] += error
        cl.command("enable")
        lo, hi = np.inf, -np.inf
        for _ in range(round(0.8 / cl.period)):
            cl.manager.step(cl.net.time)
            cl.net.advance(cl.period)
            lo = min(lo, float(np.min(c.cable_space.expected - model.tension_min)))
            hi = max(hi, float(np.max(c.cable_space.expected - model.tension_max)))
        assert lo >= 0.0 and hi <= 0.0, (lo, hi)
        assert c.data.state.value == "fault"
        assert "pull against each other" in str(list(c.data.events)), list(c.data.events)


@pytest.mark.parametrize("release, faults", [(0.0, True), (None, False)])
def test_the_torque_before_the_drives_applied_any_is_no_tension(monkeypatch, release, faults):
    """Enabled, each drive reports no torque for its first five SYNCs (the torque before it
    applied any: across processes on a loaded machine the simulated drives did, the read that
    found them enabled and the three after; here one more, as a cable's first sample only
    starts the count of its samples). Taken as the cables' tensions that is up to 98 N of
    internal tension error, and the supervisor stops 20 ms after enabling; for
    ``[drives] brake_release_time`` (default 0.05 s) after enabling the torques are not taken
    as tensions, and the robot holds."""
    from sim_backend.drives.axis import Cia402Axis

    actual = Cia402Axis.torque_actual_pm
    sent: dict[int, int] = {}

    def late_torque(axis):
        if axis.state is not p.PowerState.OPERATION_ENABLED:
            return actual(axis)
        sent[axis.cable] = sent.get(axis.cable, 0) + 1
        return 0 if sent[axis.cable] <= 5 else actual(axis)

    monkeypatch.setattr(Cia402Axis, "torque_actual_pm", late_torque)
    model = rowc_csp()
    if release is not None:
        drives = dataclasses.replace(model.drives, brake_release_time=release)
        model = dataclasses.replace(model, drives=drives)
    assert model.drives.brake_release_time == (0.05 if release is None else release)
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(0.5)
        c = cl.controller
        events = str(list(c.data.events))
        assert min(sent.values()) > 5  # every drive answered with no torque at first
        if faults:
            assert c.data.state.value != "enabled" and "pull against each other" in events, events
        else:
            assert c.data.state.value == "enabled", events
            assert float(np.max(np.abs(c.data.internal_tension_error))) < 5.0  # N


@pytest.mark.parametrize("name", ["rowc", "caroca", "cogiro", "seed000"])
def test_the_estimate_rate_comes_from_the_lowest_mode(name):
    """Unset, ``[control] disturbance_bandwidth`` is the platform's lowest mode on its cables
    over 6, the mode found here independently: the smallest eigenvalue of ``M⁻¹ W k Wᵀ`` by
    plain numpy (rowc 3.17 Hz → 0.53 Hz; 3.08 Hz → 0.51 Hz, the 0.5 Hz it was tuned to by hand,
    before its crossed pairs' offsets); set, it is
    taken as given."""
    model = load_robot(CONFIG / f"{name}.toml")
    assert model.control.disturbance_bandwidth is None
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    W = np.asarray(kin.W)
    K = W @ np.diag(model.cable_stiffness(kin.length)) @ W.T
    R = model.home.rotation
    M = np.zeros((6, 6))
    M[:3, :3] = model.platform.mass * np.eye(3)
    M[3:, 3:] = R @ np.asarray(model.platform.inertia) @ R.T
    lowest = math.sqrt(min(np.linalg.eigvals(np.linalg.solve(M, K)).real)) / (2.0 * math.pi)
    assert disturbance_bandwidth(model) == pytest.approx(lowest / 6.0, rel=1e-6)
    if name == "rowc":
        assert disturbance_bandwidth(model) == pytest.approx(0.529, abs=0.001)
    given = dataclasses.replace(model.control, disturbance_bandwidth=0.3)
    assert disturbance_bandwidth(dataclasses.replace(model, control=given)) == 0.3


@pytest.mark.parametrize(
    ("name", "mass_factor", "stiffness_factor"), [("cogiro", 2.0, 0.5), ("caroca", 0.5, 3.0)]
)
def test_a_robot_nobody_tuned_runs_the_demo_moves(name, mass_factor, stiffness_factor):
    """A user's robot: a shipped one with its platform's mass and inertia and its cables'
    stiffness changed, nothing else — the gains follow from the model (the lowest mode moves
    by √(stiffness/mass)) and the demo's moves track within a millimetre, without a fault."""
    from cdprctl.daemon.scripts import demo_targets
    from cdprctl.geometry.stiffness import lowest_mode

    base = load_robot(CONFIG / f"{name}.toml")
    platform = dataclasses.replace(
        base.platform,
        mass=base.platform.mass * mass_factor,
        inertia=np.asarray(base.platform.inertia) * mass_factor,
    )
    cables = tuple(
        dataclasses.replace(c, cross_section=c.cross_section * stiffness_factor)
        if c.cross_section is not None
        else dataclasses.replace(c, stiffness=c.stiffness * stiffness_factor)
        for c in base.cables
    )
    model = dataclasses.replace(base, platform=platform, cables=cables)
    ratio = lowest_mode(model) / lowest_mode(base)
    assert ratio == pytest.approx(math.sqrt(stiffness_factor / mass_factor), rel=0.02)
    a, b = demo_targets(model)
    with enabled(model, 0.5) as cl:
        for p in (a, model.home.position, b):
            cl.command("move", pose=np.concatenate([p, model.home.rpy]))
            cl.run(3.0)
            assert cl.controller.data.state is State.ENABLED, cl.controller.data.fault_reason
        a = cl.arrays()
        assert np.linalg.norm(a["p_true"] - a["p_des"][:, :3], axis=1).max() < 1e-3  # m


def test_the_suspects_are_the_cables_whose_error_alone_explains_it():
    """One cable's tension error ``a`` shows in the null space as ``a·p_j``; by Cauchy-Schwarz
    ``|p_j[i]| / √P_ii ≤ √P_jj`` with equality only for collinear columns, so the struck cable
    scores best (random wrench matrices, scipy's null space as the reference)."""
    from scipy.linalg import null_space

    from cdprctl.control.supervision.cable_checks import TensionDisagreement

    rng = np.random.default_rng(7)
    for _ in range(20):
        W = rng.normal(size=(6, 8))
        Ns = null_space(W)
        P = Ns @ Ns.T
        j = int(rng.integers(8))
        internal = P[:, j] * rng.uniform(-100.0, 100.0)
        assert TensionDisagreement.suspects(internal, np.diag(P))[0] == j


@pytest.mark.parametrize(("kind", "cable", "group"), [
    ("winch_slip", 5, {0, 3, 5, 6}), ("cable_snap", 2, {1, 2, 4, 7}),
])  # fmt: skip
def test_a_struck_cable_is_named_among_those_that_explain_it(kind, cable, group):
    """rowc has two redundant cables: a slip or a snap leaves a null-space error that four
    cables (one of rowc's two symmetric groups) explain within 0.4 % of each other — the
    fault names all four, the struck one among them (the message named cable 0 for a slip on
    cable 5 before)."""
    import re

    from sim_backend.faults import FaultEvent, FaultInjector

    model = rowc_csp()
    with enabled(model, 0.3) as cl:
        cl.command("move", pose=np.array([1.9, 0.35, 0.5, 0.0, 0.0, 0.0]))
        cl.run(0.5)
        value = 0.05 if kind == "winch_slip" else None
        event = FaultEvent(cl.net.time, kind, cable=cable, value=value, duration=0.5)
        FaultInjector([event]).attach(cl.net)
        cl.run(0.3, until=lambda cl: cl.controller.data.state is not State.MOVING)
        c = cl.controller
        assert c.data.state is State.STOPPING, c.data.fault_reason
        head = r"a cable is not the length its encoder says, index ([\d, or]+):"
        m = re.match(head, c.data.fault_reason)
        assert m, c.data.fault_reason
        named = {int(x) for x in re.findall(r"\d+", m.group(1))}
        assert named == group and cable in named


def test_the_stop_reels_in_only_what_a_cable_lost():
    """tension_hold_kernel against hand arithmetic: a cable short of its tension reeled in by
    gain·dt·deficit/k, no more than the step allowed; one beyond it never paid out; a slack
    or broken one left alone."""
    from cdprctl.control.cycle.cable_space import tension_hold_kernel

    error = np.array([-40.0, 25.0, -40.0, 0.0, -40.0])  # N, measured − expected
    k = np.array([4e4, 4e4, 2e4, 4e4, 400.0])  # N/m: cable 4 a spring
    tension = np.array([60.0, 125.0, 3.0, 100.0, 60.0])  # N: cable 2 below slack
    slack = np.full(5, 10.0)
    give = np.array([0.0, 0.001, 0.0, 0.0, 0.0])  # m
    tension_hold_kernel(error, k, 0.5, 0.002, tension, slack, give)
    np.testing.assert_allclose(give, [-0.5 * 40.0 / 4e4, 0.001, 0.0, 0.0, -0.002])


def test_measured_tensions_take_the_rotor_out_at_the_samples_own_times():
    """``measured_tension_kernel`` against the torque law run forward here: each motor
    accelerates at a constant rate between its samples (so the rate the samples show is the
    one at the sample), its torque ``r t + J θ̈ + b θ̇``. The tensions come back exactly, and
    the low-pass steps by the samples' own intervals — irregular, one sample repeated (a lost
    frame: nothing changes), one with a corrupted speed (skipped; the next is measured against
    the last good one) — to the closed form ``t + (t0 − t) exp(−2π f (s − s0))``. A cable's
    first sample only starts the count."""
    m, f = 2, 5.0
    J, r = np.array([2e-4, 5e-4]), np.array([0.005, 0.02])  # kg·m², m/rad
    b = np.array([0.0, 0.01])  # N·m·s/rad, viscous friction
    limit = np.array([10.0, 10.0])  # N·m
    t_true = np.array([100.0, 150.0])  # N, from the second sample on
    t0 = np.array([80.0, 80.0])  # N, where the filter starts
    out, cmd_f = t0.copy(), t0.copy()
    error, fast = np.zeros(m), np.zeros(m)
    last_s, last_v = np.full(m, -math.inf), np.zeros(m)
    s, v = 1.0, np.array([3.0, -2.0])
    steps = [  # (interval s, acceleration rad/s² per cable, speed reported)
        (0.0, (0.0, 0.0), None), (0.002, (2.0e4, -5.0e3), None), (0.0005, (-3.0e4, 1.0e4), None),
        (0.0, (0.0, 0.0), None), (0.008, (1.0e3, 0.0), None), (0.002, (4.0e3, 2.0e3), 1.0e6),
        (0.002, (4.0e3, 2.0e3), None), (0.004, (-1.0e4, 0.0), None),
    ]  # fmt: skip
    first_s, taken = None, 0
    for h, acc, corrupted in steps:
        a = np.array(acc)
        s, v = s + h, v + a * h
        torque = r * t_true + J * a + b * v
        shown = v.copy() if corrupted is None else np.full(m, corrupted)
        sampled = np.full(m, s)
        measured_tension_kernel(
            torque, shown, sampled, (r, b, np.zeros(m), np.zeros(m), np.zeros(m), J, limit),
            t_true, f, 20.0,
            (last_s, last_v, cmd_f, fast), out, error, np.full(m, math.nan),
        )  # fmt: skip
        if first_s is None:
            first_s = s
            np.testing.assert_array_equal(out, t0)  # the first sample starts the count
            continue
        if corrupted is None and h > 0.0:
            taken += 1
        expected = t_true + (t0 - t_true) * np.exp(-2.0 * math.pi * f * (s - first_s))
        if corrupted is not None:  # skipped: as after the sample before
            expected = t_true + (t0 - t_true) * np.exp(-2.0 * math.pi * f * (s - h - first_s))
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(error, out - cmd_f, rtol=0, atol=1e-12)
    assert taken == 5


def test_after_a_stall_the_targets_go_on_from_where_the_drives_went():
    """``after_stall_kernel`` against the drives' interpolation run here (each reaches its
    target one period after its SYNC, then goes on at that rate) and the closed form of a
    critically damped return: on time it changes nothing; after a late cycle the drives keep
    their rate (no reversal), and the deviation they went into goes back as
    ``x₀ (1 + t/τ) e^(−t/τ)`` over cycles of any length, its rate starting from zero."""
    m, T, tau, extrapolation = 2, 0.002, 0.01, 0.05
    ref_rate = np.array([30.0, -10.0])  # rad/s: the reference before the stall
    sent, drive_rate = np.zeros(m), np.zeros(m)
    dev, dev_rate = np.zeros(m), np.zeros(m)
    t, ref = 0.0, np.zeros(m)

    def cycle(dt, reference):
        target = reference.copy()
        reach = min(dt, extrapolation)
        after_stall_kernel(target, sent, drive_rate, dev, dev_rate, dt, T, reach, dt > 1.5 * T, tau)
        return target

    for _ in range(5):  # on time: the targets as given, the drives at the reference's rate
        t += T
        ref = ref_rate * t
        np.testing.assert_allclose(cycle(T, ref), ref, atol=1e-12)
    np.testing.assert_allclose(drive_rate, ref_rate, rtol=1e-9)
    stands = sent + drive_rate * (0.008 - T)  # the drives' interpolation after 8 ms
    t += 0.008
    ref = ref_rate * t - np.array([0.4, -0.1])  # the reference turned back meanwhile
    out = cycle(0.008, ref)
    np.testing.assert_allclose(out, stands + ref_rate * T, atol=1e-12)  # they go on
    np.testing.assert_allclose(drive_rate, ref_rate, rtol=1e-9)  # at the same rate
    x0 = out - ref
    elapsed = 0.0
    for dt in (0.002, 0.0015, 0.0025, 0.002, 0.0028, 0.001):  # none late
        elapsed += dt
        out = cycle(dt, ref)  # the reference holds still: only the deviation moves
        expected = x0 * (1.0 + elapsed / tau) * math.exp(-elapsed / tau)
        np.testing.assert_allclose(out - ref, expected, rtol=1e-9, atol=1e-12)
    # the first step back is the closed form's, whose speed starts at zero: a fraction of
    # what sending the reference at once asked (x₀ in one period)
    first = x0 * (1.0 - (1.0 + T / tau) * math.exp(-T / tau))
    assert np.all(np.abs(first) < 0.02 * np.abs(x0))


def test_the_working_pose_follows_the_estimate_through_its_low_pass():
    """Position mode works at the reference moved by the estimate's deviation from it through
    a first-order low-pass a decade below the drives' loops (``reference_pose.py``): a step of
    the deviation comes in as ``1 − e^(−2π f t)``, in position and rotation (scipy's rotation
    vectors as the reference), and the wrench matrix is the one at that pose; the targets'
    lengths stay the reference's. A deviation alternating every cycle — how drives 3 and 5
    of seed000 with its grippers rang after a stall when the distribution worked at the
    estimate itself — comes in as ``α / (2 − α)`` of it (500 Hz: 3 %)."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    model = load_robot(CONFIG / "seed000_grippers.toml")
    tr = Trajectory(model, model.control.period)
    ref = ReferencePose(model)
    f = model.drives.position_loop_bandwidth / 10.0
    assert ref.bandwidth == pytest.approx(f)  # 5 Hz as shipped
    x = np.array([7.1, 4.05, 1.45, 0.02, -0.01, 0.03])  # m, rad from the home rotation
    tr.reset(x)
    at_reference = reference_args(tr.position, tr.velocity, tr.acceleration)
    R_ref = Rotation.from_rotvec(x[3:]).as_matrix() @ model.home.rotation
    dp, dphi = np.array([3e-3, -2e-3, 1e-3]), np.array([2e-3, 1e-3, -3e-3])  # m, rad
    estimate = SimpleNamespace(
        position=x[:3] + dp, rotation=Rotation.from_rotvec(dphi).as_matrix() @ R_ref
    )
    kin = KinematicsData(model)
    dt = model.control.period  # s: one step a cycle
    for n in range(1, 41):
        ref.update(at_reference, estimate)
        share = 1.0 - math.exp(-2.0 * math.pi * f * n * dt)
        np.testing.assert_allclose(ref.position, x[:3] + share * dp, rtol=0.0, atol=1e-12)
        R = Rotation.from_rotvec(share * dphi).as_matrix() @ R_ref
        np.testing.assert_allclose(ref.rotation, R, rtol=0.0, atol=1e-12)
    inverse_kinematics(model, kin, ref.position, ref.rotation)
    np.testing.assert_allclose(ref.kin.W, kin.W, atol=1e-12)
    inverse_kinematics(model, kin, x[:3], R_ref)
    np.testing.assert_allclose(ref.reference_kin.length, kin.length, atol=1e-12)
    # alternating: the steady amplitude of a first-order low-pass at the Nyquist frequency
    ref.restart()
    alpha = 1.0 - math.exp(-2.0 * math.pi * f * dt)
    for k in range(400):
        sign = 1.0 if k % 2 == 0 else -1.0
        estimate.position = x[:3] + sign * dp
        ref.update(at_reference, estimate)
    np.testing.assert_allclose(
        np.abs(ref.position - x[:3]), alpha / (2.0 - alpha) * np.abs(dp), rtol=1e-9
    )
