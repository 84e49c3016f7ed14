"""The cables' clearance as a soft limit and a supervised check (issue 67): a move, a jog and
a path that would bring a cable within ``[interference] clearance`` of an obstacle are
refused or stopped short, also where the closest approach falls between two samples, and the
supervisor stops under the clearance (``ClearanceWatch``). The reference is brute force: the
motion sampled every 0.05 mm, each pose measured on its own (the per-pose distances are
checked against scipy and dense sampling in tests/geometry/test_interference.py). The robot is
CAROCA (112 mm clear at home) with a planted obstacle, a small box, placed next to one cable's
sweep."""

from __future__ import annotations

import dataclasses
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from cdprctl.control.supervision.clearance_watch import ClearanceWatch
from cdprctl.core.rotation import exp_so3
from cdprctl.geometry.interference import Interference, check_pose
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.interference import Box, InterferenceConfig, Plane
from cdprctl.motion.clearance import REFINE_STEP
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_plan import PathRejectedError, plan_text
from cdprctl.motion.trajectory import pose_coordinates
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
CABLE = 2  # 0-based: the cable whose sweep the lamp stands in
AT = 0.31  # m of +x travel where it passes the lamp
HALF = 0.002  # m: the lamp's half side


@pytest.fixture(scope="module")
def caroca():
    return load_robot(ROOT / "config" / "caroca.toml")


def _home(model):
    return pose_coordinates(model, np.asarray(model.home.position), model.home.rotation)


def _with_lamp(model, offset: float):
    """CAROCA with a lamp, a cube of side 4 mm, ``offset`` m beside cable ``CABLE`` 0.2 m from
    its attachment as it stands after ``AT`` m of +x travel, across both the cable and the
    motion."""
    kin = KinematicsData(model)
    x = _home(model) + np.array([AT, 0, 0, 0, 0, 0])
    inverse_kinematics(model, kin, x[:3], model.home.rotation)
    b = x[:3] + kin.rbT[:, CABLE]
    e = kin.exitT[:, CABLE]
    n = np.cross(e - b, [1.0, 0.0, 0.0])
    centre = b + 0.2 * (e - b) / np.linalg.norm(e - b) + offset * n / np.linalg.norm(n)
    lamp = Box("the lamp", centre, np.full(3, HALF), np.eye(3))
    cfg = model.interference
    return dataclasses.replace(
        model, interference=InterferenceConfig(cfg.clearance, cfg.attachment_exclusion, (), (lamp,))
    )


def _dense(model, start, direction, horizon, step=5e-5):
    """(s, least distance m) every ``step`` of the straight motion: the brute force."""
    s = np.arange(0.0, horizon + step, step)
    g, kin = Interference(model), KinematicsData(model)
    out = np.empty(len(s))
    for k, sk in enumerate(s):
        x = start + sk * direction
        inverse_kinematics(model, kin, x[:3], exp_so3(x[3:]) @ model.home.rotation)
        g.update(kin)
        out[k] = g.minimum
    return s, out


X = np.array([1.0, 0, 0, 0, 0, 0])


@pytest.mark.parametrize("step", [0.005, 0.02])  # a jog's and a move's sampling
def test_a_straight_motion_stops_short_where_brute_force_finds_the_clearance(caroca, step):
    model = _with_lamp(caroca, 0.0)  # straight in the cable's way
    lim = SoftLimits(model)
    start = _home(model)
    end, why = lim.ray_end(start, X, 0.5, step=step)
    s, d = _dense(model, start, X, 0.5)
    first = s[np.argmax(d < lim.clearance.limit)]  # where it first comes too close
    assert d[0] > 0.05 and d.min() < 0.0  # through the lamp: the cable in it, how deep
    travelled = end[0] - start[0]
    assert first - step / 64 - 1e-4 <= travelled <= first + 1e-4
    assert f"cable {CABLE + 1} and the lamp" in why and "mm apart, under the clearance 5.00" in why
    # the distance said is the one just past the end (within the bisection's 1/64 step and
    # the bound's doubling of it), not the one at the sample first found too close
    said = float(why.split("the lamp: ")[1].split(" mm")[0]) / 1e3
    assert lim.clearance.limit - 2.0 * step / 64 - 1e-4 <= said <= lim.clearance.limit  # 2 decimals


