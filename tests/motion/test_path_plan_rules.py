"""The path planner's rules (cdprctl/motion/path_plan.py) one by one, at the unit level: where
a path blends, the per-axis limits of a segment, the velocity a blend passes at (by hand), the
speed rule's edge, how densely a plan is checked (no coarser than CHECK_SPACING, and not
needlessly finer), where the smallest margin is reported, and the plan's summary."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cdprctl.motion import path_plan as pp
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_file import parse_path
from cdprctl.motion.trajectory import acceleration_limits, pose_coordinates, velocity_limits
from cdprctl.motion.waypoints import Waypoint
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
START = np.array([1.5, 0.35, 0.59, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def start_of(model) -> np.ndarray:
    return pose_coordinates(model, START[:3], model.home.rotation)


def wp(x: float, *, blend: bool = True, dwell: float = 0.0, time: float | None = None,
       speed: float | None = None) -> Waypoint:  # fmt: skip
    return Waypoint((x, 0.35, 0.59, 0.0, 0.0, 0.0), speed, time, blend, dwell, f"x {x}")


@pytest.mark.parametrize(("waypoints", "durations", "expected"), [
    ([wp(1.6), wp(1.7), wp(1.8, blend=False)], [None] * 3, [True, True, False]),
    # the last row never blends, whatever it says: the path ends there
    ([wp(1.6), wp(1.7)], [None, None], [True, False]),
    ([wp(1.6, dwell=0.5), wp(1.7), wp(1.8)], [None] * 3, [False, True, False]),
    ([wp(1.6, blend=False), wp(1.7), wp(1.8)], [None] * 3, [False, True, False]),
    # a timed segment starts or ends at rest: no blend into or out of it
    ([wp(1.6), wp(1.7), wp(1.8)], [None, 2.0, None], [False, False, False]),
    ([wp(1.6), wp(1.7), wp(1.8)], [2.0, None, None], [False, True, False]),
    ([wp(1.6), wp(1.7), wp(1.8), wp(1.9)], [None, None, 1.0, None], [True, False, False, False]),
])  # fmt: skip
def test_a_path_blends_only_where_it_passes_moving(waypoints, durations, expected):
    got = [pp._blends(waypoints, durations, i) for i in range(len(waypoints))]
    assert got == expected


def test_a_segments_limits_are_the_maximum_along_its_direction(rowc):
    """Velocity ``speed`` (m/s) along the line: per axis its share of the line's direction;
    a blended segment the speed per axis; an axis not moving its floor (FLOOR of its limit,
    ruckig needs a positive one); the acceleration limits unchanged."""
    v_lim, a_lim = velocity_limits(rowc.control), acceleration_limits(rowc.control)
    d = np.array([0.3, -0.4, 0.0, 0.0, 0.0, 0.0])  # 0.5 m, a 3-4-5 triangle
    vmax, amax = pp._limits(rowc, d, 0.15, False)
    frac = 0.15 / rowc.control.max_velocity
    assert np.allclose(vmax[:3], [v_lim[0] * frac * 0.6, v_lim[1] * frac * 0.8,
                                  v_lim[2] * pp.FLOOR])  # fmt: skip
    assert np.allclose(vmax[3:], v_lim[3:] * pp.FLOOR) and np.array_equal(amax, a_lim)
    vmax, _ = pp._limits(rowc, d, None, True)
    assert np.allclose(vmax[:3], v_lim[:3])
    turn = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.2])
    vmax, _ = pp._limits(rowc, turn, None, False)
    assert np.allclose(vmax[3:], [v_lim[3] * pp.FLOOR, v_lim[4] * pp.FLOOR, v_lim[5]])


@pytest.mark.parametrize(("blends", "expected"), [
    ((1, 1, 0, 0), [True, True, True, False]),  # rows 1-2 blend: segments 1-3 turn on the way
    ((1, 0, 0, 0), [True, True, False, False]),  # row 1 alone: segments 1-2
    ((0, 1, 0, 0), [False, True, True, False]),
])  # fmt: skip
def test_a_segment_into_or_out_of_a_blend_has_the_blend_limits_and_only_those(rowc, blends,
                                                                               expected):
    """A segment that starts or ends moving has the speed per axis; one from rest to rest
    runs along its line (an axis it does not move at the floor)."""
    rows = ((1.6, 0.35, 0.59), (1.6, 0.39, 0.59), (1.7, 0.39, 0.59), (1.7, 0.39, 0.65))
    text = "x, y, z, blend\n" + "".join(f"{x}, {y}, {z}, {b}\n"
                                        for (x, y, z), b in zip(rows, blends, strict=True))
    plan = pp.plan_path(rowc, parse_path(text, START), start_of(rowc), rowc.control.period)
    v_lim = velocity_limits(rowc.control)
    per_axis = [np.allclose(s.max_velocity[:3], v_lim[:3]) for s in plan.segments]
    assert per_axis == expected
    assert np.allclose(plan.segments[3].max_velocity[:2], v_lim[:2] * pp.FLOOR)


def test_a_blend_passes_at_the_mean_cruise_velocity_within_reach_and_caps(rowc):
    """By hand: in along x (0.2 m), out along x and y (0.2, 0.02 m) with per-axis caps 0.3 m/s
    and acceleration 1 m/s²: cruise in (0.3, 0), out (0.3, 0.03); their mean (0.3, 0.015);
    the reach over the shorter neighbour's half √(a·d) caps x at √(1·0.2) and y — which
    does not move on the way in — is zero."""
    vmax = np.full(6, 0.3)
    amax = np.full(6, 1.0)
    d_in = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    d_out = np.array([0.2, 0.02, 0.0, 0.0, 0.0, 0.0])
    v = pp._blend_velocity(d_in, d_out, (vmax, amax), (vmax, amax))
    assert np.allclose(v, [0.3, 0.0, 0.0, 0.0, 0.0, 0.0])
    # a short neighbour: the reach √(a_min·d_min) is the bound (a from both sides' least)
    d_short = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    a_out = np.full(6, 2.0)
    v = pp._blend_velocity(d_in, d_short, (vmax, amax), (vmax, a_out))
    assert v[0] == pytest.approx(math.sqrt(1.0 * 0.01))
    # reversing on an axis, or stopping on it after: zero there
    v = pp._blend_velocity(np.array([0.2, 0.1, 0, 0, 0, 0.0]), np.array([0.2, 0.0, 0, 0, 0, 0.0]),
                           (vmax, amax), (vmax, amax))  # fmt: skip
    assert v[1] == 0.0 and v[0] > 0.0
    v = pp._blend_velocity(np.array([0.2, 0.1, 0, 0, 0, 0.0]), np.array([0.2, -0.1, 0, 0, 0, 0]),
                           (vmax, amax), (vmax, amax))  # fmt: skip
    assert v[1] == 0.0


def test_a_blend_into_a_segment_of_no_length_is_at_rest_never_nan():
    vmax, amax = np.full(6, 0.3), np.full(6, 1.0)
    zero = np.zeros(6)
    with np.errstate(all="raise"):  # not even a 0/0 on the way, overwritten later
        v = pp._blend_velocity(zero, np.array([0.2, 0, 0, 0, 0, 0.0]), (vmax, amax),
                               (vmax, amax))  # fmt: skip
        assert np.array_equal(v, np.zeros(6))
        v = pp._blend_velocity(np.array([0.2, 0, 0, 0, 0, 0.0]), zero, (vmax, amax),
                               (vmax, amax))  # fmt: skip
        assert np.array_equal(v, np.zeros(6))


def test_the_speed_rule_takes_the_configured_maximum_itself(rowc):
    vmax = rowc.control.max_velocity
    for speed in (vmax, vmax * (1 + 1e-9)):  # the rule's rounding allowance included
        plan = pp.plan_path(rowc, [wp(1.6, blend=False, speed=speed)], start_of(rowc),
                            rowc.control.period)  # fmt: skip
        assert plan.segments[0].max_velocity[0] == pytest.approx(velocity_limits(rowc.control)[0])
    with pytest.raises(pp.PathRejectedError, match="exceeds the configured"):
        pp.plan_path(rowc, [wp(1.6, blend=False, speed=vmax * (1 + 1e-8))], start_of(rowc),
                     rowc.control.period)  # fmt: skip


@pytest.mark.parametrize("period", [0.0005, 0.002, 0.004, 0.01])
def test_a_plan_is_checked_every_check_spacing_and_not_needlessly_finer(rowc, period):
    """A 0.4 m move at 0.3 m/s: samples every ``CHECK_SPACING / (v·period)`` periods (one at
    least), so the largest step between samples is under CHECK_SPACING (or one period's
    travel where that is more) and, where several periods fit, over half of it."""
    plan = pp.plan_path(rowc, [wp(1.9, blend=False)], start_of(rowc), period)
    step = rowc.control.max_velocity * period
    assert plan.spacing <= max(pp.CHECK_SPACING, step) * (1 + 1e-9)
    every = max(1, int(pp.CHECK_SPACING / (max(rowc.control.max_velocity,
                                                rowc.control.max_angular_velocity) * period)))
    assert plan.spacing >= 0.9 * every * step
    assert plan.samples <= 1.2 * 0.4 / (every * step) + 50


def test_a_vertical_move_is_checked_as_densely(rowc):
    start = start_of(rowc)
    text = "x, y, z\n1.5, 0.35, 0.68\n"
    plan = pp.plan_path(rowc, parse_path(text, START), start, rowc.control.period)
    assert 0.5 * pp.CHECK_SPACING <= plan.spacing <= pp.CHECK_SPACING


def test_no_waypoints_are_refused_by_name(rowc):
    """A file has one at least (path_file); a resume past the last would have none."""
    with pytest.raises(pp.PathRejectedError, match="the path has no waypoint left to go to"):
        pp.plan_path(rowc, [], start_of(rowc), rowc.control.period)


class MarginGrowingWithX(SoftLimits):
    """Every sample holds; the margin grows with x (N): the start of a move in +x is the
    tightest point of the plan."""

    def check(self, coords, acceleration=None, floor=None, **clearance):
        x = np.asarray(coords, dtype=float).reshape(-1, 6)[:, 0]
        return 100.0 + 1000.0 * (x - 1.5), np.ones(len(x), dtype=bool)


def test_the_smallest_margin_at_the_start_is_reported_there(rowc):
    plan = pp.plan_path(rowc, [wp(1.6, blend=False), wp(1.7, blend=False)], start_of(rowc),
                        rowc.control.period, MarginGrowingWithX(rowc))  # fmt: skip
    assert plan.min_margin == pytest.approx(100.0, abs=1e-6)
    assert plan.min_margin_at == "x 1.6, t = 0.00 s"


def test_a_plan_holds_from_where_it_was_made_to_ten_micrometres(rowc):
    plan = pp.plan_path(rowc, [wp(1.6, blend=False)], start_of(rowc), rowc.control.period)
    x = start_of(rowc)
    assert plan.starts_at(x + 0.9e-5) and plan.starts_at(x - 0.9e-5)
    assert not plan.starts_at(x + 1.1e-5)
    assert not plan.starts_at(x + np.array([0, 0, 0, 0, 0, 2e-5]))


def test_the_summary_says_segments_duration_samples_spacing_in_mm_and_margin(rowc):
    plan = pp.plan_path(rowc, [wp(1.6, blend=False)], start_of(rowc), rowc.control.period)
    assert plan.summary() == (
        f"1 segment, {plan.duration:.2f} s; checked at {plan.samples} samples ≤ "
        f"{plan.spacing * 1000:.1f} mm apart, smallest tension margin {plan.min_margin:.1f} N "
        f"({plan.min_margin_at})")  # fmt: skip
    two = pp.plan_path(rowc, [wp(1.6, blend=False), wp(1.7, blend=False)], start_of(rowc),
                       rowc.control.period)  # fmt: skip
    assert two.summary().startswith("2 segments, ")


def test_a_rejected_sample_is_named_by_its_three_coordinates(rowc):
    """To 0.1 mm: the first refused sample's x, rounded to four decimals."""
    class Refuse(SoftLimits):
        def check(self, coords, acceleration=None, floor=None, **clearance):
            x = np.asarray(coords, dtype=float).reshape(-1, 6)[:, 0]
            band = (x > 1.55) & (x < 1.57)
            self.refused = x[band].tolist()
            return np.where(band, -1.0, 50.0), ~band

    limits = Refuse(rowc)
    with pytest.raises(pp.PathRejectedError, match=r"x 1\.6 \(segment 2\): at t = [0-9.]+ s, "
                       r"position \[1\.55\d*, 0\.35, 0\.59\] m: ") as refused:  # fmt: skip
        pp.plan_path(rowc, [wp(1.53, blend=False), wp(1.6, blend=False)], start_of(rowc),
                     rowc.control.period, limits)  # fmt: skip
    said = str(refused.value).split("position [")[1].split(",")[0]
    assert len(said.split(".")[1]) <= 4
    assert float(said) == pytest.approx(limits.refused[0], abs=0.5e-4 + 1e-12)


