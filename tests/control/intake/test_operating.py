"""Operating the robot in lock-step (docs/operating.md): paths from files (checked whole before
any motion, played, paused, resumed, aborted, stopped by a fault), jogs (stopped at the soft
limits, the deadman), against the simulated robot's truth."""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest

from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.motion.path_file import parse_path
from cdprctl.motion.path_plan import plan_path
from cdprctl.motion.trajectory import pose_coordinates
from cdprctl.robot_file import load_robot
from cdprctl.telemetry.zenoh.validate import CommandError, CommandValidator
from sim_backend.faults import FaultEvent, FaultInjector

ROOT = Path(__file__).resolve().parents[3]
SQUARE = (ROOT / "paths" / "rowc_square.ngc").read_text()


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def enabled(model):
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    cl.run(0.4)
    assert cl.controller.data.state.value == "enabled"
    return cl


def events(cl):
    return [e for _, e in cl.controller.data.events]


def on_polyline(p, corners):
    """Distance (m) of point p from the closed polyline through corners."""
    best = np.inf
    for a, b in itertools.pairwise(corners):
        ab = b - a
        s = np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0)
        best = min(best, float(np.linalg.norm(p - (a + s * ab))))
    return best


def test_gcode_square_with_dwell_is_traced(rowc):
    """rowc_square.ngc: the reference on the square's edges (exact stops), the dwell held, the
    simulated platform within the closed-loop table's point-to-point figures of it (max
    0.05-0.06 mm, docs/control.md), in the planned time."""
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("path", text=SQUARE, name="square")
        plan = c.desk.mailbox[-1][1].path[0]  # what submit planned for it
        seen = []
        cl.run(30.0, each=lambda cl: seen.append((cl.net.time, c.data.path_segment,
                                                   c.data.path_state, c.data.path_fraction,
                                                   c.trajectory.position[:3].copy(),
                                                   c.data.path_elapsed, c.data.path_time_left)),
               until=lambda cl: c.data.path_state == "done" and c.data.state.value == "enabled")
        assert c.data.path_state == "done" and c.data.state.value == "enabled", events(cl)[-5:]
        a = cl.arrays()
        moving = np.array([s == "moving" for s in a["state"]])
        t_move = a["t"][moving]
        assert t_move[-1] - t_move[0] == pytest.approx(plan.duration, abs=2 * cl.period)
        err = np.linalg.norm(a["p_true"] - a["p_des"], axis=1)[moving]
        assert err.max() < 0.1e-3, err.max()
        corners = np.array([[1.3, 0.35, 0.49], [1.7, 0.35, 0.49], [1.7, 0.35, 0.69],
                            [1.3, 0.35, 0.69], [1.3, 0.35, 0.49]])  # fmt: skip
        ref = [s[4] for s in seen if s[1] >= 2]  # after the G0 to the first corner
        assert max(on_polyline(p, corners) for p in ref[::5]) < 1e-6
        # the dwell: 0.5 s at the first corner, reported as such
        dwell = [s[0] for s in seen if s[2] == "dwell"]
        assert dwell[-1] - dwell[0] == pytest.approx(0.5, abs=2 * cl.period)
        fractions = [s[3] for s in seen if s[1] == 3]
        assert fractions[0] < 0.05 and fractions[-1] > 0.999 and np.all(np.diff(fractions) >= 0)
        # the time played and the time left add up to the plan's, the dwell counted; 0 left
        playing = [s for s in seen if s[2] in ("running", "dwell")]
        for s in playing[::25]:
            assert s[5] + s[6] == pytest.approx(plan.duration, abs=1e-9), s
        assert playing[0][5] < 2 * cl.period and playing[-1][6] < 2 * cl.period
        assert c.data.path_time_left == 0.0
        assert c.data.path_elapsed == pytest.approx(plan.duration, abs=2 * cl.period)


