"""The command validator's rules at the unit level (``cdprctl/telemetry/zenoh/validate.py``), no
network: each payload limit at its kind, a boolean or a string where a number goes, an unknown
field whatever its name, the commands without fields, a path's name and its rejection, a move's
scaled limits and its messages, a zero direction, a gripper named or not. Mutation testing
found these held by no test (tools/mutation_results.json); every name here says "refused",
"rejected" or "becomes", which the module's mutation selection picks."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.robot_file import load_robot
from cdprctl.telemetry.zenoh.validate import (
    MAX_PATH_PAYLOAD,
    MAX_PAYLOAD,
    CommandError,
    CommandValidator,
)


@pytest.fixture(scope="module")
def v(rowc):
    return CommandValidator(rowc, commands_enabled=True)


def test_a_payload_beyond_its_kinds_limit_is_refused(v):
    """4096 bytes for every command, 1 MiB for a path (its file travels in it): a path of
    5000 bytes is taken, the same bytes as a move or a set_tda are refused, a path beyond
    1 MiB too."""
    big = json.dumps({"text": "x" * 5000}).encode()
    assert MAX_PAYLOAD == 4096 and MAX_PATH_PAYLOAD == 1048576
    assert v.parse(big, "path") == {"text": "x" * 5000}
    for kind in ("move", "set_tda", "abort"):
        with pytest.raises(CommandError, match=f"payload of {len(big)} bytes exceeds 4096 bytes"):
            v.parse(big, kind)
    huge = json.dumps({"text": "x" * MAX_PATH_PAYLOAD}).encode()
    with pytest.raises(CommandError, match=f"exceeds {MAX_PATH_PAYLOAD} bytes"):
        v.parse(huge, "path")


@pytest.mark.parametrize("value", [True, "0.5", None, [0.5]])
def test_a_number_field_holding_no_number_is_refused(v, value):
    """max_acceleration = true would be 1.0 m/s² and within rowc's limit: refused as what it
    is, like a string, null or a list."""
    d = {"position": [1.5, 0.35, 0.59], "max_acceleration": value}
    with pytest.raises(CommandError) as exc:
        v.check("move", d, "enabled")
    assert str(exc.value) == (
        f"max_acceleration = {json.dumps(value)} must be a number (m/s²)"
    )


def test_a_vector_of_the_wrong_length_is_refused_showing_its_first_80_characters(v):
    value = list(range(100))
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": value}, "enabled")
    shown = json.dumps(value)[:80]
    assert str(exc.value) == f"position = {shown} must be a list of 3 numbers (m)"


@pytest.mark.parametrize("key", ["frame", "accel", "zzz", "Position"])
def test_an_unknown_field_is_refused_whatever_its_name(v, key):
    """Before or after "id" in the alphabet: "id" alone is allowed beside a kind's fields."""
    with pytest.raises(CommandError, match=f"^field '{key}' is unknown"):
        v.check("move", {"position": [1.5, 0.35, 0.59], key: 1}, "enabled")
    assert v.check("move", {"position": [1.5, 0.35, 0.59], "id": 7}, "enabled")[0] == "move"


@pytest.mark.parametrize(
    ("kind", "state"),
    [("enable", "ready"), ("abort", "moving"), ("disable", "enabled"), ("pause", "moving")],
)  # fmt: skip
def test_a_command_without_fields_becomes_itself(v, kind, state):
    assert v.check(kind, {}, state) == (kind, {})


def test_a_stop_becomes_its_category_2_by_default(v):
    """IEC 60204-1's stop categories: none given is 2 (decelerate and hold, as `stop` was);
    0 and 1 are taken, in every state where the controller acts on a stop."""
    assert v.check("stop", {}, "moving") == ("stop", {"category": 2})
    for category in (0, 1, 2):
        for state in ("enabling", "enabled", "moving", "disabling"):
            assert v.check("stop", {"category": category}, state) == ("stop",
                                                                       {"category": category})


@pytest.mark.parametrize("bad", [3, -1, 1.5, "1", True, None, [1]])
def test_a_stop_category_other_than_0_1_2_is_refused_naming_each(v, bad):
    with pytest.raises(CommandError) as exc:
        v.check("stop", {"category": bad}, "moving")
    text = str(exc.value)
    assert text.startswith(f"stop: category = {json.dumps(bad)} must be 0 (the drives off")
    assert "1 (decelerate, then off) or 2 (decelerate and hold)" in text


