"""The supervisor's transitions and checks, table-driven, on a stand-in for the drives; the
command acceptance table against the controller; typed faults end to end in lock-step."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from conftest import FakeDrives

from cdprctl.control.command_types import ACCEPTED_IN, Command, CommandKind, accepted
from cdprctl.control.cycle.controller import Controller
from cdprctl.control.data import ControlData
from cdprctl.control.states import PERSISTENCE, FaultKind, State
from cdprctl.control.supervision.supervisor import TRANSITIONS, Supervisor
from cdprctl.geometry.forward_kinematics import FKStatus
from cdprctl.robot_file import load_robot
from cdprctl.tda import TDAMethod, TDAOptions
from drivers.errors import DriveFaultError, DriverOperationError, DriverTimeoutError
from drivers.vocabulary import Lifecycle

ROOT = Path(__file__).resolve().parents[3]
ROWC = load_robot(ROOT / "config" / "rowc.toml")
CFG = ROWC.control


def rig(state: State, lifecycle: Lifecycle = Lifecycle.ACTIVE):
    d = ControlData(ROWC.n_cables, 0)
    d.state = state
    drives = FakeDrives(ROWC.n_cables, lifecycle)
    return Supervisor(CFG, d, drives), d, drives


def healthy(s: Supervisor, t: float = 1.0, **kw) -> None:
    args = {"fk_status": FKStatus.CONVERGED, "fk_residual": 0.0, "speed": 0.0}
    args.update(kw)
    s.supervise(t, args["fk_status"], args["fk_residual"], args["speed"], False)


# (name, start state, drives' lifecycle, what happens, expected state, expected fault kind)
CASES = [
    ("enabled when drives are on", State.ENABLING, Lifecycle.ACTIVE,
     lambda s, d, v: healthy(s, 0.1), State.ENABLED, None),
    ("enable times out", State.ENABLING, Lifecycle.INACTIVE,
     lambda s, d, v: healthy(s, 2.5), State.FAULT, FaultKind.ENABLE_TIMEOUT),
    ("still enabling", State.ENABLING, Lifecycle.INACTIVE,
     lambda s, d, v: healthy(s, 1.5), State.ENABLING, None),
    # the timeout runs from entering ENABLING, not from the start of time
    ("still enabling 1.9 s after entering it at 100 s", State.READY, Lifecycle.INACTIVE,
     lambda s, d, v: s.set_state(State.ENABLING, 100.0, "enable") or healthy(s, 101.9),
     State.ENABLING, None),
    ("enable times out 2.1 s after entering it at 100 s", State.READY, Lifecycle.INACTIVE,
     lambda s, d, v: s.set_state(State.ENABLING, 100.0, "enable") or healthy(s, 102.1),
     State.FAULT, FaultKind.ENABLE_TIMEOUT),
    # a disable decelerates first: the brakes close on a platform at rest, not in motion
    ("disabling ends ready at rest", State.DISABLING, Lifecycle.ACTIVE,
     lambda s, d, v: s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, True), State.READY, None),
    ("disabling waits while decelerating", State.DISABLING, Lifecycle.ACTIVE,
     lambda s, d, v: s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.1, False), State.DISABLING,
     None),
    ("disabling waits for the platform, not only the reference", State.DISABLING,
     Lifecycle.ACTIVE, lambda s, d, v: s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.02, True),
     State.DISABLING, None),
    ("disabling still watches the tracking", State.DISABLING, Lifecycle.ACTIVE,
     lambda s, d, v: d.pose_error.__setitem__(1, 1.01 * CFG.max_position_error)
     or s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.1, False),
     State.STOPPING, FaultKind.TRACKING),
    ("target reached", State.MOVING, Lifecycle.ACTIVE,
     lambda s, d, v: s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, True), State.ENABLED, None),
    ("drive fault: no hold", State.MOVING, Lifecycle.ERROR,
     lambda s, d, v: setattr(v, "error", DriveFaultError(1, 2, 0x2310, "overcurrent"))
     or healthy(s), State.FAULT, FaultKind.DRIVE_FAULT),
    ("silent drive", State.ENABLED, Lifecycle.ERROR,
     lambda s, d, v: setattr(v, "error", DriverTimeoutError("no feedback", 3)) or healthy(s),
     State.FAULT, FaultKind.DRIVE_SILENT),
    ("other driver error", State.READY, Lifecycle.ERROR,
     lambda s, d, v: setattr(v, "error", DriverOperationError("send failed")) or healthy(s),
     State.FAULT, FaultKind.DRIVES),
    ("FK degenerate", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: healthy(s, fk_status=FKStatus.DEGENERATE),
     State.STOPPING, FaultKind.FORWARD_KINEMATICS),
    ("encoders disagree", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: healthy(s, fk_residual=2 * CFG.max_fk_residual),
     State.STOPPING, FaultKind.ENCODERS_DISAGREE),
    ("tracking error", State.MOVING, Lifecycle.ACTIVE,
     lambda s, d, v: d.pose_error.__setitem__(1, 1.01 * CFG.max_position_error) or healthy(s),
     State.STOPPING, FaultKind.TRACKING),
    ("orientation error", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: d.pose_error.__setitem__(5, 1.01 * CFG.max_angle_error) or healthy(s),
     State.STOPPING, FaultKind.ORIENTATION),
    ("old feedback", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: v.states.feedback_age.__setitem__(4, 1.01 * CFG.max_feedback_age)
     or healthy(s) or healthy(s, 1.0 + CFG.period), State.STOPPING, FaultKind.FEEDBACK_AGE),
    ("old feedback once (the loop stalled)", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: v.states.feedback_age.__setitem__(4, 1.01 * CFG.max_feedback_age)
     or healthy(s) or v.states.feedback_age.__setitem__(4, 0.0)
     or healthy(s, 1.0 + CFG.period), State.ENABLED, None),
    ("a fault with the drives off skips the stop", State.ENABLED, Lifecycle.INACTIVE,
     lambda s, d, v: healthy(s, fk_status=FKStatus.BAD_INPUT),
     State.FAULT, FaultKind.FORWARD_KINEMATICS),
    ("the controlled stop ends in FAULT", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: s.fault(1.0, FaultKind.TRACKING, "x")
     or healthy(s, 1.0 + CFG.stop_duration), State.FAULT, FaultKind.TRACKING),
    ("drives fail during the stop", State.ENABLED, Lifecycle.ACTIVE,
     lambda s, d, v: s.fault(1.0, FaultKind.TRACKING, "x")
     or setattr(v, "lifecycle", Lifecycle.ERROR) or healthy(s, 1.1),
     State.FAULT, FaultKind.TRACKING),
]  # fmt: skip


@pytest.mark.parametrize("name,start,lc,act,end,kind", CASES, ids=[c[0] for c in CASES])
def test_transition(name, start, lc, act, end, kind):
    s, d, drives = rig(start, lc)
    act(s, d, drives)
    assert d.state is end, d.events
    assert d.fault_kind is kind
    if kind is not None:
        assert next(k for _, k in d.faults) is kind
        assert d.fault_reason
    if end is State.FAULT:
        assert "deactivate" in drives.calls  # brakes


def test_during_the_stop_is_counted_but_keeps_the_first_reason():
    s, d, drives = rig(State.MOVING)
    s.fault(1.0, FaultKind.OVER_SPEED, "too fast")
    assert d.state is State.STOPPING and s.take_stop() and not s.take_stop()
    drives.lifecycle = Lifecycle.ERROR
    healthy(s, 1.01)
    assert [k for _, k in d.faults] == [FaultKind.OVER_SPEED, FaultKind.DURING_STOP]
    assert d.fault_kind is FaultKind.OVER_SPEED and d.fault_reason == "too fast"


def test_over_speed_must_persist():
    s, d, _ = rig(State.ENABLED)
    fast = 1.5 * CFG.max_speed
    for i in range(14):  # 28 ms at 2 ms
        healthy(s, 1.0 + 0.002 * i, speed=fast)
    assert d.state is State.ENABLED
    healthy(s, 1.0 + Supervisor.OVER_SPEED_FOR, speed=fast)
    assert d.state is State.STOPPING and d.fault_kind is FaultKind.OVER_SPEED
    s2, d2, _ = rig(State.ENABLED)  # a dip below the limit starts the count again
    for i in range(30):
        healthy(s2, 1.0 + 0.002 * i, speed=fast if i % 10 else 0.0)
    assert d2.state is State.ENABLED


def test_a_condition_from_before_a_fault_must_persist_anew():
    """A drive at its torque limit when an other fault disabled the drives: after reset and
    enable it must sit at the limit for TORQUE_FOR again (the persistence once carried over
    and faulted 4 ms after the re-enable: frame loss 20 %, seed 0, lock-step)."""
    d = ControlData(ROWC.n_cables, 0)
    d.state = State.ENABLED
    drives = FakeDrives(ROWC.n_cables, Lifecycle.ACTIVE)
    limits = np.full(ROWC.n_cables, 2.6)
    s = Supervisor(CFG, d, drives, torque_limits=limits)
    drives.states.torque[1] = 2.6
    healthy(s, 1.0)  # at the limit from 1.0 s
    s.fault(1.01, FaultKind.DRIVE_FAULT, "another drive")
    s.set_state(State.READY, 3.0, "reset")
    s.set_state(State.ENABLING, 3.0, "enable")
    drives.lifecycle = Lifecycle.ACTIVE
    healthy(s, 3.01)
    assert d.state is State.ENABLED
    healthy(s, 3.02)  # at the limit since 3.02 s only
    assert d.state is State.ENABLED, d.events
    healthy(s, 3.02 + Supervisor.TORQUE_FOR)
    assert d.fault_kind is FaultKind.BEYOND_CAPACITY


@pytest.mark.parametrize("start", list(State))
def test_transition_table_is_enforced(start):
    for to in State:
        s, d, _ = rig(start)
        s.set_state(to, 1.0, "test")
        if to in TRANSITIONS[start]:
            assert d.state is to
        else:
            assert d.state is start
            assert "refused" in d.events[-1][1]


def test_every_fault_kind_says_why_it_is_immediate_or_persistent():
    for k in FaultKind:
        assert PERSISTENCE[k].split(":")[0] in ("immediate", "persistent"), k


def command_of(kind: CommandKind) -> Command:
    if kind is CommandKind.MOVE:
        return Command(kind, pose=np.array([1.6, 0.35, 0.55, 0.0, 0.0, 0.0]))
    if kind is CommandKind.SET_TDA:
        return Command(kind, tda=TDAOptions(method=TDAMethod.ENERGY, period=CFG.period))
    if kind is CommandKind.JOG:
        return Command(kind, velocity=np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
    if kind is CommandKind.PATH:
        return Command(kind, text="x, y, z\n1.6, 0.35, 0.55\n")
    return Command(kind)


@pytest.fixture(scope="module")
def controller():
    return Controller(ROWC, FakeDrives(ROWC.n_cables, Lifecycle.INACTIVE))


@pytest.mark.parametrize("kind", list(CommandKind))
def test_command_acceptance_table(controller, kind):
    c = controller
    for state in State:
        c.data.state = state
        c.drives.lifecycle = Lifecycle.INACTIVE
        c.data.events.clear()
        assert c.submit(command_of(kind))
        c.desk.handle(0.0)
        ignored = any("ignored in state" in e for _, e in c.data.events)
        assert ignored is (not accepted(kind, state)), (kind, state, list(c.data.events))
        assert accepted(kind, state) is (state in ACCEPTED_IN[kind])


def test_bad_commands_stop_at_the_mailbox(controller):
    c = controller
    c.desk.mailbox.clear()
    c.data.events.clear()
    verdicts = [
        c.submit(Command(CommandKind.MOVE, pose=np.array([np.nan, 0, 0, 0, 0, 0]))),
        c.submit(Command(CommandKind.MOVE, pose=np.zeros(6), speed=2.0)),
        c.submit(Command(CommandKind.SET_TDA, tda=TDAOptions(method=TDAMethod.QP, nu=3.0))),
    ]
    assert len(c.desk.mailbox) == 0
    texts = [e for _, e in c.data.events]
    # refused, each with the reason the event gives
    assert [v.accepted for v in verdicts] == [False] * 3
    assert [v.reason for v in verdicts] == texts
    assert texts[0] == texts[1] == "move ignored: pose or speed not finite/in range"
    assert "nu = 3.0 must be in [0, 1]" in texts[2]
    with pytest.raises(ValueError):
        Command("jump")  # an unknown kind never reaches the loop


def test_typed_faults_in_the_closed_loop():
    """A drive fault and a silent drive injected into the lock-step robot end in their kinds,
    in the data and in the counted faults."""
    from cdprctl.experiments.closed_loop import ClosedLoop
    from sim_backend.faults import FaultEvent, FaultInjector

    for event, kind in (
        (FaultEvent(0.0, "drive_fault", cable=2, value=0x2310), FaultKind.DRIVE_FAULT),
        (FaultEvent(0.0, "silent_drive", cable=3), FaultKind.DRIVE_SILENT),
    ):
        with ClosedLoop(ROWC) as cl:
            cl.startup()
            cl.command("enable")
            cl.run(0.3)
            fi = FaultInjector([], seed=1)
            fi.attach(cl.net)
            fi.events.append(
                FaultEvent(cl.net.time + 0.01, event.kind, cable=event.cable, value=event.value)
            )
            cl.run(1.5, until=lambda c: c.controller.data.state is State.FAULT)
            c = cl.controller
            assert c.data.state in (State.STOPPING, State.FAULT)
            assert c.data.fault_kind is kind, c.data.fault_reason
            assert next(k for _, k in c.data.faults) is kind


def test_enable_starts_with_no_saturation_carried_over(controller):
    """A saturation fault leaves its saturated time behind; an enable after the reset starts
    from zero (the demo's reset + enable faulted again at once, every round: cross-process,
    250 Hz, 5 minutes)."""
    c = controller
    c.data.state = State.READY
    c.drives.lifecycle = Lifecycle.INACTIVE
    c.data.saturated_for, c.data.saturation = 1.42, 0.3
    c.desk.mailbox.clear()
    assert c.submit(Command(CommandKind.ENABLE))
    c.desk.handle(0.0)
    assert c.data.state is State.ENABLING
    assert c.data.saturated_for == 0.0 and c.data.saturation == 1.0


def test_a_disable_that_never_comes_to_rest_disables_after_disable_within():
    """The drives are not kept on by a deceleration that does not end: disable_within after
    entering DISABLING (not after the start of time) the brakes close, the reason said."""
    s, d, drives = rig(State.ENABLED)
    s.set_state(State.DISABLING, 100.0, "disable")
    s.supervise(100.0 + 0.99 * s.disable_within, FKStatus.CONVERGED, 0.0, 0.1, False)
    assert d.state is State.DISABLING and drives.lifecycle is Lifecycle.ACTIVE
    s.supervise(100.0 + 1.01 * s.disable_within, FKStatus.CONVERGED, 0.0, 0.1, False)
    assert d.state is State.READY
    assert d.events[-1][1].endswith(f"(not at rest after {s.disable_within:g} s)")


def test_the_disables_bounds_are_strict_at_rest_and_in_time():
    """At exactly AT_REST m/s a platform is not yet at rest; at exactly disable_within s in
    DISABLING the deceleration has not yet timed out (both: beyond the bound, not at it)."""
    s, d, drives = rig(State.ENABLED)
    s.set_state(State.DISABLING, 1.0, "disable")
    s.supervise(1.5, FKStatus.CONVERGED, 0.0, s.AT_REST, True)
    assert d.state is State.DISABLING
    s.supervise(1.0 + s.disable_within, FKStatus.CONVERGED, 0.0, s.AT_REST, False)
    assert d.state is State.DISABLING and drives.lifecycle is Lifecycle.ACTIVE
    s.supervise(1.6, FKStatus.CONVERGED, 0.0, 0.999 * s.AT_REST, True)
    assert d.state is State.READY


@pytest.mark.parametrize("path_state", ["", "running", "stopped", "done", "aborted"])
def test_a_finished_trajectory_is_a_reached_target_unless_the_path_is_paused(path_state):
    s, d, _ = rig(State.MOVING)
    d.path_state = path_state
    s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, True)
    assert d.state is State.ENABLED and d.events[-1][1].endswith("target reached")
    s, d, _ = rig(State.MOVING)
    d.path_state = "paused"
    s.supervise(1.0, FKStatus.CONVERGED, 0.0, 0.0, True)
    assert d.events[-1][1].endswith("path paused, holding")


@pytest.mark.parametrize("limits, within", [
    # (v, a, j, ω, α, ζ): a jerk-limited stop from the top speed takes v/a + a/j; twice the
    # longer of the linear and the angular, at least 3 s — worked out here by hand
    ((1.0, 0.25, 0.5, 0.1, 1.0, 10.0), 2 * (4.0 + 0.5)),  # linear: 4.5 s
    ((0.1, 1.0, 10.0, 2.0, 0.4, 0.8), 2 * (5.0 + 0.5)),  # angular: 5.5 s
    ((0.3, 1.0, 10.0, 0.5, 2.0, 20.0), 3.0),  # rowc-like: 0.4 s, the floor
])  # fmt: skip
def test_a_disable_decelerates_for_at_most_twice_the_limits_stop_time(limits, within):
    v, a, j, w, al, ze = limits
    cfg = dataclasses.replace(CFG, max_velocity=v, max_acceleration=a, max_jerk=j,
                              max_angular_velocity=w, max_angular_acceleration=al,
                              max_angular_jerk=ze)  # fmt: skip
    s = Supervisor(cfg, ControlData(ROWC.n_cables, 0), FakeDrives(ROWC.n_cables, Lifecycle.ACTIVE))
    assert s.disable_within == pytest.approx(within, rel=1e-12)