def test_infeasible_waypoint_rejected_before_any_motion(rowc):
    """A box that takes in the top corners where the cables cannot hold the platform: the
    path is refused whole, naming the line and the tension margin, and nothing moves."""
    ws = dataclasses.replace(rowc.workspace, position_max=np.array([2.5, 0.40, 1.3]))
    model = dataclasses.replace(rowc, workspace=ws)
    text = "x, y, z\n1.5, 0.35, 0.7\n0.55, 0.35, 1.25\n1.5, 0.35, 0.59\n"
    with enabled(model) as cl:
        c = cl.controller
        before = cl.plant.position.copy()
        cl.command("path", text=text, name="bad.csv")
        assert not c.desk.mailbox
        why = events(cl)[-1]
        assert why.startswith("path bad.csv rejected: line 3 (the end of segment 2): "
                              "waypoint [0.55, 0.35, 1.25")
        assert "tension margin" in why and "N required" in why
        cl.run(0.5)
        assert c.data.state.value == "enabled" and c.data.path_state == ""
        assert np.linalg.norm(cl.plant.position - before) < 1e-5


def test_a_segment_through_an_infeasible_region_is_rejected(rowc):
    """Both ends hold (the U-shaped workspace's two arms at z = 1.1 m), the straight line
    between them does not: the sampled check names segment and time."""
    ws = dataclasses.replace(rowc.workspace, position_min=np.array([0.3, 0.33, 0.3]),
                             position_max=np.array([2.7, 0.40, 1.3]))  # fmt: skip
    model = dataclasses.replace(rowc, workspace=ws)
    text = "x, y, z\n0.45, 0.38, 1.05\n2.55, 0.38, 1.05\n"
    start = np.concatenate([model.home.position, model.home.rpy])
    wps = parse_path(text, start)
    with pytest.raises(ValueError, match=r"line 3 \(segment 2\): at t = .* tension margin"):
        plan_path(model, wps, pose_coordinates(model, start[:3], model.home.rotation),
                  model.control.period)  # fmt: skip


def test_pause_resume_abort(rowc):
    text = (ROOT / "paths" / "rowc_wipe.csv").read_text()
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("path", text=text, name="wipe")
        cl.run(2.0)
        assert c.data.path_state in ("running", "dwell") and c.data.state.value == "moving"
        cl.command("pause")
        cl.run(1.0)
        assert c.data.path_state == "paused" and c.data.state.value == "enabled"
        held = c.trajectory.position.copy()
        cl.command("jog", velocity=np.array([0.1, 0, 0, 0, 0, 0]))  # refused while paused
        cl.run(0.5)
        assert np.array_equal(c.trajectory.position, held)
        assert "jog ignored: a path is running (pause or abort it first)" in events(cl)
        segment, played, left = c.data.path_segment, c.data.path_elapsed, c.data.path_time_left
        assert played > 1.5 and left > 0.0
        cl.command("resume")
        cl.run(0.5)
        assert c.data.path_state == "running" and c.data.path_segment == segment
        # the time played goes on from the pause's (the 1.5 s held not counted)
        assert played + 0.4 < c.data.path_elapsed < played + 0.5 + cl.period
        cl.run(30.0, until=lambda cl: c.data.path_state == "done")
        assert c.data.path_state == "done"
        end = np.array([1.5, 0.35, 0.59])
        cl.run(0.5)
        assert np.linalg.norm(c.trajectory.position[:3] - end) < 1e-9
        # abort: brakes and forgets
        cl.command("path", text=text, name="wipe")
        cl.run(1.0)
        cl.command("abort")
        cl.run(1.0)
        assert c.data.path_state == "aborted" and c.data.state.value == "enabled"
        assert np.all(np.abs(c.trajectory.velocity) < 1e-12)
        cl.command("resume")
        cl.run(0.1)
        assert "resume ignored: no paused path" in events(cl)