def test_a_path_name_of_200_characters_is_taken_and_a_longer_one_refused(v):
    text = "x, y, z\n1.6, 0.35, 0.59\n"
    assert v.check("path", {"text": text, "name": "n" * 200}, "enabled")[1]["name"] == "n" * 200
    assert v.check("path", {"text": text, "name": "short"}, "enabled")[1]["name"] == "short"
    for name in ("n" * 201, 5):
        with pytest.raises(CommandError, match="name must be a string of at most 200 characters"):
            v.check("path", {"text": text, "name": name}, "enabled")


def test_a_path_the_plan_rejects_is_refused_as_a_command(v, rowc):
    """Planned from where the robot rests (the snapshot's reference): a waypoint outside the
    workspace is a CommandError naming the path, never the planner's own exception."""
    snap = {"reference": np.r_[rowc.home.position, rowc.home.rpy]}
    ok = v.check("path", {"text": "x, y, z\n1.6, 0.35, 0.59\n", "name": "a.csv"}, "enabled",
                 snap)  # fmt: skip
    assert ok[1]["plan"] is not None
    with pytest.raises(CommandError, match=r"^path b\.csv: .*x = 2\.9000 m is outside"):
        v.check("path", {"text": "x, y, z\n2.9, 0.35, 0.59\n", "name": "b.csv"}, "enabled", snap)


def test_a_moves_speed_becomes_a_fraction_of_the_limit_and_so_does_its_acceleration(v, rowc):
    c = rowc.control
    out = v.check("move", {"position": [1.6, 0.35, 0.59], "max_velocity": 0.25 * c.max_velocity,
                           "max_acceleration": 0.4 * c.max_acceleration}, "enabled")  # fmt: skip
    assert out[1]["speed"] == pytest.approx(0.25) and out[1]["accel"] == pytest.approx(0.4)
    plain = v.check("move", {"position": [1.6, 0.35, 0.59]}, "enabled")[1]
    assert plain["speed"] == 1.0 and plain["accel"] == 1.0


def test_a_pose_no_tensions_hold_is_refused_to_the_tenth_of_a_millimetre(v):
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": [0.512345, 0.35, 0.3], "rpy": [0.0, -0.19876, 0.0]},
                "enabled")  # fmt: skip
    assert str(exc.value).startswith(
        "position = [0.5123, 0.35, 0.3] m, rpy = [0.0, -0.1988, 0.0] rad cannot be held within "
        "the tension limits (INFEASIBLE"
    ), str(exc.value)


def test_a_zero_direction_is_refused(v):
    with pytest.raises(CommandError, match=r"direction = \[0.0, 0.0, 0.0\] must be a non-zero"):
        v.check("set_tda", {"method": "barycenter", "direction": [0, 0, 0]}, "enabled")
    out = v.check("set_tda", {"direction": [0, 0, 1e-3]}, "enabled")
    assert out[0] == "set_tda" and out[1]["tda"].direction == (0.0, 0.0, 1e-3)


def test_a_gripper_unnamed_on_a_robot_with_two_is_refused():
    """seed000 with its grippers on cables 1 and 8: which one must be said (with one alone it
    may go unsaid); a number names the cable as `cdprctl send ... gripper=1` gives it, a
    boolean does not."""
    v = CommandValidator(load_robot(CONFIG / "seed000_grippers.toml"), True)
    with pytest.raises(CommandError, match=r"^gripper = null must name a gripper's cable \(1, 8\)"):
        v.check("gripper", {"travel": 0.1}, "enabled")
    assert v.check("gripper", {"gripper": 8, "travel": 0.1}, "enabled")[1] == {
        "gripper": 1, "grip": "travel", "value": 0.1}  # fmt: skip
    with pytest.raises(CommandError, match=r"^gripper = true must name"):
        v.check("gripper", {"gripper": True, "travel": 0.1}, "enabled")
    assert v.check("gripper", {"gripper": "1", "force": 5}, "enabled")[1] == {
        "gripper": 0, "grip": "force", "value": 5.0}  # fmt: skip
    assert v.check("gripper", {"gripper": "1", "release": True}, "enabled")[1] == {
        "gripper": 0, "grip": "release", "value": 0.0}  # fmt: skip


