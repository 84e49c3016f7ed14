"""``cdprctl report``'s figures from a recording written by the recorder's own CSV writer
(``record._write_csvs``, the payloads as the daemon sends them): the tracking error only where
the robot tracks, the run's events on every time plot, the scene at the two poses farthest
apart, and the command's answers to a run it cannot draw."""

from __future__ import annotations

import itertools
import json

import matplotlib.pyplot as plt
import numpy as np
import pytest

from cdprctl.cli import main
from cdprctl.commands.record import _write_csvs
from cdprctl.telemetry.foxglove.scene import SceneLayout
from cdprctl.telemetry.report import report_plots as rp
from cdprctl.telemetry.report.recording import farthest_pair, load_recording

T0 = 500.0  # s, the robot's clock at the first recorded state
DT = 0.01  # s between states
#: (first row, state): ready with a stale target, enabled, moving, enabled, e-stop, ready
PHASES = [(0, "ready"), (100, "enabled"), (150, "moving"), (250, "enabled"), (300, "estop"),
          (350, "ready")]  # fmt: skip
N = 400


def _state(i: int, cables: list[str]) -> dict:
    state = [s for first, s in PHASES if first <= i][-1]
    tracking = state in ("enabled", "moving")
    x = 1.5 + 0.3 * min(max(i - 150, 0), 100) / 100  # m: the move from 1.5 to 1.8
    # 5 mm off a stale target with the drives off, 1 mm at most while tracking
    err = 1e-3 * np.sin(0.1 * i) if tracking else 5e-3
    return {
        "time": T0 + DT * i, "state": state,
        "tda": {"method": "barycenter", "status": "OK"},
        "pose": {"position": [x, 0.35, 0.59], "rpy": [0.0, 0.0, 0.0]},
        "reference": [x - err, 0.35, 0.59, 0.0, 0.0, 0.0],
        "tracking_error": [err, 0.0, 0.0, 2e-4 if not tracking else 0.0, 0.0, 0.0],
        "cables": cables, "tensions": [100.0] * len(cables),
        "torques": [0.9 if tracking else 0.0] * len(cables),
        "true_position": [x, 0.35, 0.59],
    }  # fmt: skip


EVENTS = [
    (0.0, "drives", "[{...}]"),  # the drives' identities at start-up: before the recording
    (T0 + 0.995, "event", "state ready -> enabling: enabling the drives with holding torques"),
    (T0 + 1.0, "event", "state enabling -> enabled: drives enabled, holding the pose"),
    (T0 + 1.5, "event", "state enabled -> moving: move to [1.8, 0.35, 0.59, 0, 0, 0]"),
    (T0 + 2.0, "reject", "move rejected: position.x = 9 m is outside the workspace"),
    (T0 + 2.5, "event", "state moving -> enabled: target reached"),
    (T0 + 3.0, "event", "EMERGENCY STOP: the safety chain is open"),
    (T0 + 3.0, "event", "state enabled -> estop: the drives' safety chain is open"),
    (T0 + 3.008, "fault", "emergency stop: the safety chain opened; reset once it is closed"),
    (T0 + 3.5, "event", "state estop -> ready: fault reset"),
    (T0 + 3.504, "fault", ""),
    (T0 + 60.0, "event", "state ready -> enabling: after the recording"),
]


