"""The Zenoh gateway: a process of its own beside the loop's process, so that no publication,
query or command flood can take the loop's CPU time or its GIL. It reads the loop's state
from shared memory (:mod:`snapshot`), publishes ``state``, ``timing`` and ``events``, answers
``status`` queries, validates commands (:mod:`validate`) and passes the accepted ones to the
daemon through a bounded queue; each command gets a reply on ``<prefix>/reply/<kind>``."""

from __future__ import annotations

import json
import math
import os
import queue
import sys
import threading
import time
from typing import Any

from cdprctl.model.robot import RobotModel
from cdprctl.telemetry.helper import Deadlines, paced
from cdprctl.telemetry.snapshot import STATES, SharedSnapshot
from cdprctl.telemetry.zenoh.refusals import log_refusals, refuses_anybody
from cdprctl.telemetry.zenoh.schema import (
    SCHEMA,
    clearance_parts,
    encode,
    event_payload,
    pose_payload,
    safety_payload,
    state_payload,
    timing_payload,
)
from cdprctl.telemetry.zenoh.security import UNAUTHENTICATED_WARNING
from cdprctl.telemetry.zenoh.validate import CommandError, CommandValidator


def gateway_main(
    model: RobotModel,
    shm_name: str,
    cmd_q: Any,
    evt_q: Any,
    stop: Any,
    ready: Any,
    summary: dict[str, Any],
    said: Any = None,
) -> None:
    """Runs until ``stop`` is set or the daemon's process is gone; whom its session reached
    goes to ``said`` (a queue: the daemon says it) before ``ready`` is set."""
    from cdprctl.core.realtime import loop_cpu, yield_to_the_loop

    yield_to_the_loop(loop_cpu(model.control.cpu))  # best effort: a warning changes nothing
    Gateway(model, shm_name, cmd_q, evt_q, stop, summary).run(ready, said)


class CommandLog:
    """One line per command on stderr (journald): every accepted one but a held jog's
    repeats (the first of a run, then none while they keep coming within 1 s); rejected ones
    at most 20 a second, then how many more, so a flood cannot flood the journal."""

    def __init__(self) -> None:
        self.second, self.lines, self.suppressed = -1, 0, 0
        self.jog = -math.inf

    def __call__(self, kind: str, request_id: Any, ok: bool, text: str) -> None:
        if kind == "jog" and ok:
            now, last = time.monotonic(), self.jog
            self.jog = now
            if now - last < 1.0:
                return
        second = int(time.monotonic())
        if second != self.second:
            if self.suppressed:
                line = f"cdprctl-zenoh: {self.suppressed} more commands rejected in the last second"
                print(line, file=sys.stderr, flush=True)
            self.second, self.lines, self.suppressed = second, 0, 0
        if not ok and self.lines >= 20:
            self.suppressed += 1
            return
        self.lines += 1
        verdict = "accepted" if ok else f"rejected: {text}"
        print(f"cdprctl-zenoh: command {kind} id={request_id}: {verdict}", file=sys.stderr,
              flush=True)  # fmt: skip