@pytest.mark.parametrize("offset, refused", [(0.0055, True), (0.0080, False)])
def test_a_pass_between_two_samples_is_found_by_the_bound(caroca, offset, refused):
    """The cable passes the lamp at ~``offset − HALF`` between two samples 6 cm apart, each
    of which is centimetres clear: the Lipschitz bound sends the check between them."""
    model = _with_lamp(caroca, offset)
    lim = SoftLimits(model)
    start = _home(model)
    coords = start + np.array([0.0, AT - 0.03, AT + 0.03])[:, None] * X  # samples either side of AT
    d_samples, _ = lim.clearance.at(coords)
    assert np.all(d_samples > 2 * lim.clearance.limit)  # the samples alone see nothing
    _, d = _dense(model, coords[1], X, 0.06)
    assert bool(d.min() < lim.clearance.limit) == refused
    margin, ok, _ = lim.along(coords)
    assert bool(not ok.all()) == refused
    if refused:
        assert lim.nearest[2] == pytest.approx(d.min(), abs=REFINE_STEP)
        why = lim.why(coords[2], float(margin[2]), None, lim.nearest_at[2], lim.near)
        assert why.startswith("on the way to it, at [") and "the lamp" in why


def test_a_path_into_the_lamp_is_refused_naming_segment_pair_and_distance(caroca):
    model = _with_lamp(caroca, 0.0)
    lim = SoftLimits(model)
    start = _home(model)
    z = model.home.position[2]
    text = f"x, y, z\n0.1, 0, {z}\n0.5, 0, {z}\n"
    with pytest.raises(PathRejectedError, match=rf"line 3 \(segment 2\): at t = .* s, position "
                       rf".*: cable {CABLE + 1} and the lamp: [0-9.]+ mm apart, under the "
                       r"clearance 5\.00 mm"):  # fmt: skip
        plan_text(model, text, start, model.control.period, lim)
    plan = plan_text(model, f"x, y, z\n0.1, 0, {z}\n0.2, 0, {z}\n", start, model.control.period,
                     lim)  # fmt: skip
    assert plan.samples > 2


@pytest.mark.parametrize("step", [0.005, 0.02])  # a jog's 2 cm steps: between them too
def test_a_motion_from_under_the_clearance_may_leave_it_but_get_no_closer(caroca, step):
    """From 3 mm of the lamp: back out freely; on, stopped at once (the way between two
    samples checked against the start's floor too: a review found a 2 cm step went straight
    through the lamp, the samples either side being clear of the start's 3 mm)."""
    model = _with_lamp(caroca, 0.0)
    lim = SoftLimits(model)
    s, d = _dense(model, _home(model), X, 0.35, step=1e-4)
    inside = _home(model) + s[np.argmax(d < 0.003)] * X  # 3 mm from the lamp
    back, why = lim.ray_end(inside, -X, 0.2, step=step)
    assert why == "" and back[0] == pytest.approx(inside[0] - 0.2)
    on, why = lim.ray_end(inside, X, 0.2, step=step)
    assert on[0] - inside[0] < 0.005 and "the lamp" in why
    assert re.search(r"closer than the motion started at \(2\.9\d mm apart\), under the "
                     r"clearance 5\.00 mm \(\[interference\] clearance\)$", why), why


def _on_a_table(rowc):
    """rowc with its body (half height 0.1 m) 2 mm into a table at home, and a crate 0.2 m
    from the body's +x face."""
    home = np.asarray(rowc.home.position)
    table = Plane("the table", home - np.array([0.0, 0.0, 0.1 - 0.002]), np.array([0.0, 0.0, 1.0]))
    crate = Box("the crate", home + np.array([0.1 + 0.2 + 0.05, 0, 0]), np.full(3, 0.05),
                np.eye(3))  # fmt: skip
    cfg = rowc.interference
    return dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body, (table, crate)))  # fmt: skip