@pytest.mark.parametrize(("units", "hinted"), [("m", True), ("mm", False), ("in", False)])
def test_the_millimetres_hint_is_for_a_csv_read_in_metres_only(units, hinted):
    text = "x, y, z\n1500, 350, 590\n"
    why = "x = 1500.0000 m is outside the workspace box"
    assert bool(pp.units_hint(text, units, why)) is hinted


def test_a_rows_time_is_met_to_two_periods(rowc):
    """A timed row the limits reach up to two periods late is taken (the loop steps whole
    periods, the times are the file's); three periods late it is refused by name."""
    period = rowc.control.period
    fastest = pp.plan_path(rowc, [wp(1.7, blend=False)], start_of(rowc), period).duration
    for late, taken in ((1.5, True), (2.5, False)):
        rows = [wp(1.7, blend=False, time=fastest - late * period)]
        if taken:
            pp.plan_path(rowc, rows, start_of(rowc), period)
        else:
            with pytest.raises(pp.PathRejectedError, match=r"x 1\.7: its time cannot be met"):
                pp.plan_path(rowc, rows, start_of(rowc), period)


def test_a_refused_waypoint_is_named_without_negative_zeros(rowc):
    """``-0.0`` in an error reads as a sign error the file does not have."""
    far = Waypoint((5.0, -0.00001, 0.59, -0.00002, 0.0, 0.0), None, None, False, 0.0, "row 2")
    with pytest.raises(pp.PathRejectedError, match=r"row 2 \(the end of segment \d\): waypoint "
                       r"\[5\.0, 0\.0, 0\.59, 0\.0, 0\.0, 0\.0\]: "):  # fmt: skip
        pp.plan_path(rowc, [far], start_of(rowc), rowc.control.period)


