"""What ``cdprctl run`` prints and keeps: the start-up lines (gains, the drives' identities),
the status line, the tracking statistics and the summary at exit; the configuration summary
the gateway serves. Read from ``ControlData`` and the loop's statistics only."""

from __future__ import annotations

import collections
import json
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.control.data import PHASES, ControlData
from cdprctl.control.states import ACTIVE_STATES, State
from cdprctl.model.robot import RobotModel


class RunReport:
    def __init__(self, model: RobotModel, data: ControlData, stats: Any):
        self.model, self.data, self.stats = model, data, stats
        self.errors: list[float] = []  # m, the reference against the estimate
        self.true_errors: list[float] = []  # m, against the simulated platform
        self.faults: collections.Counter[str] = collections.Counter()
        self.summary: dict[str, Any] = {}

    def track(self, true_position: Any) -> None:
        """One sample of the tracking error while the drives hold or move the platform (a
        disable's deceleration included)."""
        d = self.data
        if d.state in (State.ENABLED, State.MOVING, State.DISABLING):
            ref = d.reference[:3]
            self.errors.append(float(np.linalg.norm(ref - d.position)))
            if true_position is not None:  # the truth the simulator knows
                self.true_errors.append(float(np.linalg.norm(ref - true_position)))

    def status_line(self, now: float, every: float, true_position: Any) -> str:
        d, p = self.data, self.data.position
        # percentiles over the cycles since the last line (the whole run: in the summary)
        s = self.stats.summary(round(every / self.model.control.period))
        sim = ""
        if true_position is not None:
            q = true_position
            sim = f" true [{q[0]:.3f} {q[1]:.3f} {q[2]:.3f}]"
        # commanded tensions only while the drives are on: off, the brakes hold what they hold
        commanded = (
            f"t {d.tensions.min():5.1f}..{d.tensions.max():5.1f} N tda {d.tda_status.name}"
            if d.state in ACTIVE_STATES else "drives off, brakes closed"
        )  # fmt: skip
        return (
            f"t={now:6.1f}s {d.state.value:<9} P [{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}] m{sim} err "
            f"{np.linalg.norm(d.pose_error[:3]) * 1e3:5.2f} mm {commanded}"
            + (f" sat {d.saturation:.2f}" if d.saturation < 1.0 else "")
            + (f" path {d.path_segment}/{d.path_segments} "
               f"{d.path_fraction:.0%} {d.path_state}" if d.path_segments else "")
            + " "
            f"late p99 {s.get('lateness_p99_us', 0):6.0f} us missed {int(s.get('missed', 0))}"
        )  # fmt: skip

    def finish(self, driver_stats: dict[str, Any]) -> list[str]:
        """The summary (``self.summary``) and its lines, at exit."""
        s, d = self.stats.summary(), self.data
        errs = np.array(self.errors) if self.errors else np.zeros(1)
        per_phase = self.stats.phases[: min(self.stats.count, self.stats.size)]
        phases = {
            name: (float(np.median(per_phase[:, k])), float(np.percentile(per_phase[:, k], 99)))
            for k, name in enumerate(PHASES)
        } if len(per_phase) else {}  # fmt: skip
        true = {}
        if self.true_errors:
            true = {
                "true_tracking_rms_mm": float(np.sqrt(np.mean(np.square(self.true_errors)))) * 1e3,
                "true_tracking_max_mm": float(np.max(self.true_errors)) * 1e3,
            }
        self.summary = {
            "loop": s,
            "phases_us": phases,
            "tracking_rms_mm": float(np.sqrt(np.mean(errs**2)) * 1e3),
            "tracking_max_mm": float(errs.max() * 1e3),
            **true,
            "final_state": d.state.value,
            "fault": d.fault_reason,
            "driver": driver_stats,
            "faults": dict(self.faults),
            "saturated_cycles": d.saturated_cycles,
        }
        lines = [
            "summary:",
            f"  cycles {int(s.get('cycles', 0))}, wake lateness p50 "
            f"{s.get('lateness_p50_us', 0):.1f} us, p99 {s.get('lateness_p99_us', 0):.1f}"
            f" us, max {s.get('lateness_max_us', 0):.0f} us; compute p50 "
            f"{s.get('compute_p50_us', 0):.0f} us, p99 {s.get('compute_p99_us', 0):.0f} "
            f"us; overruns {int(s.get('overruns', 0))}, missed periods "
            f"{int(s.get('missed', 0))} ({s.get('missed_percent', 0):.3f} %)",
        ]
        if phases:
            lines.append("  per phase (median/p99 us): "
                         + ", ".join(f"{k} {v[0]:.0f}/{v[1]:.0f}" for k, v in phases.items()))
        if d.saturated_cycles:
            lines.append(f"  feedback saturated in {d.saturated_cycles} cycles (the cables gave "
                         "what they could: docs/control.md)")
        unsent = int(driver_stats.get("send_errors", 0))
        unread = int(driver_stats.get("receive_errors", 0))
        if unsent or unread:  # the bus refused them (down, bus-off, TX full)
            lines.append(f"  CAN frames the bus would not take: {unsent}, reads it refused: "
                         f"{unread} (link down, bus-off or TX queue full; ridden through up to "
                         "[drives] feedback_timeout)")  # fmt: skip
        if self.faults:
            lines.append("  faults handled: "
                         + ", ".join(f"{k} {n}" for k, n in self.faults.most_common()))
        if true:
            lines.append(f"  tracking error (the simulated platform) RMS "
                         f"{true['true_tracking_rms_mm']:.2f} mm, max "
                         f"{true['true_tracking_max_mm']:.2f} mm")
        lines.append(
            f"  tracking error (estimated) RMS {self.summary['tracking_rms_mm']:.2f} mm, "
            f"max {self.summary['tracking_max_mm']:.2f} mm; final state "
            f"{d.state.value}" + (f" ({d.fault_reason})" if d.fault_reason else "")
        )  # fmt: skip
        return lines