def test_a_number_at_its_bounds_is_taken_and_beyond_them_refused(v):
    """[lo, hi] closed: nu 0 and 1 taken, 1.5 and -0.1 refused; a move's speed from 1e-6 m/s
    (0 and below refused); a gripper's force from 0 N."""
    for nu in (0.0, 1.0):
        assert v.check("set_tda", {"method": "barycenter", "nu": nu}, "enabled")[1]["tda"].nu == nu
    for nu in (1.5, -0.1):
        with pytest.raises(CommandError, match=r"nu = .* must be in \[0, 1\]"):
            v.check("set_tda", {"nu": nu}, "enabled")
    for speed in (0.0, -0.1):
        with pytest.raises(CommandError, match=r"max_velocity = .* m/s must be in \[1e-06, 0.3\]"):
            v.check("move", {"position": [1.6, 0.35, 0.59], "max_velocity": speed}, "enabled")
    g = CommandValidator(load_robot(CONFIG / "seed000_grippers.toml"), True)
    assert g.check("gripper", {"gripper": "1", "force": 0}, "enabled")[1]["value"] == 0.0
    with pytest.raises(CommandError, match=r"force = -0.5 N must be in \[0, "):
        g.check("gripper", {"gripper": "1", "force": -0.5}, "enabled")


@pytest.mark.parametrize("bad", [[True, 0.35, 0.59], ["1.5", 0.35, 0.59]])
def test_a_vector_holding_a_boolean_or_a_string_is_refused(v, bad):
    with pytest.raises(CommandError, match="must be a list of 3 numbers"):
        v.check("move", {"position": bad}, "enabled")


def test_a_payload_of_exactly_4096_bytes_is_taken_and_one_more_refused(v):
    head = b'{"position": [1.6, 0.35, 0.59], "id": "'
    exact = head + b"x" * (4096 - len(head) - 2) + b'"}'
    assert len(exact) == 4096 and v.parse(exact, "move")["position"] == [1.6, 0.35, 0.59]
    with pytest.raises(CommandError, match="payload of 4097 bytes exceeds 4096 bytes"):
        v.parse(exact[:-2] + b'x"}', "move")


def test_an_unknown_field_is_refused_listing_what_is_allowed(v):
    """The kind is not repeated: the reply is shown as "move: rejected: ..." and the event as
    "move rejected: ..." (a newcomer read "move: rejected: move: field 'speed' ...")."""
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": [1.6, 0.35, 0.59], "speed": 1}, "enabled")
    assert str(exc.value) == ("field 'speed' is unknown (allowed: max_acceleration, "
                              "max_velocity, position, rpy, id)")  # fmt: skip
    with pytest.raises(CommandError) as exc:
        v.check("enable", {"now": True}, "ready")
    assert str(exc.value) == "field 'now' is unknown (allowed: none, id)"


def test_a_jog_is_refused_beyond_the_linear_limit_on_x_y_z_and_the_angular_one_on_the_rest(rowc):
    """The first three components against max_velocity (m/s), the last three against
    max_angular_velocity (rad/s): here 0.3 m/s and 0.5 rad/s."""
    control = dataclasses.replace(rowc.control, max_angular_velocity=0.5)
    v = CommandValidator(dataclasses.replace(rowc, control=control), True)
    assert v.check("jog", {"velocity": [0.0, 0.0, 0.0, 0.4, 0.0, 0.45]}, "enabled")[0] == "jog"
    with pytest.raises(CommandError, match=r"velocity\[2\] = 0.35 m/s exceeds \[control\] "
                       r"max_velocity = 0.3 m/s"):  # fmt: skip
        v.check("jog", {"velocity": [0.0, 0.0, 0.35, 0.0, 0.0, 0.0]}, "enabled")
    with pytest.raises(CommandError, match=r"velocity\[3\] = 0.55 rad/s exceeds"):
        v.check("jog", {"velocity": [0.0, 0.0, 0.0, 0.55, 0.0, 0.0]}, "enabled")


def test_a_tilt_beyond_the_workspace_is_refused_to_the_tenth_of_a_milliradian(v):
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": [1.5, 0.35, 0.59], "rpy": [0.0, 0.0, 0.212345]}, "enabled")
    assert str(exc.value) == ("rpy = [0.0, 0.0, 0.2123] rad is 0.212 rad (12.17°) from the "
                              "home orientation, more than workspace.max_angle = 0.2 rad "
                              "(11.46°)")  # fmt: skip


def test_an_angle_beyond_pi_is_refused_as_degrees_typed_as_radians(v):
    """30 for a yaw of 30° was 1.4159 rad after wrapping, refused only by max_angle as 1.416
    rad (81.13°): the sender never saw that its 30 was read in radians."""
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": [1.5, 0.35, 0.59], "rpy": [0.0, 0.0, 30]}, "enabled")
    assert str(exc.value) == ("rpy = [0.0, 0.0, 30.0] rad: yaw = 30 is taken in radians and is "
                              "beyond pi; did you mean degrees? 30° = 0.5236 rad: write it "
                              "30deg or 0.5236")  # fmt: skip