def test_a_rows_dwell_is_not_part_of_the_next_segments_time(rowc):
    """Times are the file's clock: a row reached at 3 s that dwells 1 s leaves at 4 s, so the
    next row at 7 s has 3 s to get there."""
    rows = [wp(1.6, blend=False, time=3.0, dwell=1.0), wp(1.7, blend=False, time=7.0)]
    plan = pp.plan_path(rowc, rows, start_of(rowc), rowc.control.period)
    assert [s.minimum_duration for s in plan.segments] == [3.0, 3.0]
    assert plan.duration == pytest.approx(7.0, abs=2 * rowc.control.period)


def test_a_blends_cruise_is_the_slowest_axis_time_over_each_axis():
    """By hand, caps not reached: in and out (0.2, 0.1) m at 0.3 m/s per axis: x needs 0.667 s,
    so the cruise is (0.3, 0.15) m/s, and y passes at 0.15 m/s."""
    vmax, amax = np.full(6, 0.3), np.full(6, 1.0)
    d = np.array([0.2, 0.1, 0.0, 0.0, 0.0, 0.0])
    v = pp._blend_velocity(d, d, (vmax, amax), (vmax, amax))
    assert np.allclose(v, [0.3, 0.15, 0.0, 0.0, 0.0, 0.0])


