"""Fault injection: each kind has its effect at the CAN boundary or in the physics, and random
schedules are reproducible from their seed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode

from cdprctl.robot_file import load_robot
from drivers import DriveFaultError, DriverTimeoutError, Lifecycle
from sim_backend.faults import FaultEvent, FaultInjector
from sim_backend.network import LockStep


@pytest.fixture
def rig():
    model = in_torque_mode(load_robot(CONFIG / "rowc.toml"))  # torque mode: the drives' frames
    with LockStep(model, period=0.002) as ls:
        ls.driver.configure()
        ls.driver.activate()
        yield ls


def hold(ls):
    return ls.plant.drum_ratio * ls.plant.tension


def run(ls, seconds):
    for _ in range(round(seconds / ls.period)):
        ls.cycle(hold(ls))


def inject(ls, *events, seed=1):
    fi = FaultInjector(list(events), seed=seed)
    fi.attach(ls.net)
    return fi


def test_frame_loss_rate(rig):
    t = rig.net.time
    fi = inject(rig, FaultEvent(t, "frame_loss", value=0.05, duration=1.0))
    missed0 = rig.driver.stats.missed_feedback
    run(rig, 1.0)
    lost = fi.counts["lost"]
    # ~5 % of ~25 frames per cycle over 500 cycles, seeded
    assert 400 < lost < 900
    assert rig.driver.stats.missed_feedback - missed0 > 100
    assert rig.driver.lifecycle is Lifecycle.ACTIVE  # occasional losses are tolerated


def test_frame_delay_shows_in_feedback_age(rig):
    inject(rig, FaultEvent(rig.net.time, "frame_delay", value=0.006, duration=0.2))
    ages = []
    for _ in range(50):
        rig.cycle(hold(rig))
        ages.append(rig.driver.states.feedback_age.max())
    assert max(ages) >= 0.006


def test_corrupted_frames_are_ignored_or_detected(rig):
    fi = inject(rig, FaultEvent(rig.net.time, "frame_corruption", value=0.3, duration=0.2))
    ignored0 = rig.driver.stats.frames_ignored
    run(rig, 0.2)
    assert fi.counts["corrupted"] > 50
    assert rig.driver.stats.frames_ignored > ignored0  # wrong lengths never decoded


def test_drive_fault_and_silent_drive(rig):
    inject(rig, FaultEvent(rig.net.time + 0.01, "drive_fault", cable=3, value=0x4310))
    run(rig, 0.05)
    assert isinstance(rig.driver.error, DriveFaultError)
    assert "temperature" in rig.driver.error.description
    model = load_robot(CONFIG / "rowc.toml")
    with LockStep(model) as ls:
        ls.driver.configure()
        ls.driver.activate()
        inject(ls, FaultEvent(ls.net.time, "silent_drive", cable=6, duration=5.0))
        run(ls, model.drives.heartbeat_timeout + 0.1)
        assert isinstance(ls.driver.error, DriverTimeoutError) and ls.driver.error.cable == 6


def test_encoder_jump(rig):
    inject(rig, FaultEvent(rig.net.time, "encoder_jump", cable=2, value=0.3))
    sampled = rig.plant.theta.copy()
    run(rig, 0.002)
    rig.driver.read(rig.net.time)
    offset = rig.driver.states.position - sampled  # reported − true, at the sampling SYNC
    assert offset[2] == pytest.approx(0.3, abs=1e-3)
    assert np.abs(offset[[0, 1, 3, 4, 5, 6, 7]]).max() < 1e-3


def test_cable_snap_and_winch_slip_and_external_wrench(rig):
    p0 = rig.plant.position.copy()
    inject(
        rig,
        FaultEvent(rig.net.time, "winch_slip", cable=1, value=0.02, duration=0.5),
        FaultEvent(rig.net.time, "external_wrench", value=(0, 30.0, 0, 0, 0, 0), ramp=0.1),
        FaultEvent(rig.net.time + 0.2, "cable_snap", cable=5),
    )
    theta1 = rig.plant.theta[1]
    run(rig, 0.5)
    assert rig.plant.drum_slip[1] == pytest.approx(0.01, rel=1e-6)  # 0.02 m/s × 0.5 s
    assert rig.plant.tension[5] == 0.0
    assert rig.plant.ext_force[1] == pytest.approx(30.0)
    assert np.linalg.norm(rig.plant.position - p0) > 1e-3
    assert math.isfinite(theta1)


def test_a_force_ramped_off_goes_as_gradually_as_it_came(rig):
    """An external_wrench event ramps from the wrench acting when it starts: zeros with a 1 s
    ramp take a 30 N force off over 1 s (it went at once, and the demo's "jet off" was a step:
    23 mm of transient on rowc where the ramp gives 6.5)."""
    on = FaultEvent(rig.net.time, "external_wrench", value=(0, 30.0, 0, 0, 0, 0), ramp=0.1)
    inject(rig, on)
    run(rig, 0.2)
    off = FaultEvent(rig.net.time, "external_wrench", value=(0.0,) * 6, ramp=1.0)
    inject(rig, off)
    run(rig, 0.25)
    assert rig.plant.ext_force[1] == pytest.approx(30.0 * 0.75, abs=0.1)
    run(rig, 1.0)
    assert rig.plant.ext_force[1] == 0.0


def test_random_schedule_is_reproducible():
    a = FaultInjector.random_faults(60.0, 8, rate=0.5, seed=42).events
    b = FaultInjector.random_faults(60.0, 8, rate=0.5, seed=42).events
    c = FaultInjector.random_faults(60.0, 8, rate=0.5, seed=43).events
    assert a == b and a != c
    assert 10 < len(a) < 60


def test_unknown_fault_kind_is_refused():
    with pytest.raises(ValueError, match="fault kind 'gremlins'"):
        FaultEvent(0.0, "gremlins")


def test_late_steps_are_said_once_a_second_and_counted():
    from sim_backend.realtime import LateSteps

    said: list[str] = []
    late = LateSteps(lambda text, **_: said.append(text))
    late.step(1.0, 0.0005)
    late.step(1.1, 0.010)  # at the bound: a step a drive could take
    assert said == [] and late.count == 0
    late.step(2.0, 0.0382)
    late.step(2.5, 0.050)  # within the second: counted, said with the next
    late.step(3.1, 0.020)
    assert len(said) == 2 and "stepped 38.2 ms late at t=2.00 s" in said[0]
    assert "stepped 20.0 ms late at t=3.10 s (1 more since the last said)" in said[1]
    assert late.count == 3 and late.worst == 0.050
    assert late.summary() == ("cdprctl sim: 3 steps later than 10 ms, the latest 50.0 ms (the "
                              "simulator starved, not the drives)")  # fmt: skip
