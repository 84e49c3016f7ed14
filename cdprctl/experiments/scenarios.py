"""The reliability matrix (issue 8): each fault injected mid-motion into the closed loop in
lock-step (deterministic, seeded), with what the loop did measured.
tests/experiments/test_reliability.py asserts on these runs; tools/reliability_table.py writes
docs/reliability.md from them.

Per run: the time from the fault to the supervisor leaving the healthy states (detection),
the state and reason it ended in (reaction), the platform's largest distance from its
reference after the fault (excursion), the largest commanded tension and torque, the
invariants (every torque finite and within its limit; every commanded tension inside
[t_min, t_max] while healthy), and whether reset + enable brought it back once the fault
cleared (recovery).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprctl.control.command_types import EnableCommand, MoveCommand, ResetCommand
from cdprctl.control.cycle.controller import Controller
from cdprctl.control.lifecycle.manager import ControllerManager
from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.model.robot import RobotModel
from sim_backend.faults import FaultEvent, FaultInjector

HEALTHY = (State.ENABLED, State.MOVING)
START = np.array([1.5, 0.35, 0.59])  # m, rowc's home
TARGET = np.array([1.9, 0.35, 0.50])  # m: the move the faults interrupt


@dataclass(frozen=True)
class Scenario:
    name: str
    kind: str  # the injected fault, sim_backend.faults.KINDS, or "sigkill"
    cable: int | None = None
    value: Any = 0.0
    duration: float = 1.0  # s; the fault clears after it (math.inf: never)
    expected: str = ""  # what should happen, for the table
    jet: float = 0.0  # N along y at the platform from the move's start (the water jet)
    brake_close: float = 0.0  # s the simulated brakes take to close (PlantOptions)


SCENARIOS = (
    Scenario("frame loss 1 %", "frame_loss", value=0.01, expected="ride through"),
    Scenario(
        "frame loss 5 %", "frame_loss", value=0.05, expected="ride through, or stop and recover"
    ),
    Scenario("frame loss 20 %", "frame_loss", value=0.20, expected="ride through or stop"),
    Scenario("frames delayed 3 ms", "frame_delay", value=0.003, expected="ride through"),
    Scenario("frames corrupted 5 %", "frame_corruption", value=0.05, expected="stop and recover"),
    Scenario("drive fault (0x2310)", "drive_fault", cable=2, value=0x2310, expected="stop"),
    Scenario("drive silent 1 s", "silent_drive", cable=3, expected="stop"),
    Scenario(
        "encoder jump 0.5 rad",
        "encoder_jump",
        cable=1,
        value=0.5,
        duration=math.inf,
        expected="stop",
    ),
    Scenario("cable snaps", "cable_snap", cable=0, duration=math.inf, expected="stop"),
    Scenario(
        "winch slips 0.05 m/s", "winch_slip", cable=5, value=0.05, duration=0.5, expected="stop"
    ),
    Scenario(
        "400 N lateral force",
        "external_wrench",
        value=(0.0, 400.0, 0.0, 0.0, 0.0, 0.0),
        duration=1.0,
        expected="stop",
    ),
    Scenario(
        "e-stop mid-move, released after 1 s",
        "estop",
        duration=1.0,
        expected="e-stop state, the drop measured; reset once released",
    ),
    Scenario(
        "e-stop released at once (20 ms)",
        "estop",
        duration=0.02,
        expected="e-stop state; reset, enable",
    ),
    Scenario(
        "e-stop under the 30 N water jet",
        "estop",
        duration=1.0,
        jet=30.0,
        expected="e-stop state, the drop measured; reset once released",
    ),
    Scenario(
        "e-stop, brakes closing in 30 ms",
        "estop",
        duration=1.0,
        brake_close=0.03,
        expected="e-stop state; the drums free until the brakes close",
    ),
    Scenario(
        "e-stop released while the brakes close (10 of 30 ms)",
        "estop",
        duration=0.01,
        brake_close=0.03,
        expected="e-stop state; reset, enable",
    ),
    Scenario(
        "daemon SIGKILLed, restarted",
        "sigkill",
        duration=2.0,
        expected="drives time out; restart holds without a jump",
    ),
)


@dataclass
class Result:
    scenario: Scenario
    detection_s: float | None = None  # fault → STOPPING/FAULT (None: never left healthy)
    reaction: str = ""
    fault_kind: str = ""  # the supervisor's FaultKind ("" when it never faulted)
    excursion_mm: float = 0.0
    max_tension_n: float = 0.0
    max_torque_nm: float = 0.0
    torque_limit_nm: float = 0.0
    nonfinite_torques: int = 0
    torques_over_limit: int = 0
    tensions_outside_limits_while_healthy: int = 0
    recovered: str = ""
    notes: list[str] = field(default_factory=list)
    # the cables' contacts at the plant's true pose over the run (sim_backend/contact.py), and
    # the least distance met (mm; inf: nothing to check)
    contacts: int = 0
    least_clearance_mm: float = math.inf

    @property
    def invariants_hold(self) -> bool:
        return (
            self.nonfinite_torques == 0
            and self.torques_over_limit == 0
            and self.tensions_outside_limits_while_healthy == 0
        )


class Watch:
    """Per-cycle checks of a controller against the plant."""

    def __init__(self, model: RobotModel, res: Result):
        self.model = model
        self.res = res
        self.limit = np.array([c.winch.torque_limit for c in model.cables])
        res.torque_limit_nm = float(self.limit.max())

    def check(self, c: Controller, p_true: np.ndarray, measure_excursion: bool) -> None:
        r = self.res
        tau = c.data.torques
        if not np.all(np.isfinite(tau)):
            r.nonfinite_torques += 1
        else:
            r.torques_over_limit += int(np.sum(np.abs(tau) > self.limit + 1e-9))
            r.max_torque_nm = max(r.max_torque_nm, float(np.max(np.abs(tau))))
        if c.data.state in HEALTHY:
            t = c.data.tensions
            bad = np.sum(t < self.model.tension_min - 1e-9) + np.sum(
                t > self.model.tension_max + 1e-9
            )
            r.tensions_outside_limits_while_healthy += int(bad)
        r.max_tension_n = max(r.max_tension_n, float(np.max(c.data.tensions)))
        if measure_excursion:
            # from the reference while the controller drives it; in the e-stop, from where the
            # platform was when the chain opened (the reference means nothing there)
            ref = c.supervisor.estop.start if c.data.state is State.ESTOP else c.trajectory.position
            d = float(np.linalg.norm(p_true - ref[:3])) * 1e3
            r.excursion_mm = max(r.excursion_mm, d)


def run(model: RobotModel, sc: Scenario, seed: int = 0, observe: float = 2.5) -> Result:
    """The scenario on ``model`` (rowc): enable, start the move, inject the fault 0.5 s in."""
    res = Result(sc)
    watch = Watch(model, res)
    cl = ClosedLoop(model)
    cl.plant.opt.brake_close_time = sc.brake_close
    try:
        cl.startup()
        cl.command("enable")
        cl.run(0.3)
        if sc.jet:
            jet = (0.0, sc.jet, 0.0, 0.0, 0.0, 0.0)
            FaultInjector([FaultEvent(cl.net.time, "external_wrench", value=jet, ramp=0.3,
                                      duration=math.inf)]).attach(cl.net)  # fmt: skip
        cl.command("move", pose=np.concatenate([TARGET, model.home.rpy]))
        cl.run(0.5)
        t_fault = cl.net.time
        if sc.kind == "sigkill":
            return _sigkill(model, cl, res, watch, sc)
        fault = FaultEvent(t_fault, sc.kind, sc.cable, sc.value, duration=sc.duration)
        if cl.net.faults is not None:  # beside the jet's
            cl.net.faults.events.append(fault)
        else:
            FaultInjector([fault], seed=seed).attach(cl.net)
        c = cl.controller
        _observe(cl, watch, res, t_fault, observe)
        d = c.data
        res.reaction = d.state.value + (f": {d.fault_reason}" if d.fault_reason else "")
        res.fault_kind = c.data.fault_kind.value if c.data.fault_kind is not None else ""
        _recover(cl, res, watch, t_fault + sc.duration)
    finally:
        res.contacts = len(cl.plant.contact.contacts)
        res.least_clearance_mm = cl.plant.contact.least * 1e3
        cl.close()
    return res


def _observe(cl: ClosedLoop, watch: Watch, res: Result, t_fault: float, seconds: float) -> None:
    def each(cl: ClosedLoop) -> None:
        c = cl.controller
        if res.detection_s is None and c.data.state in (State.STOPPING, State.FAULT, State.ESTOP):
            res.detection_s = cl.net.time - cl.period - t_fault
        # while the controller drives it, and in the e-stop (the drop onto the brakes)
        held = c.data.state in (State.STOPPING, State.ESTOP)
        watch.check(c, cl.plant.position, measure_excursion=c.data.state in HEALTHY or held)

    cl.run(seconds, each=each, record=False)


def _recover(cl: ClosedLoop, res: Result, watch: Watch, t_clear: float) -> None:
    """Once the fault has cleared: reset (if it faulted), enable, a move back to the start."""
    c = cl.controller
    if c.data.state in HEALTHY and res.detection_s is None:
        if c.data.state is State.MOVING:
            _steps(cl, watch, 3.0, until=lambda: c.data.state is not State.MOVING)
        at = np.linalg.norm(cl.plant.position - TARGET) * 1e3
        res.recovered = f"rode through; move finished {at:.1f} mm from its target"
        return
    if not math.isfinite(t_clear):
        res.recovered = "no (the fault is permanent)"
        if c.data.state is State.FAULT:
            c.submit(ResetCommand())
            _steps(cl, watch, 1.0)
            res.notes.append(
                f"reset with the fault still present: {c.data.state.value} {c.data.fault_reason}"
            )
        return
    if cl.net.time < t_clear:
        _steps(cl, watch, t_clear - cl.net.time)
    # a controlled stop ends in FAULT after stop_duration: reset only then; an e-stop's drop is
    # measured until the platform rests on the brakes
    _steps(cl, watch, 3.0, until=lambda: c.data.state is not State.STOPPING
           and (c.data.state is not State.ESTOP or c.supervisor.estop.settled))  # fmt: skip
    c.submit(ResetCommand())
    _steps(cl, watch, 1.0)
    if c.data.state is not State.READY:
        res.recovered = f"no: reset left it {c.data.state.value} {c.data.fault_reason}"
        return
    c.submit(EnableCommand())
    _steps(cl, watch, 0.5)
    before = cl.plant.position.copy()
    c.submit(MoveCommand(pose=np.concatenate([START, cl.model.home.rpy])))
    _steps(cl, watch, 4.0)
    err = np.linalg.norm(cl.plant.position - START) * 1e3
    ok = c.data.state is State.ENABLED and err < 2.0
    res.recovered = (
        f"yes: reset, enable, move back ({err:.1f} mm)"
        if ok
        else f"no: {c.data.state.value} {c.data.fault_reason} ({err:.1f} mm)"
    )
    res.notes.append(f"platform at re-enable {np.round(before, 4).tolist()} m")


def _steps(
    cl: ClosedLoop, watch: Watch, seconds: float, until: Callable[[], bool] | None = None
) -> None:
    """At least one cycle, each checked by ``watch``; ends early when ``until()``."""
    cl.run(
        max(seconds, cl.period),
        until=None if until is None else lambda _: until(),
        each=lambda cl: watch.check(cl.controller, cl.plant.position, measure_excursion=False),
        record=False,
    )


def _sigkill(model: RobotModel, cl: ClosedLoop, res: Result, watch: Watch, sc: Scenario) -> Result:
    """The controller stops dead mid-motion (no frame, no disable): the drives' communication
    timeout must stop them and close the brakes; a new controller on a new driver (the
    restarted daemon) must find the pose and hold it without a jump."""
    from drivers import create_driver

    t_kill = cl.net.time
    # the process is gone: its sockets close, nothing more is sent
    for bus in getattr(cl.rig.driver, "buses", ()):
        bus.shutdown()
    p_kill = cl.plant.position.copy()
    disabled_at = None
    trace = []
    for _ in range(round(sc.duration / cl.period)):
        cl.net.advance(cl.period)
        trace.append(cl.plant.position.copy())
        if disabled_at is None and bool(np.all(cl.plant.brake)):
            disabled_at = cl.net.time - t_kill
    last = np.array(trace[-round(0.5 / cl.period) :])
    swing = float(np.max(np.linalg.norm(last - last[-1], axis=1))) * 1e3
    res.notes.append(
        f"platform motion on the brakes in the 0.5 s before the restart: {swing:.3f} mm"
    )
    res.detection_s = disabled_at
    drift = np.linalg.norm(cl.plant.position - p_kill) * 1e3
    res.excursion_mm = float(drift)
    res.reaction = (
        f"drives disabled, brakes closed after {disabled_at * 1e3:.0f} ms"
        if disabled_at is not None
        else "drives still enabled"
    )
    driver = create_driver(
        model,
        period=cl.period,
        clock=cl.rig.clock,
        wait=cl.net.advance,
        bus_overrides=cl.rig.overrides,
    )
    m2 = ControllerManager(model, driver)
    c2 = m2.controller
    try:
        m2.startup()
        c2.submit(EnableCommand())
        p0 = cl.plant.position.copy()
        jump = 0.0
        for _ in range(round(1.0 / cl.period)):
            m2.step(cl.net.time)
            cl.net.advance(cl.period)
            watch.check(c2, cl.plant.position, measure_excursion=False)
            jump = max(jump, float(np.linalg.norm(cl.plant.position - p0)) * 1e3)
        ok = c2.data.state is State.ENABLED and jump < 0.5
        res.recovered = (
            f"{'yes' if ok else 'no'}: restarted, {c2.data.state.value}, largest move while "
            f"taking over {jump:.3f} mm"
        )
    except RuntimeError as exc:
        res.recovered = f"no: restart failed: {exc}"
    finally:
        driver.shutdown()
    return res