def gains_line(model: RobotModel, data: ControlData, driver: Any = None) -> str:
    """Where the loop's gains come from: in position mode all from the model (an ODrive
    driver's axes: the gains it sent them, ``driver.gains``)."""
    g = data.gains
    axes = [a for a in getattr(driver, "gains", None) or () if a is not None]
    if model.drives.holds_lengths and axes:
        a = axes[0]
        same = all(x == a for x in axes)
        return (
            f"gains from the model: ODrive axes hold the lengths (position control, "
            f"passthrough; the loop at {a.bandwidth:g} Hz on each rotor's inertia, at most a "
            f"fifth of the control rate; sent by CAN: "
            + (a.line() if same else f"cable 1 {a.line()}, the others per rotor")
            + f"; following error supervised by cdprctl: {window_text(model, driver)}"
            + f"), force feedback {g['force_feedback']:.1f} rad/s, external-wrench estimate "
            f"{g['disturbance_bandwidth']:.3g} Hz"
        )
    if model.drives.holds_lengths:
        torque = ", ".join(model.cables[i].name for i in model.drives.torque_cables)
        return (
            f"gains from the model: drives hold the lengths (csp, position loops "
            f"{model.drives.position_loop_bandwidth:g} Hz on each rotor's inertia"
            + (f"; cables {torque} in torque mode, their grippers'" if torque else "")
            + f"), force feedback {g['force_feedback']:.1f} rad/s (the lowest mode × "
            f"{model.control.force_feedback:g}), external-wrench estimate "
            f"{g['disturbance_bandwidth']:.3g} Hz"
        )
    return (
        "gains: torque mode, the pose loop at [control] bandwidth "
        + "/".join(f"{x:.2g}" for x in g["pose_bandwidth"])
        + " Hz (x y z roll pitch yaw; set by hand: "
        'docs/control.md, "Gains from the model")'
    )


def window_text(model: RobotModel, driver: Any) -> str:
    """The following-error window of the first cable in position mode (rad at the motor and
    mm of cable) and its time-out."""
    c = next(i for i, g in enumerate(driver.gains) if g is not None)
    w = model.cables[c].winch
    rad = float(driver.following_window[c])
    return (f"beyond {rad:.3g} rad ({rad * w.drum_radius / w.gear_ratio * 1e3:.2f} mm of cable) "
            f"for {model.drives.following_error_timeout * 1e3:g} ms")  # fmt: skip