class Gateway:
    """The gateway's session, its publishers, subscriber and queryable, and what they share:
    the last snapshot read and its state, the fault, the commands' counts."""

    def __init__(self, model: RobotModel, shm_name: str, cmd_q: Any, evt_q: Any, stop: Any,
                 summary: dict[str, Any]):  # fmt: skip
        import zenoh

        from cdprctl.telemetry.zenoh.reach import identity
        from cdprctl.telemetry.zenoh.session import open_session

        self.zenoh = zenoh
        self.model, self.cmd_q, self.evt_q, self.stop = model, cmd_q, evt_q, stop
        self.summary = summary
        zc = self.zc = model.zenoh
        P = self.prefix = zc.key_prefix(model.name)
        if zc.config_file and refuses_anybody(zc.config_file):
            log_refusals(P)  # who Zenoh refused, from its log (docs/telemetry.md, "Security")
        elif os.environ.get("RUST_LOG"):  # Zenoh's own log, asked for: plain text for the journal
            os.environ.setdefault("NO_COLOR", "1")
            zenoh.try_init_log_from_env()
        self.parent = os.getppid()
        self.snap = SharedSnapshot(model.n_cables, shm_name, g=len(model.grippers))
        self.session = open_session(
            mode=zc.mode,
            listen=zc.listen,
            connect=zc.connect,
            multicast_scouting=zc.multicast_scouting,
            config_file=zc.config_file,
        )
        self.json = JSON = zenoh.Encoding.APPLICATION_JSON
        self.network = identity(self.session, zc)
        self.pub_state = self.session.declare_publisher(
            f"{P}/state", encoding=JSON, congestion_control=zenoh.CongestionControl.DROP
        )
        self.pub_timing = self.session.declare_publisher(f"{P}/timing", encoding=JSON)
        self.pub_events = self.session.declare_publisher(
            f"{P}/events",
            encoding=JSON,
            congestion_control=zenoh.CongestionControl.BLOCK,
            reliability=zenoh.Reliability.RELIABLE,
        )
        self.names = [c.name for c in model.cables]
        self.grip_names = [g.name for g in model.grippers]
        self.parts = clearance_parts(model)
        self.brake_test = summary.get("safety", {}).get("brake_test")
        self.validator = CommandValidator(model, zc.commands)
        self.warning = (UNAUTHENTICATED_WARNING
                        if zc.commands and zc.allow_unauthenticated_commands else "")  # fmt: skip
        self.fault, self.state = "", "init"
        self.last: Any = None  # the last snapshot read
        self.counts = {"accepted": 0, "rejected": 0}
        self.rejected_event = {"last": -1.0, "suppressed": 0}  # the events' own limit
        self.log = CommandLog()
        self.reading = threading.Lock()  # the snapshot's copy buffer is one: one reader at a time
        self.last_seq = -1.0

    def reply(self, kind: str, request_id: Any, ok: bool, text: str) -> None:
        self.log(kind, request_id, ok, text)
        body = {"schema": SCHEMA, "command": kind, "id": request_id, "ok": ok, "reason": text}
        limiter = self.rejected_event
        try:
            self.session.put(f"{self.prefix}/reply/{kind}", encode(body), encoding=self.json)
            now = time.monotonic()
            if not ok and now - limiter["last"] >= 0.05:  # a flood: 20 events/s at most
                more = f" (+{limiter['suppressed']} more rejected)" if limiter["suppressed"] else ""
                self.pub_events.put(
                    encode(event_payload(now, f"{kind} rejected: {text}{more}", "reject"))
                )
                limiter["last"], limiter["suppressed"] = now, 0
            elif not ok:
                limiter["suppressed"] += 1
        except self.zenoh.ZError:  # the session is closing: nobody to answer
            pass

    def read_snapshot(self) -> Any:
        with self.reading:
            s = self.snap.read()
        if s is not None:
            self.last = s
            self.state = STATES[int(s["state"][0])]
        return s

    def on_command(self, sample: Any) -> None:
        if self.stop.is_set():
            return
        # the state now, not at the last publication: the first command after "ready:" was
        # refused as "in state init" for seconds while a first run's warm-up held the loop
        self.read_snapshot()
        kind = str(sample.key_expr).rsplit("/", 1)[-1]
        request_id = None
        try:
            d = self.validator.parse(sample.payload.to_bytes(), kind)
            request_id = d.get("id")
            if request_id is not None and (
                not isinstance(request_id, (str, int)) or len(str(request_id)) > 64
            ):
                request_id = None
                raise CommandError("id must be a string or integer of at most 64 characters")
            cmd = self.validator.check(kind, d, self.state, self.last)
            try:
                self.cmd_q.put_nowait(cmd)
            except queue.Full:
                raise CommandError("the daemon's command mailbox is full: retry later") from None
            self.counts["accepted"] += 1
            self.reply(kind, request_id, True, "accepted")
        except CommandError as exc:
            self.counts["rejected"] += 1
            self.reply(kind, request_id, False, str(exc))
        except Exception as exc:  # a validator bug must not kill the gateway
            self.counts["rejected"] += 1
            self.reply(kind, request_id, False, f"internal error: {type(exc).__name__}: {exc}")

    def on_status(self, query: Any) -> None:
        snap_now, zc = self.last, self.zc
        body = {
            "schema": SCHEMA,
            "state": self.state,
            "fault": self.fault,
            "pose": pose_payload(snap_now) if snap_now else None,
            "safety": safety_payload(snap_now, self.brake_test) if snap_now else None,
            "config": self.summary,
            "commands": {
                "enabled": zc.commands,
                "unauthenticated": bool(zc.commands and zc.allow_unauthenticated_commands),
                **self.counts,
            },
            **({"warning": self.warning} if self.warning else {}),
            "zenoh": self.network,
        }
        query.reply(f"{self.prefix}/status", encode(body), encoding=self.json)

    def publish_state(self) -> None:
        s = self.read_snapshot()
        if s is not None and s["seq"][0] != self.last_seq:
            self.last_seq = float(s["seq"][0])
            body = state_payload(s, self.names, self.fault, self.grip_names, self.brake_test,
                                 self.parts)  # fmt: skip
            if self.warning:
                body["warning"] = self.warning
            self.pub_state.put(encode(body))

    def publish_events(self) -> None:
        """The daemon's events, as they came; a fault is kept for ``status``, the drives'
        identities (read at set-up) go into its ``config``."""
        try:
            while True:
                kind, t, text = self.evt_q.get_nowait()
                if kind == "fault":
                    self.fault = text
                if kind == "drives":
                    self.summary["drives"] = json.loads(text)
                self.pub_events.put(encode(event_payload(t, text, kind)))
        except queue.Empty:
            pass

    def run(self, ready: Any, said: Any) -> None:
        from cdprctl.telemetry.zenoh.reach import connection_line

        zc, P = self.zc, self.prefix
        sub = self.session.declare_subscriber(f"{P}/cmd/*", self.on_command)
        qbl = self.session.declare_queryable(f"{P}/status", self.on_status)
        if said is not None:
            said.put(connection_line(self.session, zc))
        ready.set()
        if zc.commands:  # after ready: a first run's compiles here are not the start's to wait for
            self.validator.warm_up()
        state = Deadlines(1.0 / zc.state_rate)
        timing = Deadlines(1.0 / zc.timing_rate)
        try:
            for now in paced(self.stop, min(state.period, timing.period),
                             lambda: os.getppid() == self.parent):  # fmt: skip
                if state.due(now):
                    self.publish_state()
                if timing.due(now) and self.last is not None:
                    self.pub_timing.put(encode(timing_payload(self.last)))
                self.publish_events()
        finally:
            sub.undeclare()
            qbl.undeclare()
            self.session.close()
            self.snap.close()