def test_a_disable_mid_move_decelerates_before_the_brakes_close(rowc):
    """The holding brakes are not for stopping a moving platform: a disable (the operator's,
    or the daemon's on SIGTERM) during a move decelerates along the trajectory first; the
    drives are disabled once it stands, the platform then at rest."""
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("move", pose=np.array([1.9, 0.35, 0.5, 0.0, 0.0, 0.0]))
        cl.run(1.0)
        assert c.data.state.value == "moving"
        assert np.linalg.norm(c.trajectory.velocity[:3]) > 0.05  # m/s
        cl.command("disable")
        seen: list[tuple[str, float, bool]] = []
        platform: list[float] = []  # m/s, the simulated platform's true speed

        def each(cl: ClosedLoop) -> None:
            v = float(np.linalg.norm(c.trajectory.velocity[:3]))
            seen.append((c.data.state.value, v, bool(np.all(cl.plant.brake))))
            platform.append(float(np.linalg.norm(cl.plant.v)))

        cl.run(3.0, each=each)
        states = [s for s, _, _ in seen]
        assert states[0] == "disabling" and states[-1] == "ready", events(cl)[-6:]
        k = states.index("ready")
        assert k * cl.period > 0.05  # it took the deceleration's time, not one cycle
        assert seen[k - 1][1] < 1e-9 and not seen[k - 1][2]  # at rest, then the brakes
        assert all(b for _, _, b in seen[k + 5:])
        # it braked where it was (not on to the target, 0.74 s further), and the platform,
        # not only its reference, stood when the brakes closed
        assert c.trajectory.position[0] < 1.9 - 0.05
        assert k * cl.period < 0.7
        assert platform[k - 1] < 0.01
        assert any("disable requested: decelerating, then the drives disabled" in e
                   for e in events(cl))  # fmt: skip


def test_a_fault_mid_path_stops_it_the_controlled_way(rowc):
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("path", text=SQUARE, name="square")
        cl.run(1.0)
        FaultInjector([FaultEvent(cl.net.time + 0.01, "drive_fault", cable=3, value=0x7500)]
                      ).attach(cl.net)  # fmt: skip
        cl.run(3.0)
        assert c.data.state.value == "fault"
        assert c.data.path_state == "stopped"
        assert any(e.startswith("path stopped at segment") for e in events(cl))


def test_jog_towards_the_bound_stops_at_it(rowc):
    """+x at 0.2 m/s, repeated every 50 ms: the reference brakes onto x = 2.5 m (the box) and
    never passes it; the platform follows within the tracking error."""
    with enabled(rowc) as cl:
        c = cl.controller
        for _ in range(130):
            cl.command("jog", velocity=np.array([0.2, 0, 0, 0, 0, 0]))
            cl.run(0.05)
        a = cl.arrays()
        bound = rowc.workspace.position_max[0]
        assert a["p_des"][:, 0].max() <= bound + 1e-9
        assert a["p_des"][-1, 0] > bound - 1e-3  # at it
        assert a["p_true"][:, 0].max() < bound + 0.1e-3
        assert c.data.state.value == "enabled"  # arrived, holding, jog still alive
        box = "outside the workspace box [0.5, 2.5] m"
        assert any(e.startswith("jog: stops at [2.5") and box in e for e in events(cl))


def test_jog_stops_at_the_tension_margin_not_only_the_box(rowc):
    """A box reaching up into the U's middle: jogging up (+z) from the centre stops where the
    tension margin falls to the soft limit, well inside the box."""
    ws = dataclasses.replace(rowc.workspace, position_max=np.array([2.5, 0.40, 1.3]))
    model = dataclasses.replace(rowc, workspace=ws)
    with enabled(model) as cl:
        c = cl.controller
        for _ in range(140):
            cl.command("jog", velocity=np.array([0, 0, 0.2, 0, 0, 0]))
            cl.run(0.05)
        z = c.trajectory.position[2]
        assert 0.7 < z < 1.2
        margin, ok = c.limits.check(c.trajectory.position[None])
        assert ok[0] and margin[0] == pytest.approx(model.soft_margin, abs=0.5)
        assert any("tension margin" in e for e in events(cl))


