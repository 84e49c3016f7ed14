"""``cdprctl run``: the controller daemon — the start-up's order and the threads' wiring.

Start-up (config checked, links started, drives configured, pose estimated and checked
holdable), then the fixed-rate loop in the main thread. A second thread does all I/O: the
events the loop queued, the links (``links.py``), the scripted clients (``scripts.py``), the
status line (``report.py``), the systemd watchdog. SIGTERM/SIGINT: a controlled stop
(decelerate, disable the drives: the brakes hold), exit code 0.

With ``--sim`` the simulated robot of ``sim_backend`` runs in a child process, on the other CPU
as drives run on processors of their own, over socket pairs (``sim_backend/process.py``): what
a newcomer runs to see the whole system. Without it the drives are real (or ``cdprctl sim`` in
another process, met through ``--can-interface/--can-channel``). The daemon reads the loop
only through ``ControlData`` and talks to it only through the command mailbox.
"""

from __future__ import annotations

import signal
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cdprctl.control.command_types import DisableCommand, ResetCommand, StopCommand
from cdprctl.control.data import PHASES
from cdprctl.control.intake.desk import FULL
from cdprctl.control.lifecycle.loop import LoopStats
from cdprctl.control.lifecycle.manager import ControllerManager
from cdprctl.control.states import State
from cdprctl.core import realtime as rt
from cdprctl.daemon.links import Links, links_of
from cdprctl.daemon.report import RunReport, config_summary, gains_line
from cdprctl.daemon.scripts import Disturbance, PathScript, demo_script
from cdprctl.daemon.sdnotify import Watchdog, notify, watchdog_interval
from cdprctl.daemon.startup import (
    StartupInterrupted,
    StartupRefusedError,
    forget_stop_signals,
    start_up,
    stop_if_interrupted,
)
from cdprctl.geometry.interference import check_pose
from cdprctl.model.robot import RobotModel
from cdprctl.tda import tda_options_of
from sim_backend.contact import CONTACT_EXIT

if TYPE_CHECKING:
    from sim_backend.process import SimulatedRobotProcess

DRIVES_OFF = frozenset({State.READY, State.FAULT, State.ESTOP, State.INIT})
# where a demo played once ends (an e-stop too: its reset is the operator's, never the demo's)
DEMO_ENDS = frozenset({State.READY, State.FAULT, State.ESTOP})  # what a stop waits for
SCRIPT_STOPS = frozenset({State.FAULT, State.ESTOP})  # a scripted client sends nothing more

