"""``cdprctl run``: the controller daemon.

Start-up (config checked, drives configured, pose estimated and checked holdable), then the
fixed-rate loop in the main thread. A second thread does all I/O: the status line, the events
the loop queued, the demo's commands, the systemd watchdog. SIGTERM/SIGINT: a controlled stop
(decelerate, disable the drives: the brakes hold), exit code 0.

With ``--sim`` the simulated robot of ``sim_backend`` runs in this process on the ``inprocess``
CAN interface, stepped by the loop right after each cycle's write: what a newcomer runs to see
the whole system. Without it the drives are real (or ``cdprctl sim`` in another process, met
through ``--can-interface/--can-channel``).
"""

from __future__ import annotations

import collections
import json
import logging
import signal
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.control.commands import Command, CommandKind
from cdprctl.control.data import PHASES
from cdprctl.control.loop import LoopStats
from cdprctl.control.manager import ControllerManager
from cdprctl.control.states import State
from cdprctl.daemon import rt
from cdprctl.daemon.sdnotify import Watchdog, notify, watchdog_interval
from cdprctl.model.robot import RobotModel

LOG = logging.getLogger("cdprctl")
NOT_CALIBRATED = 4  # exit code: no valid calibration record (systemd: no restart)


class Daemon:
    def __init__(
        self,
        model: RobotModel,
        sim: bool,
        overrides: dict[str, Any],
        realtime: bool = True,
        status_every: float = 0.5,
        out: Any = None,
        zenoh: bool = False,
        timing_file: str | None = None,
        state_dir: str | None = None,
        foxglove: str | None = None,
    ):
        """``state_dir``: where the calibration record is (default
        ``/var/lib/cdprctl/<robot>``); not read when the encoders are trusted to read zero at
        home (``[drives] assume_home_at_start``, or the simulated robot of ``sim``, which
        starts there). ``foxglove``: ``[HOST:]PORT`` of the live 3D view (or ``[foxglove]
        listen`` in the config)."""
        from cdprctl.calibration.record import default_state_dir
        from drivers import create_driver

        self.state_dir = Path(state_dir) if state_dir else default_state_dir(model.name)
        self.assume_home = sim or model.drives.assume_home_at_start
        self.record: Any = None

        self.model = model
        self.sim = None
        self.out = out if out is not None else sys.stdout
        self.status_every = status_every
        self.timing_file = timing_file  # the loop's per-cycle timing is saved there at exit
        self._cycle_done = threading.Event()  # set by the loop after each cycle
        self.realtime = realtime
        period = model.control.period
        if sim:
            from sim_backend.network import SimNetwork
            from sim_backend.plant import CdprPlant

            channels = [
                f"cdprctl-sim-{uuid.uuid4().hex[:8]}-{b}" for b in range(len(model.drives.buses))
            ]
            overrides = {"interface": "inprocess", "channels": channels}
            self.plant = CdprPlant(model)
            sim_net = SimNetwork(model, self.plant, overrides)
            self.sim = sim_net

            def wait(dt: float) -> None:  # start-up calls: the simulated robot keeps time
                sim_net.advance(dt)
                time.sleep(dt)

            self.driver = create_driver(model, period=period, wait=wait, bus_overrides=overrides)
        else:
            self.driver = create_driver(model, period=period, bus_overrides=overrides)
        self.manager = ControllerManager(model, self.driver)
        self.controller = self.manager.controller
        self.stats = LoopStats(phases=len(PHASES))
        self.stop_requested = threading.Event()
        self.finished = threading.Event()
        self.summary: dict[str, Any] = {}
        self._errors: list[float] = []
        self._true_errors: list[float] = []  # m, the simulated platform against the reference
        self._last_t: float | None = None
        self._last_fault = ""  # the fault the links were last told of
        self._path: tuple[str, str] | None = None  # --path: (name, text)
        self._path_sent = self._enable_sent = False
        self._path_cycle = 0
        self._plan: Any = None  # --path's, checked before the drives were enabled
        self._stop_deadline = float("inf")
        self.faults: collections.Counter[str] = collections.Counter()
        self.link: Any = None
        if zenoh or model.zenoh.enabled:
            from cdprctl.telemetry.link import TelemetryLink

            self.link = TelemetryLink(model, self._config_summary())
        self.view: Any = None
        listen = foxglove or model.foxglove.listen
        if listen:
            from cdprctl.model.foxglove import parse_listen
            from cdprctl.telemetry.foxglove_view import FoxgloveLink

            self.view = FoxgloveLink(model, *parse_listen(listen))

    # -- the loop thread ---------------------------------------------------------------------------
    def _step_sim(self, t: float) -> None:
        if self.sim is not None:
            # the simulated robot follows the loop's clock, skipped periods included: the
            # last cycle's frames handled at the time they were sent, then the physics up to
            # this cycle. (Stepped after the cycle instead, every frame was handled a cycle's
            # time late: after a late cycle the drives took a three-period target step at the
            # last interval and faulted on their following error, `--sim --no-realtime` under
            # load)
            # The frames were sent when the last cycle's computation ended (the targets are
            # for that instant: drivers/cia402 carries them to it), not when it started.
            dt = 0.0 if self._last_t is None else t - self._last_t
            sent = 0.0 if self._last_t is None else self.driver.sent_at - self._last_t
            self._last_t = t
            # all of a stall (capped at 0.05 s, the simulated robot fell behind the loop by the
            # rest of a longer one, and its drives saw the next SYNC as a target step)
            self.sim.advance(min(max(dt, 0.0), self.sim.MAX_CATCH_UP), sent_after=sent)

    def run(
        self,
        duration: float | None,
        demo: bool,
        force: float = 0.0,
        path: tuple[str, str] | None = None,
    ) -> int:
        """``path``: (name, text) of a path file to play once (enable, the path, disable);
        checked whole before the drives are enabled (exit 2 when rejected)."""
        c = self.controller
        self._path = path
        self._print(
            f"cdprctl run: {self.model.name}, {self.model.n_cables} "
            f"{self.model.drives.driver} drives, {self.model.control.rate:g} Hz, TDA "
            f"{c.tda.options.method.value}" + (", simulated robot" if self.sim else "")
        )
        self._print(self._gains_line())
        if self.link is not None:
            if not self.link.start():
                self._print("cdprctl run: the Zenoh gateway did not start in 20 s", err=True)
                self._close_links()
                self.driver.shutdown()
                return 1
            zc = self.model.zenoh
            if zc.commands and zc.allow_unauthenticated_commands:
                from cdprctl.telemetry.security import UNAUTHENTICATED_WARNING

                self._print(f"warning: {UNAUTHENTICATED_WARNING}", err=True)
            self._print(
                f"zenoh: {zc.key_prefix(self.model.name)}/{{state,timing,events,status}}, "
                f"commands {'on' if zc.commands else 'off'}"
                + (f", listening on {', '.join(zc.listen)}" if zc.listen else "")
            )
        if self.view is not None:
            if not self.view.start():
                self._print(f"cdprctl run: the Foxglove view did not start on "
                            f"{self.view.host}:{self.view.port} in 20 s", err=True)  # fmt: skip
                self._close_links()
                self.driver.shutdown()
                return 1
            self._print(
                f"foxglove: ws://{self.view.host}:{self.view.port} — the live 3D view "
                "(open it in Foxglove: docs/foxglove.md)"
            )
        # real-time settings next (the gateway, started before, keeps its own CPU affinity);
        # locking memory and freezing the collector take a while,
        # and once the drives are started their heartbeats are watched
        warnings = []
        if self.realtime:
            rc = self.model.control
            warnings = rt.apply_realtime(rc.sched_priority, rc.cpu, rc.lock_memory, rc.freeze_gc)
        for w in warnings:
            self._print(f"warning: {w}", err=True)
        from cdprctl.calibration.record import CalibrationError
        from cdprctl.calibration.startup import how_to_calibrate, load_record

        if self.assume_home:
            self._print(
                "encoders: taken as zero at the home pose ("
                + ("the simulated robot starts there" if self.sim else
                   "[drives] assume_home_at_start = true") + ")"
            )  # fmt: skip
        else:
            try:
                self.record = load_record(self.model, self.state_dir)
            except CalibrationError as exc:
                return self._refuse(str(exc))
            r = self.record
            self._print(f"calibration: {r.method} of {r.time} ({self.state_dir})")
        self._print(
            "start-up: loading the compiled kernels (the first run on a machine compiles "
            "them: about a minute), configuring the drives, estimating the pose"
        )
        try:
            self.manager.startup(calibration=None if self.assume_home else self._calibration)
        except CalibrationError as exc:
            return self._refuse(str(exc))
        except Exception as exc:  # start-up failures are reported, never a traceback
            hint = "" if self.assume_home else f" ({how_to_calibrate(self.model, self.state_dir)})"
            self._print(f"cdprctl run: start-up failed: {exc}{hint}", err=True)
            self.driver.shutdown()
            self._close_links()
            return 1
        for w in self.driver.warnings:
            self._print(f"warning: {w}", err=True)
        self._report_identities()
        if path is not None and not self._check_path(*path):
            self.driver.shutdown()
            if self.sim is not None:
                self.sim.close()
            self._close_links()
            return 2
        p = c.estimator.position
        self._print(
            f"ready: pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m, holding tensions "
            f"{c.hold_tensions.min():.1f}..{c.hold_tensions.max():.1f} N"
        )
        notify("READY=1")
        old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
        io = threading.Thread(
            target=self._io, args=(duration, demo, force), name="cdprctl-io", daemon=True
        )
        wd = None
        interval = watchdog_interval()
        if interval:
            wd = Watchdog(lambda: c.cycle, interval, on_start=self._helper_thread)
            wd.start()
        io.start()
        try:
            self.manager.run(
                self._should_stop,
                self.stats,
                after=self._cycle_done.set,
                plant_step=self._step_sim if self.sim is not None else None,
            )
        finally:
            if self.realtime:
                rt.restore_gc()
            for s, h in old.items():
                signal.signal(s, h)
            if wd is not None:
                wd.stop()
            if self.timing_file:
                self.stats.save(self.timing_file, self.model.control.period)
            notify("STOPPING=1")
            io.join(timeout=2.0)
            self.driver.shutdown()
            if self.sim is not None:
                self.sim.close()
        self._drain_events()
        self._close_links()
        self._report()
        if path is not None and not self.stop_requested.is_set():
            self._print(f"path {path[0]}: {c.data.path_state or 'not run'}")
            return 0 if c.data.path_state == "done" else 3
        return 0 if c.state is not State.FAULT or self.stop_requested.is_set() else 3

    def _close_links(self) -> None:
        if self.link is not None:
            self.link.close()
        if self.view is not None:
            self.view.close()

    def _check_path(self, name: str, text: str) -> bool:
        """The whole path from the pose start-up found, before any motion."""
        from cdprctl.motion.path_file import PathFileError
        from cdprctl.motion.path_plan import PathRejectedError, plan_text

        c = self.controller
        try:
            plan = plan_text(self.model, text, c.trajectory.position.copy(),
                             self.model.control.period, c.limits, name)  # fmt: skip
        except (PathFileError, PathRejectedError) as exc:
            self._print(f"cdprctl run: path {name} rejected: {exc}", err=True)
            return False
        self._print(f"path {name}: {plan.summary()}")
        self._plan = plan
        return True

    def _path_step(self) -> bool:
        """Plays ``--path``: enable, send it, and True once it ended (done, or stopped)."""
        c, d = self.controller, self.controller.data
        assert self._path is not None
        if not self._path_sent:
            if c.state is State.READY:
                if not self._enable_sent:
                    c.submit(Command(CommandKind.ENABLE))
                    self._enable_sent = True
            elif c.state is State.ENABLED and c.trajectory.finished:
                name, text = self._path
                c.submit(Command(CommandKind.PATH, text=text, name=name, plan=(self._plan, 0)))
                self._path_sent = True
                self._path_cycle = c.cycle
            elif c.state is State.FAULT:
                return True
            return False
        if c.state is State.FAULT:
            return True
        if c.cycle < self._path_cycle + 3:  # the loop has not taken it yet
            return False
        return d.path_state in ("done", "aborted", "stopped", "") and c.state is State.ENABLED

    def _calibration(self, driver: Any) -> tuple[np.ndarray, np.ndarray]:
        """The record's offsets, once the configured drives match it (``Manager.startup``)."""
        from cdprctl.calibration.startup import check_drives, offsets

        check_drives(self.model, self.record, driver)
        return offsets(self.record)

    def _refuse(self, why: str) -> int:
        """No enable without a valid calibration: the drives stay disabled (brakes on)."""
        from cdprctl.calibration.startup import how_to_calibrate

        self._print(
            f"cdprctl run: refusing to enable the drives: {why}; "
            f"{how_to_calibrate(self.model, self.state_dir)}",
            err=True,
        )
        self.driver.shutdown()
        self._close_links()
        return NOT_CALIBRATED

    # after a signal the I/O thread ends the run with a controlled stop; if it cannot (it died
    # or hangs), the loop ends this long after the signal: the drives' communication timeout
    # then stops them, and shutdown() disables them
    STOP_FALLBACK = 5.0  # s

    def _on_signal(self, signum: int, frame: Any) -> None:
        if not self.stop_requested.is_set():
            self._stop_deadline = time.monotonic() + self.STOP_FALLBACK
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

    def _io(self, duration: float | None, demo: bool, force: float) -> None:
        self._helper_thread()
        try:
            self._io_loop(duration, demo, force)
        except Exception as exc:  # the I/O thread must not die silently: stop the run
            self._print(f"cdprctl run: I/O thread failed: {type(exc).__name__}: {exc}", err=True)
            self.controller.submit(Command(CommandKind.DISABLE))
            time.sleep(0.5)
            self.finished.set()

    def _io_loop(self, duration: float | None, demo: bool, force: float) -> None:
        c = self.controller
        t0 = time.monotonic()
        script = demo_script(self.model, force) if demo else []
        next_status = 0.0
        stopping_since: float | None = None
        self._enable_sent = False
        path_over = False
        link = self.link
        tick = 0.05 if link is None else min(0.05, 1.0 / self.model.zenoh.state_rate)
        view = self.view
        if view is not None:
            tick = min(tick, 1.0 / self.model.foxglove.rate)
        from cdprctl.telemetry.snapshot import controller_values
        next_tick = time.monotonic()
        while True:
            now = time.monotonic() - t0
            self._drain_events()
            due = view is not None and view.due()
            if link is not None or due:  # the loop's values, once for both
                true = self.plant.position if self.sim is not None else None
                values = controller_values(c.data, true)
                if due:
                    view.write(values)
                if link is not None:
                    link.publish(values, self.stats)
            if link is not None:
                for cmd in link.take_commands():
                    if not c.submit(cmd):
                        link.event(c.time, f"command {cmd.kind} dropped: mailbox full", "reject")
            while script and script[0][0] <= now:
                _, action = script.pop(0)
                action(self)
            if c.state in (State.ENABLED, State.MOVING):
                e = c.estimator
                err = float(np.linalg.norm(c.trajectory.position[:3] - e.position))
                self._errors.append(err)
                if self.sim is not None:  # the truth the simulator knows
                    ref = c.trajectory.position[:3]
                    self._true_errors.append(float(np.linalg.norm(ref - self.plant.position)))
            if self.status_every and now >= next_status:
                self._status_line(now)
                next_status += self.status_every
            if demo and not script and duration is not None and c.state is State.FAULT:
                c.submit(Command(CommandKind.RESET))  # a long demo run carries on after a fault
            if demo and not script and duration is not None and c.state is State.READY:
                # with --duration the demo plays again while a whole round still fits
                again = demo_script(self.model, force)
                if now + again[-1][0] < duration:
                    script = [(now + at, action) for at, action in again]
            if self._path is not None and not path_over:
                path_over = self._path_step()
            end = path_over or (duration is not None and now >= duration) or (
                demo and not script and duration is None and c.state in (State.READY, State.FAULT)
            )
            if (end or self.stop_requested.is_set()) and stopping_since is None:
                stopping_since = now
                if c.state in (State.ENABLED, State.MOVING, State.ENABLING):
                    c.submit(Command(CommandKind.STOP))
                    c.submit(Command(CommandKind.DISABLE))
            if stopping_since is not None and (
                c.state in (State.READY, State.FAULT, State.INIT) or now - stopping_since > 3.0
            ):
                self.finished.set()
                return
            # absolute ticks, so telemetry keeps its rate; then the end of the loop's next
            # cycle: this thread's work (it holds the GIL) falls in the idle rest of that
            # period, not on the loop's wake-up (benchmarks/bench_telemetry.py)
            next_tick = max(next_tick + tick, time.monotonic())
            time.sleep(max(0.0, next_tick - time.monotonic()))
            self._cycle_done.clear()
            self._cycle_done.wait(2.0 * self.model.control.period)

    def _drain_events(self) -> None:
        d = self.controller.data
        while d.events:
            t, text = d.events.popleft()
            self._print(f"[t={t:9.3f}] {text}")
            if self.link is not None:
                self.link.event(t, text)
            if self.view is not None:
                self.view.event(t, text)
        while d.faults:
            self.faults[d.faults.popleft()[1].value] += 1
        if d.fault_reason != self._last_fault:  # a fault, or its reset (telemetry only)
            self._last_fault = d.fault_reason
            if self.link is not None:
                self.link.event(d.time, d.fault_reason, "fault")
            if self.view is not None and d.fault_reason:
                self.view.event(d.time, d.fault_reason, "fault")

    def _status_line(self, now: float) -> None:
        c = self.controller
        e = c.estimator
        # percentiles over the cycles since the last line (the whole run: in the summary)
        s = self.stats.summary(round(self.status_every / self.model.control.period))
        sim = ""
        if self.sim is not None:
            true = self.plant.position
            sim = f" true [{true[0]:.3f} {true[1]:.3f} {true[2]:.3f}]"
        self._print(
            f"t={now:6.1f}s {c.state.value:<9} P [{e.position[0]:.3f} {e.position[1]:.3f} "
            f"{e.position[2]:.3f}] m{sim} err {np.linalg.norm(c.pose_error[:3]) * 1e3:5.2f} mm "
            f"t {c.tensions.min():5.1f}..{c.tensions.max():5.1f} N tda {c.tda_status.name}"
            + (f" sat {c.data.saturation:.2f}" if c.data.saturation < 1.0 else "")
            + (f" path {c.data.path_segment}/{c.data.path_segments} "
               f"{c.data.path_fraction:.0%} {c.data.path_state}" if c.data.path_segments else "")
            + " "
            f"late p99 {s.get('lateness_p99_us', 0):6.0f} us missed {int(s.get('missed', 0))}"
        )

    def _report(self) -> None:
        s = self.stats.summary()
        c = self.controller
        errs = np.array(self._errors) if self._errors else np.zeros(1)
        per_phase = self.stats.phases[: min(self.stats.count, self.stats.size)]
        phases = (
            {
                name: (float(np.median(per_phase[:, k])), float(np.percentile(per_phase[:, k], 99)))
                for k, name in enumerate(PHASES)
            }
            if len(per_phase)
            else {}
        )
        self.summary = {
            "loop": s,
            "phases_us": phases,
            "tracking_rms_mm": float(np.sqrt(np.mean(errs**2)) * 1e3),
            "tracking_max_mm": float(errs.max() * 1e3),
            **(
                {
                    "true_tracking_rms_mm": float(np.sqrt(np.mean(np.square(self._true_errors))))
                    * 1e3,
                    "true_tracking_max_mm": float(np.max(self._true_errors)) * 1e3,
                }
                if self._true_errors
                else {}
            ),
            "final_state": c.state.value,
            "fault": c.fault_reason,
            "driver": self.driver.stats.as_dict(),
            "faults": dict(self.faults),
            "saturated_cycles": c.data.saturated_cycles,
        }
        self._print("summary:")
        self._print(
            f"  cycles {int(s.get('cycles', 0))}, wake lateness p50 "
            f"{s.get('lateness_p50_us', 0):.1f} us, p99 {s.get('lateness_p99_us', 0):.1f}"
            f" us, max {s.get('lateness_max_us', 0):.0f} us; compute p50 "
            f"{s.get('compute_p50_us', 0):.0f} us, p99 {s.get('compute_p99_us', 0):.0f} "
            f"us; overruns {int(s.get('overruns', 0))}, missed periods "
            f"{int(s.get('missed', 0))} ({s.get('missed_percent', 0):.3f} %)"
        )
        if "sim_step_p50_us" in s:
            self._print(
                f"  the simulated robot's step before each cycle (not in compute): p50 "
                f"{s['sim_step_p50_us']:.0f} us, p99 {s['sim_step_p99_us']:.0f} us"
            )
        if phases:
            self._print(
                "  per phase (median/p99 us): "
                + ", ".join(f"{k} {v[0]:.0f}/{v[1]:.0f}" for k, v in phases.items())
            )
        if c.data.saturated_cycles:
            self._print(
                f"  feedback saturated in {c.data.saturated_cycles} cycles (the cables gave "
                "what they could: docs/control.md)"
            )
        if self.faults:
            self._print(
                "  faults handled: " + ", ".join(f"{k} {n}" for k, n in self.faults.most_common())
            )
        if self._true_errors:
            self._print(
                f"  tracking error (the simulated platform) RMS "
                f"{self.summary['true_tracking_rms_mm']:.2f} mm, max "
                f"{self.summary['true_tracking_max_mm']:.2f} mm"
            )
        self._print(
            f"  tracking error (estimated) RMS {self.summary['tracking_rms_mm']:.2f} mm, "
            f"max {self.summary['tracking_max_mm']:.2f} mm; final state "
            f"{c.state.value}" + (f" ({c.fault_reason})" if c.fault_reason else "")
        )

    def _gains_line(self) -> str:
        """Where the loop's gains come from: in position mode all from the model."""
        c, m = self.controller, self.model
        if m.drives.holds_lengths:
            cs = c.cable_space
            torque = ", ".join(m.cables[i].name for i in m.drives.torque_cables)
            return (
                f"gains from the model: drives hold the lengths (csp, position loops "
                f"{m.drives.position_loop_bandwidth:g} Hz on each rotor's inertia"
                + (f"; cables {torque} in torque mode, their grippers'" if torque else "")
                + f"), force feedback {cs.iff:.1f} rad/s (the lowest mode × "
                f"{m.control.force_feedback:g}), external-wrench estimate "
                f"{cs.disturbance_bandwidth:.3g} Hz"
            )
        return (
            "gains: torque mode, the pose loop at [control] bandwidth "
            + "/".join(f"{x:.2g}" for x in c.pose.bandwidth)
            + " Hz (x y z roll pitch yaw; set by hand: "
            'docs/control.md, "Gains from the model")'
        )

    def _report_identities(self) -> None:
        """The drives' identities (0x1018, read at set-up): printed, and in status."""
        identities = getattr(self.driver, "identities", None)
        nodes = getattr(self.driver, "node", None)
        if not identities or nodes is None:
            return
        drives = []
        for c, ident in enumerate(identities):
            node = int(nodes[c])
            drives.append({"cable": self.model.cables[c].name, "node": node, **(ident or {})})
            if ident:
                text = ", ".join(f"{k} 0x{v:08X}" for k, v in ident.items())
            else:
                text = "no identity object"
            self._print(f"drive of cable index {c} (node {node}): {text}")
        if self.link is not None:
            self.link.event(self.controller.time, json.dumps(drives), "drives")

    def _config_summary(self) -> dict[str, Any]:
        import cdprctl
        from cdprctl.telemetry.scene import SceneLayout

        m, c = self.model, self.model.control
        return {
            "robot": m.name,
            "config_file": m.source_file,
            "cables": [w.name for w in m.cables],
            "tension_min": m.tension_min.tolist(),
            "tension_max": m.tension_max.tolist(),
            "torque_limit": [w.winch.torque_limit for w in m.cables],
            "rate_hz": c.rate,
            "tda": c.tda_method,
            "limits": {  # what a jog may ask (control/jog.py)
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
            "simulated": self.sim is not None,
            "versions": {"cdprctl": getattr(cdprctl, "__version__", "?"), **_versions()},
        }

    def _print(self, text: str, err: bool = False) -> None:
        print(text, file=sys.stderr if err else self.out, flush=True)


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("eclipse-zenoh", "python-can", "ruckig", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "?"
    return out


def demo_targets(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """The demo's two move targets (m, base frame): 0.3 m along x and 0.1 m down, 0.2 m back
    along x, from home, within the workspace."""
    home = model.home.position
    lo, hi = model.workspace.position_min, model.workspace.position_max
    a = np.clip(home + np.array([0.3, 0.0, -0.1]), lo, hi)
    b = np.clip(home + np.array([-0.2, 0.0, 0.0]), lo, hi)
    return a, b


def demo_script(model: RobotModel, force: float = 0.0) -> list[tuple[float, Any]]:
    """Enable, a move and back, optionally a lateral disturbance at home (``force`` N along y,
    ramped in over 1 s like the ARK 2020 water jet; simulated robot only), a move, home,
    disable."""
    home = model.home.position
    a, b = demo_targets(model)
    rpy = model.home.rpy

    def move(p: np.ndarray) -> Any:
        pose = np.concatenate([p, rpy])
        return lambda d: d.controller.submit(Command(CommandKind.MOVE, pose=pose))

    def lateral(on: bool) -> Any:
        def act(d: Daemon) -> None:
            if d.sim is None:
                return
            from sim_backend.faults import FaultEvent, FaultInjector

            value = (0.0, force, 0.0, 0.0, 0.0, 0.0) if on else (0.0,) * 6
            FaultInjector(
                [FaultEvent(d.sim.time, "external_wrench", value=value, ramp=1.0)]
            ).attach(d.sim)
            d.controller.events.append(
                (d.controller.time, f"demo: {force:g} N lateral force " + ("on" if on else "off"))
            )

        return act

    return [
        (0.3, lambda d: d.controller.submit(Command(CommandKind.ENABLE))),
        (1.0, move(a)),
        (4.0, move(home)),
        *([(7.0, lateral(True))] if force else []),
        (10.0, move(b)),
        (13.0, move(home)),
        *([(16.0, lateral(False))] if force else []),
        (19.0, lambda d: d.controller.submit(Command(CommandKind.DISABLE))),
    ]