def test_an_axis_that_reverses_passes_at_rest_even_when_the_mean_is_not_zero():
    vmax, amax = np.full(6, 0.3), np.full(6, 1.0)
    v = pp._blend_velocity(np.array([0.2, 0.1, 0, 0, 0, 0.0]), np.array([0.2, -0.04, 0, 0, 0, 0]),
                           (vmax, amax), (vmax, amax))  # fmt: skip
    assert v[1] == 0.0 and v[0] > 0.0


def test_a_blend_is_no_faster_than_the_slower_segments_limit():
    """In at 0.05 m/s, out at 0.3 m/s: the mean cruise (0.175) is capped at 0.05."""
    amax = np.full(6, 1.0)
    d = np.array([0.2, 0.0, 0.0, 0.0, 0.0, 0.0])
    v = pp._blend_velocity(d, d, (np.full(6, 0.05), amax), (np.full(6, 0.3), amax))
    assert v[0] == pytest.approx(0.05)
    v = pp._blend_velocity(d, d, (np.full(6, 0.3), amax), (np.full(6, 0.05), amax))
    assert v[0] == pytest.approx(0.05)


def test_a_plan_holds_at_exactly_its_start_tolerance():
    plan = pp.PathPlan(segments=[], duration=0.0, samples=0, spacing=0.0, min_margin=0.0,
                       min_margin_at="", start=np.zeros(6))  # fmt: skip
    edge = np.zeros(6)
    edge[2] = pp.START_TOLERANCE
    assert plan.starts_at(edge) and plan.starts_at(-edge)