def test_a_rotation_alone_that_brings_cables_within_the_clearance_is_refused_as_a_rotation():
    """CAROCA at home turned 0.6 rad about y (its max_angle): the target alone is clear of
    contact, the way there comes under the clearance; the refusal names the rotation, not
    only the position it stays at (the desk's words: tests/motion/test_clearance_limits.py)."""
    caroca = load_robot(CONFIG / "caroca.toml")
    v = CommandValidator(caroca, commands_enabled=True)
    move = {"position": [0.0, 0.0, 1.0], "rpy": [0.0, 0.6, 0.0]}
    with pytest.raises(CommandError) as exc:
        v.check("move", move, "enabled", {"reference": np.array([0, 0, 1.0, 0, 0, 0])})
    assert str(exc.value).startswith(
        "position = [0.0, 0.0, 1.0] m, rpy = [0.0, 0.6, 0.0] rad: the rotation to the target, "
        "34.38° (0.6000 rad) about [0.0, 1.0, 0.0] (base frame) at [0.0, 0.0, 1.0] m, leaves "
        "the soft limits after 3"
    )
    assert str(exc.value).endswith("under the clearance 5.00 mm ([interference] clearance)")


def test_a_direction_too_short_is_refused(v):
    with pytest.raises(CommandError, match="must be a non-zero 3-vector"):
        v.check("set_tda", {"direction": [1e-10, 0, 0]}, "enabled")


def test_an_imposition_is_kept_only_by_the_energy_method_and_a_value_from_zero_is_refused_below(
    rowc,
):
    """A robot file's imposition stays when set_tda keeps or chooses the energy method and is
    dropped for any other; an imposed value is taken from 0 (its unit's)."""
    from cdprctl.model.control import ImposeConfig

    control = dataclasses.replace(
        rowc.control, tda_method="energy", impositions=(ImposeConfig(2, "deformation", 0.0),)
    )
    v = CommandValidator(dataclasses.replace(rowc, control=control), True)
    kept = v.check("set_tda", {"method": "energy"}, "enabled")[1]["tda"]
    assert len(kept.impositions) == 1 and kept.impositions[0].cable == 2
    for method in ("barycenter", "closed-form", "pinv", "sotda"):
        out = v.check("set_tda", {"method": method}, "enabled")[1]["tda"]
        assert out.impositions == (), method
    imposed = v.check("impose", {"cable": "1", "quantity": "deformation", "value": 0.0},
                      "enabled")[1]["tda"]  # fmt: skip
    assert imposed.impositions[0].value == 0.0
    with pytest.raises(CommandError, match=r"value = -0.001 m must be in \[0, "):
        v.check("impose", {"cable": "1", "quantity": "deformation", "value": -0.001}, "enabled")


def test_a_move_to_the_workspace_box_edge_is_taken_and_beyond_refused(v):
    for pos in ([2.5, 0.35, 0.59], [0.5, 0.35, 0.59], [1.5, 0.4, 0.59], [1.5, 0.35, 0.7]):
        assert v.check("move", {"position": pos}, "enabled")[0] == "move", pos
    with pytest.raises(CommandError, match=r"position.x = 2.5001 m is outside the workspace"):
        v.check("move", {"position": [2.5001, 0.35, 0.59]}, "enabled")


def test_a_jog_at_its_limit_is_taken_and_a_zero_acceleration_refused(v):
    assert v.check("jog", {"velocity": [0.3, 0.0, 0.0, 0.0, 0.0, -0.3]}, "enabled")[0] == "jog"
    with pytest.raises(CommandError, match=r"max_acceleration = 0 m/s² must be in \[1e-06, "):
        v.check("move", {"position": [1.6, 0.35, 0.59], "max_acceleration": 0}, "enabled")


def test_an_acceleration_becomes_its_fraction_of_a_limit_other_than_one(rowc):
    control = dataclasses.replace(rowc.control, max_acceleration=2.0)
    v = CommandValidator(dataclasses.replace(rowc, control=control), True)
    out = v.check("move", {"position": [1.6, 0.35, 0.59], "max_acceleration": 0.5}, "enabled")
    assert out[1]["accel"] == pytest.approx(0.25)


def test_a_pose_short_of_the_wrench_margin_is_refused_to_the_tenth_of_a_millimetre(rowc):
    strict = dataclasses.replace(
        rowc, workspace=dataclasses.replace(rowc.workspace, wrench_margin=1000.0)
    )
    v = CommandValidator(strict, True)
    with pytest.raises(CommandError) as exc:
        v.check("move", {"position": [1.512345, 0.35, 0.59], "rpy": [0.0, 0.012345, 0.0]},
                "enabled")  # fmt: skip
    assert str(exc.value).startswith(
        "position = [1.5123, 0.35, 0.59] m, rpy = [0.0, 0.0123, 0.0] rad: "), str(exc.value)


