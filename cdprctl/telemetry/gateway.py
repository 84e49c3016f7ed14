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
from cdprctl.telemetry.refusals import log_refusals, refuses_anybody
from cdprctl.telemetry.schema import (
    SCHEMA,
    encode,
    event_payload,
    pose_payload,
    safety_payload,
    state_payload,
    timing_payload,
)
from cdprctl.telemetry.security import UNAUTHENTICATED_WARNING
from cdprctl.telemetry.snapshot import STATES, SharedSnapshot
from cdprctl.telemetry.validate import CommandError, CommandValidator


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
    import zenoh

    from cdprctl.realtime import loop_cpu, yield_to_the_loop
    from cdprctl.telemetry.reach import connection_line, identity
    from cdprctl.telemetry.session import open_session

    yield_to_the_loop(loop_cpu(model.control.cpu))  # best effort: a warning changes nothing
    zc = model.zenoh
    P = zc.key_prefix(model.name)
    if zc.config_file and refuses_anybody(zc.config_file):
        log_refusals(P)  # who Zenoh refused, from its log (docs/telemetry.md, "Security")
    elif os.environ.get("RUST_LOG"):  # Zenoh's own log, asked for: plain text for the journal
        os.environ.setdefault("NO_COLOR", "1")
        zenoh.try_init_log_from_env()
    parent = os.getppid()
    snap = SharedSnapshot(model.n_cables, shm_name, g=len(model.grippers))
    session = open_session(
        mode=zc.mode,
        listen=zc.listen,
        connect=zc.connect,
        multicast_scouting=zc.multicast_scouting,
        config_file=zc.config_file,
    )
    JSON = zenoh.Encoding.APPLICATION_JSON
    network = identity(session, zc)
    pub_state = session.declare_publisher(
        f"{P}/state", encoding=JSON, congestion_control=zenoh.CongestionControl.DROP
    )
    pub_timing = session.declare_publisher(f"{P}/timing", encoding=JSON)
    pub_events = session.declare_publisher(
        f"{P}/events",
        encoding=JSON,
        congestion_control=zenoh.CongestionControl.BLOCK,
        reliability=zenoh.Reliability.RELIABLE,
    )
    names = [c.name for c in model.cables]
    grip_names = [g.name for g in model.grippers]
    brake_test = summary.get("safety", {}).get("brake_test")
    validator = CommandValidator(model, zc.commands)
    warning = UNAUTHENTICATED_WARNING if zc.commands and zc.allow_unauthenticated_commands else ""
    shared: dict[str, Any] = {"fault": "", "state": "init", "last": None}
    counts = {"accepted": 0, "rejected": 0}
    limiter = {"last": -1.0, "suppressed": 0}
    log_limit = {"second": -1, "lines": 0, "suppressed": 0, "jog": -math.inf}

    def log(kind: str, request_id: Any, ok: bool, text: str) -> None:
        """One line per command on stderr (journald): every accepted one but a held jog's
        repeats (the first of a run, then none while they keep coming within 1 s); rejected
        ones at most 20 a second, then how many more, so a flood cannot flood the journal."""
        if kind == "jog" and ok:
            now, last = time.monotonic(), log_limit["jog"]
            log_limit["jog"] = now
            if now - last < 1.0:
                return
        second = int(time.monotonic())
        if second != log_limit["second"]:
            if log_limit["suppressed"]:
                n = log_limit["suppressed"]
                line = f"cdprctl-zenoh: {n} more commands rejected in the last second"
                print(line, file=sys.stderr, flush=True)
            log_limit.update(second=second, lines=0, suppressed=0)
        if not ok and log_limit["lines"] >= 20:
            log_limit["suppressed"] += 1
            return
        log_limit["lines"] += 1
        verdict = "accepted" if ok else f"rejected: {text}"
        line = f"cdprctl-zenoh: command {kind} id={request_id}: {verdict}"
        print(line, file=sys.stderr, flush=True)

    def reply(kind: str, request_id: Any, ok: bool, text: str) -> None:
        log(kind, request_id, ok, text)
        body = {"schema": SCHEMA, "command": kind, "id": request_id, "ok": ok, "reason": text}
        try:
            session.put(f"{P}/reply/{kind}", encode(body), encoding=JSON)
            now = time.monotonic()
            if not ok and now - limiter["last"] >= 0.05:  # a flood: 20 events/s at most
                more = f" (+{limiter['suppressed']} more rejected)" if limiter["suppressed"] else ""
                pub_events.put(
                    encode(event_payload(now, f"{kind} rejected: {text}{more}", "reject"))
                )
                limiter["last"], limiter["suppressed"] = now, 0
            elif not ok:
                limiter["suppressed"] += 1
        except zenoh.ZError:  # the session is closing: nobody to answer
            pass

    reading = threading.Lock()  # the snapshot's copy buffer is one: one reader at a time

    def read_snapshot() -> Any:
        with reading:
            s = snap.read()
        if s is not None:
            shared["last"] = s
            shared["state"] = STATES[int(s["state"][0])]
        return s

    def on_command(sample: Any) -> None:
        if stop.is_set():
            return
        # the state now, not at the last publication: the first command after "ready:" was
        # refused as "in state init" for seconds while a first run's warm-up held the loop
        read_snapshot()
        kind = str(sample.key_expr).rsplit("/", 1)[-1]
        request_id = None
        try:
            d = validator.parse(sample.payload.to_bytes(), kind)
            request_id = d.get("id")
            if request_id is not None and (
                not isinstance(request_id, (str, int)) or len(str(request_id)) > 64
            ):
                request_id = None
                raise CommandError("id must be a string or integer of at most 64 characters")
            cmd = validator.check(kind, d, shared["state"], shared["last"])
            try:
                cmd_q.put_nowait(cmd)
            except queue.Full:
                raise CommandError("the daemon's command mailbox is full: retry later") from None
            counts["accepted"] += 1
            reply(kind, request_id, True, "accepted")
        except CommandError as exc:
            counts["rejected"] += 1
            reply(kind, request_id, False, str(exc))
        except Exception as exc:  # a validator bug must not kill the gateway
            counts["rejected"] += 1
            reply(kind, request_id, False, f"internal error: {type(exc).__name__}: {exc}")

    def on_status(query: Any) -> None:
        snap_now = shared["last"]
        body = {
            "schema": SCHEMA,
            "state": shared["state"],
            "fault": shared["fault"],
            "pose": pose_payload(snap_now) if snap_now else None,
            "safety": safety_payload(snap_now, brake_test) if snap_now else None,
            "config": summary,
            "commands": {
                "enabled": zc.commands,
                "unauthenticated": bool(zc.commands and zc.allow_unauthenticated_commands),
                **counts,
            },
            **({"warning": warning} if warning else {}),
            "zenoh": network,
        }
        query.reply(f"{P}/status", encode(body), encoding=JSON)

    sub = session.declare_subscriber(f"{P}/cmd/*", on_command)
    qbl = session.declare_queryable(f"{P}/status", on_status)
    if said is not None:
        said.put(connection_line(session, zc))
    ready.set()
    if zc.commands:  # after ready: a first run's compiles here are not the start's to wait for
        validator.warm_up()
    state_dt = 1.0 / zc.state_rate
    timing_dt = 1.0 / zc.timing_rate
    next_state = next_timing = time.monotonic()
    last_seq = -1.0
    try:
        while not stop.is_set() and os.getppid() == parent:
            now = time.monotonic()
            if now >= next_state:
                s = read_snapshot()
                if s is not None and s["seq"][0] != last_seq:
                    last_seq = float(s["seq"][0])
                    body = state_payload(s, names, shared["fault"], grip_names, brake_test)
                    if warning:
                        body["warning"] = warning
                    pub_state.put(encode(body))
                next_state += state_dt
                if next_state < now:  # a stall: no burst
                    next_state = now + state_dt
            if now >= next_timing:
                if shared["last"] is not None:
                    pub_timing.put(encode(timing_payload(shared["last"])))
                next_timing = max(next_timing + timing_dt, now)
            try:
                while True:
                    kind, t, text = evt_q.get_nowait()
                    if kind == "fault":
                        shared["fault"] = text
                    if kind == "drives":  # their identities, read at set-up: in status too
                        summary["drives"] = json.loads(text)
                    pub_events.put(encode(event_payload(t, text, kind)))
            except queue.Empty:
                pass
            time.sleep(max(0.0, min(next_state, next_timing) - time.monotonic()))
    finally:
        sub.undeclare()
        qbl.undeclare()
        session.close()
        snap.close()