def test_deadman_stops_a_silent_jog(rowc):
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("jog", velocity=np.array([-0.2, 0, 0, 0, 0, 0]), frame="platform")
        t0 = cl.net.time
        v = []
        cl.run(1.0, each=lambda cl: v.append((cl.net.time - t0, c.trajectory.velocity[0])))
        v = np.array(v)
        assert v[:, 1].min() < -0.04  # it moved (-x)
        deadman = rowc.control.jog_deadman
        stopped = v[np.abs(v[:, 1]) < 1e-12]
        assert stopped[0, 0] < deadman + 0.5  # braking from 0.2 m/s: 0.2 s at 1 m/s², jerk
        assert stopped[0, 0] > deadman
        assert c.data.state.value == "enabled"
        assert any("deadman" in e for e in events(cl))


def test_jog_rejects_bad_input(rowc):
    with enabled(rowc) as cl:
        c = cl.controller
        before = c.trajectory.position.copy()
        for v in ([1.0, 0, 0, 0, 0, 0], [np.nan, 0, 0, 0, 0, 0], [0.1, 0, 0]):
            cl.command("jog", velocity=np.array(v))
            assert events(cl)[-1].startswith("jog ignored")
        cl.command("jog", velocity=np.array([0.1, 0, 0, 0, 0, 0]), frame="tool")
        assert events(cl)[-1].startswith("jog ignored")
        cl.run(0.3)
        assert np.array_equal(c.trajectory.position, before)


def test_a_move_whose_line_leaves_the_limits_is_refused(rowc):
    """Both ends of the U's top held, the straight line between them not: the move is refused
    where it would leave, and nothing moves."""
    ws = dataclasses.replace(rowc.workspace, position_min=np.array([0.3, 0.33, 0.3]),
                             position_max=np.array([2.7, 0.40, 1.3]))  # fmt: skip
    model = dataclasses.replace(rowc, workspace=ws)
    with enabled(model) as cl:
        c = cl.controller
        cl.command("move", pose=np.array([0.45, 0.38, 1.05, 0, 0, 0]))
        cl.run(8.0, until=lambda cl: c.data.state.value == "enabled" and c.trajectory.finished
               and c.data.motion == "")  # fmt: skip
        assert np.linalg.norm(c.trajectory.position[:3] - [0.45, 0.38, 1.05]) < 1e-9
        cl.command("move", pose=np.array([2.55, 0.38, 1.05, 0, 0, 0]))
        assert not c.desk.mailbox
        why = events(cl)[-1]
        assert why.startswith("move to [2.55, 0.38, 1.05, 0.0, 0.0, 0.0] ignored: the line to "
                              "the target leaves the soft limits after [")  # fmt: skip
        assert "] m: the tension margin is" in why  # a translation: no rotation named
        x = float(why.split("after [", 1)[1].split(",", 1)[0])
        assert 0.45 < x < 2.55  # between the arms
        # one rule: the gateway, given the reference the loop publishes, refuses it in the
        # same words before it replies
        gateway = CommandValidator(model, commands_enabled=True)
        with pytest.raises(CommandError) as exc:
            gateway.check("move", {"position": [2.55, 0.38, 1.05]}, "enabled",
                          {"reference": c.data.reference.copy()})  # fmt: skip
        assert str(exc.value).endswith(why.split(" ignored: ", 1)[1])


def test_a_rotation_alone_beyond_max_angle_is_refused_naming_the_rotation(rowc):
    """A move to the same position turned 0.25 rad about z (rowc's max_angle 0.2 rad): the
    desk's refusal names the rotation in degrees and rad, and the limit, and nothing moves."""
    with enabled(rowc) as cl:
        c = cl.controller
        before = c.trajectory.position.copy()
        cl.command("move", pose=np.r_[rowc.home.position, 0.0, 0.0, 0.25])
        assert not c.desk.mailbox
        why = events(cl)[-1]
        assert why.startswith("move to [1.5, 0.35, 0.59, 0.0, 0.0, 0.25] ignored: the rotation "
                              "to the target, 14.32° (0.2500 rad) about [0.0, 0.0, 1.0] (base "
                              "frame) at [1.5, 0.35, 0.59] m, leaves the soft limits after "
                              "11.4")  # fmt: skip
        assert why.endswith("exceeds workspace.max_angle = 0.2 rad (11.46°)")
        cl.run(0.2)
        assert np.array_equal(c.trajectory.position, before)