def test_a_platform_resting_on_the_floor_keeps_every_other_check(rowc):
    """rowc's body resting 2 mm into a table (a plane: a signed distance, −2 mm) beside a
    crate: a jog along the table stops at the crate as it does without the table (each
    check its own floor: the table's contact does not switch the others off), a jog into
    the table stops at once, a jog up off it goes."""
    home = np.asarray(rowc.home.position)
    model = _on_a_table(rowc)
    lim = SoftLimits(model)
    start = _home(model)
    g = Interference(model)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, home, model.home.rotation)
    g.update(kin)
    assert g.minimum == pytest.approx(-0.002, abs=1e-9) and "the table" in g.describe()
    end, why = lim.ray_end(start, X, 0.5, step=0.02)
    assert 0.195 - 0.02 / 64 - 1e-4 <= end[0] - start[0] <= 0.195 + 1e-4
    assert "the crate" in why
    down, why = lim.ray_end(start, -np.eye(6)[2], 0.1, step=0.02)
    assert down[2] - start[2] > -0.001 and "the table" in why
    assert "closer than the motion started at (overlapping by 2.00 mm)" in why
    up, why = lim.ray_end(start, np.eye(6)[2], 0.05, step=0.02)
    assert why == "" and up[2] == pytest.approx(start[2] + 0.05)


def test_the_supervisor_rides_through_a_shallow_dip_and_stops_on_a_deep_or_lasting_one(caroca):
    model = _with_lamp(caroca, 0.0)
    g, kin = Interference(model), KinematicsData(model)
    s, d = _dense(model, _home(model), X, 0.35, step=1e-5)
    limit = g.clearance

    def at(distance):  # the pose where the cable is ``distance`` from the lamp
        x = _home(model) + s[np.argmax(d < distance)] * X
        inverse_kinematics(model, kin, x[:3], model.home.rotation)
        g.update(kin)

    watch = ClearanceWatch(g)
    at(0.02)
    assert watch.check(0.0) is None and watch.limit == limit
    at(limit - 0.0003)  # shallow: ridden through for HOLD
    assert watch.check(0.001) is None
    assert watch.check(0.001 + 0.5 * watch.HOLD) is None
    why = watch.check(0.001 + watch.HOLD)
    assert why is not None and "for 10 ms" in why and f"cable {CABLE + 1} and the lamp" in why
    watch.held(0.1, False)  # the state left the supervised ones
    at(0.02)
    assert watch.check(0.2) is None
    at(limit - 0.0006)  # deep: at once
    why = watch.check(0.201)
    assert why is not None and "by more than 0.5 mm" in why and "4.4" in why
    watch.held(0.3, False)
    at(0.003)  # enabled under the clearance: the limit is where it started, less NOISE
    assert watch.check(0.4) is None and watch.limit == pytest.approx(0.003 - watch.NOISE, abs=2e-5)
    at(0.0028)
    assert watch.check(0.41) is None and watch.check(0.5) is None