class Daemon:
    # after a signal the I/O thread ends the run with a controlled stop; if it cannot (it died
    # or hangs), the loop ends this long after the signal: the drives' communication timeout
    # then stops them, and shutdown() disables them
    STOP_FALLBACK = 5.0  # s

    def __init__(self, model: RobotModel, sim: bool, overrides: dict[str, Any],
                 realtime: bool = True, status_every: float = 0.5, out: Any = None,
                 zenoh: bool = False, timing_file: str | None = None,
                 state_dir: str | None = None, foxglove: str | None = None,
                 as_built: RobotModel | None = None, ros2: bool = False):  # fmt: skip
        """``state_dir``: where the calibration record is (default
        ``/var/lib/cdprctl/<robot>``, a simulated robot's apart from it: ``state_dir.py``);
        not read when the encoders are trusted to read zero at home (``[drives]
        assume_home_at_start``, or the simulated robot of ``sim``, which starts there).
        ``foxglove``: ``[HOST:]PORT`` of the live 3D view (or ``[foxglove] listen`` in the
        config). ``ros2``: publish to ROS 2 (or ``[ros2] enabled``).
        ``as_built``: with ``sim``, the robot the simulated plant is (its geometry; the drives
        from ``model``), in a process of its own (``sim_backend/process.py``)."""
        from cdprctl.core.state_dir import default_state_dir, simulated_state_dir
        from drivers import create_driver
        from drivers.simulated import simulated_robot

        self.model = model
        self.bus_hint = ""  # the bus options given, as options: the refusals' commands repeat them
        # a simulated robot's records are apart from a real robot's (cdprctl/core/state_dir.py)
        self.simulated_robot = sim or simulated_robot(model, overrides)
        self.state_dir = Path(state_dir) if state_dir else (
            simulated_state_dir if self.simulated_robot else default_state_dir)(model.name)
        self.assume_home = sim or model.drives.assume_home_at_start
        self.record: Any = None
        self.brake_record: Any = None  # the brake test a real robot's start-up took
        self.out = out if out is not None else sys.stdout
        # first, before the simulated robot is built (its first build compiles for ~10 s)
        self.say(f"cdprctl run: {model.name}, {model.n_cables} {model.drives.driver} drives, "
                    f"{model.control.rate:g} Hz, TDA {tda_options_of(model).method.value}"
                    + (", simulated robot" if sim else ""))  # fmt: skip
        if sim:
            self.say("building the simulated robot (the first run on a machine compiles its "
                        "kernels too: about 15 s more)")  # fmt: skip
        self.status_every, self.timing_file, self.realtime = status_every, timing_file, realtime
        self._cycle_done = threading.Event()  # set by the loop after each cycle
        period = model.control.period
        self.sim: SimulatedRobotProcess | None = None
        self.driver: Any = None
        try:
            if sim:
                from sim_backend.process import SimulatedRobotProcess

                self.sim = SimulatedRobotProcess(model, as_built, realtime, self.say)
                self.driver = create_driver(model, period=period, bus_overrides=self.sim.overrides)
                self.driver.liveness.drives_ran_at = self.sim.stepped_at
            else:
                self.driver = create_driver(model, period=period, bus_overrides=overrides)
        except BaseException:  # a stop signal while they were built: their buses closed
            self._close_buses()  # (python-can warned "not properly shut down" at exit)
            raise
        self.manager = ControllerManager(model, self.driver)
        self.data = self.manager.data
        self.stats = LoopStats(phases=len(PHASES))
        self.report = RunReport(model, self.data, self.stats)
        self.stop_requested = threading.Event()
        self.finished = threading.Event()
        self._stop_deadline = float("inf")
        self._stopped_by = ""  # the signal that asked for the stop
        # s: the longest a stop waits for the drives to be off (a disable's deceleration)
        self._stop_wait = self.manager.controller.supervisor.disable_within + 1.0
        self._last_fault = ""  # the fault the links were last told of
        self.links = Links(links_of(model, zenoh, foxglove,
                                    lambda: config_summary(model, self.sim is not None,
                                                           self.state_dir,
                                                           not self.assume_home),
                                    ros2=ros2))  # fmt: skip

    def _close_buses(self) -> None:
        if self.driver is not None:
            self.driver.shutdown()
        self._close_sim()

    def _close_sim(self) -> None:
        """The simulated robot's process ended, and the reads it was not run for said."""
        if self.sim is None:
            return
        liveness = self.driver.liveness if self.driver is not None else None
        if liveness is not None:
            liveness.drives_ran_at = None  # the view of its page released: the page closes
            if stalled := int(liveness.stalled_reads[0]):
                self.say(f"cdprctl run: {stalled} reads without feedback ridden through: the "
                         "simulated robot was not run meanwhile (a busy machine), its drives "
                         "deaf — the simulator's lateness, not a drive's silence")  # fmt: skip
        self.sim.close()

    @property
    def summary(self) -> dict[str, Any]:
        return self.report.summary

    def run(self, duration: float | None, demo: bool, force: float = 0.0,
            path: tuple[str, str, str] | None = None) -> int:  # fmt: skip
        """``path``: (name, text, units) of a path file to play once (enable, the path, disable);
        checked whole before the drives are enabled (exit 2 when rejected)."""
        try:
            return self._run(duration, demo, force, path)
        finally:  # however it ended: what the start-up froze is collectable again
            rt.restore_gc()

    def _run(self, duration: float | None, demo: bool, force: float,
             path: tuple[str, str, str] | None) -> int:  # fmt: skip
        m, d = self.model, self.data
        self.say(gains_line(m, d, self.driver))
        try:
            script = start_up(self, path)
            # from here a signal is the loop's controlled stop (until now: the start-up's end)
            old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
            stop_if_interrupted()  # a signal whose exception a library swallowed ends it here
        except (StartupRefusedError, StartupInterrupted) as exc:
            self.say(exc.message, err=True)
            self._close_buses()
            self.links.close()
            return exc.code
        finally:
            forget_stop_signals()
        p = d.position
        self.say(f"ready: pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m, holding tensions "
                    f"{d.hold_tensions.min():.1f}..{d.hold_tensions.max():.1f} N")  # fmt: skip
        g = check_pose(m, d.position, d.rotation)  # at the estimated start pose (before the loop)
        if g.minimum < g.clearance:
            self.say(f"warning: at the start pose {g.describe()}, under the clearance "
                     f"{g.clearance * 1e3:.2f} mm: a motion may leave it, never closer than "
                     "here (a move home: than home) (docs/clearance.md)", err=True)  # fmt: skip
        notify("READY=1")
        io = threading.Thread(target=self._io, args=(duration, demo, force, script),
                              name="cdprctl-io", daemon=True)  # fmt: skip
        interval = watchdog_interval()
        wd = Watchdog(lambda: d.cycle, interval, on_start=self._helper_thread) if interval else None
        try:  # the helper threads started in it leave the loop's CPU and priority
            with rt.realtime_loop(m.control, self.realtime,
                                  lambda w: self.say(f"warning: {w}", err=True)):  # fmt: skip
                if wd is not None:
                    wd.start()
                io.start()
                self.manager.run(self._should_stop, self.stats, after=self._cycle_done.set)
        finally:
            if wd is not None:
                wd.stop()
            if self.timing_file:
                self.stats.save(self.timing_file, m.control.period)
            notify("STOPPING=1")
            if io.ident is not None:
                io.join(timeout=2.0)
            self.driver.shutdown()
            self._close_sim()
        self._drain_events()
        self.links.close()
        for line in self.report.finish(self.driver.stats.as_dict()):
            self.say(line)
        if script is not None and script.rejected:  # checked whole: the drives never enabled
            self.say(f"cdprctl run: path {script.name} rejected: {script.rejected}", err=True)
            code = 2
        elif path is not None and not self.stop_requested.is_set():
            why = (f" (stopped at the {d.state.value}: {d.fault_reason})"
                   if d.state in SCRIPT_STOPS else "")  # fmt: skip
            self.say(f"path {path[0]}: {d.path_state or 'not run'}{why}")
            code = 0 if d.path_state == "done" else 3
        else:
            code = 0 if d.state is not State.FAULT or self.stop_requested.is_set() else 3
        if code == 0 and self.sim is not None and self.sim.contacts:
            self.say(f"cdprctl run: exit {CONTACT_EXIT}: the simulated robot recorded "
                     f"{self.sim.contacts} contact(s) (above)", err=True)  # fmt: skip
            code = CONTACT_EXIT
        for s, h in old.items():  # a signal during the shut-down above only asked again
            signal.signal(s, h)
        return code

    def _script_stopped(self, script: list[Any]) -> list[Any]:
        """The demo at a fault or an e-stop: its remaining commands are not sent (a faulted
        robot ignores them; a script talking to it misleads its reader), said in one line.
        With --duration the round after the fault's reset starts afresh."""
        d = self.data
        left = sum(not isinstance(step, Disturbance) for _, step in script)
        why = f" ({d.fault_reason})" if d.fault_reason else ""
        self.say(f"[t={d.time:9.3f}] demo: stopped at the {d.state.value}{why}; its "
                    f"remaining {left} commands not sent")  # fmt: skip
        if self.sim is not None and any(isinstance(step, Disturbance) for _, step in script):
            self.sim.disturb(0.0)  # the demo's own lateral force, due off later, off now
        return []

    def _on_signal(self, signum: int, frame: Any) -> None:
        if not self.stop_requested.is_set():
            self._stop_deadline = time.monotonic() + self.STOP_FALLBACK
            self._stopped_by = signal.Signals(signum).name
        self.stop_requested.set()

    def _should_stop(self) -> bool:
        return self.finished.is_set() or (
            self.stop_requested.is_set() and time.monotonic() > self._stop_deadline
        )

    # -- the I/O thread ----------------------------------------------------------------------------
    def _helper_thread(self) -> None:
        if self.realtime:
            rc = self.model.control
            rt.helper_thread(rt.loop_cpu(rc.cpu), rc.sched_priority)

    def _io(self, duration: float | None, demo: bool, force: float,
            path: PathScript | None) -> None:  # fmt: skip
        self._helper_thread()
        try:
            self._io_loop(duration, demo, force, path)
        except Exception as exc:  # the I/O thread must not die silently: stop the run
            self.say(f"cdprctl run: I/O thread failed: {type(exc).__name__}: {exc}", err=True)
            self.manager.submit(DisableCommand())
            self._await_disabled(time.monotonic())
            self.finished.set()

    def _await_disabled(self, since: float) -> None:
        """Until the drives are off (READY, FAULT, INIT): a disable's deceleration, at most the
        supervisor's ``disable_within`` and a second from ``since`` (was a fixed 0.5 s, shorter
        than a deceleration: the loop then ended mid-way)."""
        limit = since + self._stop_wait
        while self.data.state not in DRIVES_OFF:
            if time.monotonic() > limit:
                return
            time.sleep(self.model.control.period)

    def _io_loop(self, duration: float | None, demo: bool, force: float,
                 path: PathScript | None) -> None:  # fmt: skip
        d, submit, sim = self.data, self.manager.submit, self.sim
        t0 = time.monotonic()
        script = demo_script(self.model, force) if demo else []
        next_status = 0.0
        stopping_since: float | None = None
        next_tick = time.monotonic()
        while True:
            now = time.monotonic() - t0
            true = sim.position if sim is not None else None
            if sim is not None:
                sim.poll()
            self._drain_events()
            self.links.publish(d, self.stats, true)
            for taken in self.links.take_commands():
                if submit(taken) is FULL:  # a refusal's reason is an event already
                    self.links.event(d.time, f"command {taken.kind} dropped: mailbox full",
                                     "reject")  # fmt: skip
            if script and d.state in SCRIPT_STOPS:
                script = self._script_stopped(script)
            while script and script[0][0] <= now:
                step = script.pop(0)[1]
                if isinstance(step, Disturbance):
                    if sim is not None:
                        sim.disturb(step.force)
                        d.events.append((d.time, f"demo: {force:g} N lateral force "
                                         + ("on" if step.force else "off")))  # fmt: skip
                else:
                    submit(step)
            self.report.track(true)
            if self.status_every and now >= next_status:
                self.say(self.report.status_line(now, self.status_every, true))
                next_status += self.status_every
            if demo and not script and duration is not None and d.state is State.FAULT:
                submit(ResetCommand())  # a long demo run carries on after a fault
            if demo and not script and duration is not None and d.state is State.READY:
                # with --duration the demo plays again while a whole round still fits
                again = demo_script(self.model, force)
                if now + again[-1][0] < duration:
                    script = [(now + at, step) for at, step in again]
            if path is not None and not path.done and (cmd := path.step(d)) is not None:
                submit(cmd)
            end = (path is not None and path.done) or (
                duration is not None and now >= duration) or (
                demo and not script and duration is None and d.state in DEMO_ENDS
            )  # fmt: skip
            if (end or self.stop_requested.is_set()) and stopping_since is None:
                stopping_since = now
                drives_on = d.state in (State.ENABLED, State.MOVING, State.ENABLING)
                if self.stop_requested.is_set():
                    how = ": decelerating, then the drives disabled" if drives_on else ""
                    self.say(f"[t={d.time:9.3f}] stop requested by {self._stopped_by}{how}")
                if drives_on:
                    submit(StopCommand())
                    submit(DisableCommand())
            if stopping_since is not None and (
                d.state in DRIVES_OFF or now - stopping_since > self._stop_wait
            ):
                self.finished.set()
                return
            # absolute ticks, so telemetry keeps its rate; then the end of the loop's next
            # cycle: this thread's work (it holds the GIL) falls in the idle rest of that
            # period, not on the loop's wake-up (benchmarks/bench_telemetry.py)
            next_tick = max(next_tick + self.links.tick, time.monotonic())
            time.sleep(max(0.0, next_tick - time.monotonic()))
            self._cycle_done.clear()
            self._cycle_done.wait(2.0 * self.model.control.period)

    def _drain_events(self) -> None:
        d = self.data
        while d.events:
            t, text = d.events.popleft()
            self.say(f"[t={t:9.3f}] {text}")
            self.links.event(t, text)
        while d.faults:
            self.report.faults[d.faults.popleft()[1].value] += 1
        if d.fault_reason != self._last_fault:  # a fault, or its reset (telemetry only)
            self._last_fault = d.fault_reason
            self.links.event(d.time, d.fault_reason, "fault")

    def say(self, text: str, err: bool = False) -> None:
        """A line to the operator: stdout (or ``err``: stderr), flushed (journald reads it)."""
        print(text, file=sys.stderr if err else self.out, flush=True)