def identity_lines(model: RobotModel, driver: Any) -> tuple[list[str], str]:
    """The drives' identities (0x1018, read at set-up): a line per drive, and the JSON the
    status carries ("" when the driver reads none)."""
    identities = getattr(driver, "identities", None)
    nodes = getattr(driver, "node", None)
    if not identities or nodes is None:
        return [], ""
    lines, drives = [], []
    for c, ident in enumerate(identities):
        node = int(nodes[c])
        drives.append({"cable": model.cables[c].name, "node": node, **(ident or {})})
        text = ", ".join(f"{k} 0x{v:08X}" for k, v in ident.items()) if ident else (
            "no identity object")  # fmt: skip
        lines.append(f"drive of cable index {c} (node {node}): {text}")
    skipped = getattr(driver, "skipped", None) or [[] for _ in identities]
    for c, what in enumerate(skipped):
        drives[c]["skipped"] = list(what)
    lines += skipped_lines(skipped, [int(n) for n in nodes])
    return lines, json.dumps(drives)


def skipped_lines(skipped: list[list[str]], nodes: list[int]) -> list[str]:
    """What each drive's set-up skipped (drivers/cia402/drive_setup.OPTIONAL), a line per
    object, drives that skipped the same named together."""
    groups: dict[tuple[str, ...], list[int]] = {}
    for c, what in enumerate(skipped):
        if what:
            groups.setdefault(tuple(what), []).append(c)
    lines = []
    for items, cables in groups.items():
        who = (f"drive of cable index {cables[0]} (node {nodes[cables[0]]})" if len(cables) == 1
               else f"drives of cable indices {', '.join(map(str, cables))} (nodes "
                    f"{', '.join(str(nodes[c]) for c in cables)})")  # fmt: skip
        lines += [f"{who}: {line}" for line in items]
    return lines


def safety_summary(model: RobotModel, state_dir: Path, required: bool) -> dict[str, Any]:
    """The brake test on record (``required``: a real robot, which ``run`` enables only with
    a passed one younger than the interval) and each fault kind's stop category."""
    from cdprctl.model.safety import STOP_CATEGORIES
    from cdprctl.safety.brake_record import BrakeTestError, due_time, load

    test: dict[str, Any] = {"required": required, "time": None, "passed": None,
                            "next_due": None}  # fmt: skip
    try:
        rec = load(state_dir)
        if rec.robot == model.name:
            test.update(time=rec.time, passed=rec.passed, next_due=due_time(rec, model))
    except BrakeTestError:
        pass
    stops = {k: model.safety.category_of(k) for k in STOP_CATEGORIES}
    return {"brake_test": test, "stop_category": stops}


def config_summary(model: RobotModel, simulated: bool, state_dir: Path | None = None,
                   brake_test_required: bool = False) -> dict[str, Any]:  # fmt: skip
    """What the gateway's status serves of the configuration."""
    import cdprctl
    from cdprctl.calibration.friction_record import friction_summary
    from cdprctl.telemetry.foxglove.scene import SceneLayout

    m, c = model, model.control
    return {
        "robot": m.name,
        "config_file": m.source_file,
        "cables": [w.name for w in m.cables],
        "tension_min": m.tension_min.tolist(),
        "tension_max": m.tension_max.tolist(),
        "torque_limit": [w.winch.torque_limit for w in m.cables],
        "rate_hz": c.rate,
        "tda": c.tda_method,
        "limits": {  # what a jog may ask (control/intake/jog.py)
            "max_velocity": c.max_velocity,
            "max_angular_velocity": c.max_angular_velocity,
            "jog_deadman": c.jog_deadman,
        },
        "workspace": {
            "position_min": m.workspace.position_min.tolist(),
            "position_max": m.workspace.position_max.tolist(),
            "max_angle": m.workspace.max_angle,
        },
        # what a client needs to draw the robot (cdprctl record --mcap's scene)
        "layout": SceneLayout.from_model(m).to_dict(),
        # the ROS 2 link's topics (docs/ros2.md): a recording's ROS 2 channels name them alike
        "ros2": {"enabled": m.ros2.enabled, "namespace": m.ros2.topic_namespace(m.name),
                 "domain_id": None if m.ros2.environment_problem() else m.ros2.domain()},
        "simulated": simulated,
        **({"safety": safety_summary(m, state_dir, brake_test_required),
            "friction": friction_summary(m, state_dir)}
           if state_dir is not None else {}),
        "versions": {"cdprctl": getattr(cdprctl, "__version__", "?"), **_versions()},
    }


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("eclipse-zenoh", "python-can", "ruckig", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "?"
    return out