@pytest.fixture
def run(tmp_path, rowc):
    cables = list(SceneLayout.from_model(rowc).names)
    rows = {
        "state": [_state(i, cables) for i in range(N)],
        "timing": [{"schema": "cdprctl/1", "time": T0 + 1.0 * k, "lateness_p50_us": 5.0,
                    "lateness_p99_us": 50.0, "lateness_max_us": 90.0, "compute_p50_us": 200.0,
                    "missed": float(k // 2)} for k in range(4)],
        "events": [{"time": t, "kind": k, "text": x} for t, k, x in EVENTS],
    }
    _write_csvs(tmp_path, rows)
    config = {"robot": rowc.name, "tension_min": [10.0] * 8, "tension_max": [200.0] * 8,
              "torque_limit": [2.6] * 8,
              "layout": SceneLayout.from_model(rowc).to_dict()}  # fmt: skip
    (tmp_path / "meta.json").write_text(json.dumps({"config": config}))
    rec = load_recording(tmp_path)
    assert not isinstance(rec, str)
    return rec


def _not_tracking(rec) -> np.ndarray:
    return np.array([s not in ("enabled", "moving") for s in rec.states])


def test_the_tracking_error_only_where_the_robot_tracks(run):
    """With the drives off the recorded "error" is against a stale target (5 mm here): NaN
    there, in the series, the plotted line and the RMS and max of the title (1 mm)."""
    off = _not_tracking(run)
    assert off.sum() == 100 + 50 + 50  # ready, e-stop, ready again
    err = run.position_error_mm()
    assert np.all(np.isnan(err[off])) and np.all(np.isfinite(err[~off]))
    fig = rp.tracking_figure(run)
    ax = fig.axes[0]
    line = next(x for x in ax.get_lines() if x.get_label() == "tracking error")
    y = np.asarray(line.get_ydata(), dtype=float)
    assert np.all(np.isnan(y[off])) and np.nanmax(y) <= 1.0 + 1e-9
    assert "max 1.00 mm" in ax.get_title()
    # the spans without tracking are shaded: from t = 0, the e-stop and after
    spans = rp.not_tracking_spans(run.t, run.tracking())
    assert np.ravel(spans) == pytest.approx([0.0, 1.0, 3.0, 3.99])
    assert len(ax.patches) == 2 and ax.patches[0].get_label() == rp.NOT_TRACKING
    plt.close(fig)
    # the orientation error of pose.png too
    fig = rp.pose_figure(run)
    rx = np.asarray(fig.axes[1].get_lines()[0].get_ydata(), dtype=float)
    assert np.all(np.isnan(rx[off])) and np.all(rx[~off] == 0.0)
    plt.close(fig)


def test_no_tracking_at_all_says_so(run, tmp_path):
    run.rows = [r for r, s in zip(run.rows, run.states, strict=True) if s == "ready"]
    run.t = run.t[: len(run.rows)]
    fig = rp.tracking_figure(run)
    assert "nothing to measure" in fig.axes[0].get_title()
    plt.close(fig)


def _event_lines(ax) -> list[float]:
    return sorted(float(x.get_xdata()[0]) for x in ax.get_lines() if x.get_gid() == "event")


def _event_labels(fig) -> list[str]:
    """The labels along the top of the figure's axes (secondary x axes' tick labels)."""
    return [t.get_text() for ax in fig.axes for child in ax.child_axes
            for t in child.get_xticklabels()]  # fmt: skip


def test_every_time_plot_marks_the_runs_events(run):
    """A line per event in the recording's span (not the drives' identities from before it,
    nor one after it), at its time from the first state, on every time axis; short labels,
    events at the same instant sharing one; faults and the e-stop in red."""
    inside = [t - T0 for t, k, _ in EVENTS if k != "drives" and T0 <= t <= T0 + DT * (N - 1)]
    assert len(inside) == 10
    figures = [rp.pose_figure(run), rp.tracking_figure(run), rp.tensions_figure(run),
               rp.torques_figure(run), rp.timing_figure(run)]  # fmt: skip
    for fig in figures:
        time_axes = [ax for ax in fig.axes if ax.get_xlabel() == "time (s)" or
                     ax.get_shared_x_axes().get_siblings(ax) != [ax]]  # fmt: skip
        assert time_axes
        for ax in time_axes:
            assert _event_lines(ax) == pytest.approx(sorted(inside), abs=1e-6), fig
        labels = _event_labels(fig)
        assert "enabling, enabled" in labels  # 5 ms apart: one label
        assert "moving" in labels and "move rejected" in labels
        assert "E-STOP, fault: emergency stop" in labels
        assert "ready, fault cleared" in labels
        assert not any("after the recording" in x for x in labels)
        plt.close(fig)
    fig = rp.tracking_figure(run)
    colours = {round(float(x.get_xdata()[0]), 3): x.get_color() for x in fig.axes[0].get_lines()
               if x.get_gid() == "event"}  # fmt: skip
    assert colours[3.0] == "red" and colours[2.0] == "darkorange" and colours[1.5] == "0.35"
    assert colours[3.504] == "0.35"  # the fault's clearing: no alarm
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert {"event: state change", "event: command rejected", "event: fault, e-stop"} <= set(
        legend)
    plt.close(fig)


@pytest.mark.parametrize(
    "label, kind, text",
    [("moving", "event", "state enabled -> moving: move to [1, 2, 3]"),
     ("ready (stop category 0)", "event", "state enabled -> ready: stop category 0: the drives"),
     ("FAULT", "event", "state stopping -> fault: stopped; drives disabled"),
     ("fault: tracking error 12.0 mm > 10.0 mm", "fault", "tracking error 12.0 mm > 10.0 mm"),
     ("command move dropped", "reject", "command move dropped: mailbox full"),
     ("demo", "event", "demo: 30 N lateral force on"),
     ("fault: the encoders disagree with every…", "fault",
      "the encoders disagree with every pose: forward-kinematics residual")],
)  # fmt: skip
def test_event_labels_are_short(label, kind, text):
    assert rp.event_label(rp.Event(0.0, kind, text)) == label


def _brute_force(p: np.ndarray) -> float:
    ok = np.all(np.isfinite(p), axis=1)
    return max((float(np.linalg.norm(p[i] - p[j])) for i, j in
                itertools.combinations(np.flatnonzero(ok), 2)), default=0.0)  # fmt: skip


def _old_rule(p: np.ndarray) -> tuple[int, int]:
    """The pair the scene drew as "the two farthest points" before: the farthest from the
    start, then the farthest from both."""
    far = int(np.nanargmax(np.linalg.norm(p - p[0], axis=1)))
    both = np.minimum(np.linalg.norm(p - p[0], axis=1), np.linalg.norm(p - p[far], axis=1))
    return far, int(np.nanargmax(both))


def test_the_farthest_pair_is_the_farthest_by_brute_force():
    rng = np.random.default_rng(65)
    # a run from the middle to the left, up and over to the right: the old rule took the
    # right end (farthest from the start) and the top (farthest from both), 0.94 m apart,
    # while the two ends are 1.9 m apart
    corners = np.array([[0.0, 0, 0], [-0.9, 0, 0], [0.5, 0.8, 0], [1.0, 0, 0]])
    run = np.vstack([np.linspace(a, b, 40) for a, b in itertools.pairwise(corners)])
    old = _old_rule(run)
    assert np.linalg.norm(run[old[0]] - run[old[1]]) < 0.6 * _brute_force(run)
    sets = [run,
            rng.normal(size=(300, 3)),
            rng.uniform(size=(250, 3)) * [1.0, 1.0, 0.0],  # planar
            np.repeat(rng.normal(size=(20, 3)), 15, axis=0),  # at rest, repeated
            np.vstack([rng.normal(size=(100, 3)), [[np.nan] * 3], [[50.0, 0, 0]]]),
            np.array([[0.0, 0, 0], [0, 0, 0]])]  # fmt: skip
    for p in sets:
        i, j = farthest_pair(p)
        assert i < j or (i == j == 0)
        assert float(np.linalg.norm(p[i] - p[j])) == pytest.approx(_brute_force(p), abs=1e-12)
    assert farthest_pair(np.array([[1.0, 2, 3]])) == (0, 0)
    assert farthest_pair(np.full((4, 3), np.nan)) == (0, 0)


def test_the_scene_draws_the_farthest_pair(run, tmp_path):
    """The recording's stills: the start, the end and the two rows farthest apart (the start
    of the move and its end here), each titled with why it is drawn."""
    picks = dict(rp.scene_picks(run))
    p = run.positions()
    i, j = [k for k, why in picks.items() if "farthest pair" in why]
    assert float(np.linalg.norm(p[i] - p[j])) == pytest.approx(_brute_force(p[::7]), abs=0.01)
    assert float(np.linalg.norm(p[i] - p[j])) == pytest.approx(0.3)
    assert picks[0].startswith("start") and picks[N - 1].endswith("end")
    assert rp.scene_figure(run, str(tmp_path / "scene.png"))
    assert (tmp_path / "scene.png").stat().st_size > 20_000


def test_report_writes_every_figure(run, capsys):
    assert main(["report", str(run.run)]) == 0
    for name in ("pose", "tracking", "tensions", "torques", "timing", "scene"):
        assert (run.run / f"{name}.png").stat().st_size > 10_000, name
    assert "scene.png" in capsys.readouterr().out


def test_report_without_a_recording_says_why(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 1
    assert "state.csv is missing (record a run first)" in capsys.readouterr().err
    (tmp_path / "state.csv").write_text("time,state\n")
    assert main(["report", str(tmp_path)]) == 1
    assert "has no rows" in capsys.readouterr().err
    (tmp_path / "state.csv").write_text("time,state,x\n1.0,ready,1.5\n")
    (tmp_path / "meta.json").write_text("[1, 2]")
    assert main(["report", str(tmp_path)]) == 1
    assert "meta.json is not the robot's status" in capsys.readouterr().err


def test_a_state_from_before_the_loop_is_left_out(tmp_path, rowc):
    """A recording started with the daemon gets one state stamped 0.0 (before the loop's
    first cycle; the loop's clock is thousands of s on): it squeezed every plot's run into
    its right edge. state.csv starts at the loop's first state."""
    cables = list(SceneLayout.from_model(rowc).names)
    early = {**_state(0, cables), "time": 0.0, "state": "init"}
    _write_csvs(tmp_path, {"state": [early] + [_state(i, cables) for i in range(5)],
                           "timing": [], "events": []})  # fmt: skip
    lines = (tmp_path / "state.csv").read_text().splitlines()
    assert len(lines) == 6 and lines[1].startswith(f"{T0},")
