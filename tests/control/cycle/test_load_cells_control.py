"""The load cells on the control side (``cdprctl/control/cycle/tension_source.py``), lock-step on
rowc_load_cells: the measured tensions are the cells' where a cable has one; the robot holds
through the cells' noise and a lost frame; a dead cell and a drifting one are faults named
with their values within 100 ms, the robot stopping by the kind's category (1); a cell that
is gone leaves the torque's estimate."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.cycle.tension_source import cable_tension, disagreement_kernel
from cdprctl.control.cycle.torques import WinchTorques
from cdprctl.control.states import FaultKind
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.robot_file import load_robot
from sim_backend.faults import FaultEvent, FaultInjector

MODEL = load_robot(CONFIG / "rowc_load_cells.toml")


def enabled(model=MODEL, seconds: float = 0.5) -> ClosedLoop:
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(seconds)
    assert cl.controller.data.state.value == "enabled", cl.controller.data.fault_reason
    return cl


def fault_time(cl: ClosedLoop, seconds: float) -> float:
    """s of simulated time at which the controller faulted (inf: it did not)."""
    d = cl.controller.data
    cl.run(seconds, until=lambda c: bool(d.faults), record=False)
    return d.faults[0][0] if d.faults else math.inf


def test_the_cells_are_the_measured_tensions_and_noise_rides_through():
    """3 s at rest with each cell's 0.1 N noise and 1 % of its frames lost: no fault; the
    measured tensions are the plant's within 0.1 N (the torque's within the friction)."""
    with enabled() as cl:
        FaultInjector([FaultEvent(cl.net.time, "frame_loss", value=0.01)], seed=3).attach(cl.net)
        cl.run(3.0, record=False)
        d = cl.controller.data
        assert d.state.value == "enabled" and not d.faults, d.fault_reason
        np.testing.assert_allclose(d.measured_tensions, cl.plant.tension, atol=0.1)


@pytest.mark.parametrize("kind, value, expect", [
    ("load_cell_dead", 0.0, r"load cell of cable index 3 \(node 24, bus 0\) dead: no value "
     r"within its timeout 30 ms"),
    ("load_cell_drift", 200.0, r"load cell of cable index 3 \(node 24\) and its drive's torque "
     r"disagree: \d+\.\d N measured by the cell, \d+\.\d N from the torque, \d+\.\d N apart "
     r"for 50 ms, beyond both their errors \(0\.5 N accuracy \+ 10 N estimate_error\)"),
])  # fmt: skip
def test_a_dead_or_drifting_cell_is_a_fault_within_100_ms(kind, value, expect):
    """Dead: no value for its timeout. Drifting at 200 N/s: apart beyond accuracy +
    estimate_error (10.5 N) 52 ms after it starts; named within 100 ms of either. The stop is
    category 1, a controlled one: the cell's cable falls back on its torque."""
    with enabled() as cl:
        t0 = cl.net.time + 0.02
        FaultInjector([FaultEvent(t0, kind, cable=3, value=value)]).attach(cl.net)
        t_fault = fault_time(cl, 0.5)
        d = cl.controller.data
        onset = t0 if kind == "load_cell_dead" else t0 + 10.5 / value
        assert t_fault - onset < 0.1, (t_fault - onset, d.fault_reason)
        assert d.faults[0][1] is FaultKind.LOAD_CELL
        assert d.state.value == "stopping" and d.stop_category == 1
        assert re.search(expect, d.fault_reason), d.fault_reason
        cl.run(0.1, record=False)
        assert np.all(np.isfinite(d.torques)) and np.all(np.isfinite(d.measured_tensions))


def test_a_knock_shorter_than_the_disagreement_time_rides_through():
    """A 30 N step on a cell for 20 ms (a knock, a loose contact), beyond the bound but
    shorter than disagreement_time: no fault."""
    with enabled() as cl:
        FaultInjector([FaultEvent(cl.net.time + 0.02, "load_cell_offset", cable=5, value=30.0,
                                  duration=0.02)]).attach(cl.net)  # fmt: skip
        cl.run(0.5, record=False)
        assert not cl.controller.data.faults, cl.controller.data.fault_reason