def test_a_path_of_exactly_the_longest_number_of_periods_is_taken(rowc, monkeypatch):
    """MAX_DURATION counts the periods the trajectory runs: a path of n periods is taken
    when n periods fit, and refused when one fewer do."""
    period = rowc.control.period
    rows = [wp(1.6, blend=False)]
    n = round(pp.plan_path(rowc, rows, start_of(rowc), period).duration / period)
    monkeypatch.setattr(pp, "MAX_DURATION", (n + 0.5) * period)
    pp.plan_path(rowc, rows, start_of(rowc), period)
    monkeypatch.setattr(pp, "MAX_DURATION", (n - 0.5) * period)
    with pytest.raises(pp.PathRejectedError, match=r"x 1\.6: the path lasts longer than"):
        pp.plan_path(rowc, rows, start_of(rowc), period)


def test_a_path_file_is_a_job_of_an_hour_at_most(rowc):
    """At 0.1 s periods (36 000 of them in an hour): a row timed at 3599.5 s is taken, one at
    3600.5 s refused, and the error says the hour."""
    period = 0.1
    pp.plan_path(rowc, [wp(1.55, blend=False, time=3599.5)], start_of(rowc), period)
    with pytest.raises(pp.PathRejectedError, match=r"x 1\.55: the path lasts longer than 3600 s"):
        pp.plan_path(rowc, [wp(1.55, blend=False, time=3600.5)], start_of(rowc), period)


def test_a_segments_translation_and_rotation_have_separate_directions(rowc):
    """The line's direction is taken in position (m) and in rotation (rad) apart: a turn does
    not slow the translation's axes, nor z share its direction with the rotation's."""
    v_lim = velocity_limits(rowc.control)
    d = np.array([0.3, 0.0, 0.4, 0.2, 0.0, 0.0])
    vmax, _ = pp._limits(rowc, d, None, False)
    assert np.allclose(vmax, v_lim * [0.6, pp.FLOOR, 0.8, 1.0, pp.FLOOR, pp.FLOOR])


def test_a_segment_has_six_coordinates_everywhere():
    """ruckig's binding would take a list of any length: a segment refuses a wrong one."""
    six = [0.0] * 6
    pp.Segment(np.zeros(6), six, six, six, None, 0.0, "row 2")
    for bad in ([0.0] * 5, [0.0] * 7):
        with pytest.raises(ValueError, match=r"row 2: a segment's velocity has [57] coordinates"):
            pp.Segment(np.zeros(6), bad, six, six, None, 0.0, "row 2")


def test_a_turn_in_place_is_checked_in_angle_and_does_not_translate(rowc):
    """spacing is the translation between samples (m): a rotation in place has none."""
    text = "x, y, z, roll, yaw\n1.5, 0.35, 0.59, 0.1, 0.1\n"
    plan = pp.plan_path(rowc, parse_path(text, START), start_of(rowc), rowc.control.period)
    assert plan.spacing == pytest.approx(0.0, abs=1e-12) and plan.samples > 10


def test_the_clearance_report_says_the_least_its_pair_and_the_limit_exactly(rowc):
    """The path's clearance line, whole: the least distance in mm (two decimals), its pair,
    line and time, and the limit (a 12.5 mm clearance: its mm are the file's, not rounded
    from another unit); nothing said of a start under the clearance where the path starts
    clear; a plan with nothing to check says so; an overlap says "overlapping by"."""
    import dataclasses

    model = dataclasses.replace(rowc, interference=dataclasses.replace(
        rowc.interference, clearance=0.0125))  # fmt: skip
    plan = pp.plan_path(model, [wp(1.6, blend=False), wp(1.7, blend=False)], start_of(model),
                        model.control.period, SoftLimits(model))  # fmt: skip
    lim = SoftLimits(model)
    lim.check(np.array([start_of(model)]))  # the least at the start, measured apart
    assert 0.0125 < plan.min_clearance <= float(lim.nearest[0]) + 1e-12
    assert plan.clearance_text() == (
        f"least clearance {plan.min_clearance * 1e3:.2f} mm: {plan.min_clearance_at}; limit "
        "12.50 mm ([interference] clearance)")  # fmt: skip
    assert "start" not in plan.min_clearance_at and plan.min_clearance_at.endswith(" s)")
    assert round(plan.min_clearance * 1e3, 2) == float(plan.clearance_text().split()[2])
    nothing = dataclasses.replace(plan, min_clearance=math.inf)
    assert nothing.clearance_text() == ("clearance: nothing to check (one cable, no body, no "
                                        "obstacle)")  # fmt: skip
    touching = dataclasses.replace(plan, min_clearance=0.0)  # 0: a distance still, no words
    assert touching.clearance_text().startswith("least clearance 0.00 mm: ")
    deep = dataclasses.replace(plan, min_clearance=-0.02)
    assert deep.clearance_text().startswith("least clearance overlapping by 20.00 mm: ")