def test_a_rotation_alone_is_refused_naming_the_rotation_and_the_limit(caroca, rowc):
    """CAROCA turned about y at its home position: its cables 1 and 8 come under the clearance
    before 0.6 rad (3.2 mm there). The refusal names the rotation asked (degrees and rad, its
    axis) and how far it may turn, not the position it stays at; the brute force
    (tools/clearance_check.py, numpy, 0.1 mm) finds the cables clear at the angle allowed and
    under the clearance 1/64 of the line's step beyond it. Beyond max_angle (rowc turned
    0.25 rad about z, its limit 0.2 rad) the refusal names the limit in both units too."""
    sys.path.insert(0, str(ROOT / "tools"))
    import clearance_check as brute

    lim = SoftLimits(caroca)
    start = _home(caroca)
    why = lim.line_refusal(start, start + np.array([0, 0, 0, 0, 0.6, 0]))
    m = re.fullmatch(r"the rotation to the target, 34\.38° \(0\.6000 rad\) about \[0\.0, 1\.0, "
                     r"0\.0\] \(base frame\) at \[0\.0, 0\.0, 1\.0\] m, leaves the soft limits "
                     r"after ([0-9.]+)° \(([0-9.]+) rad\): cables (1 and 8|4 and 5): [0-9.]+ mm "
                     r"apart, under the clearance 5\.00 mm \(\[interference\] clearance\)", why)
    assert m, why
    allowed = float(m.group(2))
    assert float(m.group(1)) == pytest.approx(np.degrees(allowed), abs=0.01)
    check = brute.Clearance(caroca)
    p = caroca.home.position

    def least(angle: float) -> float:
        return check.at(p, brute.rotation(np.array([0.0, angle, 0.0])))["cables"][0]

    assert least(allowed - 1e-4) >= caroca.interference.clearance - 6e-5
    assert least(allowed + 0.02 / 64 + 1e-4) < caroca.interference.clearance
    assert not lim.line_refusal(start, start + np.array([0, 0, 0, 0, allowed - 1e-3, 0]))

    rl = SoftLimits(rowc)
    start = _home(rowc)
    why = rl.line_refusal(start, start + np.array([0, 0, 0, 0, 0, 0.25]))
    assert why.startswith("the rotation to the target, 14.32° (0.2500 rad) about [0.0, 0.0, "
                          "1.0] (base frame) at [1.5, 0.35, 0.59] m, leaves the soft limits "
                          "after 11.4")  # fmt: skip
    assert why.endswith("exceeds workspace.max_angle = 0.2 rad (11.46°)")
    # a move that also translates says both: where, and how much of its rotation
    why = rl.line_refusal(start, start + np.array([0.1, 0, 0, 0, 0, 0.25]))
    assert re.match(r"the line to the target leaves the soft limits after \[1\.5\d+, 0\.35, "
                    r"0\.59\] m and 11\.4\d° \(0\.19\d+ rad\) of its 14\.32° \(0\.2500 rad\) "
                    r"rotation: the tilt ", why), why


def test_the_platform_is_kept_off_a_fixture_by_jogs_and_paths(rowc):
    """rowc's body (0.2 m x 0.1 m x 0.2 m) 0.2 m from a crate in +x: a jog toward it stops
    where the body is ``clearance`` from it (face to face: 0.195 m, the sampling's step/64),
    a path ending with the body in it is refused naming the body and the crate, one stopping
    short of it is planned."""
    home = np.asarray(rowc.home.position)
    crate = Box("the crate", home + np.array([0.1 + 0.2 + 0.05, 0, 0]), np.full(3, 0.05), np.eye(3))
    cfg = rowc.interference
    model = dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body, (crate,)))  # fmt: skip
    lim = SoftLimits(model)
    start = _home(model)
    end, why = lim.ray_end(start, X, 0.5, step=0.02)
    assert 0.195 - 0.02 / 64 - 1e-4 <= end[0] - start[0] <= 0.195 + 1e-4
    assert why.startswith("the platform's body and the crate: ")
    x, y, z = home
    with pytest.raises(PathRejectedError, match=r"line 3 \(the end of segment 2\): .*the "
                       r"platform's body and the crate: overlapping by 100\.00 mm, under the "
                       r"clearance 5\.00 mm"):  # fmt: skip
        plan_text(model, f"x, y, z\n{x + 0.1}, {y}, {z}\n{x + 0.3}, {y}, {z}\n", start,
                  model.control.period, lim)  # fmt: skip
    plan = plan_text(model, f"x, y, z\n{x + 0.1}, {y}, {z}\n{x + 0.15}, {y}, {z}\n", start,
                     model.control.period, lim)  # fmt: skip
    assert plan.samples > 2