def test_cable_tension_and_the_disagreement_kernel():
    """The rule: the cell's where finite, else the torque's. The kernel against the torque law
    by hand (``(τ − b θ̇ − τ_c tanh(θ̇/ω_ε)) / r``), a dead cell reported first."""
    assert cable_tension(100.0, 97.5) == 97.5
    assert cable_tension(100.0, math.nan) == 100.0
    w = WinchTorques(MODEL)
    m = MODEL.n_cables
    torque, velocity = np.full(m, 1.0), np.full(m, 2.0)
    by_hand = (1.0 - w.viscous[0] * 2.0 - w.coulomb[0] * math.tanh(2.0 / 0.05)) / w.r[0]
    measured = np.full(m, math.nan)
    measured[[1, 4]] = by_hand + 3.0, by_hand + 12.0
    est, meas = np.full(2, math.nan), np.full(2, math.nan)
    cells, bound = np.array([1, 4]), np.array([10.5, 10.5])
    z = np.zeros(m)
    k = disagreement_kernel(cells, torque, velocity, z, w.terms, measured, 0.5, est, meas, bound)
    assert k == 1 and est[1] == pytest.approx(by_hand) and meas[1] == by_hand + 12.0
    measured[4] = math.nan
    assert disagreement_kernel(cells, torque, velocity, z, w.terms, measured, 0.5, est, meas,
                               bound) == -3  # fmt: skip


def test_no_cells_no_change():
    """rowc without cells: the check has nothing to watch (the shipped robots unchanged)."""
    model = dataclasses.replace(MODEL, sensors=load_robot(CONFIG / "rowc.toml").sensors)
    with enabled(model, 0.2) as cl:
        assert not cl.controller.load_cells.cells
        assert np.all(np.isnan(cl.rig.driver.states.tension))


def test_the_observer_takes_the_cells_over_a_wrong_torque():
    """Torque mode's observer (``observer_kernel``) at rest on tensions that balance the
    weight and w_e: the drives' torques 20 % and 0.3 N·m off, the cells right. With every
    cell the estimate converges to w_e; without cells (NaN) to something else."""
    from conftest import in_torque_mode

    from cdprctl.control.cycle.cycle_io import pose_args
    from cdprctl.control.cycle.estimator import Estimator
    from cdprctl.control.cycle.observer import WrenchObserver
    from cdprctl.control.data import ControlData
    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics

    base = in_torque_mode(MODEL)
    model = dataclasses.replace(
        base, control=dataclasses.replace(base.control, observer_bandwidth=2.0)
    )  # Hz: 3 s are 37 time constants
    est = Estimator(model)
    est.reset(model.home.position, model.home.rotation)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    est.kin.W[:] = kin.W
    est.kin.WT[:] = kin.WT
    w_e = np.array([4.0, 30.0, -6.0, 0.5, -0.3, 0.2])  # N, N·m at P
    weight = np.concatenate([model.platform.mass * model.gravity, np.zeros(3)])  # com at P
    assert np.allclose(model.platform.com, 0.0)
    t_a = np.linalg.lstsq(kin.W, -(weight + w_e), rcond=None)[0]
    torque = 1.2 * WinchTorques(model).r * t_a + 0.3  # N·m: what a wrong model reads
    zeros = np.zeros(model.n_cables)
    for cells, close in ((t_a, True), (np.full(model.n_cables, math.nan), False)):
        d = ControlData(model.n_cables, 0)
        obs = WrenchObserver(model, d)
        obs.reset(pose_args(est))
        for k in range(round(3.0 / model.control.period)):
            obs.update(k * model.control.period, torque, zeros, np.zeros(6), pose_args(est),
                       est.kin, cells)  # fmt: skip
        error = np.abs(d.ext_estimate - w_e).max()
        assert (error < 0.05) if close else (error > 5.0), (close, d.ext_estimate)
