"""The supervisor's checks one by one, at their limits and in their words: which values fault,
after how long, with which reason (the value, the limit, the unit), and what the stop is. Each
case here was a mutant of supervisor.py that the table of test_supervisor.py let through
(make mutation, docs/mutation.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import FakeDrives

from cdprctl.control.data import ControlData
from cdprctl.control.states import FaultKind, State
from cdprctl.control.supervision.cable_checks import TensionDisagreement
from cdprctl.control.supervision.persistence import Persistence
from cdprctl.control.supervision.supervisor import Supervisor
from cdprctl.geometry.forward_kinematics import FKStatus
from cdprctl.robot_file import load_robot
from drivers.vocabulary import Lifecycle

ROOT = Path(__file__).resolve().parents[3]
ROWC = load_robot(ROOT / "config" / "rowc.toml")
CFG = ROWC.control
M = ROWC.n_cables
TENSION_LIMITS = np.full(M, 10.0)  # N
TORQUE_LIMITS = np.full(M, 2.0)  # N·m


def rig(state: State = State.ENABLED, position_mode: bool = False):
    d = ControlData(M, 0)
    d.state = state
    drives = FakeDrives(M, Lifecycle.ACTIVE)
    s = Supervisor(CFG, d, drives,
                   TENSION_LIMITS if position_mode else None,
                   TORQUE_LIMITS if position_mode else None)  # fmt: skip
    return s, d, drives


def run(s: Supervisor, t0: float, t1: float, dt: float = 0.002, **kw) -> None:
    args = {"fk_status": FKStatus.CONVERGED, "fk_residual": 0.0, "speed": 0.0}
    args.update(kw)
    for t in np.arange(t0, t1 + 1e-12, dt):
        s.supervise(float(t), args["fk_status"], args["fk_residual"], args["speed"], False)


def test_reasons_name_the_value_the_limit_and_the_unit():
    s, d, _ = rig()
    residual = CFG.max_fk_residual + 1.234e-3
    run(s, 1.0, 1.0, fk_residual=residual)
    assert d.fault_kind is FaultKind.ENCODERS_DISAGREE
    assert (f"forward-kinematics residual {residual * 1e3:.2f} mm > "
            f"{CFG.max_fk_residual * 1e3:.0f} mm" in d.fault_reason)  # fmt: skip
    # a tracking error along x alone (the norm takes every axis)
    s, d, _ = rig(State.MOVING)
    d.pose_error[0] = CFG.max_position_error + 1.23e-3
    run(s, 1.0, 1.0)
    assert d.fault_kind is FaultKind.TRACKING
    assert d.fault_reason == (f"tracking error {(CFG.max_position_error + 1.23e-3) * 1e3:.1f} mm "
                              f"> {CFG.max_position_error * 1e3:.1f} mm")  # fmt: skip
    s, d, v = rig()
    v.states.feedback_age[2] = CFG.max_feedback_age + 0.0012
    run(s, 1.0, 1.0 + CFG.period, dt=CFG.period)
    assert d.fault_kind is FaultKind.FEEDBACK_AGE
    assert d.fault_reason == (f"feedback {(CFG.max_feedback_age + 0.0012) * 1e3:.1f} ms old > "
                              f"{CFG.max_feedback_age * 1e3:.0f} ms")  # fmt: skip


def test_a_speed_at_the_limit_is_not_over_it():
    s, d, _ = rig()
    run(s, 1.0, 1.5, speed=CFG.max_speed)
    assert d.state is State.ENABLED
    run(s, 1.5, 1.5 + Supervisor.OVER_SPEED_FOR, speed=CFG.max_speed * 1.001)
    assert d.fault_kind is FaultKind.OVER_SPEED


def test_beyond_capacity_brakes_at_once_without_a_controlled_stop():
    """A drive at its torque limit for TORQUE_FOR: the cables cannot hold the platform, so no
    controlled stop (it would hold with the same torques): FAULT, drives off, brakes."""
    s, d, v = rig(State.MOVING, position_mode=True)
    v.states.torque[3] = -TORQUE_LIMITS[3]
    run(s, 1.0, 1.0 + Supervisor.TORQUE_FOR - 0.004)
    assert d.state is State.MOVING
    run(s, 1.0 + Supervisor.TORQUE_FOR - 0.002, 1.0 + Supervisor.TORQUE_FOR)
    assert d.state is State.FAULT and d.fault_kind is FaultKind.BEYOND_CAPACITY
    assert "deactivate" in v.calls
    assert "cable index 3 at its torque limit (-2.00 of ±2.00 N·m) for 30 ms" in d.fault_reason


def test_the_cable_tension_check_faults_on_what_persists_beyond_its_limit():
    s, d, _ = rig(State.ENABLED, position_mode=True)
    d.internal_tension_error[5] = 1.5 * TENSION_LIMITS[5]  # 1.5 times: faster than plain time
    d.internal_leverage[:] = 0.5
    run(s, 1.0, 1.0 + TensionDisagreement.TENSION_FOR)
    assert d.fault_kind is FaultKind.CABLE_TENSION and d.state is State.STOPPING
    assert "index 5:" in d.fault_reason and "+15.0 N at index 5 (> 10.0 N" in d.fault_reason
    assert f"for {TensionDisagreement.TENSION_FOR * 1e3:.0f} ms;" in d.fault_reason
    s, d, _ = rig(State.ENABLED, position_mode=True)
    d.internal_tension_error[5] = 0.99 * TENSION_LIMITS[5]
    run(s, 1.0, 2.0)
    assert d.state is State.ENABLED


def test_a_drive_at_its_torque_limit_leaves_the_tension_check_to_the_capacity_check():
    s, d, v = rig(State.ENABLED, position_mode=True)
    d.internal_tension_error[1] = 3.0 * TENSION_LIMITS[1]
    v.states.torque[1] = TORQUE_LIMITS[1]
    run(s, 1.0, 1.0 + 0.02)  # less than TORQUE_FOR: no fault of either kind yet
    assert d.state is State.ENABLED


@pytest.mark.parametrize(
    "internal, leverage, suspects, words",
    [
        ([0, 0, 9.0, 0, 1.0, 0, 0, 0], np.full(8, 0.5), [2], "index 2:"),
        # equal scores: both named, best first, "or" between the last two
        ([0, 4.0, 0, 4.0, 0, 0, 0, 0], np.full(8, 0.5), [1, 3], "index 1 or 3:"),
        ([5.0, 0, 4.9, 0, 4.8, 0, 0, 0], np.full(8, 0.5), [0, 2, 4], "index 0, 2 or 4:"),
        # the leverage weighs: |e|/√leverage, so the smaller error on the smaller leverage wins
        ([4.0, 0, 0, 0, 0, 0, 0, 3.0], np.array([1.0, 1, 1, 1, 1, 1, 1, 0.25]), [7], "index 7:"),
        # at 0.9 of the best a cable is a suspect, at 0.8 it is not
        ([10.0, 9.05, 8.0, 0, 0, 0, 0, 0], np.full(8, 0.5), [0, 1], "index 0 or 1:"),
        # exactly at SUSPECT_SHARE (0.9 × 4.0 is 3.6 in floating point): "at least" it
        ([4.0, 3.6, 0, 0, 0, 0, 0, 0], np.ones(8), [0, 1], "index 0 or 1:"),
        # a cable the null space does not reach (leverage 0) with no error: not a suspect
        ([0, 6.0, 0, 0, 0, 0, 0, 0], np.array([0.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]), [1],
         "index 1:"),
    ],
)  # fmt: skip
def test_the_suspects_are_the_cables_that_explain_the_internal_error(
    internal, leverage, suspects, words
):
    with np.errstate(all="raise"):  # no 0/0 on the fault path (a leverage of zero)
        assert TensionDisagreement.suspects(np.array(internal, float), leverage) == suspects
    s, d, _ = rig(State.ENABLED, position_mode=True)
    d.internal_tension_error[:] = np.array(internal, float) * 5.0  # N, beyond the 10 N limit
    d.internal_leverage[:] = leverage
    run(s, 1.0, 1.0 + TensionDisagreement.TENSION_FOR)
    assert d.fault_kind is FaultKind.CABLE_TENSION
    assert words in d.fault_reason, d.fault_reason
    assert ("would explain it" in d.fault_reason) == (len(suspects) > 1)


def test_the_controlled_stop_holds_for_stop_duration_then_disables():
    s, d, v = rig(State.MOVING)
    s.fault(10.0, FaultKind.TRACKING, "x")
    run(s, 10.0, 10.0 + CFG.stop_duration - 0.01)
    assert d.state is State.STOPPING and "deactivate" not in v.calls
    run(s, 10.0 + CFG.stop_duration, 10.0 + CFG.stop_duration)
    assert d.state is State.FAULT and "deactivate" in v.calls


def test_limits_are_exclusive_and_every_axis_counts():
    """A tracking or orientation error exactly at its limit holds; just over it faults, on
    whichever axis it is (the norms take x, y, z and roll, pitch, yaw)."""
    for axis, limit in ((0, CFG.max_position_error), (1, CFG.max_position_error),
                        (2, CFG.max_position_error), (3, CFG.max_angle_error),
                        (4, CFG.max_angle_error), (5, CFG.max_angle_error)):  # fmt: skip
        s, d, _ = rig(State.MOVING)
        d.pose_error[axis] = limit
        run(s, 1.0, 1.0)
        assert d.state is State.MOVING, axis
        d.pose_error[axis] = limit * 1.001
        run(s, 1.002, 1.002)
        assert d.fault_kind in (FaultKind.TRACKING, FaultKind.ORIENTATION), axis
        assert d.state is State.STOPPING


def test_over_speed_reason_says_how_long_it_persisted():
    s, d, _ = rig()
    run(s, 1.0, 1.0 + Supervisor.OVER_SPEED_FOR, speed=2 * CFG.max_speed)
    assert d.fault_reason.endswith(f"for {Supervisor.OVER_SPEED_FOR * 1e3:.0f} ms")
    assert "for 30 ms" in d.fault_reason  # the documented 30 ms


def test_the_cable_tension_fault_comes_after_its_documented_50_ms_inverse_time():
    """Beyond its limit by a ratio r the error faults after 50 ms / r (inverse time)."""
    for ratio in (1.0001, 2.5):
        s, d, _ = rig(State.ENABLED, position_mode=True)
        d.internal_tension_error[2] = ratio * TENSION_LIMITS[2]
        t, dt = 1.0, 0.001
        while d.state is State.ENABLED and t < 2.0:
            run(s, t, t)
            t += dt
        assert d.fault_kind is FaultKind.CABLE_TENSION
        assert t - 1.0 == pytest.approx(0.05 / ratio, abs=2 * dt)


class Outcome:
    """A distribution's outcome as the supervisor reads it (``TDAOutput``'s status, message)."""

    def __init__(self, status: str, message: str):
        self.status, self.message = type("S", (), {"name": status})(), message


def test_the_distributions_faults_stop_the_controlled_way():
    """Three cycles in a row with no feasible feed-forward, or the feedback saturated beyond
    max_saturation_time (the time counted while saturated, not before): a controlled stop."""
    s, d, v = rig(State.MOVING)
    d.dt = 0.002
    s.distribution(1.0, 2, Outcome("INFEASIBLE", "x"))
    assert d.state is State.MOVING
    s.distribution(1.002, 3, Outcome("INFEASIBLE", "wrench infeasible"))
    assert d.state is State.STOPPING and d.fault_kind is FaultKind.TENSION_DISTRIBUTION
    assert d.fault_reason == "tension distribution INFEASIBLE (the feed-forward alone): " \
        "wrench infeasible"
    s, d, v = rig(State.MOVING)
    d.saturation, d.dt = 0.5, 0.0
    d.saturated_for = CFG.max_saturation_time  # at the limit, not over it
    s.distribution(1.0, 0, Outcome("OK", ""))
    assert d.state is State.MOVING and d.saturated_cycles == 1
    d.dt = 0.002
    s.distribution(1.002, 0, Outcome("OK", ""))
    assert d.state is State.STOPPING and "feedback wrench saturated for" in d.fault_reason
    assert "deactivate" not in v.calls  # held, then disabled after the stop


def test_a_state_change_is_an_event_and_staying_is_not():
    s, d, _ = rig(State.ENABLED)
    s.set_state(State.MOVING, 1.0, "move")
    assert list(d.events) == [(1.0, "state enabled -> moving: move")]
    s.set_state(State.MOVING, 1.1, "move again")
    assert len(d.events) == 1


def test_the_controlled_stop_ends_at_the_first_cycle_past_its_length():
    s, d, v = rig(State.MOVING)
    s.fault(10.0, FaultKind.TRACKING, "x")
    run(s, 10.0 + CFG.stop_duration + 0.0013, 10.0 + CFG.stop_duration + 0.0013)
    assert d.state is State.FAULT and "deactivate" in v.calls


def test_the_tension_check_stands_alone_without_a_torque_check():
    """Tension limits without torque limits (no drive can be at its limit): the check acts from
    the first cycle."""
    d = ControlData(M, 0)
    d.state = State.ENABLED
    s = Supervisor(CFG, d, FakeDrives(M, Lifecycle.ACTIVE), TENSION_LIMITS, None)
    d.internal_tension_error[1] = 2.0 * TENSION_LIMITS[1]
    run(s, 1.0, 1.0 + TensionDisagreement.TENSION_FOR)
    assert d.fault_kind is FaultKind.CABLE_TENSION


def test_saturated_time_drains_at_a_quarter_of_real_time():
    s, d, _ = rig(State.MOVING)
    d.saturation, d.saturated_for, d.dt = 1.0, 0.1, 0.002
    s.distribution(1.0, 0, Outcome("OK", ""))
    assert d.saturated_for == pytest.approx(0.1 - Supervisor.SATURATION_LEAK * 0.002)
    assert Supervisor.SATURATION_LEAK == 0.25  # documented: drains at a quarter of real time


def test_each_limit_exactly_reached_is_not_beyond_it():
    """Every check faults beyond its limit, not at it: an FK residual, a feedback age, an
    internal tension error equal to the limit, and the enable time-out on its last instant
    (values exact in binary, so the comparison itself is what is tested)."""
    s, d, _ = rig()
    run(s, 1.0, 1.1, fk_residual=CFG.max_fk_residual)
    assert d.state is State.ENABLED
    s, d, v = rig()
    v.states.feedback_age[:] = CFG.max_feedback_age
    run(s, 1.0, 1.1)
    assert d.state is State.ENABLED
    s, d, _ = rig(State.ENABLED, position_mode=True)
    d.internal_tension_error[4] = TENSION_LIMITS[4]  # ratio exactly 1
    run(s, 1.0, 1.5)
    assert d.state is State.ENABLED
    s, d, v = rig(State.ENABLING)
    v.lifecycle = Lifecycle.INACTIVE  # the drives never report enabled
    s.t_state = 100.0
    s.supervise(100.0 + Supervisor.ENABLE_TIMEOUT, FKStatus.CONVERGED, 0.0, 0.0, False)
    assert d.state is State.ENABLING
    s.supervise(100.0 + Supervisor.ENABLE_TIMEOUT + 0.25, FKStatus.CONVERGED, 0.0, 0.0, False)
    assert d.fault_kind is FaultKind.ENABLE_TIMEOUT


def test_a_drive_at_exactly_its_at_limit_share_counts_as_at_its_limit():
    """``AT_LIMIT`` of the torque limit is at the limit (the capacity check's threshold is
    inclusive: a drive clamped there is not applying what it was asked)."""
    s, d, v = rig(State.MOVING, position_mode=True)
    v.states.torque[2] = Supervisor.AT_LIMIT * TORQUE_LIMITS[2]
    run(s, 1.0, 1.0 + Supervisor.TORQUE_FOR)
    assert d.fault_kind is FaultKind.BEYOND_CAPACITY


def test_a_persistence_holds_once_on_for_its_duration():
    """``Persistence.held``: True at the instant the time on reaches its duration (to within
    1 ns of rounding), not a sample later; a sample at the same instant adds nothing."""
    p = Persistence(1.0)
    assert not p.held(0.0, True)
    assert not p.held(0.0, True)
    assert not p.held(0.5, True)
    assert p.held(1.0 - 1e-9, True)
    p = Persistence(1.0)
    p.held(0.0, True)
    assert not p.held(1.0 - 2e-9, True)


def test_what_persists_across_enabled_and_moving_is_not_restarted():
    """ENABLED → MOVING is supervised on both sides: a drive at its torque limit since before
    a move began faults ``TORQUE_FOR`` after it reached the limit, not after the move began.
    Leaving the supervised states (a stop, a fault) restarts the count."""
    s, d, v = rig(State.ENABLED, position_mode=True)
    v.states.torque[1] = TORQUE_LIMITS[1]
    run(s, 1.0, 1.02)
    s.set_state(State.MOVING, 1.02, "a move")
    run(s, 1.022, 1.0 + Supervisor.TORQUE_FOR)
    assert d.fault_kind is FaultKind.BEYOND_CAPACITY
    s, d, v = rig(State.ENABLED, position_mode=True)
    v.states.torque[1] = TORQUE_LIMITS[1]
    run(s, 1.0, 1.02)
    s.set_state(State.DISABLING, 1.02, "disable")
    s.set_state(State.READY, 1.02, "disabled")
    s.set_state(State.ENABLING, 1.02, "enable")
    s.set_state(State.ENABLED, 1.022, "enabled")
    run(s, 1.024, 1.024 + 0.02)
    assert d.state is State.ENABLED  # 20 ms at the limit since the enable: not yet


def test_more_bad_cycles_than_the_limit_fault_too():
    """The feed-forward infeasible ``BAD_CYCLES`` times in a row or more: a count that went
    past the limit (the cycle at the limit skipped) stops the robot all the same."""
    s, d, _ = rig(State.MOVING)
    d.dt = 0.002
    s.distribution(1.0, Supervisor.BAD_CYCLES + 1, Outcome("INFEASIBLE", "no tensions"))
    assert d.fault_kind is FaultKind.TENSION_DISTRIBUTION


def test_saturated_time_drains_to_zero_and_no_further():
    """After a long unsaturated stretch the saturated time is 0, not below: the next
    saturation counts from zero, not from a credit."""
    s, d, _ = rig(State.MOVING)
    d.saturation, d.saturated_for, d.dt = 1.0, 0.01, 0.002
    for k in range(200):
        s.distribution(1.0 + k * 0.002, 0, Outcome("OK", ""))
    assert d.saturated_for == 0.0


@pytest.mark.parametrize("name", ["OVER_SPEED_FOR", "TORQUE_FOR", "TENSION_FOR"])
def test_persistence_times_are_reported_in_milliseconds(monkeypatch, name):
    """Each persistent fault's reason says how long it persisted, in ms: checked with the
    constant at 2 s, where a wrong factor shows in the printed figure."""
    monkeypatch.setattr(TensionDisagreement if name == "TENSION_FOR" else Supervisor, name, 2.0)
    s, d, v = rig(State.MOVING, position_mode=name != "OVER_SPEED_FOR")
    if name == "OVER_SPEED_FOR":
        run(s, 1.0, 3.0, dt=0.01, speed=2.0 * CFG.max_speed)
    elif name == "TORQUE_FOR":
        v.states.torque[0] = TORQUE_LIMITS[0]
        run(s, 1.0, 3.0, dt=0.01)
    else:
        d.internal_tension_error[0] = 1.01 * TENSION_LIMITS[0]
        run(s, 1.0, 3.0, dt=0.01)
    assert d.fault_reason and "2000 ms" in d.fault_reason, d.fault_reason


def test_limits_in_the_reasons_are_in_milli_units():
    """The FK residual's and the feedback age's limits, printed to the mm and the ms: checked
    at limits where a wrong factor shows (2 m, 2 s)."""
    import dataclasses

    cfg = dataclasses.replace(CFG, max_fk_residual=2.0, max_feedback_age=2.0)
    d = ControlData(M, 0)
    d.state = State.ENABLED
    v = FakeDrives(M, Lifecycle.ACTIVE)
    s = Supervisor(cfg, d, v)
    run(s, 1.0, 1.0, fk_residual=2.5)
    assert "residual 2500.00 mm > 2000 mm" in d.fault_reason, d.fault_reason
    d = ControlData(M, 0)
    d.state = State.ENABLED
    v = FakeDrives(M, Lifecycle.ACTIVE)
    s = Supervisor(cfg, d, v)
    v.states.feedback_age[:] = 2.5
    run(s, 1.0, 1.1, dt=0.01)
    assert "> 2000 ms" in d.fault_reason, d.fault_reason


def test_a_paused_path_holding_is_not_a_target_reached():
    """MOVING → ENABLED when the trajectory has stopped: for a paused path the event says so
    (it had said 'target reached' right after 'path paused in segment 2')."""
    for path_state, words in (("paused", "path paused, holding"), ("", "target reached")):
        s, d, _ = rig(State.MOVING)
        d.path_state = path_state
        s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, True)
        assert d.state is State.ENABLED
        assert d.events[-1][1] == f"state moving -> enabled: {words}", d.events


def test_a_disable_does_not_restart_what_must_persist():
    """DISABLING is supervised: an over-speed that began while moving faults when it has
    lasted OVER_SPEED_FOR, whether or not a disable came in between (an operator pressing
    disable because something looks wrong restarted the count: 30 → 50 ms)."""
    s, d, _ = rig(State.MOVING)
    fast = 2 * CFG.max_speed
    run(s, 1.0, 1.0 + 0.6 * Supervisor.OVER_SPEED_FOR, speed=fast)
    s.set_state(State.DISABLING, 1.0 + 0.6 * Supervisor.OVER_SPEED_FOR, "disable")
    run(s, 1.0 + 0.6 * Supervisor.OVER_SPEED_FOR + 0.002, 1.0 + Supervisor.OVER_SPEED_FOR,
        speed=fast)  # fmt: skip
    assert d.fault_kind is FaultKind.OVER_SPEED