def test_a_direction_of_1e_9_becomes_the_options_direction(v):
    assert v.check("set_tda", {"direction": [1e-9, 0, 0]}, "enabled")[1]["tda"].direction == (
        1e-9, 0.0, 0.0)  # fmt: skip


def test_an_imposed_energy_up_to_1e6_is_taken_and_beyond_refused(v):
    out = v.check("impose", {"cable": "1", "quantity": "energy", "value": 1e6}, "enabled")
    assert out[1]["tda"].impositions[0].value == 1e6
    with pytest.raises(CommandError, match=r"value = 1e\+06 J must be in \[0, 1e\+06\] J"):
        v.check("impose", {"cable": "1", "quantity": "energy", "value": 1e6 + 0.5}, "enabled")


def test_a_gripper_command_on_a_robot_with_one_becomes_that_grippers_and_needs_one_action():
    """One gripper: it may go unnamed; none of travel, force or release is refused."""
    g = load_robot(CONFIG / "seed000_grippers.toml")
    v = CommandValidator(dataclasses.replace(g, grippers=g.grippers[:1]), True)
    assert v.check("gripper", {"travel": 0.1}, "enabled")[1] == {
        "gripper": 0, "grip": "travel", "value": 0.1}  # fmt: skip
    with pytest.raises(CommandError, match="give exactly one of travel"):
        v.check("gripper", {}, "enabled")


def _lp_margin(model, p):
    """N: the tension margin at ``p`` (home orientation) by scipy's LP, apart from the
    project's margins: max t with W f = the wrench to hold, t_min + t ≤ f ≤ t_max − t."""
    from scipy.optimize import linprog

    from cdprctl.geometry.kinematics import wrench_matrix

    n, R = model.n_cables, model.home.rotation
    W = wrench_matrix(model, p, R)
    w = -(model.gravity_wrench(R) + np.asarray(model.control.external_wrench, dtype=float))
    eye = np.eye(n)
    lp = linprog(np.r_[np.zeros(n), -1.0], A_eq=np.c_[W, np.zeros(6)], b_eq=w,
                 A_ub=np.r_[np.c_[-eye, np.ones(n)], np.c_[eye, np.ones(n)]],
                 b_ub=np.r_[-model.tension_min, model.tension_max],
                 bounds=[(None, None)] * (n + 1))  # fmt: skip
    assert lp.status == 0, lp.message
    return -lp.fun


def test_a_move_whose_straight_line_leaves_the_limits_is_refused_before_the_reply(rowc):
    """rowc's workspace box widened into a U (both ends of its top held, the middle not): with
    the loop's snapshot the gateway refuses the move the desk would ignore, with the desk's
    message, where the line leaves the held region; scipy's LP along the line finds the same
    point. Without a snapshot only the target is checked, and it is held."""
    ws = dataclasses.replace(rowc.workspace, position_min=np.array([0.3, 0.33, 0.3]),
                             position_max=np.array([2.7, 0.40, 1.3]))  # fmt: skip
    model = dataclasses.replace(rowc, workspace=ws)
    v = CommandValidator(model, commands_enabled=True)
    a, b = np.array([0.45, 0.38, 1.05]), np.array([2.55, 0.38, 1.05])
    move = {"position": b.tolist()}
    assert v.check("move", move, "enabled")[1]["pose"][:3] == b.tolist()
    snap = {"reference": np.r_[a, 0.0, 0.0, 0.0]}
    with pytest.raises(CommandError) as exc:
        v.check("move", move, "enabled", snap)
    why = str(exc.value)
    assert why.startswith("position = [2.55, 0.38, 1.05] m, rpy = [0.0, 0.0, 0.0] rad: the "
                          "line to the target leaves the soft limits after [")  # fmt: skip
    assert "the tension margin is" in why and "N required" in why
    x = float(why.split("after [", 1)[1].split(",", 1)[0])
    need = model.soft_margin
    # the LP every 5 mm from the start: held up to x, and not 1 mm beyond it
    for xi in np.arange(a[0], x, 0.005):
        assert _lp_margin(model, np.array([xi, a[1], a[2]])) >= need - 1e-6, xi
    assert _lp_margin(model, np.array([x + 0.001, a[1], a[2]])) < need
    # a line the limits hold: taken with the snapshot too
    assert v.check("move", {"position": [0.6, 0.38, 1.05]}, "enabled", snap)[0] == "move"