def test_the_supervisor_keeps_every_other_check_of_a_platform_resting_on_the_floor(rowc):
    """The supervisor's floor is per check as the soft limits' is: rowc's body 2 mm into a
    table at the first supervised cycle; the table's check may stay there (less NOISE), the
    crate's keeps the clearance — the platform pushed within 4 mm of the crate stops, as
    one pressed 0.6 mm deeper into the table does."""
    home = np.asarray(rowc.home.position)
    model = _on_a_table(rowc)
    g, kin = Interference(model), KinematicsData(model)

    def at(dx, dz=0.0):
        inverse_kinematics(model, kin, home + np.array([dx, 0.0, dz]), model.home.rotation)
        g.update(kin)

    watch = ClearanceWatch(g)
    at(0.0)
    assert watch.check(0.0) is None and watch.limit == pytest.approx(-0.002 - watch.NOISE)
    at(0.1)  # along the table, 0.1 m from the crate
    assert watch.check(0.1) is None
    at(0.2 - 0.004)  # 4 mm from the crate: by 1 mm under the clearance, at once
    why = watch.check(0.2)
    assert why is not None and "the platform's body and the crate: 4.00 mm apart" in why
    assert "under the limit 5.00 mm" in why and "by more than 0.5 mm" in why
    at(0.0, -0.0006)  # back, and 0.6 mm deeper into the table: past its NOISE
    why = watch.check(0.3)
    assert why is not None and "the platform's body and the table: overlapping by 2.60 mm" in why
    assert "deeper than its limit (overlapping by 2.50 mm)" in why


def test_a_path_from_under_the_clearance_reports_the_distance_it_starts_at(rowc):
    """rowc 3 mm from a crate, a path away from it: planned, its least clearance the 3 mm
    met at the start with that pair (a newcomer's trial printed the floor, 5.00 mm); a path
    that leaves the crate and comes by nothing closer says the start too."""
    home = np.asarray(rowc.home.position)
    crate = Box("the crate", home + np.array([0.1 + 0.003 + 0.05, 0, 0]), np.full(3, 0.05),
                np.eye(3))  # fmt: skip
    cfg = rowc.interference
    model = dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body, (crate,)))  # fmt: skip
    lim = SoftLimits(model)
    x, y, z = home
    plan = plan_text(model, f"x, y, z\n{x - 0.1}, {y}, {z}\n", _home(model),
                     model.control.period, lim)  # fmt: skip
    assert plan.min_clearance == pytest.approx(0.003, abs=1e-6)
    assert plan.clearance_text() == (
        "least clearance 3.00 mm: the platform's body and the crate, under the clearance since "
        "the start (3.00 mm apart there: no closer allowed) (line 2, t = 0.00 s); limit 5.00 mm "
        "([interference] clearance)")  # whole: nothing more said of the start


def test_a_refusal_from_under_the_clearance_prints_the_two_distances_apart():
    """seed000 stands 3.61 mm from its cube at home (its paper's geometry); its demo's first
    move, on the way down and along x, came closer by a few µm and was refused with "3.612 mm
    apart, closer than the 3.61 mm the motion started at" (the floor at two decimals, the
    distance at three: as if 3.612 were closer than 3.61). Each is printed to the decimals that
    tell them apart, the distance the smaller."""
    model = load_robot(ROOT / "config" / "seed000.toml")
    lim = SoftLimits(model)
    for direction in ([1.0, 0, -0.33, 0, 0, 0], [0.0, 1, 0, 0, 0, 0], [-1.0, 0, 0, 0, 0, 0]):
        _, why = lim.ray_end(_home(model), np.array(direction), 0.05, step=0.0005)
        said = re.search(r"cube: ([\d.]+) mm apart, closer than the motion started at "
                         r"\(([\d.]+) mm apart\)", why)  # fmt: skip
        if said is None:
            continue  # this direction leaves the cube (or its end is another limit)
        d, floor = said.groups()
        assert len(d) == len(floor) and float(d) < float(floor), why
        break
    else:
        raise AssertionError("no direction from home came closer to the cube")


