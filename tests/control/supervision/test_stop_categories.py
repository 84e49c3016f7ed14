"""IEC 60204-1's stop categories (docs/safety.md, "Stop categories"): which each fault kind may
take and the config that chooses (`[safety.stop_category]`), the supervisor's category 2 stop
(holding, powered, watched, until a reset or disable) on a stand-in for the drives, and the
`stop` command's three categories end to end in lock-step on rowc mid-move."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import CONFIG, FakeDrives

from cdprctl.control.command_types import Command, CommandKind
from cdprctl.control.data import ControlData
from cdprctl.control.states import FaultKind, State
from cdprctl.control.supervision.supervisor import Supervisor
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.geometry.forward_kinematics import FKStatus
from cdprctl.model import ConfigError
from cdprctl.model.safety import STOP_CATEGORIES, SafetyConfig, stop_key
from cdprctl.robot_file import load_robot
from drivers.vocabulary import Lifecycle

ROWC = CONFIG / "rowc.toml"


def test_every_fault_kind_has_its_stop_categories():
    assert set(STOP_CATEGORIES) == {k.value for k in FaultKind}
    for kind, (allowed, why) in STOP_CATEGORIES.items():
        assert set(allowed) <= {0, 1, 2} and len(set(allowed)) == len(allowed)
        assert why or allowed == (1, 0, 2), kind  # every category withheld says why


def test_the_defaults_are_what_the_supervisor_did_before():
    """Drive faults, silence, the driver, the enable's time-out, beyond capacity and a fault
    during the stop disable at once (0); every other fault holds, then disables (1)."""
    s = SafetyConfig()
    at_once = {"drive fault", "drive silent", "drives", "enable timeout", "beyond capacity",
               "during the stop"}  # fmt: skip
    for kind in FaultKind:
        assert s.category_of(kind.value) == (0 if kind.value in at_once else 1), kind


def test_a_stop_category_section_is_read_and_a_bad_one_refused_saying_why(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text(f'base = "{ROWC}"\n[safety.stop_category]\ntracking = 2\n'
                    "platform_speed = 0\nencoders_disagree = 0\n")  # fmt: skip
    safety = load_robot(good).safety
    assert safety.category_of("tracking") == 2 and safety.category_of("platform speed") == 0
    assert safety.category_of("encoders disagree") == 0 and safety.category_of("orientation") == 1
    bad = tmp_path / "bad.toml"
    bad.write_text(f'base = "{ROWC}"\n[safety.stop_category]\ndrive_fault = 1\n'
                   "cable_tension = 2\ntracking = true\ntracking_error = 2\n"
                   "orientation = 2.0\n")  # fmt: skip
    with pytest.raises(ConfigError) as exc:
        load_robot(bad)
    errors = "\n".join(exc.value.errors)
    assert "safety.stop_category.drive_fault = 1 must be an integer, one of 0 (the drive " \
        "itself has stopped producing torque: its brake holds)" in errors
    assert "safety.stop_category.cable_tension = 2 must be an integer, one of 0, 1 (a slipped " \
        "or broken cable" in errors
    assert "safety.stop_category.tracking = true must be an integer, one of 0, 1, 2" in errors
    assert "safety.stop_category.orientation = 2 must be an integer, one of 0, 1, 2 (written " \
        "2.0: a float)" in errors
    assert "safety.stop_category.tracking_error is not a known key (did you mean tracking?" \
        in errors
    assert stop_key("platform speed") == "platform_speed"


# -- the supervisor's category 2 stop, on a stand-in for the drives ------------------------------
def rig(category: int):
    model = load_robot(ROWC)
    d = ControlData(model.n_cables, 0)
    d.state = State.MOVING
    drives = FakeDrives(model.n_cables, Lifecycle.ACTIVE)
    safety = SafetyConfig(stop_category={"tracking": category})
    s = Supervisor(model.control, d, drives, safety=safety)
    return s, d, drives


def healthy(s, t, **kw):
    args = {"fk_status": FKStatus.CONVERGED, "fk_residual": 0.0, "speed": 0.0, **kw}
    s.supervise(t, args["fk_status"], args["fk_residual"], args["speed"], False)


def test_category_2_holds_powered_past_the_stop_duration_until_a_reset():
    s, d, drives = rig(2)
    s.fault(1.0, FaultKind.TRACKING, "tracking error 60 mm")
    assert d.state is State.STOPPING and d.stop_category == 2 and s.take_stop()
    end = 1.0 + s.config.stop_duration
    for t in np.arange(1.0, end + 5.0, 0.01):
        healthy(s, float(t))
    assert d.state is State.STOPPING and drives.lifecycle is Lifecycle.ACTIVE
    assert "deactivate" not in drives.calls
    assert s.holding_after_stop(end + 5.0) and not s.holding_after_stop(end - 0.01)
    assert s.holding_after_stop(end)  # from stop_duration on, not after it


def test_a_category_1_stop_is_never_a_hold_a_reset_may_end():
    """Past stop_duration a category 1 stop is the supervisor's to end (disabled, FAULT): a
    reset handled before it does so in that cycle must not take it as a category 2 hold."""
    s, _, _ = rig(1)
    s.fault(1.0, FaultKind.TRACKING, "x")
    assert not s.holding_after_stop(1.0 + s.config.stop_duration + 1.0)


def test_category_1_disables_after_the_stop_duration():
    s, d, drives = rig(1)
    s.fault(1.0, FaultKind.TRACKING, "tracking error 60 mm")
    healthy(s, 1.0 + s.config.stop_duration)
    assert d.state is State.FAULT and drives.calls == ["deactivate"] and d.stop_category == 1


def test_category_0_disables_at_once():
    s, d, drives = rig(0)
    s.fault(1.0, FaultKind.TRACKING, "tracking error 60 mm")
    assert d.state is State.FAULT and drives.calls == ["deactivate"] and not s.take_stop()
    assert d.stop_category == 0


def test_a_category_2_hold_is_watched_and_a_failure_disables_at_once():
    """While a category 2 stop holds, the checks go on: the encoders disagreeing then is a
    fault during the stop — the drives off at once (category 0)."""
    s, d, drives = rig(2)
    s.fault(1.0, FaultKind.TRACKING, "x")
    t = 1.0 + s.config.stop_duration + 1.0
    healthy(s, t)
    assert d.state is State.STOPPING
    healthy(s, t + 0.01, fk_residual=1.0)
    assert d.state is State.FAULT and d.stop_category == 0 and drives.calls == ["deactivate"]
    assert d.faults[-1][1] is FaultKind.DURING_STOP
    assert "FAULT during the stop: the encoders disagree" in d.events[-2][1]


def test_a_drive_fault_takes_category_0_whatever_tracking_takes():
    s, d, _ = rig(2)
    s.fault(1.0, FaultKind.DRIVE_FAULT, "drive")
    assert d.state is State.FAULT and d.stop_category == 0


# -- end to end, lock-step ------------------------------------------------------------------------
def moving(cl, mid_move: bool = True) -> None:
    cl.startup()
    cl.command("enable")
    cl.run(0.5)
    cl.command("move", pose=np.array([1.8, 0.35, 0.5, 0.0, 0.0, 0.0]))
    if mid_move:
        cl.run(0.4)  # ~0.2 m/s
        assert float(np.linalg.norm(cl.plant.v)) > 0.1


def test_stop_category_0_mid_move_puts_the_platform_on_its_brakes_at_once():
    """`stop` category 0 at ~0.2 m/s: the drives disabled within two cycles, ready (not a
    fault), the brakes catch the platform: its drop measured against the plant (rowc's
    simulated brakes close at once, the cables' stretch catches it: a few mm)."""
    with ClosedLoop(load_robot(ROWC)) as cl:
        c = cl.controller
        moving(cl)
        p0 = cl.plant.position.copy()
        cl.command("stop", category=0)
        cl.run(2 * cl.period)
        assert c.data.state is State.READY and c.data.stop_category == 0
        assert bool(np.all(cl.plant.brake))
        cl.run(1.0)
        drop = float(np.linalg.norm(cl.plant.position - p0))
        assert drop < 0.01, drop  # m
        assert c.data.fault_kind is None
        cl.command("enable")  # no reset needed: a stop, not a fault
        cl.run(0.5)
        assert c.data.state is State.ENABLED and c.data.stop_category == -1


def test_stop_category_1_decelerates_then_disables():
    with ClosedLoop(load_robot(ROWC)) as cl:
        c = cl.controller
        moving(cl)
        cl.command("stop", category=1)
        cl.run(0.1)
        assert c.data.state is State.DISABLING and c.data.stop_category == 1
        assert not np.any(cl.plant.brake)  # decelerating under power
        cl.run(3.0)
        assert c.data.state is State.READY and bool(np.all(cl.plant.brake))
        assert float(np.linalg.norm(cl.plant.v)) < 0.005


def test_stop_category_2_decelerates_and_holds_powered():
    with ClosedLoop(load_robot(ROWC)) as cl:
        c = cl.controller
        moving(cl)
        cl.command("stop")  # the default: category 2
        cl.run(2.0)
        assert c.data.state is State.ENABLED and c.data.stop_category == 2
        assert not np.any(cl.plant.brake) and float(np.linalg.norm(cl.plant.v)) < 0.005


def test_a_faults_category_2_stop_ends_with_a_reset_holding_or_a_disable(tmp_path):
    """rowc with tracking faults configured as category 2: a tracking fault (the limit
    lowered so a move trips it) holds the pose powered past stop_duration; a reset before
    then is refused, after it the robot holds enabled and moves again; the same stop ended by
    a disable goes to ready on the brakes."""
    config = tmp_path / "ss2.toml"
    config.write_text(f'base = "{ROWC}"\n[safety.stop_category]\ntracking = 2\n')
    model = load_robot(config)
    model = dataclasses.replace(model, control=dataclasses.replace(
        model.control, max_position_error=0.0005))  # fmt: skip
    for end in ("reset", "disable"):
        with ClosedLoop(model) as cl:
            c = cl.controller
            moving(cl, mid_move=False)
            cl.run(1.0, until=lambda cl: cl.controller.data.state is State.STOPPING)
            assert c.data.state is State.STOPPING and c.data.fault_kind is FaultKind.TRACKING
            assert c.data.stop_category == 2
            c.submit(Command(CommandKind(end)))
            cl.run(0.1)
            assert c.data.state is State.STOPPING
            assert f"{end} refused: the controlled stop (category 2) is under way" in [
                e for _, e in c.data.events][-1]  # fmt: skip
            cl.run(model.control.stop_duration + 1.0)
            assert c.data.state is State.STOPPING and not np.any(cl.plant.brake)
            assert float(np.linalg.norm(cl.plant.v)) < 0.005
            c.submit(Command(CommandKind(end)))
            cl.run(3.0)
            if end == "reset":
                assert c.data.state is State.ENABLED and c.data.fault_kind is None
                assert c.data.stop_category == -1 and not np.any(cl.plant.brake)
            else:
                assert c.data.state is State.READY and bool(np.all(cl.plant.brake))


def test_check_config_and_monitor_say_the_safety_settings_and_state(tmp_path, capsys):
    from cdprctl.cli import main
    from cdprctl.commands.zenoh_tools import safety_line

    f = tmp_path / "ss2.toml"
    f.write_text(f'base = "{ROWC}"\n[safety.stop_category]\ntracking = 2\n')
    assert main(["check-config", str(f)]) == 0
    assert ("safety      brake test every 8 h at 1.3 x the worst-case load, at most 4 counts; "
            "stop categories: tracking 2") in capsys.readouterr().out  # fmt: skip
    line = safety_line({"chain": "open", "brakes": "closed", "stop_category": 0, "tripped": "",
                        "brake_test": {"required": False, "time": None}})  # fmt: skip
    assert line == ("safety   chain open, brakes closed, stop category 0; no brake test on "
                    "record (not required)")  # fmt: skip
    line = safety_line({"chain": "closed", "brakes": "released", "stop_category": None,
                        "tripped": "tracking", "brake_test": {"required": True, "passed": True,
                        "time": "T0", "next_due": "T1"}})  # fmt: skip
    assert line == ("safety   chain closed, brakes released, stop category — (tracking); brake "
                    "test passed T0, next due T1")  # fmt: skip