def _in_a_crate(rowc):
    """rowc with a crate 20 mm into its body's +x face at home."""
    home = np.asarray(rowc.home.position)
    crate = Box("the crate", home + np.array([0.1 - 0.02 + 0.05, 0, 0]), np.full(3, 0.05),
                np.eye(3))  # fmt: skip
    cfg = rowc.interference
    return dataclasses.replace(rowc, interference=InterferenceConfig(
        cfg.clearance, cfg.attachment_exclusion, cfg.body, (crate,)))  # fmt: skip


def test_a_platform_already_in_a_fixture_may_leave_it_but_never_go_deeper(rowc):
    """rowc's body 20 mm into a crate at home (a newcomer's trial: a path took it from 20 to
    70 mm in and passed, every distance in a box being 0): the depth is signed now, so a path
    and a jog further in are refused at once, and the way out is free."""
    home = np.asarray(rowc.home.position)
    model = _in_a_crate(rowc)
    lim = SoftLimits(model)
    start = _home(model)
    assert check_pose(model, home, model.home.rotation).describe() == (
        "the platform's body and the crate: overlapping by 20.00 mm")
    x, y, z = home
    with pytest.raises(PathRejectedError, match=r"overlapping by 70\.00 mm, closer than the "
                       r"motion started at \(overlapping by 20\.00 mm\)"):  # fmt: skip
        plan_text(model, f"x, y, z\n{x + 0.05}, {y}, {z}\n", start, model.control.period, lim)
    plan = plan_text(model, f"x, y, z\n{x - 0.05}, {y}, {z}\n", start, model.control.period, lim)
    assert plan.min_clearance == pytest.approx(-0.02, abs=1e-6)  # out of it: the start's depth
    deeper, why = lim.ray_end(start, X, 0.05, step=0.005)
    assert deeper[0] - start[0] < 1e-4 and "the crate: overlapping by" in why
    out, why = lim.ray_end(start, -X, 0.05, step=0.005)
    assert why == "" and out[0] == pytest.approx(start[0] - 0.05)


def test_a_robot_under_the_clearance_at_home_may_always_come_back_home():
    """seed000 stands 3.61 mm from its cube at home: its demo went out to x = 6.8 m (the
    cube farther) and its move back home was refused, "closer than the motion started at" —
    the robot could never return. A motion that ends at home may come as close as home is:
    a path and a move home pass; a jog (no end) and a motion past home keep their start's
    floor, said so."""
    model = load_robot(ROOT / "config" / "seed000.toml")
    lim = SoftLimits(model)
    home = _home(model)
    out = home + np.array([-0.2, 0, 0, 0, 0, 0])
    d_home = lim.clearance.closest_at(home)[0]
    assert 0.0036 < d_home < lim.clearance.closest_at(out)[0] < lim.clearance.limit
    x, y, z = model.home.position
    rpy = ", ".join(f"{a:g}" for a in model.home.rpy)
    back = plan_text(model, f"x, y, z, roll, pitch, yaw\n{x}, {y}, {z}, {rpy}\n", out,
                     model.control.period, lim)  # fmt: skip
    assert back.samples > 2 and "at the home pose it goes to" in back.clearance_text()
    assert lim.line_refusal(out, home) == ""  # the move home
    past, why = lim.ray_end(out, home - out, 1.5, step=0.005)  # a jog on, past home
    assert past[0] < home[0]  # stopped before home: its start's floor
    assert re.search(r"cube: 3\.\d+ mm apart, closer than the motion started at \(3\.\d+ mm "
                     r"apart\)", why), why  # fmt: skip


def test_a_clear_robot_goes_into_a_fixture_only_as_far_as_home_is_and_only_home(rowc):
    """rowc's home 20 mm into a crate (a newcomer's cell): from a pose clear of it, a path
    into the crate elsewhere is refused (it passed while any pose as deep as home was
    allowed), and the path home is not."""
    home = np.asarray(rowc.home.position)
    model = _in_a_crate(rowc)
    lim = SoftLimits(model)
    clear = _home(model) + np.array([-0.1, 0, 0, 0, 0, 0])
    x, y, z = home
    with pytest.raises(PathRejectedError, match=r"the platform's body and the crate: "
                       r"overlapping by 10\.00 mm, under the clearance 5\.00 mm"):  # fmt: skip
        plan_text(model, f"x, y, z\n{x - 0.01}, {y}, {z}\n", clear, model.control.period, lim)
    plan = plan_text(model, f"x, y, z\n{x}, {y}, {z}\n", clear, model.control.period, lim)
    assert plan.min_clearance == pytest.approx(-0.02, abs=1e-6)
    # a path that ends at home but goes into the crate elsewhere first (a review: home's
    # floor held along the whole path): refused on its way
    with pytest.raises(PathRejectedError, match=r"line 2 \(segment 1\): .*the platform's body "
                       r"and the crate: \d\.\d\d mm apart, under the clearance 5\.00 mm"):
        plan_text(model, f"x, y, z\n{x - 0.01}, {y + 0.03}, {z}\n{x}, {y}, {z}\n", clear,
                  model.control.period, lim)  # fmt: skip
    assert lim.line_refusal(clear, _home(model)) == ""  # the move home, straight


def test_the_supervisor_lets_a_robot_enabled_away_from_home_go_back_home(rowc):
    """rowc's home 20 mm into a crate, the robot enabled 0.1 m clear of it and moved home:
    the watch's floor is the lower of the first cycle's and home's, less its NOISE — no fault
    on the way home (a review: it took the first cycle's alone and faulted at the crate's
    face, short of home), and a fault 2 mm deeper than home (past its NOISE)."""
    home = np.asarray(rowc.home.position)
    model = _in_a_crate(rowc)
    lim = SoftLimits(model)

    def walk(watch, steps):
        g, kin = watch.interference, KinematicsData(model)
        for k, dx in enumerate(steps):
            inverse_kinematics(model, kin, home + np.array([dx, 0.0, 0.0]), model.home.rotation)
            g.update(kin)
            if (why := watch.check(0.004 * k)) is not None:
                return dx, why
        return None, ""

    home_ok = ClearanceWatch(Interference(model), lim.clearance.home_distance)
    assert walk(home_ok, np.linspace(-0.1, 0.0, 101)) == (None, "")
    deeper, why = walk(ClearanceWatch(Interference(model), lim.clearance.home_distance),
                       np.r_[np.linspace(-0.1, 0.0, 101), 0.002])  # fmt: skip
    assert deeper == 0.002 and "overlapping by 22.00 mm" in why
    blind = ClearanceWatch(Interference(model))  # without home's distances: the old rule
    stopped, _ = walk(blind, np.linspace(-0.1, 0.0, 101))
    assert stopped is not None and stopped < -0.02  # at the crate's face, short of home


def test_a_path_home_in_two_steps_on_one_line_goes_home():
    """seed000 from x − 0.2 m home through x − 0.1 m, all on one line: a straight motion home,
    so every waypoint may come as close as home is — the last, home itself, too (checked
    against the path's end, not its first waypoint)."""
    model = load_robot(ROOT / "config" / "seed000.toml")
    lim = SoftLimits(model)
    out = _home(model) + np.array([-0.2, 0, 0, 0, 0, 0])
    x, y, z = model.home.position
    rpy = ", ".join(f"{a:g}" for a in model.home.rpy)
    plan = plan_text(model, f"x, y, z, roll, pitch, yaw\n{x - 0.1}, {y}, {z}, {rpy}\n"
                     f"{x}, {y}, {z}, {rpy}\n", out, model.control.period, lim)  # fmt: skip
    assert plan.samples > 2 and "at the home pose it goes to" in plan.clearance_text()

